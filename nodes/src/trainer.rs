//! `equiarm train` over DDS: the trainer node. One [`Learner`] fed from `/transitions` and
//! `/episodes` (reliable keep-last 100) through [`Ingest`] (frames stored once, demos only from
//! successful episodes, never the eval env); actor snapshots out on `/policy/weights` (latched) and a
//! `TrainerStatus` on `/trainer/status` once per second.
//!
//! - One update per `num_envs` non-eval transitions once the replay holds `training_starts`
//!   (docs/paper.md §2). Updates run on tokio's blocking pool while this task keeps taking samples
//!   (a keep-last reader that is not read drops samples); rows received meanwhile wait in a queue and
//!   owed updates are caught up.
//! - Weights: version 1 (the initial actor) at start, then after the first update and every
//!   `--weights-every` updates.
//! - Stops at `total_updates`, on SIGINT/SIGTERM, or after `--idle-timeout-s` without transitions:
//!   it first takes what is still in flight (up to 2 s), then writes a checkpoint.
//! - `--deterministic` (lock-step, with policies run with `--deterministic`): the training envs'
//!   messages are taken in rounds ([`crate::lockstep`]): round r is every env's r-th transition, in
//!   env-name order, each followed by its episode's result when it ends one. After each round: its
//!   rows into the replay, one update once the replay is ready, then the next weights version
//!   (version r + 2; the policies answer their r-th observation with version r + 1). No weights go
//!   out after the round that reaches `total_updates`, so the envs stop there and two runs with one
//!   seed record the same transitions and end with the same weights. The first weights wait until
//!   `num_envs` sims are seen on `/transitions` and `/episodes`. The eval pair is not part of the
//!   rounds: it acts on whatever weights are current, so evaluations are not reproducible.
//!
//! ## Limitations
//! EpisodeResults count as evaluation when `eval` is set (`equiarm sim --eval`) or their env is the
//! eval env; transitions only by their env. Resume restores the learner, metrics and weights version, not held demos;
//! `--deterministic` refuses `--resume`. In lock-step a lost transition or an env that stops stalls
//! the rounds (logged with what the round waits for) until the idle timeout.

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use equiarm_msgs::builtin_interfaces::Time;
use equiarm_msgs::msg::{EpisodeResult, PolicyWeights, TrainerStatus, Transition};
use equiarm_msgs::std_msgs::Header;
use equiarm_sac::agent::Metrics;
use equiarm_sac::config::TrainConfig;
use equiarm_sac::learner::{Learner, LearnerError, read_json, write_json};
use equiarm_sac::metrics::MetricsWriter;
use equiarm_sac::replay::Stored;
use equiarm_sac::train::{EvalResult, RunSummary, find_checkpoint, step_dir_name, write_curve, write_latest};
use log::{info, warn};
use serde::{Deserialize, Serialize};
use tokio::task::JoinHandle;

use crate::ingest::{Ingest, UpdateDebt};
use crate::lockstep::{Item, Lockstep};
use crate::ros::{RosNode, RosOptions, Subscriber, qos};
use crate::train_cli::{TrainArgs, stop_flag};

/// Saved beside each checkpoint (`trainer.json`).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
struct NodeState {
    global_step: u64,
    evals: Vec<EvalResult>,
    version: u64,
}

type Update = JoinHandle<(Learner, Result<Metrics, LearnerError>)>;

fn wall_stamp() -> Header {
    let ns =
        std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_nanos() as i64).unwrap_or(0);
    Header::new(Time::from_nanos(ns), "")
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

fn start_update(home: &mut Option<Learner>) -> Option<Update> {
    let mut l = home.take()?;
    Some(tokio::task::spawn_blocking(move || {
        let m = l.update();
        (l, m)
    }))
}

/// Hands `t` to the ingest (its rows into `queue`); a refused transition is counted and logged once
/// per sender and kind of defect.
fn ingest_transition(
    ingest: &mut Ingest,
    t: &Transition,
    queue: &mut Vec<Stored>,
    bad_logged: &mut HashSet<(String, &'static str)>,
) {
    match ingest.transition(t) {
        Ok(rows) => queue.extend(rows),
        Err(e) if bad_logged.insert((t.obs.env.clone(), e.cause())) => warn!(
            "skipping a transition of '{}' (seq {}): {e} (further {} defects of this env are counted, not logged)",
            t.obs.env,
            t.obs.seq,
            e.cause()
        ),
        Err(_) => {}
    }
}

/// Hands a training env's result to the ingest (released demos into `queue`) and logs its metrics.
fn ingest_episode(
    ingest: &mut Ingest,
    r: &EpisodeResult,
    queue: &mut Vec<Stored>,
    metrics: &mut MetricsWriter,
    step: u64,
    wall_s: f64,
) -> anyhow::Result<()> {
    queue.extend(ingest.episode(r));
    let named = [
        ("charts/episodic_return", r.ret as f64),
        ("charts/discounted_return", r.discounted_return as f64),
        ("charts/episodic_length", r.steps as f64),
        ("charts/success", r.success as u8 as f64),
    ];
    metrics.log(step, wall_s, &named)?;
    Ok(())
}

/// Lock-step: counts a message the rounds refused and logs it (the 1st, 2nd, 4th, 8th, …).
fn log_refused(r: Result<(), crate::lockstep::Refused>, refused: &mut u64) {
    if let Err(e) = r {
        *refused += 1;
        if refused.is_power_of_two() {
            warn!("{e} ({refused} refused so far)");
        }
    }
}

/// Lock-step: a transition a sim sends before it has matched this trainer's reader is lost and
/// stalls every round, so the first weights (which start the envs) wait until `/transitions` and
/// `/episodes` have at least `n` writers each and their counts held still for a second (at most 60 s).
async fn wait_for_sims(
    node: &RosNode,
    tr: &Subscriber<Transition>,
    ep: &Subscriber<EpisodeResult>,
    n: usize,
    stop: &std::sync::atomic::AtomicBool,
) {
    let (t0, mut last, mut since) = (Instant::now(), (0, 0), Instant::now());
    loop {
        let now = (tr.publisher_count(node), ep.publisher_count(node));
        if now != last {
            (last, since) = (now, Instant::now());
        }
        if now.0 >= n && now.1 >= n && since.elapsed() >= Duration::from_secs(1) {
            info!("{}: {} writers on /transitions, {} on /episodes; starting the rounds", node.name(), now.0, now.1);
            return;
        }
        if stop.load(Ordering::Relaxed) || t0.elapsed() > Duration::from_secs(60) {
            warn!(
                "{}: {} writers on /transitions and {} on /episodes after {:.0} s (num_envs {n}); starting anyway",
                node.name(),
                now.0,
                now.1,
                t0.elapsed().as_secs_f64()
            );
            return;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// Runs the trainer node until `total_updates`, a signal or the idle timeout.
pub async fn run(args: &TrainArgs, cfg: TrainConfig, opts: &RosOptions) -> anyhow::Result<RunSummary> {
    if args.deterministic && args.resume.is_some() {
        anyhow::bail!(
            "--deterministic does not resume (--resume): the policies count rounds from the first weights version of a fresh run"
        );
    }
    let started = Instant::now();
    let dir = args.run_dir();
    let _claim = equiarm_sac::train::RunDirLock::acquire_for(&dir, args.resume.as_deref(), args.force)?;
    write_json(&dir.join("config.json"), &cfg)?;
    let mut learner = Learner::with_device(cfg.clone(), args.device.clone())?;
    let mut st = NodeState::default();
    let mut metrics = match &args.resume {
        Some(p) => {
            let ck = find_checkpoint(p)?;
            learner.resume(&ck)?;
            st = read_json(&ck.join("trainer.json")).unwrap_or_default();
            info!("resumed {} at {} updates", ck.display(), learner.updates());
            MetricsWriter::resume(&dir, st.global_step)?
        }
        None => MetricsWriter::create(&dir)?,
    };
    let stop = stop_flag();
    let mut node = RosNode::new("/", "trainer", opts)?;
    let tr_sub = node.subscription::<Transition>("/transitions", qos::stream(100))?;
    let ep_sub = node.subscription::<EpisodeResult>("/episodes", qos::stream(100))?;
    let weights_pub = node.publisher::<PolicyWeights>("/policy/weights", qos::latched())?;
    let status_pub = node.publisher::<TrainerStatus>("/trainer/status", qos::stream(10))?;
    let mut ingest = Ingest::new(&cfg, &args.eval_namespace);
    // Lock-step: the rounds, when the last one was handed on, the round a stall was logged for,
    // messages refused.
    let mut lockstep = args.deterministic.then(|| Lockstep::new(cfg.num_envs));
    let (mut last_round, mut stall_logged, mut refused) = (Instant::now(), None::<u64>, 0u64);
    let (mut debt, mut pending_eval, mut queue) =
        (UpdateDebt::new(cfg.num_envs, cfg.training_starts), Vec::<EpisodeResult>::new(), Vec::<Stored>::new());
    // The learner is None while an update runs; `known` is (updates, replay len, expert len, last metrics).
    let mut known = (learner.updates(), learner.replay().len(), learner.replay().expert_len(), Metrics::default());
    let (mut home, mut task): (Option<Learner>, Option<Update>) = (Some(learner), None);
    let (mut last_tr, mut last_status, mut status_counts) = (None::<Instant>, Instant::now(), (known.0, 0u64));
    let mut bad_logged = HashSet::new();
    let mut progress = (!args.quiet).then(|| equiarm_sac::progress::Progress::new(cfg.total_updates, "updates"));
    let mut last_ck = None;
    let wall = |s: &Instant| s.elapsed().as_secs_f64();
    let idle = Duration::from_secs_f64(args.idle_timeout_s.max(0.1));
    let publish_weights = async |learner: &Learner, st: &mut NodeState| -> anyhow::Result<()> {
        st.version += 1;
        let data = learner.agent().actor_bytes()?;
        let model = cfg.agent.model.name().to_string();
        let w = PolicyWeights {
            header: wall_stamp(),
            version: st.version,
            updates: learner.updates(),
            model,
            format: "safetensors".into(),
            data,
        };
        weights_pub.publish(w).await
    };
    if lockstep.is_some() {
        wait_for_sims(&node, &tr_sub, &ep_sub, cfg.num_envs, &stop).await;
    }
    publish_weights(home.as_ref().expect("home"), &mut st).await?;
    let mode = if lockstep.is_some() { ", deterministic lock-step" } else { "" };
    info!("{}: waiting for transitions ({} envs, eval env '{}'{mode})", node.name(), cfg.num_envs, args.eval_namespace);
    // Stop reason and the end of the final drain (what is in flight when stopping is still taken).
    let mut stopping: Option<(&str, Instant)> = None;
    loop {
        if stopping.is_none() {
            let why = if stop.load(Ordering::Relaxed) {
                Some("signal")
            } else if known.0 >= cfg.total_updates {
                Some("total_updates reached")
            } else {
                last_tr.is_some_and(|t: Instant| t.elapsed() > idle).then_some("idle timeout")
            };
            stopping = why.map(|w| (w, Instant::now() + Duration::from_secs(2)));
        }
        let ready = debt.ready(known.1 + queue.len());
        let round_ready = lockstep.as_ref().is_some_and(Lockstep::ready);
        let work = home.is_some() && stopping.is_none() && ((debt.owed() > 0 && ready) || round_ready);
        let mut got = Vec::new();
        while let Some((t, _)) = tr_sub.recv_timeout(Duration::ZERO).await? {
            got.push(Ok(t));
        }
        while let Some((r, _)) = ep_sub.recv_timeout(Duration::ZERO).await? {
            got.push(Err(r));
        }
        let mut done = None;
        if task.as_ref().is_some_and(|t| t.is_finished()) {
            done = Some(finished(&mut task).await?);
        } else if got.is_empty() && stopping.is_some() && task.is_none() {
            match tr_sub.recv_timeout(Duration::from_millis(300)).await? {
                Some((t, _)) if stopping.is_some_and(|s| Instant::now() < s.1) => got.push(Ok(t)),
                _ => break,
            }
        } else if got.is_empty() && !work {
            tokio::select! {
                r = tr_sub.recv() => got.push(Ok(r?.0)),
                r = ep_sub.recv() => got.push(Err(r?.0)),
                r = finished(&mut task) => done = Some(r?),
                _ = tokio::time::sleep(Duration::from_millis(100)) => {}
            }
        }
        for m in got {
            match m {
                // Lock-step: the training envs' messages wait for their round.
                Ok(t) if lockstep.is_some() && !ingest.is_eval(&t.obs.env) => {
                    last_tr = Some(Instant::now());
                    let r = lockstep.as_mut().expect("checked").transition(t);
                    log_refused(r, &mut refused);
                }
                Ok(t) => {
                    last_tr = Some(Instant::now());
                    ingest_transition(&mut ingest, &t, &mut queue, &mut bad_logged);
                    if !ingest.is_eval(&t.obs.env) {
                        st.global_step += 1;
                        debt.transition(known.1 + queue.len());
                    }
                }
                // Evaluations as in the paper: the eval pair's episodes that end once the update
                // count has reached the next multiple of eval_every; the ones in between are dropped.
                Err(r) if r.eval || ingest.is_eval(&r.env) => {
                    let due = cfg.eval_every > 0
                        && known.0 >= (st.evals.last().map_or(0, |e| e.updates) / cfg.eval_every + 1) * cfg.eval_every;
                    if due {
                        pending_eval.push(r);
                    }
                    if due && pending_eval.len() >= cfg.eval_episodes.max(1) {
                        let e = evaluation(&pending_eval, known.0);
                        pending_eval.clear();
                        let named = [
                            ("eval/success_rate", e.success_rate),
                            ("eval/discounted_return", e.discounted_return),
                            ("eval/episodic_return", e.mean_return),
                            ("eval/episodic_length", e.mean_length),
                            ("eval/updates", e.updates as f64),
                        ];
                        metrics.log(st.global_step, wall(&started), &named)?;
                        info!(
                            "evaluation at {} updates: success rate {:.2}, discounted return {:.3}",
                            e.updates, e.success_rate, e.discounted_return
                        );
                        st.evals.push(e);
                        write_curve(&dir, &cfg, &st.evals)?;
                    }
                }
                Err(r) => match lockstep.as_mut() {
                    Some(ls) => log_refused(ls.episode(r), &mut refused),
                    None => {
                        let before = known.1 + queue.len();
                        ingest_episode(&mut ingest, &r, &mut queue, &mut metrics, st.global_step, wall(&started))?;
                        debt.episode(before, known.1 + queue.len());
                    }
                },
            }
        }
        if let Some((learner, m)) = done {
            let m = m?;
            let u = learner.updates();
            if u % 10 == 0 || u == 1 {
                metrics.log(st.global_step, wall(&started), &m.named())?;
            }
            // Lock-step: the round's weights, except after the last update (the envs stop there).
            let due = match lockstep {
                Some(_) => u < cfg.total_updates,
                None => u == 1 || (args.weights_every > 0 && u.is_multiple_of(args.weights_every)),
            };
            if due {
                publish_weights(&learner, &mut st).await?;
            }
            if cfg.checkpoint_every > 0 && u.is_multiple_of(cfg.checkpoint_every) {
                last_ck = Some(checkpoint(&learner, &st, &dir)?);
            }
            if let Some(p) = progress.as_mut() {
                let (name, n) = lockstep.as_ref().map_or(("owed", debt.owed()), |l| ("rounds", l.rounds()));
                p.update(
                    u,
                    &[
                        ("alpha", format!("{:.3}", m.alpha)),
                        ("transitions", ingest.counts.transitions.to_string()),
                        (name, n.to_string()),
                    ],
                );
            }
            known.3 = m;
            home = Some(learner);
        }
        if let Some(learner) = home.as_mut() {
            // Lock-step: one complete round at a time, in order; then its update or its weights.
            let round = match lockstep.as_mut().filter(|_| stopping.is_none()).and_then(Lockstep::next_round) {
                Some(items) => {
                    for item in items {
                        match item {
                            Item::Transition(t) => {
                                ingest_transition(&mut ingest, &t, &mut queue, &mut bad_logged);
                                st.global_step += 1;
                            }
                            Item::Episode(r) => ingest_episode(
                                &mut ingest,
                                &r,
                                &mut queue,
                                &mut metrics,
                                st.global_step,
                                wall(&started),
                            )?,
                        }
                    }
                    true
                }
                None => false,
            };
            for row in queue.drain(..) {
                learner.push(row)?;
            }
            let mut update = false;
            if round {
                last_round = Instant::now();
                update = learner.ready() && learner.updates() < cfg.total_updates;
                if !update {
                    publish_weights(learner, &mut st).await?;
                }
            }
            known = (learner.updates(), learner.replay().len(), learner.replay().expert_len(), known.3);
            if lockstep.is_none()
                && stopping.is_none()
                && debt.owed() > 0
                && learner.ready()
                && learner.updates() < cfg.total_updates
            {
                debt.pay();
                update = true;
            }
            if update {
                task = start_update(&mut home);
            }
        }
        if let Some(ls) = &lockstep
            && home.is_some()
            && stopping.is_none()
            && last_round.elapsed() >= Duration::from_secs(10)
            && stall_logged != Some(ls.rounds())
        {
            stall_logged = Some(ls.rounds());
            warn!(
                "deterministic: round {} has waited {:.0} s for {}",
                ls.rounds(),
                last_round.elapsed().as_secs_f64(),
                ls.waiting_for().join(", ")
            );
        }
        if last_status.elapsed() >= Duration::from_secs(1) {
            let dt = last_status.elapsed().as_secs_f32();
            let (m, last) = (known.3, st.evals.last());
            let status = TrainerStatus {
                header: wall_stamp(),
                updates: known.0,
                transitions: ingest.counts.transitions,
                buffer_size: known.1 as u64,
                expert_transitions: known.2 as u64,
                critic_loss: (m.qf1_loss + m.qf2_loss) / 2.0,
                actor_loss: m.actor_loss,
                alpha: m.alpha,
                updates_per_s: (known.0 - status_counts.0) as f32 / dt,
                transitions_per_s: (ingest.counts.transitions - status_counts.1) as f32 / dt,
                last_eval_return: last.map_or(f32::NAN, |e| e.mean_return as f32),
                last_eval_success_rate: last.map_or(f32::NAN, |e| e.success_rate as f32),
                last_eval_episodes: last.map_or(0, |e| e.episodes as u32),
            };
            if let Err(e) = status_pub.publish(status).await {
                warn!("{e:#}");
            }
            (last_status, status_counts) = (Instant::now(), (known.0, ingest.counts.transitions));
        }
    }
    let learner = home.expect("the loop ends with the learner home");
    if let Some(p) = progress.as_mut() {
        p.finish();
    }
    info!("{}: stopping ({}) at {} updates", node.name(), stopping.map_or("", |s| s.0), learner.updates());
    if last_ck.as_ref().is_none_or(|p: &PathBuf| !p.ends_with(step_dir_name(learner.updates()))) {
        last_ck = Some(checkpoint(&learner, &st, &dir)?);
    }
    write_json(&dir.join("evals.json"), &st.evals)?;
    // The curve is redrawn at every evaluation; draw it at the end too (a run may end before one).
    write_curve(&dir, &cfg, &st.evals)?;
    if let Some(ls) = &lockstep {
        let (t, r) = ls.pending();
        info!(
            "deterministic: {} rounds; left outside a round: {t} transitions, {r} episode results; {refused} refused",
            ls.rounds()
        );
    }
    let c = &ingest.counts;
    info!(
        "received {} transitions (stored {}, expert held {}, eval {})",
        c.transitions, c.stored, c.expert_held, c.eval
    );
    info!(
        "expert transitions dropped (failed episodes) {}, malformed {}; replay {}",
        c.expert_dropped,
        c.bad,
        learner.replay().len()
    );
    Ok(RunSummary {
        run_dir: dir,
        evals: st.evals,
        global_step: st.global_step,
        updates: learner.updates(),
        wall_s: wall(&started),
        last_checkpoint: last_ck,
        demos: c.expert_episodes,
    })
}

/// One evaluation from its episodes.
fn evaluation(episodes: &[EpisodeResult], updates: u64) -> EvalResult {
    let n = episodes.len().max(1) as f64;
    let mean = |f: &dyn Fn(&EpisodeResult) -> f64| episodes.iter().map(f).sum::<f64>() / n;
    EvalResult {
        updates,
        episodes: episodes.len(),
        success_rate: mean(&|r| r.success as u8 as f64),
        mean_return: mean(&|r| r.ret as f64),
        discounted_return: mean(&|r| r.discounted_return as f64),
        mean_length: mean(&|r| r.steps as f64),
    }
}

fn checkpoint(learner: &Learner, st: &NodeState, run_dir: &Path) -> anyhow::Result<PathBuf> {
    let dir = run_dir.join("checkpoints").join(step_dir_name(learner.updates()));
    learner.save(&dir)?;
    write_json(&dir.join("trainer.json"), st)?;
    write_latest(run_dir, learner.updates())?;
    info!("checkpoint {}", dir.display());
    Ok(dir)
}
