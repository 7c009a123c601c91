//! rosbag2-compatible MCAP bags, without ROS: what `ros2 bag`, Foxglove, `rosbags` and the `mcap`
//! Python tools read.
//!
//! - [`Writer`]: a bag directory `NAME/` with `NAME_0.mcap`, `NAME_1.mcap`, … (split by size or
//!   duration) and `metadata.yaml` (version 8, QoS as integer-enum YAML strings, which every distro
//!   from Humble on reads), MCAP profile `ros2`, one `ros2msg` schema per type with the concatenated
//!   nested definition, `cdr` channels with `offered_qos_profiles` and `topic_type_hash`, the
//!   `rosbag2` metadata record at open and close, chunk compression none / lz4 / zstd, and a timed
//!   flush so that a killed recorder loses at most one flush interval.
//! - [`Reader`]: every message of a bag directory or file in file order; a file whose end is missing
//!   (a killed recorder) is read chunk by chunk up to the last complete chunk.
//! - [`recover`]: rewrites a killed bag as a complete, indexed one.
//! - [`eval`]: per-episode metrics and success rates with Wilson intervals.
//!
//! ## Limitations
//! - `topic_type_hash` is written empty (`""`, accepted by every reader); REP-2011 hashes are not
//!   computed.
//! - Messages are read in file order (the order they were received), not re-sorted by log time.
//! - Files are memory-mapped for reading: do not modify a bag while it is being read.

mod decode;
mod error;
pub mod eval;
mod metadata;
mod metadata_check;
pub mod qos;
mod reader;
mod recover;
mod writer;

pub use decode::{DecodeError, same_definition};
pub use error::BagError;
pub use metadata_check::MetadataCheck;
pub use reader::{BagInfo, FileInfo, FileRead, LostChunk, ReadMode, ReadReport, Reader, RecordedMessage, TopicStats};
pub use recover::{DamagedChannel, RecoverReport, recover};
pub use writer::{BagSummary, Compression, TopicId, TopicInfo, Writer, WriterOptions};

/// Nanoseconds since the Unix epoch, the time unit of every MCAP record.
pub type Nanos = u64;
