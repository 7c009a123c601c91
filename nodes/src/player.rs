//! `equiarm bag play`: re-publishes a bag's messages on their recorded topics (or remapped ones) at
//! the recorded pace scaled by `--rate`, with each topic's recorded QoS reliability.
//!
//! With `--lockstep`, playing starts once a publisher of each `gripper_cmd` topic has appeared (at
//! most 30 s), and each Observation is re-published until the command naming its seq arrives (10
//! tries, then it is skipped).
//!
//! ## Limitations
//! Only types equiarm knows can be played (`equiarm msg list`); messages of other types are counted
//! and skipped. Messages go out in file order (the order they were received when recorded).

use std::collections::HashMap;
use std::future::Future;
use std::path::PathBuf;
use std::pin::Pin;
use std::time::{Duration, Instant};

use anyhow::bail;
use equiarm_bag::{ReadMode, Reader};
use equiarm_msgs::msg::{GripperCommand, Observation};
use equiarm_msgs::{RosMessage, cdr};
use log::{info, warn};

use crate::ros::{Publisher, RosNode, RosOptions, qos, shutdown_signal};

/// What to play and how.
#[derive(Clone, Debug)]
pub struct PlayConfig {
    /// Bag directory or `.mcap` file.
    pub bag: PathBuf,
    /// Speed factor: 2.0 plays twice as fast; 0 or less means as fast as possible.
    pub rate: f64,
    /// Topic remaps `from -> to`.
    pub remaps: Vec<(String, String)>,
    /// Seconds to wait after creating publishers, so subscribers can match before the first message.
    pub wait_for_match: Duration,
    /// Lock-step: after each `Observation` (on `.../observation`), wait for the `GripperCommand` on the
    /// sibling `.../gripper_cmd` that names its seq (re-publishing every this long, at most 10 times),
    /// instead of keeping the recorded pace. Drives a policy node from a bag as fast as it answers.
    pub lockstep: Option<Duration>,
    /// Refuse a damaged or truncated bag instead of playing what is readable (warned either way).
    pub strict: bool,
}

type PublishFuture<'a> = Pin<Box<dyn Future<Output = anyhow::Result<()>> + Send + 'a>>;

/// A publisher that takes CDR bytes.
trait RawPublisher: Send + Sync {
    fn publish_cdr<'a>(&'a self, data: &'a [u8]) -> PublishFuture<'a>;
}

impl<M: RosMessage> RawPublisher for Publisher<M> {
    fn publish_cdr<'a>(&'a self, data: &'a [u8]) -> PublishFuture<'a> {
        Box::pin(async move {
            let msg = cdr::decode::<M>(data)?;
            self.publish(msg).await
        })
    }
}

fn remap(remaps: &[(String, String)], topic: &str) -> String {
    remaps.iter().find(|(from, _)| from == topic).map(|(_, to)| to.clone()).unwrap_or_else(|| topic.to_string())
}

/// Waits up to `timeout` for a command naming `seq` (commands for other seqs are ignored).
async fn wait_for_answer(
    sub: &crate::ros::Subscriber<GripperCommand>,
    seq: u64,
    timeout: Duration,
) -> anyhow::Result<bool> {
    let deadline = Instant::now() + timeout;
    while let Some(left) = deadline.checked_duration_since(Instant::now()) {
        match sub.recv_timeout(left).await? {
            Some((c, _)) if c.obs_seq == seq => return Ok(true),
            Some(_) => continue,
            None => break,
        }
    }
    Ok(false)
}

/// The values of `key` in an `offered_qos_profiles` YAML, one per recorded publisher.
fn offered<'a>(offered_qos: &'a str, key: &str) -> Vec<&'a str> {
    offered_qos.lines().filter_map(|l| l.trim().strip_prefix(key)).map(str::trim).collect()
}

/// Best effort if every recorded publisher offered best effort (integer-enum YAML `reliability: 2`,
/// or Jazzy's `best_effort`), else reliable.
fn recorded_best_effort(offered_qos: &str) -> bool {
    let values = offered(offered_qos, "reliability:");
    !values.is_empty() && values.iter().all(|v| *v == "2" || *v == "best_effort")
}

/// Transient local (latched, like `/policy/weights`) if every recorded publisher offered it
/// (`durability: 1`, or `transient_local`): a late subscriber then gets the last sample played.
fn recorded_latched(offered_qos: &str) -> bool {
    let values = offered(offered_qos, "durability:");
    !values.is_empty() && values.iter().all(|v| *v == "1" || *v == "transient_local")
}

/// The profile a topic is played with: as its publishers offered it.
fn played_qos(offered_qos: &str) -> ros2_client::qos::QosProfile {
    match (recorded_best_effort(offered_qos), recorded_latched(offered_qos)) {
        (true, _) => qos::sensor_data(),
        (false, true) => qos::latched(),
        (false, false) => qos::stream(100),
    }
}

/// Plays the bag once; returns (published, skipped) counts. What the bag lost (truncated files,
/// damaged chunks) is warned first, as `bag info` reports it; with `strict` it is an error.
pub async fn run(opts: &RosOptions, cfg: PlayConfig) -> anyhow::Result<(u64, u64)> {
    crate::signals::install()?; // first: a signal during start-up is then not lost
    let info = Reader::open(&cfg.bag)?.info()?;
    equiarm_train::bag_report::warn_damage(&cfg.bag, &info, cfg.strict)?;
    if info.messages == 0 {
        bail!("{}: the bag holds no messages", cfg.bag.display());
    }
    let mut node = RosNode::new("/", "equiarm_player", opts)?;
    let mut publishers: HashMap<String, Box<dyn RawPublisher>> = HashMap::new();
    for (topic, t) in &info.topics {
        let to = remap(&cfg.remaps, topic);
        let profile = played_qos(&t.offered_qos);
        let made: anyhow::Result<Box<dyn RawPublisher>> = crate::with_message_type!(&t.type_name, M => {
            Box::new(node.publisher::<M>(&to, profile)?) as Box<dyn RawPublisher>
        });
        match made {
            Ok(p) => {
                info!("playing {topic} ({}) on {to}", t.type_name);
                publishers.insert(topic.clone(), p);
            }
            Err(e) => warn!("skipping {topic}: {e:#}"),
        }
    }
    // lock-step: one command subscription per observation topic
    let mut answers: HashMap<String, crate::ros::Subscriber<GripperCommand>> = HashMap::new();
    if cfg.lockstep.is_some() {
        for (topic, t) in &info.topics {
            if t.type_name == Observation::TYPE_NAME {
                let to = remap(&cfg.remaps, topic);
                let Some(base) = to.strip_suffix("observation") else { continue };
                let cmd_topic = format!("{base}gripper_cmd");
                answers.insert(topic.clone(), node.subscription::<GripperCommand>(&cmd_topic, qos::command())?);
                info!("lock-step: {to} waits for {cmd_topic}");
            }
        }
    }
    // Every wait below also wakes on SIGINT/SIGTERM: a bag whose next timestamp lies hours ahead (or
    // a lock-step peer that never answers) must not make the player unkillable.
    let signal = shutdown_signal();
    tokio::pin!(signal);
    macro_rules! or_stop {
        ($wait:expr) => {
            tokio::select! {
                s = &mut signal => { info!("{} received, stopping playback", s?); None }
                v = $wait => Some(v),
            }
        };
    }
    // Lock-step needs someone to answer: wait (up to 30 s) for a publisher on each gripper_cmd topic
    // (a loaded machine can take seconds to discover it), then the usual match delay.
    for (topic, sub) in &answers {
        match or_stop!(node.wait_for_publisher(sub, Duration::from_secs(30))) {
            None => return Ok((0, 0)),
            Some(false) => {
                warn!("lock-step: nothing publishes the gripper commands answering {topic} yet; playing anyway")
            }
            Some(true) => {}
        }
    }
    if or_stop!(tokio::time::sleep(cfg.wait_for_match)).is_none() {
        return Ok((0, 0));
    }

    // Read the bag in a blocking task and hand messages over a bounded channel (back-pressure keeps
    // memory flat for big bags).
    let (tx, mut rx) = tokio::sync::mpsc::channel::<(String, u64, Vec<u8>)>(256);
    let bag = cfg.bag.clone();
    let reading = tokio::task::spawn_blocking(move || {
        let reader = Reader::open(&bag)?;
        let mut other: std::collections::HashSet<String> = Default::default();
        reader
            .for_each(ReadMode::Salvage, |m| {
                if !m.recorded_as_built() {
                    if other.insert(m.topic.to_string()) {
                        warn!(
                            "skipping {}: recorded with another definition of {} (a bag from another equiarm)",
                            m.topic, m.type_name
                        );
                    }
                    return Ok(());
                }
                tx.blocking_send((m.topic.to_string(), m.log_time, m.data.to_vec()))
            })?
            .ok();
        Ok::<(), anyhow::Error>(())
    });
    let (mut published, mut skipped, mut interrupted) = (0u64, 0u64, false);
    let start = Instant::now();
    let t0 = info.start;
    loop {
        let Some(next) = or_stop!(rx.recv()) else {
            interrupted = true;
            break;
        };
        let Some((topic, log_time, data)) = next else { break };
        let Some(p) = publishers.get(&topic) else {
            skipped += 1;
            continue;
        };
        if let (Some(every), Some(sub)) = (cfg.lockstep, answers.get(&topic)) {
            let seq = cdr::decode::<Observation>(&data)?.seq;
            let mut answered = false;
            let mut stopped = false;
            for _ in 0..10 {
                p.publish_cdr(&data).await?;
                match or_stop!(wait_for_answer(sub, seq, every)) {
                    None => stopped = true,
                    Some(got) => answered = got?,
                }
                if answered || stopped {
                    break;
                }
            }
            if stopped {
                interrupted = true;
                break;
            }
            if answered {
                published += 1;
            } else {
                skipped += 1;
                warn!("{topic}: no gripper command for seq {seq} after 10 tries; going on");
            }
            continue;
        }
        if cfg.rate > 0.0 {
            // (the rate's bounds keep this within a Duration: at most 2^64 ns / MIN_RATE, about 1.8e13 s)
            let due = Duration::from_secs_f64(log_time.saturating_sub(t0) as f64 / 1e9 / cfg.rate);
            if let Some(wait) = due.checked_sub(start.elapsed())
                && or_stop!(tokio::time::sleep(wait)).is_none()
            {
                interrupted = true;
                break;
            }
        }
        match p.publish_cdr(&data).await {
            Ok(()) => published += 1,
            Err(e) => {
                skipped += 1;
                warn!("{topic}: {e:#}");
            }
        }
    }
    drop(rx);
    // Stopped early, the reader fails at its next send to the closed channel: not an error then.
    let read = reading.await?;
    if !interrupted {
        read?;
    }
    // give reliable subscribers a moment to receive the tail before the node goes away
    tokio::time::sleep(Duration::from_millis(300)).await;
    drop(publishers);
    drop(node);
    Ok((published, skipped))
}

#[cfg(test)]
mod tests {
    use super::*;
    use equiarm_bag::qos::{OfferedQos, offered_qos_yaml};

    #[test]
    fn recorded_reliability_is_read_from_both_yaml_forms() {
        assert!(recorded_best_effort(&offered_qos_yaml(&[OfferedQos::best_effort(1)])));
        assert!(!recorded_best_effort(&offered_qos_yaml(&[OfferedQos::reliable(10)])));
        assert!(!recorded_best_effort(&offered_qos_yaml(&[OfferedQos::best_effort(1), OfferedQos::reliable(1)])));
        assert!(recorded_best_effort("- history: unknown\n  reliability: best_effort\n"));
        assert!(!recorded_best_effort(""));
    }

    /// Regression: `bag play` republished the latched `/policy/weights` volatile, so a policy that
    /// started after the sample was played never got it.
    #[test]
    fn recorded_transient_local_is_played_latched() {
        assert!(recorded_latched(&offered_qos_yaml(&[OfferedQos::latched(1)])));
        assert!(!recorded_latched(&offered_qos_yaml(&[OfferedQos::reliable(10)])));
        assert!(!recorded_latched(&offered_qos_yaml(&[OfferedQos::latched(1), OfferedQos::reliable(1)])));
        assert!(recorded_latched("- history: keep_last\n  durability: transient_local\n"));
        assert!(!recorded_latched(""));
    }
}
