//! The recorder node (`equiarm record`): subscribes to topics and writes them to a rosbag2 MCAP bag
//! with `equiarm_bag`. One task per topic takes the message ros2-client decoded (it offers no raw
//! subscription), re-encodes it (CDR, ~memcpy speed) and hands it to the writer task, which owns
//! the bag, flushes it on a timer (so a kill loses at most the flush interval) and prints a one-line
//! status.
//!
//! With `foxglove` set it also serves every recorded message to Foxglove over WebSocket
//! ([`crate::live`]).
//!
//! Every second it counts each recorded topic's publishers, and says when a topic that had some has
//! none left (a publisher ended, or DDS lost it: a stalled machine can let a participant's lease
//! expire) and when one is back, and lists at the end the topics that lost theirs, so a bag with a
//! gap does not pass for a complete one.
//!
//! ## Limitations
//! Only the types equiarm knows (`equiarm msg list`) can be recorded: ros2-client offers no
//! raw-bytes subscription. With `--all`, topics are found by discovery (polled every 100 ms by default).

use std::collections::HashSet;
use std::io::Write as _;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use anyhow::{Context as _, bail};
use equiarm_bag::qos::OfferedQos;
use equiarm_bag::{TopicId, TopicInfo, Writer, WriterOptions};
use equiarm_msgs::{RosMessage, TypeInfo, cdr};
use log::{info, warn};
use tokio::sync::mpsc;

use crate::live::Live;
use crate::ros::{RosNode, RosOptions, qos, shutdown_signal};
use crate::topic_watch::Watch;

/// What to record and how.
#[derive(Clone, Debug)]
pub struct RecordConfig {
    /// The bag directory to create.
    pub output: PathBuf,
    /// Topics to record, each with its type (`/env0/observation`, `equiarm_msgs/msg/Observation`).
    pub topics: Vec<(String, String)>,
    /// Also record every discovered topic of a known type.
    pub all: bool,
    /// How often `all` looks for new topics (rosbag2's `--polling-interval`, default 100 ms). A
    /// topic's messages published before its subscription matches are not recorded.
    pub polling_interval: Duration,
    /// Bag writing options.
    pub writer: WriterOptions,
    /// Print the status line every this often (None: never).
    pub status_every: Option<Duration>,
    /// Stop after this long (None: until SIGINT/SIGTERM).
    pub duration: Option<Duration>,
    /// Serve what is recorded to Foxglove over WebSocket on this address ([`crate::live`]).
    pub foxglove: Option<std::net::SocketAddr>,
}

/// One received message on its way to the writer.
struct Sample {
    topic: TopicId,
    log_time: u64,
    publish_time: u64,
    data: Vec<u8>,
}

fn now_ns() -> u64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map(|d| d.as_nanos() as u64).unwrap_or(0)
}

/// The QoS we subscribe with and record as offered: camera streams are best effort (a reliable
/// reader would not match them), everything else of the suite is reliable.
fn qos_for(type_name: &str) -> (ros2_client::qos::QosProfile, OfferedQos) {
    match type_name {
        "sensor_msgs/msg/Image" | "sensor_msgs/msg/CameraInfo" => (qos::sensor_data(), OfferedQos::best_effort(1)),
        "equiarm_msgs/msg/PolicyWeights" => (qos::latched(), OfferedQos::latched(1)),
        _ => (qos::stream(100), OfferedQos::reliable(10)),
    }
}

async fn forward<M: RosMessage>(
    sub: Arc<crate::ros::Subscriber<M>>,
    topic: TopicId,
    tx: mpsc::Sender<Sample>,
) -> anyhow::Result<()> {
    loop {
        let (msg, info) = sub.recv().await?;
        let log_time = now_ns();
        let publish_time = info.source_timestamp().map(|t| t.to_nanos().max(0) as u64).unwrap_or(log_time);
        let data = cdr::encode(&msg)?;
        if tx.send(Sample { topic, log_time, publish_time, data }).await.is_err() {
            return Ok(()); // the writer has finished
        }
    }
}

/// Subscribes to `name` as the type `type_name` and spawns its forwarding task.
fn subscribe(
    node: &mut RosNode,
    (writer, live): (&mut Writer, &mut Option<Live>),
    name: &str,
    type_name: &str,
    tx: &mpsc::Sender<Sample>,
    tasks: &mut Vec<tokio::task::JoinHandle<()>>,
    watches: &mut Vec<Watch>,
) -> anyhow::Result<()> {
    if node.secured() && name == "/clock" {
        // RustDDS 0.15 keys a remote reader's keys by (local writer, remote participant): a second
        // reader of one writer in a participant (ros2-client's node has its own /clock reader) is
        // refused, and the writer then sends nothing to anyone (docs/security.md).
        warn!("not recording /clock: a secured node cannot hold a second /clock reader (RustDDS 0.15)");
        return Ok(());
    }
    let (profile, offered) = qos_for(type_name);
    crate::with_message_type!(type_name, M => {
        let info = TopicInfo::of::<M>(name, &[offered]);
        let topic = writer.add_topic(info.clone())?;
        if let Some(l) = live.as_mut() {
            l.add(topic, &info)?;
        }
        let sub = Arc::new(node.subscription::<M>(name, profile)?);
        let counted = sub.clone();
        watches.push(Watch {
            name: name.to_string(),
            count: Box::new(move |node| counted.publisher_count(node)),
            had: false,
            lost: false,
        });
        let tx = tx.clone();
        let task_name = name.to_string();
        tasks.push(tokio::spawn(async move {
            if let Err(e) = forward(sub, topic, tx).await {
                warn!("recording {task_name} stopped: {e:#}");
            }
        }));
        info!("recording {name} ({type_name})");
    })?;
    Ok(())
}

/// ROS name and type of a discovered DDS topic, if it is a ROS topic of a known type.
///
/// `/clock` counts only as `rosgraph_msgs/msg/Clock`, what ROS 2 and `equiarm sim --clock` publish:
/// ros2-client (our ROS 2 library) announces a `/clock` topic of type `builtin_interfaces/msg/Time`
/// in every node, on which nothing is ever published, and recording that one first would leave the
/// real clock unrecorded.
fn ros_topic(dds_name: &str, dds_type: &str) -> Option<(String, &'static str)> {
    let name = dds_name
        .strip_prefix("rt/")
        .map(|n| format!("/{n}"))
        .or_else(|| dds_name.starts_with('/').then(|| dds_name.to_string()))?;
    let t = equiarm_msgs::ALL_TYPES.iter().find(|t| t.dds_type_name == dds_type)?;
    if name == "/clock" && t.type_name != equiarm_msgs::rosgraph_msgs::Clock::TYPE_NAME {
        return None;
    }
    Some((name, t.type_name))
}

/// Runs the recorder until SIGINT/SIGTERM (or `duration`), then finishes the bag.
pub async fn run(opts: &RosOptions, cfg: RecordConfig) -> anyhow::Result<equiarm_bag::BagSummary> {
    crate::signals::install()?; // first: a signal during start-up is then not lost
    if cfg.topics.is_empty() && !cfg.all {
        bail!("nothing to record: name topics as TOPIC:TYPE, or pass --all");
    }
    for (_, t) in &cfg.topics {
        if TypeInfo::find(t).is_none() {
            bail!("unknown message type '{t}' (see `equiarm msg list`)");
        }
    }
    let mut writer = Writer::create(&cfg.output, cfg.writer.clone())
        .with_context(|| format!("creating bag {}", cfg.output.display()))?;
    let mut node = RosNode::new("/", "equiarm_recorder", opts)?;
    let (tx, mut rx) = mpsc::channel::<Sample>(4096);
    let mut live = match cfg.foxglove {
        Some(addr) => Some(Live::start(addr).await?),
        None => None,
    };
    let mut recording: HashSet<String> = HashSet::new();
    let (mut tasks, mut watches) = (Vec::new(), Vec::new());
    for (name, type_name) in &cfg.topics {
        subscribe(&mut node, (&mut writer, &mut live), name, type_name, &tx, &mut tasks, &mut watches)?;
        recording.insert(name.clone());
    }
    let signal = shutdown_signal();
    tokio::pin!(signal);
    let start = Instant::now();
    let mut tick = tokio::time::interval(Duration::from_millis(50));
    let mut last_status = Instant::now();
    let mut last_discovery = Instant::now() - Duration::from_secs(10);
    let mut last_watch = Instant::now();
    let (mut messages, mut bytes, mut since, mut since_count) = (0u64, 0u64, Instant::now(), 0u64);
    loop {
        tokio::select! {
            s = &mut signal => {
                info!("{} received, finishing the bag", s?);
                break;
            }
            Some(sample) = rx.recv() => {
                writer.write(sample.topic, sample.log_time, sample.publish_time, &sample.data)?;
                if let Some(l) = &live {
                    l.log(sample.topic, sample.log_time, &sample.data);
                }
                messages += 1;
                bytes += sample.data.len() as u64;
                writer.flush_if_due(start.elapsed().as_nanos() as u64)?;
            }
            _ = tick.tick() => {
                writer.flush_if_due(start.elapsed().as_nanos() as u64)?;
                if cfg.duration.is_some_and(|d| start.elapsed() >= d) {
                    break;
                }
                if cfg.all && last_discovery.elapsed() >= cfg.polling_interval {
                    last_discovery = Instant::now();
                    for t in node.discovered_topics() {
                        if let Some((name, type_name)) = ros_topic(&t.name, &t.type_name)
                            && recording.insert(name.clone()) {
                                subscribe(&mut node, (&mut writer, &mut live), &name, type_name, &tx, &mut tasks, &mut watches)?;
                            }
                    }
                }
                if last_watch.elapsed() >= Duration::from_secs(1) {
                    last_watch = Instant::now();
                    for w in &mut watches {
                        w.check(&node);
                    }
                }
                if let Some(every) = cfg.status_every
                    && last_status.elapsed() >= every {
                        let rate = (messages - since_count) as f64 / since.elapsed().as_secs_f64();
                        eprint!("\rrecording {}: {messages} messages, {:.1} MB, {rate:.0} msg/s   ",
                            cfg.output.display(), bytes as f64 / 1e6);
                        let _ = std::io::stderr().flush();
                        (since, since_count, last_status) = (Instant::now(), messages, Instant::now());
                    }
            }
        }
    }
    drop(tx);
    let lost: Vec<&str> = watches.iter().filter(|w| w.lost).map(|w| w.name.as_str()).collect();
    if !lost.is_empty() {
        warn!("these topics had no publisher left when recording stopped: {}", lost.join(", "));
    }
    drop(watches);
    // stop the subscriptions before the node goes (RustDDS complains about readers outliving it)
    for t in &tasks {
        t.abort();
    }
    for t in tasks {
        let _ = t.await;
    }
    // drain what is already queued, then finish
    while let Ok(sample) = rx.try_recv() {
        writer.write(sample.topic, sample.log_time, sample.publish_time, &sample.data)?;
    }
    if cfg.status_every.is_some() {
        eprintln!();
    }
    let summary = writer.finish()?;
    drop(node);
    info!("bag {} finished: {} messages in {} file(s)", summary.dir.display(), summary.messages, summary.files.len());
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dds_names_map_to_ros_names_of_known_types() {
        assert_eq!(
            ros_topic("rt/env0/observation", "equiarm_msgs::msg::dds_::Observation_"),
            Some(("/env0/observation".into(), "equiarm_msgs/msg/Observation"))
        );
        assert_eq!(ros_topic("rt/x", "std_msgs::msg::dds_::String_"), None);
        // ros2-client's placeholder /clock is not recorded; the real one is.
        assert_eq!(ros_topic("rt/clock", "builtin_interfaces::msg::dds_::Time_"), None);
        assert_eq!(
            ros_topic("rt/clock", "rosgraph_msgs::msg::dds_::Clock_"),
            Some(("/clock".to_string(), "rosgraph_msgs/msg/Clock"))
        );
        assert_eq!(ros_topic("rq/x/srvRequest", "equiarm_msgs::msg::dds_::Observation_"), None);
    }
}
