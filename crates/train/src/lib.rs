//! equiarm_train: a training run around the learner ([`equiarm_sac`]), with no ROS in it.
//!
//! - [`inprocess`]: the transport-free training loop (`equiarm train --in-process`).
//! - [`env`](mod@env): the simulator side: env configs, episode seeds, frames, expert demonstrations.
//! - [`evaluation`]: greedy evaluations, in-process or from published episode results.
//! - [`grid`]: the one grid runner (experiment grids, the rotation experiment) and its status.
//! - [`record`], [`rundir`]: what a run writes (config, metrics, evaluations, checkpoints) and its
//!   directory's layout and lock.
//! - [`config`]: the config checks that need the simulator.
//! - [`metrics`], [`plot`], [`progress`]: CleanRL-style scalar logs, the learning-curve PNG and
//!   the progress line.
//! - [`device_check`]: `equiarm device-check`, update and action times on a device beside the CPU's,
//!   and a short run there.
//!
//! The nodes' logic, without DDS (the nodes in `equiarm_nodes` are adapters around it):
//! - [`trainer`], [`ingest`], [`lockstep`]: the trainer node's decisions, its intake of transitions and episode results, and
//!   its deterministic rounds.
//! - [`policy`], [`gate`]: the policy node's acting and when it answers.
//! - [`stepper`]: the sim node's env, stepped by commands, as messages.
//! - [`policy_eval`], [`bag_report`]: an actor replayed on a recorded bag; `bag info` and
//!   `bag eval` texts.

use std::fmt::Display;
use std::path::{Path, PathBuf};

use thiserror::Error;

/// The exit status of a command stopped by SIGINT or SIGTERM before its work was all done, with
/// what it had finished kept (a run's checkpoint, a grid's finished runs): the same command
/// continues it.
pub const STOPPED_EXIT: i32 = 3;

pub mod bag_report;
pub mod config;
pub mod device_check;
pub mod env;
pub mod evaluation;
pub mod gate;
pub mod grid;
pub mod ingest;
pub mod inprocess;
pub mod lockstep;
pub mod metrics;
pub mod plot;
pub mod policy;
pub mod policy_eval;
pub mod progress;
pub mod record;
pub mod rundir;
pub mod stepper;
pub mod trainer;
pub mod video;

/// Errors of a training run.
#[derive(Debug, Error)]
pub enum TrainError {
    /// The config failed its checks.
    #[error(transparent)]
    Config(#[from] equiarm_sac::config::ConfigError),
    /// The learner failed.
    #[error(transparent)]
    Learner(#[from] equiarm_sac::learner::LearnerError),
    /// The simulator failed.
    #[error("simulator: {0}")]
    Sim(equiarm_sim::SimError),
    /// A frame could not be stored.
    #[error("frame: {0}")]
    Frame(equiarm_sac::frame::FrameError),
    /// The simulator rendered a frame that is not square.
    #[error("frame is {width}×{height}, must be square")]
    NotSquare {
        /// Width in pixels.
        width: usize,
        /// Height in pixels.
        height: usize,
    },
    /// A run or checkpoint directory cannot be used as asked (in use, holds another run, not a
    /// checkpoint, written by another build).
    #[error("{path}: {message}")]
    RunDir {
        /// The directory or file.
        path: PathBuf,
        /// What is wrong, and the way out.
        message: String,
    },
    /// Reading or writing a file failed (the file, and the cause).
    #[error(transparent)]
    File(#[from] equiarm_types::files::FileError),
    /// A JSON file of the run could not be read or written.
    #[error(transparent)]
    Json(#[from] equiarm_sac::learner::JsonFileError),
    /// The metrics log could not be written or read.
    #[error(transparent)]
    Metrics(#[from] metrics::MetricsError),
    /// The learning curve could not be drawn.
    #[error(transparent)]
    Plot(#[from] plot::PlotError),
    /// Writing an evaluation video failed.
    #[error(transparent)]
    Video(#[from] video::VideoError),
    /// The expert did not produce enough successful demos.
    #[error("the expert succeeded in {got} of {tried} demo episodes; {want} needed")]
    Demos {
        /// Successes.
        got: usize,
        /// Episodes tried.
        tried: usize,
        /// Needed.
        want: usize,
    },
}

// By hand, not `#[from]`: these messages show their cause, so it is not also chained as a source
// (docs/conventions.md, "Errors").
impl From<equiarm_sim::SimError> for TrainError {
    fn from(e: equiarm_sim::SimError) -> Self {
        TrainError::Sim(e)
    }
}

impl From<equiarm_sac::frame::FrameError> for TrainError {
    fn from(e: equiarm_sac::frame::FrameError) -> Self {
        TrainError::Frame(e)
    }
}

impl TrainError {
    /// A [`TrainError::RunDir`] about `path`.
    pub fn run_dir(path: &Path, message: impl Display) -> Self {
        TrainError::RunDir { path: path.to_path_buf(), message: message.to_string() }
    }
}
