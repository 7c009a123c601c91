//! equiarm's fuzz program on stable Rust: every external input of equiarm (CDR messages, bags,
//! configs, weights, optimiser state, checkpoints, URDF files, command-line numbers) as a target
//! fed with mutated valid seeds. Panics, aborts and hangs are caught, the inputs that caused them
//! saved. See `docs/fuzzing.md` for the targets, the mutator and how to run it.
//!
//! Modules: [`mutate`] (the seed mutator), [`targets`] (seeds and harnesses), [`runner`] (the
//! parent and worker processes).

pub mod mutate;
pub mod runner;
pub mod targets;
