//! `equiarm train` over DDS: the trainer node, an adapter around [`equiarm_train::trainer::Trainer`]
//! (which decides what to store, when to update, evaluate, checkpoint and publish weights; its docs
//! say how). Here: the training envs' `observation` topics (`--envs`), `/transitions` and
//! `/episodes` in (reliable keep-last 100), actor snapshots out on
//! `/policy/weights` (latched) and a `TrainerStatus` on `/trainer/status` once per second. Updates
//! run on tokio's blocking pool while this task keeps taking samples (a keep-last reader that is not
//! read drops samples).
//!
//! Stops at `total_updates`, on SIGINT/SIGTERM, or after `--idle-timeout-s` without transitions: it
//! first takes what is still in flight (up to 2 s), then writes a checkpoint. An error on the way
//! (a failed publish or update, a full disk) also ends with a checkpoint of the learner where it
//! can still be written.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context as _;
use equiarm_msgs::msg::{EpisodeResult, Observation, PolicyWeights, TrainerStatus, Transition};
use equiarm_sac::agent::Metrics;
use equiarm_sac::config::TrainConfig;
use equiarm_sac::learner::{Learner, LearnerError};
use equiarm_train::record::RunSummary;
use equiarm_train::trainer::{Trainer, TrainerOptions};
use log::{info, warn};
use tokio::task::JoinHandle;

use crate::ros::{Publisher, RosNode, RosOptions, Subscriber, qos};
use crate::signals::{CHECKPOINT_AND_STOP, stop_flag};
use crate::train_cli::TrainArgs;

type Update = JoinHandle<(Learner, Result<Metrics, LearnerError>)>;

/// The node's endpoints and the learner, home or away in an update.
struct Node {
    node: RosNode,
    observations: Vec<Subscriber<Observation>>,
    transitions: Subscriber<Transition>,
    episodes: Subscriber<EpisodeResult>,
    weights: Publisher<PolicyWeights>,
    status: Publisher<TrainerStatus>,
    trainer: Trainer,
    home: Option<Learner>,
    task: Option<Update>,
    /// The stop reason and the end of the final drain (what is in flight when stopping is still taken).
    stopping: Option<(&'static str, Instant)>,
}

async fn finished(task: &mut Option<Update>) -> anyhow::Result<(Learner, Result<Metrics, LearnerError>)> {
    match task.as_mut() {
        Some(t) => {
            let r = t.await.context("the update task failed");
            *task = None;
            r
        }
        None => std::future::pending().await,
    }
}

impl Node {
    async fn publish_weights(&mut self) -> anyhow::Result<()> {
        let learner = self.home.as_ref().expect("the learner is home");
        let w = self.trainer.weights(learner)?;
        self.weights.publish(w).await
    }

    /// One turn of the loop; `false` once the run is over.
    async fn turn(&mut self, signal: &AtomicBool, idle: Duration) -> anyhow::Result<bool> {
        if self.stopping.is_none() {
            let why = self.trainer.stop_reason(signal.load(Ordering::Relaxed), idle);
            self.stopping = why.map(|w| (w, Instant::now() + Duration::from_secs(2)));
        }
        let work = self.home.is_some() && self.stopping.is_none() && self.trainer.has_work();
        // Frames first: the Transitions that name them are joined as they come.
        for sub in &self.observations {
            while let Some((o, _)) = sub.recv_timeout(Duration::ZERO).await? {
                self.trainer.observation(&o);
            }
        }
        let mut got = Vec::new();
        while let Some((t, _)) = self.transitions.recv_timeout(Duration::ZERO).await? {
            got.push(Ok(t));
        }
        while let Some((r, _)) = self.episodes.recv_timeout(Duration::ZERO).await? {
            got.push(Err(r));
        }
        let mut done = None;
        if self.task.as_ref().is_some_and(|t| t.is_finished()) {
            done = Some(finished(&mut self.task).await?);
        } else if got.is_empty() && self.stopping.is_some() && self.task.is_none() {
            match self.transitions.recv_timeout(Duration::from_millis(300)).await? {
                Some((t, _)) if self.stopping.is_some_and(|s| Instant::now() < s.1) => got.push(Ok(t)),
                _ => return Ok(false),
            }
        } else if got.is_empty() && !work {
            tokio::select! {
                r = self.transitions.recv() => got.push(Ok(r?.0)),
                r = self.episodes.recv() => got.push(Err(r?.0)),
                r = finished(&mut self.task) => done = Some(r?),
                _ = tokio::time::sleep(Duration::from_millis(100)) => {}
            }
        }
        for m in got {
            match m {
                Ok(t) => self.trainer.transition(t),
                Err(r) => self.trainer.episode(r)?,
            }
        }
        if let Some((learner, m)) = done {
            let learner = self.home.insert(learner);
            if self.trainer.updated(learner, m?)? {
                self.publish_weights().await?;
            }
        }
        if let Some(learner) = self.home.as_mut() {
            let next = self.trainer.with_learner(learner, self.stopping.is_some())?;
            if next.weights {
                self.publish_weights().await?;
            }
            if next.update {
                let mut l = self.home.take().expect("home");
                self.task = Some(tokio::task::spawn_blocking(move || {
                    let m = l.update();
                    (l, m)
                }));
            }
        }
        self.trainer.check_stall(self.home.is_some() && self.stopping.is_none());
        if let Some(status) = self.trainer.status()
            && let Err(e) = self.status.publish(status).await
        {
            warn!("{e:#}");
        }
        Ok(true)
    }
}

/// Lock-step: a transition a sim sends before it has matched this trainer's reader is lost and
/// stalls every round, so the first weights (which start the envs) wait until every training env's
/// sim has been heard on its `observation` topic (a sim re-publishes its first observation until it
/// is answered; the frames go to the trainer) and `/transitions` and `/episodes` have at least `n`
/// writers each, the counts held still for a second (at most 60 s). The `/transitions` and
/// `/episodes` readers are created before the observation readers, so a sim that has matched this
/// node's observation reader has been told of them first. Counting writers alone is not enough: the
/// eval sim writes on `/transitions` too.
async fn wait_for_sims(n: &mut Node, envs: &[String], stop: &AtomicBool) -> anyhow::Result<()> {
    let (t0, mut last, mut since) = (Instant::now(), (0, 0), Instant::now());
    let mut heard = vec![false; n.observations.len()];
    loop {
        for (sub, heard) in n.observations.iter().zip(heard.iter_mut()) {
            while let Some((o, _)) = sub.recv_timeout(Duration::ZERO).await? {
                n.trainer.observation(&o);
                *heard = true;
            }
        }
        let now = (n.transitions.publisher_count(&n.node), n.episodes.publisher_count(&n.node));
        if now != last {
            (last, since) = (now, Instant::now());
        }
        let all_heard = heard.iter().all(|h| *h);
        if all_heard && now.0 >= envs.len() && now.1 >= envs.len() && since.elapsed() >= Duration::from_secs(1) {
            info!(
                "{}: every training env heard, {} writers on /transitions, {} on /episodes; starting the rounds",
                n.node.name(),
                now.0,
                now.1
            );
            return Ok(());
        }
        if stop.load(Ordering::Relaxed) || t0.elapsed() > Duration::from_secs(60) {
            let silent: Vec<&str> = envs.iter().zip(&heard).filter(|(_, h)| !**h).map(|(e, _)| e.as_str()).collect();
            warn!(
                "{}: {} writers on /transitions and {} on /episodes after {:.0} s (num_envs {}), no observation yet from [{}]; starting anyway",
                n.node.name(),
                now.0,
                now.1,
                t0.elapsed().as_secs_f64(),
                envs.len(),
                silent.join(", ")
            );
            return Ok(());
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// Runs the trainer node until `total_updates`, a signal or the idle timeout.
pub async fn run(args: &TrainArgs, cfg: TrainConfig, opts: &RosOptions) -> anyhow::Result<RunSummary> {
    let stop = stop_flag(CHECKPOINT_AND_STOP); // first: a signal while the run opens is then not lost
    let envs = args.env_namespaces(cfg.num_envs);
    let options = TrainerOptions {
        run_dir: args.run_dir(),
        resume: args.resume.clone(),
        force: args.force,
        eval_namespace: args.eval_namespace.clone(),
        envs: envs.clone(),
        deterministic: args.deterministic,
        device: args.device.clone(),
        weights_every: args.weights_every,
        progress: !args.quiet,
    };
    let (num_envs, deterministic) = (cfg.num_envs, args.deterministic);
    let (trainer, learner) = Trainer::open(cfg, options)?;
    let mut node = RosNode::new("/", "trainer", opts)?;
    // (the transition and episode readers first: see wait_for_sims)
    let transitions = node.subscription::<Transition>("/transitions", qos::stream(100))?;
    let episodes = node.subscription::<EpisodeResult>("/episodes", qos::stream(100))?;
    let topics = envs.iter().map(|ns| format!("{}/observation", ns.trim_end_matches('/')));
    let observations =
        topics.map(|t| node.subscription::<Observation>(&t, qos::command())).collect::<Result<_, _>>()?;
    let mut n = Node {
        observations,
        transitions,
        episodes,
        weights: node.publisher::<PolicyWeights>("/policy/weights", qos::latched())?,
        status: node.publisher::<TrainerStatus>("/trainer/status", qos::stream(10))?,
        node,
        trainer,
        home: Some(learner),
        task: None,
        stopping: None,
    };
    if deterministic {
        wait_for_sims(&mut n, &envs, &stop).await?;
    }
    let idle = Duration::from_secs_f64(args.idle_timeout_s.max(0.1));
    let mode = if deterministic { ", deterministic lock-step" } else { "" };
    let mut outcome = n.publish_weights().await;
    if outcome.is_ok() {
        info!("{}: waiting for transitions ({num_envs} envs, eval env '{}'{mode})", n.node.name(), args.eval_namespace);
        outcome = loop {
            match n.turn(&stop, idle).await {
                Ok(true) => {}
                Ok(false) => break Ok(()),
                Err(e) => break Err(e),
            }
        };
    }
    // Every way out ends with a checkpoint of the learner: wait for a running update to bring it home.
    let mut learner = match (n.home.take(), n.task.take()) {
        (Some(l), _) => l,
        (None, Some(task)) => task.await.context("the update task failed")?.0,
        (None, None) => unreachable!("the learner is home or in its update"),
    };
    let why = match (&outcome, n.stopping) {
        (Err(_), _) => "error",
        (Ok(()), Some((why, _))) => why,
        (Ok(()), None) => "end",
    };
    let summary = n.trainer.finish(&mut learner, why);
    outcome?;
    Ok(summary?)
}
