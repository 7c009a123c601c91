//! equiarm's exporters: what robot-learning tools read, made from a bag.
//!
//! - [`steps`]: a bag's steps (Transitions joined with their Observations), episode by episode;
//! - [`lerobot`]: a LeRobotDataset v3.0 directory (Parquet data, `meta/`), one row per step;
//! - [`video`]: one MP4 (H.264) per episode, colour beside depth with a caption.
//!
//! No ROS imports: the bag is read with `equiarm_bag`, the messages are `equiarm_msgs`' types.

use std::path::PathBuf;

use equiarm_types::files::FileError;

pub mod lerobot;
pub mod steps;
pub mod video;

/// Why an export failed.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// The bag could not be opened or read.
    #[error(transparent)]
    Bag(#[from] equiarm_bag::BagError),
    /// A topic of the bag was recorded with another definition of its type.
    #[error("{}: {cause}", bag.display())]
    Decode {
        /// The bag.
        bag: PathBuf,
        /// Which topic and type.
        cause: equiarm_bag::DecodeError,
    },
    /// Writing a file failed.
    #[error(transparent)]
    File(#[from] FileError),
    /// The output directory exists and is not empty.
    #[error("{}: exists and is not empty (give a new directory)", .0.display())]
    OutExists(PathBuf),
    /// The bag holds no step to export.
    #[error("{}: no Transition of the bag could be joined with its Observations (a bag of the suite records `/transitions` and every env's `observation`)", .0.display())]
    NoSteps(PathBuf),
    /// An Observation's images do not decode, or its size differs from the first one's.
    #[error("observation {env}/{seq}: {reason}")]
    Frame {
        /// Its env.
        env: String,
        /// Its seq.
        seq: u64,
        /// What is wrong.
        reason: String,
    },
    /// Writing a video failed.
    #[error(transparent)]
    Video(#[from] equiarm_train::video::VideoError),
    /// Encoding a frame or a Parquet file failed.
    #[error("{}: {reason}", path.display())]
    Encode {
        /// The file being written.
        path: PathBuf,
        /// What failed.
        reason: String,
    },
}
