//! Trained policies from Python (`equiarm.load_policy`): the actor of a checkpoint, acting as the
//! policy node acts. The observation becomes the replay's frame ([`StoredFrame::new`]: colour bytes,
//! depth in f16) and the network input is [`equiarm_sac::learner::act_on`]'s centre crop, the one
//! function the node, the trainer and `equiarm bag eval --policy` use.

use std::path::PathBuf;
use std::sync::Mutex;

use equiarm_sac::agent::{ActMode, Agent};
use equiarm_sac::frame::StoredFrame;
use equiarm_types::ACTION_DIM;
use numpy::{PyArray1, PyReadonlyArray2, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;

use crate::guard;

/// A checkpoint's actor (Python: `equiarm._equiarm.Policy`).
#[pyclass(module = "equiarm._equiarm")]
pub struct Policy {
    agent: Mutex<Agent>,
    image_size: usize,
    checkpoint: PathBuf,
}

impl Policy {
    /// The actor, or the error saying an earlier internal error left it unusable.
    fn agent(&self) -> PyResult<std::sync::MutexGuard<'_, Agent>> {
        self.agent
            .lock()
            .map_err(|_| PyRuntimeError::new_err("policy unusable after an earlier internal error: load it again"))
    }
}

fn value_error(arg: &str, e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(format!("{arg}: {e}"))
}

#[pymethods]
impl Policy {
    /// The actor of `checkpoint`: a checkpoint directory, a run directory (its latest checkpoint)
    /// or a `checkpoints/latest` pointer file. `seed` seeds the sampling noise.
    #[new]
    #[pyo3(signature = (checkpoint, *, seed=0))]
    fn new(checkpoint: PathBuf, seed: u64) -> PyResult<Self> {
        guard(|| {
            let shown = checkpoint.display();
            if !checkpoint.exists() {
                return Err(value_error("checkpoint", format!("{shown} does not exist")));
            }
            if !equiarm_train::rundir::names_checkpoint(&checkpoint) {
                return Err(value_error(
                    "checkpoint",
                    format!(
                        "{shown} is a file: give the checkpoint or run directory (its manifest.json names the architecture)"
                    ),
                ));
            }
            let dir = equiarm_train::rundir::find_checkpoint(&checkpoint).map_err(|e| value_error("checkpoint", e))?;
            let m = equiarm_sac::learner::read_manifest(&dir).map_err(|e| value_error("checkpoint", e))?;
            let mut agent = Agent::new(m.config.agent.clone(), seed).map_err(|e| value_error("checkpoint", e))?;
            let actor = dir.join("actor.safetensors");
            agent.load_actor(&actor).map_err(|e| value_error("checkpoint", e))?;
            Ok(Policy { agent: Mutex::new(agent), image_size: m.config.image_size, checkpoint: dir })
        })
    }

    /// The normalised action (float32, (5,)) for one observation: `color` uint8 (S, S, 3), `depth`
    /// float32 (S, S) in metres, `holding`; `deterministic`: tanh of the mean (the node's `greedy`
    /// mode), else a sample (`sample` mode).
    #[pyo3(signature = (color, depth, holding, deterministic=true))]
    fn act<'py>(
        &self,
        py: Python<'py>,
        color: PyReadonlyArray3<'py, u8>,
        depth: PyReadonlyArray2<'py, f32>,
        holding: bool,
        deterministic: bool,
    ) -> PyResult<Bound<'py, PyArray1<f32>>> {
        guard(|| {
            let shape = color.shape().to_vec();
            let s = shape[0];
            if shape != [s, s, 3] {
                return Err(value_error("color", format!("shape {shape:?}, expected (S, S, 3) with square frames")));
            }
            if depth.shape() != [s, s] {
                return Err(value_error("depth", format!("shape {:?}, expected ({s}, {s}) like color", depth.shape())));
            }
            let color = color.as_array().iter().copied().collect::<Vec<u8>>();
            let depth = depth.as_array().iter().copied().collect::<Vec<f32>>();
            let frame = StoredFrame::new(s, color, &depth, holding).map_err(|e| value_error("observation", e))?;
            let mode = if deterministic { ActMode::Greedy } else { ActMode::Sample };
            let u = py.detach(|| -> PyResult<[f32; ACTION_DIM]> {
                let mut agent = self.agent()?;
                let input = agent.config().input_size;
                if s < input {
                    return Err(value_error(
                        "color",
                        format!("frames of {s} px are smaller than the network input, {input} px"),
                    ));
                }
                let out = equiarm_sac::learner::act_on(&mut agent, &[&frame], input, mode)
                    .map_err(|e| PyRuntimeError::new_err(format!("acting: {e}")))?;
                Ok(out[0])
            })?;
            Ok(PyArray1::from_vec(py, u.to_vec()))
        })
    }

    /// Side of the frames the actor was trained on, pixels (the run's `image_size`).
    #[getter]
    fn image_size(&self) -> usize {
        self.image_size
    }

    /// Side of the network input (the centre crop), pixels.
    #[getter]
    fn input_size(&self) -> PyResult<usize> {
        Ok(self.agent()?.config().input_size)
    }

    /// The network family (`equi`, `cnn`, …).
    #[getter]
    fn model(&self) -> PyResult<&'static str> {
        Ok(self.agent()?.config().model.name())
    }

    /// The checkpoint directory the actor came from.
    #[getter]
    fn checkpoint(&self) -> PathBuf {
        self.checkpoint.clone()
    }
}
