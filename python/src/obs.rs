//! Observations as numpy arrays. Each image buffer the simulator made moves into its array (no copy);
//! a batch of n envs' frames is assembled in Rust (one `memcpy` per frame), outside the GIL.
//!
//! The observation of one env, as Python sees it:
//! - `color`: uint8, (H, W, 3), RGB;
//! - `depth`: float32, (H, W), planar depth in metres (background: the camera's far distance);
//! - `gripper`: float32, (2,): the holding flag (0 or 1) and the measured jaw opening in [0, 1].

use equiarm_sim::{Observation, StepResult};
use equiarm_types::ACTION_DIM;
use numpy::{PyArray1, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::args::Units;

/// Length of the `gripper` vector.
pub const GRIPPER_DIM: usize = 2;

/// The gripper vector of an observation.
pub fn gripper(o: &Observation) -> [f32; GRIPPER_DIM] {
    [if o.holding { 1.0 } else { 0.0 }, o.open_ratio]
}

fn array<'py, T: numpy::Element>(py: Python<'py>, v: Vec<T>, shape: &[usize]) -> PyResult<Bound<'py, PyAny>> {
    Ok(PyArray1::from_vec(py, v).reshape(shape)?.into_any())
}

/// One observation as the dict above (its buffers moved, not copied).
pub fn observation(py: Python<'_>, o: Observation) -> PyResult<Bound<'_, PyDict>> {
    let (h, w) = (o.height, o.width);
    let d = PyDict::new(py);
    let g = gripper(&o).to_vec();
    d.set_item("color", array(py, o.color, &[h, w, 3])?)?;
    d.set_item("depth", array(py, o.depth, &[h, w])?)?;
    d.set_item("gripper", array(py, g, &[GRIPPER_DIM])?)?;
    Ok(d)
}

/// What one env's reset or step gave, kept for the batch.
pub struct Outcome {
    /// The observation (after a step: the next one; after an automatic reset: the new episode's first).
    pub obs: Observation,
    /// The seed of the observation's episode.
    pub seed: u64,
    /// Reward of the step (0 for a reset).
    pub reward: f32,
    /// The task ended the episode (success or an object out of the workspace).
    pub terminated: bool,
    /// The episode's step limit ended it.
    pub truncated: bool,
    /// The task's success test held after the step.
    pub success: bool,
    /// This outcome is a reset (the action was not applied).
    pub reset: bool,
}

impl Outcome {
    /// The outcome of a reset.
    pub fn reset(obs: Observation, seed: u64) -> Self {
        Outcome { obs, seed, reward: 0.0, terminated: false, truncated: false, success: false, reset: true }
    }

    /// The outcome of a step.
    pub fn step(r: StepResult, seed: u64) -> Self {
        let terminated = r.info.success || r.info.invalid;
        Outcome {
            obs: r.observation,
            seed,
            reward: r.reward,
            terminated,
            truncated: r.info.timeout && !terminated,
            success: r.info.success,
            reset: false,
        }
    }

    /// The step's info dict: `success`, `invalid` (an object left the workspace), `expert_action`
    /// (the planner's action for the new state, in `units`), `seed` and `step` of the episode.
    pub fn info<'py>(&self, py: Python<'py>, units: Units) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        d.set_item("success", self.success)?;
        d.set_item("invalid", self.terminated && !self.success)?;
        d.set_item("expert_action", array(py, units.express(self.obs.expert_action).to_vec(), &[ACTION_DIM])?)?;
        d.set_item("seed", self.seed)?;
        d.set_item("step", self.obs.step)?;
        Ok(d)
    }
}

/// The outcomes of n envs as arrays with a leading env axis: an observation dict (`color` (n, H, W, 3),
/// `depth` (n, H, W), `gripper` (n, 2)) and `reward`, `terminated`, `truncated`, `success`, `reset`
/// (n,), `expert_action` (n, 5) in the env's units, `seed` and `step` (n,).
pub struct Batch {
    n: usize,
    side: usize,
    color: Vec<u8>,
    depth: Vec<f32>,
    gripper: Vec<f32>,
    reward: Vec<f32>,
    terminated: Vec<bool>,
    truncated: Vec<bool>,
    success: Vec<bool>,
    reset: Vec<bool>,
    expert: Vec<f32>,
    seed: Vec<u64>,
    step: Vec<u32>,
}

impl Batch {
    /// Gathers `outcomes` (all of frames `side` × `side`, or all without images: side 0).
    pub fn gather(outcomes: Vec<Outcome>, side: usize, units: Units) -> Self {
        let n = outcomes.len();
        let mut b = Batch {
            n,
            side,
            color: Vec::with_capacity(n * side * side * 3),
            depth: Vec::with_capacity(n * side * side),
            gripper: Vec::with_capacity(n * GRIPPER_DIM),
            reward: Vec::with_capacity(n),
            terminated: Vec::with_capacity(n),
            truncated: Vec::with_capacity(n),
            success: Vec::with_capacity(n),
            reset: Vec::with_capacity(n),
            expert: Vec::with_capacity(n * ACTION_DIM),
            seed: Vec::with_capacity(n),
            step: Vec::with_capacity(n),
        };
        for o in outcomes {
            b.color.extend_from_slice(&o.obs.color);
            b.depth.extend_from_slice(&o.obs.depth);
            b.gripper.extend_from_slice(&gripper(&o.obs));
            b.reward.push(o.reward);
            b.terminated.push(o.terminated);
            b.truncated.push(o.truncated);
            b.success.push(o.success);
            b.reset.push(o.reset);
            b.expert.extend_from_slice(&units.express(o.obs.expert_action));
            b.seed.push(o.seed);
            b.step.push(o.obs.step);
        }
        b
    }

    /// The observation dict and the per-env dict of the other arrays.
    pub fn into_py(self, py: Python<'_>) -> PyResult<(Bound<'_, PyDict>, Bound<'_, PyDict>)> {
        let (n, s) = (self.n, self.side);
        let obs = PyDict::new(py);
        obs.set_item("color", array(py, self.color, &[n, s, s, 3])?)?;
        obs.set_item("depth", array(py, self.depth, &[n, s, s])?)?;
        obs.set_item("gripper", array(py, self.gripper, &[n, GRIPPER_DIM])?)?;
        let rest = PyDict::new(py);
        rest.set_item("reward", array(py, self.reward, &[n])?)?;
        rest.set_item("terminated", array(py, self.terminated, &[n])?)?;
        rest.set_item("truncated", array(py, self.truncated, &[n])?)?;
        rest.set_item("success", array(py, self.success, &[n])?)?;
        rest.set_item("reset", array(py, self.reset, &[n])?)?;
        rest.set_item("expert_action", array(py, self.expert, &[n, ACTION_DIM])?)?;
        rest.set_item("seed", array(py, self.seed, &[n])?)?;
        rest.set_item("step", array(py, self.step, &[n])?)?;
        Ok((obs, rest))
    }
}
