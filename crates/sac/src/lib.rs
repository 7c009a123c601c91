//! equiarm_sac: SAC from demonstrations as in Wang et al. (ICLR 2023), PAPER_SPEC §2, with no ROS in it.
//!
//! Limitations: FERM (CURL) is not implemented yet.

pub mod augment;
pub mod frame;
pub mod replay;
pub mod schedule;
