//! # equiarm_sim
//!
//! The simulator of equiarm: BulletArm's five close-loop manipulation tasks (Wang et al., ICLR 2023,
//! docs/paper.md §3) in rapier, seen by an oblique RGBD camera, with expert planners. No ROS here: a node
//! maps [`Env`] calls to messages.
//!
//! ```no_run
//! use equiarm_sim::{Env, EnvConfig, TaskKind};
//! let mut env = Env::new(EnvConfig::new(TaskKind::BlockPicking))?;
//! let mut obs = env.reset(0)?;
//! loop {
//!     let r = env.step(&obs.expert_action)?;
//!     obs = r.observation;
//!     if r.done { break; }
//! }
//! # Ok::<(), equiarm_sim::SimError>(())
//! ```
//!
//! Modules: [`assets`] (URDF files), [`world`] (rapier settings, scene), [`gripper`] (floating
//! gripper, action semantics, holding), [`arm`] (the arm drawn carrying the gripper, its inverse
//! kinematics), [`camera`] (intrinsics/extrinsics, presets), [`render`]
//! (rasteriser + ray-cast oracle), [`tasks`] (tasks and expert planners), [`env`](mod@env) (Env / VecEnv),
//! [`corrupt`] (symmetry corruptions), [`snapshot`] (PNG output), [`rotest`] (the rotation-estimation
//! experiment's scene, corruptions and pairs).
//!
//! Limitations: the gripper floats (the arm is drawn following it, but exerts no force); the bowl is built from boxes; determinism holds
//! for one build on one machine (rapier's `enhanced-determinism` is not enabled).

pub mod arm;
pub mod assets;
pub mod camera;
pub mod corrupt;
pub mod env;
pub mod error;
pub mod gripper;
pub mod render;
pub mod rng;
pub mod rotest;
pub mod snapshot;
pub mod tasks;
pub mod world;

pub use assets::{AssetKind, Assets};
pub use camera::{Camera, CameraConfig, ViewPreset};
pub use env::{Corruption, Env, EnvConfig, Observation, StepInfo, StepResult, VecEnv};
pub use error::{Result, SimError};
pub use gripper::Action;
pub use render::Frame;
pub use tasks::TaskKind;
pub use world::SimParams;
