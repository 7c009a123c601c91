//! equiarm_sac: SAC from demonstrations as in Wang et al. (ICLR 2023), docs/paper.md §2, with no ROS in it.
//!
//! - [`agent`]: the SAC agent (critic → actor → α → target), Equi / CNN / SEN networks by name.
//! - [`replay`], [`frame`], [`augment`]: prioritised replay with expert retention over compact
//!   shared frames; RAD/DrQ random crops and the centre crop for acting.
//! - [`learner`]: agent + replay + crops + checkpoints, fed by any transport.
//! - [`config`]: the typed run configuration, paper and reduced presets per task.
//! - [`optim`]: Adam and Polyak keyed by parameter path (checkpoints load across processes).
//! - [`rng`], [`schedule`]: seeded ChaCha streams saved in checkpoints; linear and cosine schedules.
//! - [`tensorfile`]: safetensors files of named f32 tensors (optimiser state).
//! - [`timing`]: how long an update and an action take on a device (benchmarks, `equiarm device-check`).
//!
//! The training run around it (the in-process loop, demos, evaluation, run directories, metrics,
//! plots) is `equiarm_train`; the simulator is not a dependency of the learner.

pub mod agent;
pub mod augment;
pub mod config;
pub mod frame;
pub mod learner;
pub mod optim;
pub mod replay;
pub mod rng;
pub mod schedule;
pub mod tensorfile;
pub mod timing;
