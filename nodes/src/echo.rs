//! `equiarm topic echo`: prints the messages of a topic as JSON lines (one per message), like
//! `ros2 topic echo` without a ROS installation. Long arrays (image data, weights) are summarised by
//! their length; non-finite floats print as `null` (JSON has no NaN or infinity).

use std::io::Write;
use std::time::Duration;

use anyhow::Context as _;
use equiarm_msgs::RosMessage;
use serde_json::Value;

use crate::ros::{RosNode, RosOptions, qos, shutdown_signal};

/// Arrays longer than this print as `"<N elements>"`.
pub const MAX_ARRAY: usize = 16;

/// QoS to subscribe with, by the names the command line uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum QosChoice {
    /// best effort, keep-last 1 (camera images)
    SensorData,
    /// reliable, volatile, keep-last 10 (rclpy's default)
    Reliable,
    /// reliable, transient-local, keep-last 1 (policy weights)
    Latched,
}

impl QosChoice {
    fn profile(self) -> ros2_client::qos::QosProfile {
        match self {
            QosChoice::SensorData => qos::sensor_data(),
            QosChoice::Reliable => qos::command(),
            QosChoice::Latched => qos::latched(),
        }
    }
}

/// A message as one JSON line, long arrays summarised.
pub fn to_json_line<M: RosMessage>(msg: &M) -> anyhow::Result<String> {
    let mut v = serde_json::to_value(msg).with_context(|| format!("converting a {} to JSON", M::TYPE_NAME))?;
    summarise(&mut v);
    Ok(v.to_string())
}

fn summarise(v: &mut Value) {
    match v {
        Value::Array(a) if a.len() > MAX_ARRAY => *v = Value::String(format!("<{} elements>", a.len())),
        Value::Array(a) => a.iter_mut().for_each(summarise),
        Value::Object(o) => o.values_mut().for_each(summarise),
        _ => {}
    }
}

/// Subscribes to `topic` as `M` and writes each message to `out` until `count` messages (if given),
/// SIGINT or SIGTERM. Returns how many were printed.
pub async fn echo<M: RosMessage>(
    opts: &RosOptions,
    topic: &str,
    qos: QosChoice,
    count: Option<u64>,
    mut out: impl Write,
) -> anyhow::Result<u64> {
    crate::signals::install()?; // first: a signal during start-up is then not lost
    let mut node = RosNode::new("/", "equiarm_echo", opts)?;
    let sub = node.subscription::<M>(topic, qos.profile())?;
    let mut printed = 0;
    let signal = shutdown_signal();
    tokio::pin!(signal);
    while count.is_none_or(|c| printed < c) {
        tokio::select! {
            s = &mut signal => {
                log::info!("{}: {} received, shutting down", node.name(), s?);
                break;
            }
            r = sub.recv_timeout(Duration::from_millis(500)) => {
                if let Some((msg, _info)) = r? {
                    writeln!(out, "{}", to_json_line(&msg)?).context("writing to stdout")?;
                    out.flush().context("writing to stdout")?;
                    printed += 1;
                }
            }
        }
    }
    Ok(printed)
}

/// Calls `$body` with `$M` bound to the message type named `$name` (any of `equiarm_msgs::ALL_TYPES`).
#[macro_export]
macro_rules! with_message_type {
    ($name:expr, $M:ident => $body:expr) => {{
        use equiarm_msgs::RosMessage as _;
        let name: &str = $name;
        let full = equiarm_msgs::TypeInfo::find(name).map(|t| t.type_name);
        match full {
            Some(equiarm_msgs::builtin_interfaces::Time::TYPE_NAME) => {
                type $M = equiarm_msgs::builtin_interfaces::Time;
                Ok($body)
            }
            Some(equiarm_msgs::rosgraph_msgs::Clock::TYPE_NAME) => {
                type $M = equiarm_msgs::rosgraph_msgs::Clock;
                Ok($body)
            }
            Some(equiarm_msgs::std_msgs::Header::TYPE_NAME) => {
                type $M = equiarm_msgs::std_msgs::Header;
                Ok($body)
            }
            Some(equiarm_msgs::sensor_msgs::Image::TYPE_NAME) => {
                type $M = equiarm_msgs::sensor_msgs::Image;
                Ok($body)
            }
            Some(equiarm_msgs::sensor_msgs::CameraInfo::TYPE_NAME) => {
                type $M = equiarm_msgs::sensor_msgs::CameraInfo;
                Ok($body)
            }
            Some(equiarm_msgs::sensor_msgs::RegionOfInterest::TYPE_NAME) => {
                type $M = equiarm_msgs::sensor_msgs::RegionOfInterest;
                Ok($body)
            }
            Some(equiarm_msgs::geometry_msgs::Vector3::TYPE_NAME) => {
                type $M = equiarm_msgs::geometry_msgs::Vector3;
                Ok($body)
            }
            Some(equiarm_msgs::geometry_msgs::Quaternion::TYPE_NAME) => {
                type $M = equiarm_msgs::geometry_msgs::Quaternion;
                Ok($body)
            }
            Some(equiarm_msgs::geometry_msgs::Transform::TYPE_NAME) => {
                type $M = equiarm_msgs::geometry_msgs::Transform;
                Ok($body)
            }
            Some(equiarm_msgs::geometry_msgs::TransformStamped::TYPE_NAME) => {
                type $M = equiarm_msgs::geometry_msgs::TransformStamped;
                Ok($body)
            }
            Some(equiarm_msgs::tf2_msgs::TFMessage::TYPE_NAME) => {
                type $M = equiarm_msgs::tf2_msgs::TFMessage;
                Ok($body)
            }
            Some(equiarm_msgs::msg::GripperCommand::TYPE_NAME) => {
                type $M = equiarm_msgs::msg::GripperCommand;
                Ok($body)
            }
            Some(equiarm_msgs::msg::Observation::TYPE_NAME) => {
                type $M = equiarm_msgs::msg::Observation;
                Ok($body)
            }
            Some(equiarm_msgs::msg::Transition::TYPE_NAME) => {
                type $M = equiarm_msgs::msg::Transition;
                Ok($body)
            }
            Some(equiarm_msgs::msg::EpisodeResult::TYPE_NAME) => {
                type $M = equiarm_msgs::msg::EpisodeResult;
                Ok($body)
            }
            Some(equiarm_msgs::msg::PolicyWeights::TYPE_NAME) => {
                type $M = equiarm_msgs::msg::PolicyWeights;
                Ok($body)
            }
            Some(equiarm_msgs::msg::TrainerStatus::TYPE_NAME) => {
                type $M = equiarm_msgs::msg::TrainerStatus;
                Ok($body)
            }
            _ => Err(anyhow::anyhow!("unknown message type '{name}' (see `equiarm msg list`)")),
        }
    }};
}

#[cfg(test)]
mod tests {
    use super::*;
    use equiarm_msgs::msg::PolicyWeights;

    #[test]
    fn long_arrays_are_summarised() {
        let w = PolicyWeights { version: 3, data: vec![1; 100], ..Default::default() };
        let line = to_json_line(&w).unwrap();
        assert!(line.contains("\"data\":\"<100 elements>\""), "{line}");
        assert!(line.contains("\"version\":3"), "{line}");
    }

    #[test]
    fn every_listed_type_dispatches() {
        for t in equiarm_msgs::ALL_TYPES {
            let n: anyhow::Result<&str> = with_message_type!(t.type_name, M => M::TYPE_NAME);
            assert_eq!(n.unwrap(), t.type_name);
        }
        let r: anyhow::Result<&str> = with_message_type!("x/msg/Y", M => M::NAME);
        assert!(r.unwrap_err().to_string().contains("unknown message type 'x/msg/Y'"));
    }
}
