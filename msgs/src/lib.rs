//! equiarm's ROS 2 messages: Rust types, their CDR encoding, and their `.msg` definitions.
//!
//! The types are generated at build time from the `.msg` files of this crate's folder (`msgs/msg/`
//! for our package `equiarm_msgs`, `msgs/ros_std/` for the standard `builtin_interfaces`,
//! `std_msgs`, `sensor_msgs`, `rosgraph_msgs`, `geometry_msgs` and `tf2_msgs` types we use), so field order, types, units (documented on each field)
//! and the schema text written into bags can never disagree. The same `msg/` folder is a ROS 2
//! interface package: `colcon build` gives rclpy users the Python types.
//!
//! Modules: [`msg`] (ours), [`builtin_interfaces`], [`std_msgs`], [`sensor_msgs`], [`rosgraph_msgs`],
//! [`geometry_msgs`], [`tf2_msgs`]. Every type
//! implements [`RosMessage`]; [`cdr`] encodes and decodes them exactly as ROS 2 does on the wire
//! (XCDR1 little endian with its 4-byte encapsulation header).
//!
//! ```
//! use equiarm_msgs::{cdr, msg::GripperCommand, RosMessage};
//! let cmd = GripperCommand { obs_seq: 7, dx: 0.01, source: GripperCommand::SOURCE_TELEOP, ..Default::default() };
//! let bytes = cdr::encode(&cmd).unwrap();
//! assert_eq!(&bytes[..4], &[0, 1, 0, 0]);
//! assert_eq!(cdr::decode::<GripperCommand>(&bytes).unwrap(), cmd);
//! assert_eq!(GripperCommand::TYPE_NAME, "equiarm_msgs/msg/GripperCommand");
//! ```
//!
//! ## Limitations
//! Bounded sequences and strings (`T[<=N]`, `string<=N`) are accepted but their bounds are not
//! enforced; `wstring` and field default values are not supported (the build fails if used).

pub mod cdr;
mod image;
pub mod obs_frame;

pub use image::ImageError;

/// Longest peer-supplied string a log line shows whole ([`shown`]).
pub const SHOWN_CHARS: usize = 64;

/// A string from a message (an env name, a run id) as a log line shows it: whole up to
/// [`SHOWN_CHARS`] characters, else its start and how long it is, so a peer cannot fill a log with
/// one megabyte-long field.
///
/// ```
/// assert_eq!(equiarm_msgs::shown("env0"), "env0");
/// let long = "x".repeat(1 << 20);
/// assert_eq!(equiarm_msgs::shown(&long), format!("{}… (1048576 bytes)", "x".repeat(64)));
/// ```
pub fn shown(s: &str) -> std::borrow::Cow<'_, str> {
    match s.char_indices().nth(SHOWN_CHARS) {
        None => s.into(),
        Some((end, _)) => format!("{}… ({} bytes)", &s[..end], s.len()).into(),
    }
}
pub use obs_frame::ObsFrameError;

use serde::{Serialize, de::DeserializeOwned};

include!(concat!(env!("OUT_DIR"), "/messages.rs"));

/// The version of equiarm's message definitions (`msg/*.msg`), one more at every change of a field:
/// checkpoints of the trainer node record it, and a resume under another version is refused (its
/// weights and replay would be read through another transport's layout). Bags need no number: they
/// carry each type's definition text, which readers compare with [`RosMessage::DEFINITION`].
///
/// 2: a Transition names its observations by seq (`obs_seq`, `next_obs_seq`) instead of carrying
/// them; an Observation says whether it is an episode's `terminal` frame; PolicyWeights carry the
/// trainer's `run_id`, within which versions only grow.
/// 3: an Observation carries its frame compressed ([`obs_frame`]: `height`, `width`, zstd planes of
/// rgb8 colour and half-float depth) instead of two `sensor_msgs/Image`s.
pub const SCHEMA_VERSION: u32 = 3;

/// A ROS 2 message type: its names and its definition text.
pub trait RosMessage: Serialize + DeserializeOwned + Clone + Default + std::fmt::Debug + Send + Sync + 'static {
    /// ROS package, e.g. `sensor_msgs`.
    const PACKAGE: &'static str;
    /// Type name within the package, e.g. `Image`.
    const NAME: &'static str;
    /// Full ROS 2 name as tools show it, e.g. `sensor_msgs/msg/Image`.
    const TYPE_NAME: &'static str;
    /// Name on the DDS wire (what rmw implementations register), e.g. `sensor_msgs::msg::dds_::Image_`.
    const DDS_TYPE_NAME: &'static str;
    /// This type's own `.msg` text, verbatim.
    const MSG_TEXT: &'static str;
    /// The complete definition in rosbag2's concatenated format (the MCAP `ros2msg` schema): this
    /// type's text, then each nested type once behind `====…` and `MSG: pkg/Type` lines.
    const DEFINITION: &'static str;
}

/// Names and definition of one message type, for look-ups by name (see [`ALL_TYPES`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TypeInfo {
    /// Full ROS 2 name, e.g. `equiarm_msgs/msg/Observation`.
    pub type_name: &'static str,
    /// DDS wire name, e.g. `equiarm_msgs::msg::dds_::Observation_`.
    pub dds_type_name: &'static str,
    /// Complete concatenated definition (see [`RosMessage::DEFINITION`]).
    pub definition: &'static str,
}

impl TypeInfo {
    /// The entry for `M`.
    pub const fn of<M: RosMessage>() -> Self {
        Self { type_name: M::TYPE_NAME, dds_type_name: M::DDS_TYPE_NAME, definition: M::DEFINITION }
    }

    /// Finds a type by its ROS 2 name; accepts `pkg/msg/Type` and `pkg/Type`.
    pub fn find(name: &str) -> Option<&'static TypeInfo> {
        let full = match name.split('/').collect::<Vec<_>>().as_slice() {
            [pkg, ty] => format!("{pkg}/msg/{ty}"),
            _ => name.to_string(),
        };
        ALL_TYPES.iter().find(|t| t.type_name == full)
    }
}

impl builtin_interfaces::Time {
    /// Builds a time from nanoseconds since the epoch (negative values give negative `sec` with
    /// `nanosec` in `[0, 1e9)`, as ROS 2 normalises them).
    pub fn from_nanos(ns: i64) -> Self {
        let sec = ns.div_euclid(1_000_000_000);
        let nanosec = ns.rem_euclid(1_000_000_000) as u32;
        Self { sec: sec.clamp(i32::MIN as i64, i32::MAX as i64) as i32, nanosec }
    }

    /// Nanoseconds since the epoch.
    pub fn as_nanos(&self) -> i64 {
        self.sec as i64 * 1_000_000_000 + self.nanosec as i64
    }
}

impl std_msgs::Header {
    /// A header with the given stamp and frame.
    pub fn new(stamp: builtin_interfaces::Time, frame_id: impl Into<String>) -> Self {
        Self { stamp, frame_id: frame_id.into() }
    }
}

/// The `source` values of [`msg::GripperCommand`] by name, for command lines and logs.
pub fn command_source_name(source: u8) -> &'static str {
    match source {
        msg::GripperCommand::SOURCE_POLICY => "policy",
        msg::GripperCommand::SOURCE_EXPERT => "expert",
        msg::GripperCommand::SOURCE_RANDOM => "random",
        msg::GripperCommand::SOURCE_TELEOP => "teleop",
        _ => "unknown",
    }
}
