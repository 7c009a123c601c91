//! # equiarm_rotest
//!
//! The supervised rotation-estimation experiment of Wang et al. (ICLR 2023) — see docs/rotest.md: a
//! classifier sees two RGBD images of three objects, before and after the scene was rotated by
//! one of eight angles about the workspace centre, and names the angle. A C8-equivariant network
//! against a CNN, under symmetry-breaking corruptions of the images or the labels. No ROS here.
//!
//! - [`dataset`]: the `pairs.rotest` file (JSON header, one zstd chunk per pair).
//! - [`generate`]: generating a dataset in parallel (scene and rendering in `equiarm_sim::rotest`),
//!   snapshot PNGs.
//! - [`bound`]: the upper bound on the accuracy of an invariant classifier.
//! - [`train`]: training and evaluation, the run file.
//! - [`resume`]: a run's checkpoint, to continue it where it stopped.
//! - [`grid`]: the experiment's grid of runs: where each stands, training those left.
//! - [`report`]: the table and figures over many runs.
//! - [`cli`]: the `equiarm rotest` subcommands.

pub mod bound;
pub mod cli;
pub mod dataset;
pub mod error;
pub mod generate;
pub mod grid;
pub mod report;
pub mod resume;
pub mod train;

pub use error::{Result, RotestError};
