//! equiarm_sac: SAC from demonstrations as in Wang et al. (ICLR 2023), PAPER_SPEC §2, with no ROS in it.
//!
//! - [`agent`]: the SAC agent (critic → actor → α → target), Equi / CNN / SEN networks by name.
//! - [`replay`], [`frame`], [`augment`]: prioritised replay with expert retention over compact
//!   shared frames; RAD/DrQ random crops and the centre crop for acting.
//! - [`learner`]: agent + replay + crops + checkpoints, fed by any transport.
//! - [`train`]: the transport-free training loop (`equiarm train --in-process`).
//! - [`config`]: the typed run configuration, paper and reduced presets per task.
//! - [`optim`]: Adam and Polyak keyed by parameter path (checkpoints load across processes).
//! - [`rng`], [`schedule`]: seeded ChaCha streams saved in checkpoints; Linear/Every schedules.
//! - [`metrics`], [`plot`], [`progress`]: CleanRL-style scalar logs, the learning-curve PNG and
//!   the progress line.
//!
//! Limitations: FERM (CURL) is not implemented yet.

pub mod agent;
pub mod augment;
pub mod config;
pub mod frame;
pub mod learner;
pub mod metrics;
pub mod optim;
pub mod plot;
pub mod progress;
pub mod replay;
pub mod rng;
pub mod schedule;
pub mod tensorfile;
pub mod train;
