//! equiarm's experiment runner (no ROS): a named grid of in-process SAC runs (task × model variant
//! × camera view × corruption × seed) read from `experiments/NAME.toml` ([`grid`]), run a few at a
//! time as child processes that survive interruption ([`runner`]), and reported from the run
//! directories alone as a Markdown table and learning-curve figures ([`report`]). The command line
//! is `equiarm experiment run|status|report NAME` ([`cli`]); `equiarm experiment claims` checks the
//! paper's claims on the reports' archives ([`claims`]).

pub mod claims;
pub mod cli;
pub mod error;
pub mod grid;
pub mod report;
pub mod runner;

pub use error::{ExperimentError, Result};
