//! The one place equiarm touches ros2-client: context and node creation (names, namespaces,
//! `ROS_DOMAIN_ID`, `ROS_LOCALHOST_ONLY`), the QoS profiles of the topic graph, typed publishers and
//! subscriptions on tokio, the spinner task, and shutdown on SIGINT/SIGTERM.
//!
//! ## Distro
//! ros2-client is built with its `jazzy` feature by default (this crate's `jazzy` feature): Jazzy and
//! every later distro (Kilted, Lyrical, Rolling) use the 16-byte Gid in `ros_discovery_info`, so
//! `ros2 node list` and `ros2 topic` see our nodes there. Humble uses a 24-byte Gid: Humble users build
//! with `--no-default-features --features humble`. Topic data (CDR) is the same for all distros.
//!
//! ## Limitations
//! - Parameter services are off: ros2-client answers them only with the Fast DDS ("Enhanced")
//!   service mapping, which rmw_cyclonedds clients cannot use. Configuration comes
//!   from the command line instead.
//! - RustDDS keeps up to 8192 unacknowledged samples per reliable writer and has no back-pressure:
//!   publish large samples only as fast as the lock-step loop needs.

use std::collections::HashMap;
use std::net::Ipv4Addr;
use std::sync::Arc;
use std::time::Duration;

use anyhow::{anyhow, bail};
use equiarm_msgs::RosMessage;

use crate::endpoints::{BadInputLog, Padded};
pub use crate::endpoints::{Publisher, Subscriber};
use crate::secure::{Joined, Security};
pub use crate::signals::shutdown_signal;
use log::{debug, info, warn};
use ros2_client::dds::rustdds::DomainParticipantBuilder;
use ros2_client::qos::{Durability, History, QosProfile, WhenFull};
use ros2_client::{Context, MessageTypeName, Name, Node, NodeName, NodeOptions};

/// QoS profiles of the equiarm topic graph (docs/architecture.md#qos).
pub mod qos {
    use super::*;

    /// Camera images and camera info: best effort, volatile, keep-last 1 (ROS `qos_profile_sensor_data`
    /// up to depth; rclpy subscribers must use the sensor-data profile).
    pub fn sensor_data() -> QosProfile {
        QosProfile::subscription_default()
            .reliability_best_effort()
            .durability(Durability::Volatile)
            .history(History::KeepLast { depth: 1 })
    }

    /// Observations and gripper commands: reliable, volatile, keep-last 10 (rclpy's default profile,
    /// so `create_subscription(Msg, topic, 10)` in rclpy matches).
    pub fn command() -> QosProfile {
        reliable(10)
    }

    /// Transitions, episode results, trainer status: reliable, volatile, keep-last `depth`. The rate is
    /// bounded by the lock-step loop, so a bounded history loses nothing in practice.
    pub fn stream(depth: usize) -> QosProfile {
        reliable(depth)
    }

    /// Policy weights: reliable, transient-local, keep-last 1, so a policy node started late gets the
    /// latest weights. Only for samples published rarely (RustDDS keeps unacked samples for late joiners).
    pub fn latched() -> QosProfile {
        reliable(1).durability(Durability::TransientLocal)
    }

    fn reliable(depth: usize) -> QosProfile {
        QosProfile::publisher_default()
            .reliability_reliable(WhenFull::Wait(Duration::from_millis(100)))
            .durability(Durability::Volatile)
            .history(History::KeepLast { depth })
    }
}

/// Where and how a node joins the ROS 2 graph. [`RosOptions::from_env`] reads the environment the
/// way ROS 2 tools do; everything is also settable by hand (tests use their own domain ids).
#[derive(Clone, Debug, PartialEq, Eq, Default)]
pub struct RosOptions {
    /// DDS domain (ROS_DOMAIN_ID), 0..=232.
    pub domain_id: u16,
    /// Use only the loopback interface (ROS_LOCALHOST_ONLY=1 or ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST).
    pub localhost_only: bool,
    /// DDS Security (the ROS_SECURITY_* variables; off by default).
    pub security: Security,
}

impl RosOptions {
    /// Reads `ROS_DOMAIN_ID`, `ROS_LOCALHOST_ONLY` and `ROS_AUTOMATIC_DISCOVERY_RANGE` (RustDDS ignores
    /// them, so we apply them ourselves). A malformed value is an error naming the variable.
    pub fn from_env() -> anyhow::Result<Self> {
        Self::from_vars(|k| std::env::var(k).ok())
    }

    /// As [`Self::from_env`], reading variables through `get` (for tests).
    pub fn from_vars(get: impl Fn(&str) -> Option<String>) -> anyhow::Result<Self> {
        let domain_id = match get("ROS_DOMAIN_ID").map(|s| s.trim().to_string()) {
            None => 0,
            Some(s) if s.is_empty() => 0,
            Some(s) => match s.parse::<u16>() {
                Ok(d) if d <= 232 => d,
                _ => bail!("ROS_DOMAIN_ID='{s}' is not a DDS domain id (an integer 0..=232)"),
            },
        };
        let localhost_only = get("ROS_LOCALHOST_ONLY").is_some_and(|v| v.trim() == "1")
            || get("ROS_AUTOMATIC_DISCOVERY_RANGE").is_some_and(|v| v.trim().eq_ignore_ascii_case("LOCALHOST"));
        Ok(Self { domain_id, localhost_only, security: Security::from_vars(&get) })
    }
}

/// A ROS 2 node with its DDS participant and spinner. Dropping it leaves the graph cleanly.
pub struct RosNode {
    // Field order matters: the node is dropped before its context.
    pub(crate) node: Node,
    context: Context,
    fqn: String,
    bad_input: Arc<BadInputLog>,
    /// Joined with DDS Security (its publishers pad their samples, see `Padded`).
    secured: bool,
}

impl RosNode {
    /// Creates a node `name` in `namespace` (`"/"` or `"/env0"`), joins the domain and starts the
    /// spinner on the current tokio runtime.
    pub fn new(namespace: &str, name: &str, opts: &RosOptions) -> anyhow::Result<Self> {
        let mut builder = DomainParticipantBuilder::new(opts.domain_id);
        if opts.localhost_only {
            builder = builder.with_only_networks([Ipv4Addr::LOCALHOST]);
        }
        let fqn = if namespace == "/" { format!("/{name}") } else { format!("{namespace}/{name}") };
        let (builder, joined) = opts.security.apply(builder, &fqn, opts.domain_id)?;
        let participant =
            builder.build().map_err(|e| anyhow!("creating DDS participant on domain {}: {e:?}", opts.domain_id))?;
        // the plugins have read the key: a decrypted one leaves memory here
        let enclave = joined.map(|Joined { name, key }| {
            drop(key);
            name
        });
        let context = Context::from_domain_participant(participant)
            .map_err(|e| anyhow!("creating ROS 2 context on domain {}: {e:?}", opts.domain_id))?;
        let node_name = NodeName::new(namespace, name)
            .map_err(|e| anyhow!("bad node name '{name}' in namespace '{namespace}': {e:?}"))?;
        let options = NodeOptions::new().enable_rosout(true).start_parameter_services(false);
        let mut node = context.new_node(node_name, options).map_err(|e| anyhow!("creating node '{name}': {e:?}"))?;
        let spinner = node.spinner().map_err(|e| anyhow!("creating spinner of node '{name}': {e:?}"))?;
        let task_name = fqn.clone();
        let mut spin = Box::pin(async move {
            if let Err(e) = spinner.spin().await {
                warn!("{task_name}: spinner stopped: {e:?}");
            }
        });
        // The spinner makes its readers (ROS discovery info, /clock) in its first poll: poll it
        // here once, so that they exist before this node makes its own topics. RustDDS 0.15.1 takes
        // the participant's lock and its security plugins' lock in opposite orders when one thread
        // makes a topic while another makes a reader, and a secured node then hangs at start-up
        // (docs/security.md).
        let mut cx = std::task::Context::from_waker(std::task::Waker::noop());
        if spin.as_mut().poll(&mut cx).is_pending() {
            tokio::spawn(spin);
        }
        let security = enclave.as_ref().map_or("off".to_string(), |e| format!("enclave {e}"));
        info!(
            "{fqn}: joined ROS 2 domain {} (localhost only: {}; security: {security})",
            opts.domain_id, opts.localhost_only
        );
        let secured = enclave.is_some();
        Ok(Self { node, context, fqn, bad_input: Arc::new(BadInputLog::default()), secured })
    }

    /// Fully qualified node name, e.g. `/env0/sim`.
    pub fn name(&self) -> &str {
        &self.fqn
    }

    /// Whether the node joined with DDS Security.
    pub fn secured(&self) -> bool {
        self.secured
    }

    /// The DDS domain this node is on.
    pub fn domain_id(&self) -> u16 {
        self.context.domain_id()
    }

    /// Topic name resolution as in ROS 2: absolute names stay, relative ones get the node namespace.
    fn topic<M: RosMessage>(&self, topic: &str, qos: &QosProfile) -> anyhow::Result<ros2_client::dds::rustdds::Topic> {
        let name = Name::parse(topic).map_err(|e| anyhow!("bad topic name '{topic}': {e:?}"))?;
        self.node
            .create_topic(&name, MessageTypeName::new(M::PACKAGE, M::NAME), qos)
            .map_err(|e| anyhow!("creating topic '{topic}' ({}): {e:?}", M::TYPE_NAME))
    }

    /// A publisher of `M` on `topic` with `qos`.
    pub fn publisher<M: RosMessage>(&mut self, topic: &str, qos: QosProfile) -> anyhow::Result<Publisher<M>> {
        let t = self.topic::<M>(topic, &qos)?;
        let inner = self
            .node
            .create_publisher::<Padded<M>>(&t, Some(qos))
            .map_err(|e| anyhow!("creating publisher on '{topic}' ({}): {e:?}", M::TYPE_NAME))?;
        debug!("{}: publishing {} on {topic}", self.fqn, M::TYPE_NAME);
        Ok(Publisher { inner, topic: topic.to_string(), pad: self.secured })
    }

    /// A subscription to `M` on `topic` with `qos`. Payloads that do not decode are counted, logged once
    /// per topic, and skipped (see [`Subscriber::recv`]).
    pub fn subscription<M: RosMessage>(&mut self, topic: &str, qos: QosProfile) -> anyhow::Result<Subscriber<M>> {
        let t = self.topic::<M>(topic, &qos)?;
        let inner = self
            .node
            .create_subscription::<M>(&t, Some(qos))
            .map_err(|e| anyhow!("creating subscription on '{topic}' ({}): {e:?}", M::TYPE_NAME))?;
        debug!("{}: subscribed to {} on {topic}", self.fqn, M::TYPE_NAME);
        Ok(Subscriber { inner, topic: topic.to_string(), log: self.bad_input.clone() })
    }

    /// Topics seen on the graph so far (DDS names and type names, e.g. `rt/env0/observation`,
    /// `equiarm_msgs::msg::dds_::Observation_`), one entry per topic.
    pub fn discovered_topics(&self) -> Vec<ros2_client::DiscoveredTopic> {
        let mut v = self.context.discovered_topics();
        v.sort_by(|a, b| (&a.name, &a.type_name).cmp(&(&b.name, &b.type_name)));
        v.dedup_by(|a, b| a.name == b.name && a.type_name == b.type_name);
        v
    }

    /// Payloads dropped because they did not decode, per topic, since the node started.
    pub fn bad_input_counts(&self) -> HashMap<String, u64> {
        self.bad_input.counts()
    }

    /// Waits until a publisher has matched at least one subscription, up to `timeout`.
    /// Returns whether one matched. (Matching on our side does not prove the remote side has matched
    /// too: don't rely on the first sample of a volatile stream.)
    pub async fn wait_for_subscription<M: RosMessage>(&self, publ: &Publisher<M>, timeout: Duration) -> bool {
        tokio::time::timeout(timeout, publ.inner.wait_for_subscription(&self.node)).await.is_ok()
    }

    /// Waits until a subscription has matched at least one publisher, up to `timeout`.
    pub async fn wait_for_publisher<M: RosMessage>(&self, sub: &Subscriber<M>, timeout: Duration) -> bool {
        tokio::time::timeout(timeout, sub.inner.wait_for_publisher(&self.node)).await.is_ok()
    }
}

/// The default log filter: our crates at info, RustDDS's per-datagram warnings and error floods off
/// (RustDDS logs a warning per malformed or unexpected datagram). The writer's "send_message_to_readers: No locators" warning is off too: on a host
/// whose loopback has no multicast (Linux's default) RustDDS repeats it for every sample sent to a
/// same-host reader, which it still reaches through its loopback fallback (train.sh's trainer logged
/// ~1,400 of them in its first 90 s). `RUST_LOG` overrides it.
pub const DEFAULT_LOG_FILTER: &str = "info,rustdds=warn,rustdds::network::udp_sender=error,\
rustdds::rtps::writer=error,rustdds::structure::sequence_number=off,ros2_client=warn";

/// Initialises logging to stderr once per process (later calls do nothing).
pub fn init_logging() {
    let env = env_logger::Env::default().default_filter_or(DEFAULT_LOG_FILTER);
    let _ = env_logger::Builder::from_env(env).format_timestamp_millis().try_init();
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vars<'a>(pairs: &'a [(&'a str, &'a str)]) -> impl Fn(&str) -> Option<String> + 'a {
        move |k| pairs.iter().find(|(n, _)| *n == k).map(|(_, v)| v.to_string())
    }

    #[test]
    fn ros_env_is_read_and_validated() {
        assert_eq!(RosOptions::from_vars(vars(&[])).unwrap(), RosOptions::default());
        let o = RosOptions::from_vars(vars(&[("ROS_DOMAIN_ID", "42"), ("ROS_LOCALHOST_ONLY", "1")])).unwrap();
        assert_eq!(o, RosOptions { domain_id: 42, localhost_only: true, security: Security::Off });
        let o = RosOptions::from_vars(vars(&[("ROS_AUTOMATIC_DISCOVERY_RANGE", "localhost")])).unwrap();
        assert!(o.localhost_only);
        for bad in ["233", "-1", "abc"] {
            let e = RosOptions::from_vars(vars(&[("ROS_DOMAIN_ID", bad)])).unwrap_err().to_string();
            assert!(e.contains("ROS_DOMAIN_ID") && e.contains(bad), "{e}");
        }
    }

    #[test]
    fn qos_profiles_match_the_architecture() {
        assert_eq!(qos::sensor_data().reliability, ros2_client::qos::Reliability::BestEffort);
        assert_eq!(qos::command().history, History::KeepLast { depth: 10 });
        assert_eq!(qos::latched().durability, Durability::TransientLocal);
        assert_eq!(qos::latched().history, History::KeepLast { depth: 1 });
    }
}
