//! # equiarm_types
//!
//! The domain's words as types, defined once for every crate above: the tasks and their per-task
//! facts ([`TaskKind`]), the camera views ([`ViewPreset`]) and the arm in view ([`ArmView`]), the symmetry corruptions
//! ([`Corruption`]), the network families ([`ModelKind`]), the augmentations ([`Augmentation`]),
//! the gripper [`Action`] with its normalisation, and the network input's planes ([`OBS_PLANES`]).
//!
//! Each named value has one spelling, written once ([`named_enum!`]): `Display`, `FromStr`,
//! serde's string form, clap's `ValueEnum` and the lists of names in help and error texts all come
//! from it, so text is parsed once, at the edge, and a config holds these types. No simulator,
//! network or ROS dependency: this crate is at the bottom of the graph.
//!
//! Beside the words, what every crate does with files the same way ([`files`]): the error of a file
//! operation, and writing a file whole or not at all.

pub mod action;
pub mod augmentation;
pub mod corruption;
pub mod files;
pub mod model;
mod named;
pub mod planes;
pub mod task;
pub mod view;

pub use action::{ACTION_DIM, Action, MAX_DPOS, MAX_DROT, NormalizedAction};
pub use augmentation::{Augmentation, AugmentationKind};
pub use corruption::{Corruption, CorruptionKind};
pub use model::ModelKind;
pub use named::ParseError;
pub use planes::{OBS_PLANES, Plane};
pub use task::{PAPER_EPISODE_STEPS, TaskKind};
pub use view::{ArmView, ViewPreset};
