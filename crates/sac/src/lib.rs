//! equiarm_sac: SAC from demonstrations as in Wang et al. (ICLR 2023), PAPER_SPEC §2, with no ROS in it.
//!
//! - [`agent`]: the SAC agent (critic → actor → α → target), Equi / CNN / SEN networks by name.
//! - [`optim`]: Adam and Polyak keyed by parameter path (checkpoints load across processes).
//! - [`rng`]: seeded ChaCha streams whose exact position is saved in checkpoints.
//! - [`metrics`], [`plot`], [`progress`]: CleanRL-style scalar logs, the learning-curve PNG and
//!   the progress line.
//!
//! Limitations: FERM (CURL) is not implemented yet.

pub mod agent;
pub mod metrics;
pub mod optim;
pub mod plot;
pub mod progress;
pub mod rng;
pub mod tensorfile;
