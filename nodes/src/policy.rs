//! `equiarm policy`: the actor on the ROS 2 graph. It answers each `Observation` on `observation`
//! (relative to the namespace) with a `GripperCommand` on `gripper_cmd` naming its seq, and in the
//! learning modes (`sample`, `greedy`) takes new actor weights from `/policy/weights` (transient-local,
//! so a late node gets the latest snapshot). What it answers is [`equiarm_train::policy`]'s, when
//! [`equiarm_train::gate`]'s.
//!
//! ## Limitations
//! One env per node. Acting is on the runtime thread (batch 1), so a slow actor delays weights too.

use std::collections::HashSet;

use equiarm_msgs::msg::{GripperCommand, Observation, PolicyWeights, TrainerStatus};
use equiarm_train::gate::Gate;
use equiarm_train::policy::{AnswerError, MAX_LOGGED_SENDERS, Policy, WeightsOutcome};
use log::{info, warn};

use crate::policy_cli::{PolicyArgs, architecture};
use crate::ros::{Publisher, RosNode, RosOptions, Subscriber, qos, shutdown_signal};

/// Runs the node until SIGINT/SIGTERM; returns the commands sent.
pub async fn run(args: &PolicyArgs, opts: &RosOptions) -> anyhow::Result<u64> {
    crate::signals::install()?; // first: a signal during start-up is then not lost
    let (agent, frame, actor) = architecture(args)?;
    let mut policy = Policy::new(args.mode, agent.clone(), frame, actor.as_deref(), args.seed)?
        .with_expert_episodes(args.expert_episodes);
    let mut gate = match args.eval_every {
        Some(every) => Gate::windows(every, args.eval_episodes, policy.learns())?,
        None => Gate::new(args.max_lead, args.steps_per_update, args.deterministic, policy.learns())?,
    };
    let mut node = RosNode::new(&args.namespace, "policy", opts)?;
    let obs_sub = node.subscription::<Observation>("observation", qos::command())?;
    let cmd_pub = node.publisher::<GripperCommand>("gripper_cmd", qos::command())?;
    let weights_sub =
        policy.learns().then(|| node.subscription::<PolicyWeights>(&args.weights_topic, qos::latched())).transpose()?;
    let status_sub = gate
        .needs_status()
        .then(|| node.subscription::<TrainerStatus>("/trainer/status", qos::stream(10)))
        .transpose()?;
    let arch = if policy.learns() {
        format!(", {} hidden {} input {}", agent.model.name(), agent.hidden, agent.input_size)
    } else {
        String::new()
    };
    info!("{}: mode {:?}{arch}, gate {:?}", node.name(), args.mode, gate.rule());
    let (mut sent, mut bad, mut refused, mut logged) = (0u64, 0u64, HashSet::new(), HashSet::new());
    let signal = shutdown_signal();
    tokio::pin!(signal);
    loop {
        let ready = tokio::select! {
            s = &mut signal => { info!("{}: {} received, shutting down", node.name(), s?); break; }
            r = recv_some(status_sub.as_ref()) => {
                let updates = r?.0.updates;
                gate.on_status(updates);
                policy.on_trainer_status(updates);
                gate.release(&policy)
            }
            r = obs_sub.recv() => {
                let obs = r?.0;
                // screened before the gate may hold it (a held good one is not displaced by a bad one)
                match policy.screen(&obs) {
                    Ok(()) => gate.offer(obs, &policy),
                    Err(reason) => { skip(&obs, &reason, (&mut bad, &mut logged)); None }
                }
            }
            r = recv_some(weights_sub.as_ref()) => {
                let (w, _) = r?;
                let (version, updates, run) = (w.version, w.updates, equiarm_msgs::shown(&w.run_id).into_owned());
                match policy.on_weights(w) {
                    // In lock-step a new version comes every round: log the first and every 100th.
                    WeightsOutcome::Loaded if !args.deterministic || version % 100 == 1 => info!("weights version {version} (updates {updates})"),
                    WeightsOutcome::Loaded | WeightsOutcome::Stale => {}
                    WeightsOutcome::NewRun { was } => warn!("weights of run '{run}' (version {version}), after run '{}': following the new run", equiarm_msgs::shown(&was)),
                    WeightsOutcome::Older { current } => warn!("ignoring weights version {version} of run '{run}': version {current} is in use and versions only grow within a run"),
                    WeightsOutcome::Refused(why) => if refused.insert(why.clone()) { warn!("refusing weights version {version}: {why}") },
                    WeightsOutcome::Failed(why) => warn!("weights version {version} did not load, keeping version {}: {why}", policy.version()),
                }
                gate.release(&policy)
            }
        };
        if let Some(obs) = ready {
            answer(&mut policy, obs, &cmd_pub, &mut sent, (&mut bad, &mut logged)).await;
            if let Some((median, p95)) = policy.latency_report().filter(|_| !args.quiet) {
                info!("actor latency (batch 1, last 100): median {median:.2} ms, p95 {p95:.2} ms");
            }
        }
    }
    if let Some(s) = policy.staleness() {
        info!(
            "{}: the weights of {} learned actions were {:.1} updates behind the trainer on average (median {}, p95 {}, max {})",
            node.name(),
            s.actions,
            s.mean,
            s.median,
            s.p95,
            s.max
        );
    }
    let held = if gate.holds() { " (one observation held back)" } else { "" };
    info!(
        "{}: sent {sent} commands, skipped {bad} observations, weights version {}{held}",
        node.name(),
        policy.version()
    );
    Ok(sent)
}

/// Answers `obs` and publishes the command; a bad Observation is counted, and logged once per
/// sender and cause (`skips`: the count, and the pairs logged, at most `MAX_LOGGED_SENDERS`).
async fn answer(
    policy: &mut Policy,
    obs: Observation,
    cmd_pub: &Publisher<GripperCommand>,
    sent: &mut u64,
    skips: (&mut u64, &mut HashSet<(String, &'static str)>),
) {
    match policy.answer(&obs) {
        Ok(cmd) => match cmd_pub.publish(cmd).await {
            Ok(()) => *sent += 1,
            Err(e) => warn!("{e:#}"),
        },
        Err(reason) => skip(&obs, &reason, skips),
    }
}

/// Counts a bad Observation, and logs it once per sender and cause.
fn skip(obs: &Observation, reason: &AnswerError, (bad, logged): (&mut u64, &mut HashSet<(String, &'static str)>)) {
    let cause = reason.cause();
    *bad += 1;
    if logged.len() < MAX_LOGGED_SENDERS && logged.insert((obs.env.clone(), cause)) {
        let env = equiarm_msgs::shown(&obs.env);
        warn!(
            "skipping Observation seq {} of '{env}': {reason} (further {cause} defects of this env are counted, not logged; {bad} skipped so far)",
            obs.seq
        );
    }
}

async fn recv_some<M: equiarm_msgs::RosMessage>(
    sub: Option<&Subscriber<M>>,
) -> anyhow::Result<(M, ros2_client::MessageInfo)> {
    match sub {
        Some(s) => s.recv().await,
        None => std::future::pending().await,
    }
}
