//! The environment API: [`Env::reset`] / [`Env::step`] with the paper's step semantics, observations
//! as ROS-ready buffers (rgb8 colour, f32 planar depth in metres, a holding flag) plus the expert
//! action in physical units, and [`VecEnv`] stepping many envs in parallel with rayon.
//!
//! Determinism contract: the same config, seed and action sequence give byte-identical observations
//! (same build, same machine). Each reset builds a fresh rapier world; all randomness comes from the
//! seed; parallel stepping runs each env on one thread, so the thread count does not matter.
//!
//! Symmetry corruptions ([`Corruption`], docs/paper.md §5): random reflection of every observation, the
//! single-camera orthographic occlusion projection, and the gripper-only scene (no checker floor, no
//! arm). The arm that carries the gripper is drawn unless [`EnvConfig::arm`] hides it ([`crate::arm`]).

use std::sync::Arc;

use rapier3d::prelude::*;
use rayon::prelude::*;

use crate::arm::Arm;
use crate::assets::Assets;
use crate::camera::{Camera, CameraConfig};
use crate::error::{Result, SimError};
use crate::gripper::{Action, Gripper};
use crate::render::{Frame, MeshCache, rasterize};
use crate::rng::Rng;
use crate::tasks::{RESET_TCP, TaskKind, TaskState};
use crate::world::{Scene, SimParams};

pub use equiarm_types::{ArmView, Corruption};

/// Largest episode step limit accepted (the paper's is 50).
pub const MAX_EPISODE_STEPS: u32 = 10_000;

/// Everything that defines an env (serde: unknown keys are rejected; missing keys take the
/// defaults of [`EnvConfig::new`] with block picking).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EnvConfig {
    /// The task: its objects, success test and expert planner.
    pub task: TaskKind,
    /// The camera (default: the paper's oblique `camera_side_rgbd` view, 152 × 152 pixels).
    pub camera: CameraConfig,
    /// Physics settings.
    pub params: SimParams,
    /// Symmetry corruptions of the observations (default: none).
    pub corruption: Corruption,
    /// Whether the arm carrying the gripper is drawn (default: visible, as in the paper; the
    /// gripper-only corruption hides it whatever this says).
    pub arm: ArmView,
    /// Episode length limit (50 for every task in the paper).
    pub max_steps: u32,
    /// Render images. With `false`, observations carry empty image buffers (for planner runs).
    pub render: bool,
}

impl Default for EnvConfig {
    fn default() -> Self {
        Self::new(TaskKind::BlockPicking)
    }
}

impl EnvConfig {
    /// The paper's setup of `task`: default camera and physics, no corruption, the arm in view, 50
    /// steps per episode, images rendered.
    pub fn new(task: TaskKind) -> Self {
        Self {
            task,
            camera: CameraConfig::default(),
            params: SimParams::default(),
            corruption: Corruption::default(),
            arm: ArmView::Visible,
            max_steps: 50,
            render: true,
        }
    }
}

/// What the agent (or a node) sees after a reset or step.
#[derive(Clone, Debug, PartialEq)]
pub struct Observation {
    /// Steps taken in this episode.
    pub step: u32,
    /// Image width, pixels (0 if rendering is off).
    pub width: usize,
    /// Image height, pixels (0 if rendering is off).
    pub height: usize,
    /// rgb8, H×W×3, row-major (empty if rendering is off).
    pub color: Vec<u8>,
    /// Planar depth in metres, H×W, row-major (empty if rendering is off).
    pub depth: Vec<f32>,
    /// Body ids, H×W (names in [`Env::segmentation_names`]).
    pub segmentation: Vec<u16>,
    /// The gripper holds an object.
    pub holding: bool,
    /// Measured jaw opening in [0, 1].
    pub open_ratio: f32,
    /// TCP position (m) and yaw (rad).
    pub tcp: [f32; 3],
    /// Gripper yaw about world z, rad, as commanded: neither wrapped nor clipped (0 at reset).
    pub yaw: f32,
    /// The expert planner's action for this state, in physical units.
    pub expert_action: Action,
}

/// Extra information from a step.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct StepInfo {
    /// The task's success test holds after this step: reward 1, the episode ends.
    pub success: bool,
    /// An object left the workspace: the episode ends with reward 0.
    pub invalid: bool,
    /// The step limit was reached.
    pub timeout: bool,
}

/// The result of [`Env::step`].
#[derive(Clone, Debug, PartialEq)]
pub struct StepResult {
    /// The observation after the step (the terminal one when `done`).
    pub observation: Observation,
    /// 1.0 when the task's success test holds after the step, else 0.0 (sparse).
    pub reward: f32,
    /// The episode ended: success, an invalid state or the step limit (`info` says which).
    pub done: bool,
    /// Why the episode ended, if it did.
    pub info: StepInfo,
}

struct Episode {
    scene: Scene,
    gripper: Gripper,
    arm: Option<Arm>,
    task: TaskState,
    meshes: MeshCache,
    steps: u32,
    reflect_rng: Rng,
    expert: Action,
    done: bool,
}

/// One simulated environment.
pub struct Env {
    config: EnvConfig,
    camera: Camera,
    assets: Arc<Assets>,
    episode: Option<Episode>,
}

impl Env {
    /// Builds an env with the bundled assets.
    pub fn new(config: EnvConfig) -> Result<Self> {
        Self::with_assets(config, Arc::new(Assets::bundled()?))
    }

    /// Builds an env sharing already-loaded assets.
    pub fn with_assets(config: EnvConfig, assets: Arc<Assets>) -> Result<Self> {
        config.params.validate()?;
        if !(1..=MAX_EPISODE_STEPS).contains(&config.max_steps) {
            return Err(SimError::Config {
                field: "max_steps",
                message: format!("{} must be 1..={MAX_EPISODE_STEPS} (the paper's limit is 50)", config.max_steps),
            });
        }
        let camera = Camera::new(config.camera.clone())?;
        Ok(Self { config, camera, assets, episode: None })
    }

    /// The configuration the env was built with.
    pub fn config(&self) -> &EnvConfig {
        &self.config
    }

    /// The validated camera (intrinsics, pose, `CameraInfo`) the observations are rendered with.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// Names of the segmentation ids of the current episode (index = id).
    pub fn segmentation_names(&self) -> &[String] {
        self.episode.as_ref().map(|e| e.scene.seg_names.as_slice()).unwrap_or(&[])
    }

    /// The current scene (after a reset).
    pub fn scene(&self) -> Option<&Scene> {
        self.episode.as_ref().map(|e| &e.scene)
    }

    /// The pose of the gripper's tool centre point in the world: origin at the TCP, turned by the
    /// commanded yaw about the world's z axis (up). `None` before the first reset. The palm is
    /// kinematic, so after a reset or a step this is where the gripper is.
    pub fn gripper_pose(&self) -> Option<nalgebra::Isometry3<f64>> {
        let g = &self.episode.as_ref()?.gripper;
        let t = nalgebra::Translation3::new(g.tcp.x as f64, g.tcp.y as f64, g.tcp.z as f64);
        Some(nalgebra::Isometry3::from_parts(t, nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.0, g.yaw as f64)))
    }

    /// Whether the scene shows the arm: [`EnvConfig::arm`] visible and not the gripper-only scene.
    pub fn shows_arm(&self) -> bool {
        self.config.arm == ArmView::Visible && !self.config.corruption.gripper_only
    }

    /// Starts a new episode from `seed`.
    pub fn reset(&mut self, seed: u64) -> Result<Observation> {
        let mut rng = Rng::new(seed);
        let reflect_rng = Rng::new(seed ^ 0xa076_1d64_78bd_642f);
        let mut scene = Scene::new(&self.config.params, &self.assets, !self.config.corruption.gripper_only)?;
        let tcp = Vector::new(RESET_TCP[0], RESET_TCP[1], RESET_TCP[2]);
        let gripper = Gripper::insert(&mut scene, &self.assets, tcp, 0.0, 1.0)?;
        let task = TaskState::spawn(self.config.task, &mut scene, &self.assets, &mut rng)?;
        for _ in 0..scene.params.reset_settle_substeps {
            scene.step();
        }
        // last, so that the rest of the scene is built the same with the arm as without it
        let arm = (self.shows_arm()).then(|| Arm::insert(&mut scene, &self.assets)).transpose()?;
        let meshes = MeshCache::new(&scene);
        self.episode = Some(Episode {
            scene,
            gripper,
            arm,
            task,
            meshes,
            steps: 0,
            reflect_rng,
            expert: Action::default(),
            done: false,
        });
        Ok(self.observe())
    }

    /// Applies `action` (physical units; clipped to the action ranges, the target clamped to the
    /// workspace). A non-finite component is rejected with an error and nothing moves.
    pub fn step(&mut self, action: &Action) -> Result<StepResult> {
        if !action.is_finite() {
            return Err(SimError::Action(format!("non-finite component in {action:?}")));
        }
        let ep = self.episode.as_mut().ok_or(SimError::NotReset)?;
        if ep.done {
            return Err(SimError::EpisodeOver { steps: ep.steps });
        }
        ep.gripper.apply(&mut ep.scene, *action);
        ep.steps += 1;
        let held = ep.gripper.held_bodies(&ep.scene);
        let success = ep.task.success(&ep.scene, &ep.gripper, &held);
        let invalid = !success && !ep.task.valid(&ep.scene, &held);
        let timeout = ep.steps >= self.config.max_steps;
        let done = success || invalid || timeout;
        ep.done = done;
        let observation = self.observe();
        Ok(StepResult {
            observation,
            reward: if success { 1.0 } else { 0.0 },
            done,
            info: StepInfo { success, invalid, timeout },
        })
    }

    /// Resets with `seed` and follows the expert planner to the end of the episode; returns the
    /// last step's result (its `info` says whether the episode succeeded).
    pub fn run_expert_episode(&mut self, seed: u64) -> Result<StepResult> {
        let mut obs = self.reset(seed)?;
        loop {
            let r = self.step(&obs.expert_action)?;
            if r.done {
                return Ok(r);
            }
            obs = r.observation;
        }
    }

    /// The expert action for the current state (the one in the last observation).
    pub fn expert_action(&self) -> Option<Action> {
        self.episode.as_ref().map(|e| e.expert)
    }

    /// Renders the current scene without corruptions (colour, depth, segmentation).
    pub fn render(&self) -> Option<Frame> {
        let ep = self.episode.as_ref()?;
        let mut frame = Frame::new(self.camera.width(), self.camera.height(), self.camera.config.far as f32);
        rasterize(&ep.scene, &ep.meshes, &self.camera, &mut frame);
        Some(frame)
    }

    fn observe(&mut self) -> Observation {
        if let Some(ep) = self.episode.as_mut()
            && let Some(arm) = ep.arm.as_mut()
        {
            let palm = *ep.scene.physics.bodies[ep.gripper.palm].position();
            arm.follow(&mut ep.scene, &palm);
        }
        let frame = if self.config.render { self.render() } else { None };
        let corruption = self.config.corruption;
        let (w, h) = (self.camera.width(), self.camera.height());
        let camera = self.camera.clone();
        let ep = self.episode.as_mut().expect("observe is called with an episode");
        let held = ep.gripper.held_bodies(&ep.scene);
        ep.expert = ep.task.expert_action(&ep.scene, &ep.gripper, &held);
        let (mut color, mut depth, mut segmentation) = match frame {
            Some(f) => (f.color, f.depth, f.segmentation),
            None => (Vec::new(), Vec::new(), Vec::new()),
        };
        if !depth.is_empty() {
            if corruption.occlusion_projection {
                let f = crate::corrupt::occlusion_projection(
                    &camera,
                    &depth,
                    &segmentation,
                    &ep.gripper,
                    &ep.scene,
                    ep.task.goal,
                );
                depth = f.depth;
                segmentation = f.segmentation;
                color = vec![0; w * h * 3];
            }
            if corruption.random_reflection {
                let cols = ep.reflect_rng.coin();
                let rows = ep.reflect_rng.coin();
                crate::corrupt::reflect(&mut color, 3, w, h, cols, rows);
                crate::corrupt::reflect(&mut depth, 1, w, h, cols, rows);
                crate::corrupt::reflect(&mut segmentation, 1, w, h, cols, rows);
            }
        }
        let t = ep.gripper.tcp;
        Observation {
            step: ep.steps,
            width: if color.is_empty() { 0 } else { w },
            height: if color.is_empty() { 0 } else { h },
            color,
            depth,
            segmentation,
            holding: !held.is_empty(),
            open_ratio: ep.gripper.open_ratio(&ep.scene),
            tcp: [t.x, t.y, t.z],
            yaw: ep.gripper.yaw,
            expert_action: ep.expert,
        }
    }
}

/// Many envs stepped in parallel (one rayon task per env).
pub struct VecEnv {
    /// The envs; [`VecEnv::reset`] and [`VecEnv::step`] give env k the k-th seed or action.
    pub envs: Vec<Env>,
}

impl VecEnv {
    /// `n` envs with one config, sharing one copy of the assets.
    pub fn new(config: EnvConfig, n: usize) -> Result<Self> {
        let assets = Arc::new(Assets::bundled()?);
        let envs = (0..n).map(|_| Env::with_assets(config.clone(), assets.clone())).collect::<Result<_>>()?;
        Ok(Self { envs })
    }

    /// Resets env k with `seeds[k]`.
    pub fn reset(&mut self, seeds: &[u64]) -> Result<Vec<Observation>> {
        if seeds.len() != self.envs.len() {
            return Err(SimError::Config {
                field: "seeds",
                message: format!("{} seeds for {} envs", seeds.len(), self.envs.len()),
            });
        }
        self.envs.par_iter_mut().zip(seeds.par_iter()).map(|(e, s)| e.reset(*s)).collect()
    }

    /// Steps env k with `actions[k]`.
    pub fn step(&mut self, actions: &[Action]) -> Result<Vec<StepResult>> {
        if actions.len() != self.envs.len() {
            return Err(SimError::Config {
                field: "actions",
                message: format!("{} actions for {} envs", actions.len(), self.envs.len()),
            });
        }
        self.envs.par_iter_mut().zip(actions.par_iter()).map(|(e, a)| e.step(a)).collect()
    }
}
