//! The simulator's envs for Python: [`SimEnv`] (one env; `equiarm.make` wraps it as a Gymnasium
//! `Env`) and [`SimVecEnv`] (n envs stepped in parallel in Rust threads with the GIL released;
//! `equiarm.make_vec` and the BulletArm runner wrap it).
//!
//! Seeds: an env's episodes are reset with the successive outputs of `Rng::new(seed)` (the sim
//! node's `--seed` rule, so the same seed and actions give the node's frames); `SimVecEnv` gives
//! env k the seed `seed + k` (BulletArm's rule for its processes).

use std::sync::{Mutex, MutexGuard};

use equiarm_sim::rng::Rng;
use equiarm_sim::{Env, EnvConfig, SimError, VecEnv};
use equiarm_types::{ACTION_DIM, Action};
use numpy::PyArray1;
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rayon::prelude::*;

use crate::args::{self, Units};
use crate::obs::{Batch, Outcome};
use crate::{ResetNeeded, guard};

/// The Python exception of a simulator error, prefixed with `context` (e.g. `env 3: `).
fn sim_error(e: SimError, context: &str) -> PyErr {
    match e {
        SimError::EpisodeOver { .. } | SimError::NotReset => ResetNeeded::new_err(format!("{context}{e}")),
        SimError::Config { .. } | SimError::Action(_) => PyValueError::new_err(format!("{context}{e}")),
        other => PyRuntimeError::new_err(format!("{context}{other}")),
    }
}

/// What to do when a stepped env's episode has ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Autoreset {
    /// Refuse the step ([`ResetNeeded`]).
    Off,
    /// Gymnasium's default: the next step resets the env (its action is ignored, reward 0).
    NextStep,
    /// BulletArm's `auto_reset`: the step that ends an episode returns the new episode's first
    /// observation with the ended step's reward and flags.
    SameStep,
}

impl Autoreset {
    fn parse(text: &str) -> PyResult<Self> {
        match text {
            "off" => Ok(Autoreset::Off),
            "next_step" => Ok(Autoreset::NextStep),
            "same_step" => Ok(Autoreset::SameStep),
            other => Err(PyValueError::new_err(format!("autoreset: `{other}`: use off, next_step or same_step"))),
        }
    }
}

/// One env and its episode seeds.
pub struct Slot {
    env: Env,
    seeds: Rng,
    seed: u64,
    over: bool,
    steps: u32,
}

impl Slot {
    fn new(env: Env, seed: u64) -> Self {
        Slot { env, seeds: Rng::new(seed), seed: 0, over: true, steps: 0 }
    }

    fn reset(&mut self) -> Result<Outcome, SimError> {
        let seed = self.seeds.next_u64();
        self.reset_with(seed)
    }

    fn reset_with(&mut self, seed: u64) -> Result<Outcome, SimError> {
        self.seed = seed;
        let obs = self.env.reset(self.seed)?;
        (self.over, self.steps) = (false, 0);
        Ok(Outcome::reset(obs, self.seed))
    }

    fn step(&mut self, a: &Action) -> Result<Outcome, SimError> {
        let r = self.env.step(a)?;
        (self.over, self.steps) = (r.done, r.observation.step);
        Ok(Outcome::step(r, self.seed))
    }

    fn advance(&mut self, a: &Action, mode: Autoreset) -> Result<Outcome, SimError> {
        match mode {
            Autoreset::NextStep if self.over => self.reset(),
            Autoreset::Off | Autoreset::NextStep => self.step(a),
            Autoreset::SameStep => {
                let mut out = self.step(a)?;
                if self.over {
                    let first = self.reset()?;
                    (out.obs, out.seed, out.reset) = (first.obs, first.seed, true);
                }
                Ok(out)
            }
        }
    }

    fn steps_left(&self) -> u32 {
        if self.over { 0 } else { self.env.config().max_steps.saturating_sub(self.steps) }
    }
}

/// An env config's facts for Python: `task` (its name), `image_size` (side of the square images,
/// pixels), `far` (the depth of background pixels, the camera's far distance, m: the largest depth),
/// `max_steps` (the episode step limit), `render` (whether observations carry images).
fn facts<'py>(py: Python<'py>, c: &EnvConfig) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("task", c.task.name())?;
    d.set_item("image_size", c.camera.width)?;
    d.set_item("far", c.camera.far)?;
    d.set_item("max_steps", c.max_steps)?;
    d.set_item("render", c.render)?;
    Ok(d)
}

/// Locks an env, or says that an earlier internal error left it unusable.
fn lock<T>(m: &Mutex<T>) -> PyResult<MutexGuard<'_, T>> {
    m.lock().map_err(|_| {
        PyRuntimeError::new_err("this env is unusable after an earlier internal error in equiarm: create a new one")
    })
}

/// One simulated env (Python: `equiarm._equiarm.SimEnv`).
#[pyclass(module = "equiarm._equiarm")]
pub struct SimEnv {
    slot: Mutex<Slot>,
    units: Units,
    config: EnvConfig,
}

#[pymethods]
impl SimEnv {
    /// An env of `task`; see `equiarm.make` for the arguments.
    #[new]
    #[pyo3(signature = (task, *, image_size=152, view="side", corruption="none", arm="visible", max_steps=None, render=true, seed=0, units="normalized"))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        task: &str,
        image_size: usize,
        view: &str,
        corruption: &str,
        arm: &str,
        max_steps: Option<u32>,
        render: bool,
        seed: u64,
        units: &str,
    ) -> PyResult<Self> {
        guard(|| {
            let config = args::env_config(task, image_size, view, corruption, arm, max_steps, render)?;
            let units = Units::parse(units)?;
            let env = Env::new(config.clone()).map_err(|e| sim_error(e, ""))?;
            Ok(SimEnv { slot: Mutex::new(Slot::new(env, seed)), units, config })
        })
    }

    /// Starts an episode (with `seed`: from now on the episodes' seeds come from it; with
    /// `episode_seed`: this one episode is reset with exactly that seed, e.g. an `EpisodeResult`'s
    /// or `info["seed"]`, and the stream is left as it was); returns `(observation, info)`.
    #[pyo3(signature = (seed=None, episode_seed=None))]
    fn reset<'py>(
        &self,
        py: Python<'py>,
        seed: Option<u64>,
        episode_seed: Option<u64>,
    ) -> PyResult<(Bound<'py, PyDict>, Bound<'py, PyDict>)> {
        guard(|| {
            let out = py.detach(|| -> PyResult<Outcome> {
                let mut s = lock(&self.slot)?;
                if let Some(seed) = seed {
                    s.seeds = Rng::new(seed);
                }
                match episode_seed {
                    Some(e) => s.reset_with(e),
                    None => s.reset(),
                }
                .map_err(|e| sim_error(e, ""))
            })?;
            let info = out.info(py, self.units)?;
            Ok((crate::obs::observation(py, out.obs)?, info))
        })
    }

    /// Applies `action` (float array of shape (5,) in the env's units); returns `(observation,
    /// reward, terminated, truncated, info)`.
    #[allow(clippy::type_complexity)]
    fn step<'py>(
        &self,
        py: Python<'py>,
        action: &Bound<'py, PyAny>,
    ) -> PyResult<(Bound<'py, PyDict>, f32, bool, bool, Bound<'py, PyDict>)> {
        guard(|| {
            let a = self.units.physical(args::action(action, "action")?);
            let out =
                py.detach(|| -> PyResult<Outcome> { lock(&self.slot)?.step(&a).map_err(|e| sim_error(e, "")) })?;
            let info = out.info(py, self.units)?;
            let (reward, terminated, truncated) = (out.reward, out.terminated, out.truncated);
            Ok((crate::obs::observation(py, out.obs)?, reward, terminated, truncated, info))
        })
    }

    /// The expert planner's action for the current state, in the env's units.
    fn expert_action<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f32>>> {
        guard(|| {
            let s = lock(&self.slot)?;
            let a = s.env.expert_action().ok_or_else(|| ResetNeeded::new_err("the env has not been reset"))?;
            Ok(PyArray1::from_vec(py, self.units.express(a).to_vec()))
        })
    }

    /// Steps left before the episode's step limit (0 when it has ended or not started).
    fn steps_left(&self) -> PyResult<u32> {
        guard(|| Ok(lock(&self.slot)?.steps_left()))
    }

    /// The env's facts: `task`, `image_size`, `far`, `max_steps`, `render` (a dict).
    #[getter]
    fn facts<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        facts(py, &self.config)
    }
}

/// n simulated envs stepped in parallel (Python: `equiarm._equiarm.SimVecEnv`).
#[pyclass(module = "equiarm._equiarm")]
pub struct SimVecEnv {
    slots: Mutex<Vec<Slot>>,
    units: Units,
    config: EnvConfig,
}

impl SimVecEnv {
    fn side(&self) -> usize {
        if self.config.render { self.config.camera.width } else { 0 }
    }

    /// Runs `f` on the slots `ids` (all when `None`) in parallel with the GIL released; the batch
    /// of their outcomes in `ids`' order.
    fn each<'py, F>(
        &self,
        py: Python<'py>,
        ids: Option<&[usize]>,
        f: F,
    ) -> PyResult<(Bound<'py, PyDict>, Bound<'py, PyDict>)>
    where
        F: Fn(usize, &mut Slot) -> Result<Outcome, SimError> + Sync + Send,
    {
        let outcomes = py.detach(|| -> PyResult<Vec<Outcome>> {
            let mut slots = lock(&self.slots)?;
            let n = slots.len();
            let chosen: Vec<(usize, &mut Slot)> = match ids {
                None => slots.iter_mut().enumerate().collect(),
                Some(ids) => {
                    let mut seen = vec![false; n];
                    for &k in ids {
                        if k >= n || std::mem::replace(&mut seen[k], true) {
                            return Err(PyValueError::new_err(format!(
                                "env ids: {k} is {} (the envs are 0..{n})",
                                if k >= n { "out of range" } else { "given twice" }
                            )));
                        }
                    }
                    let mut by_id: Vec<Option<&mut Slot>> = slots.iter_mut().map(Some).collect();
                    ids.iter().map(|&k| (k, by_id[k].take().expect("checked above"))).collect()
                }
            };
            chosen.into_par_iter().map(|(k, s)| f(k, s).map_err(|e| sim_error(e, &format!("env {k}: ")))).collect()
        })?;
        Batch::gather(outcomes, self.side(), self.units).into_py(py)
    }
}

#[pymethods]
impl SimVecEnv {
    /// `n` envs of `task`; see `equiarm.make_vec` for the arguments.
    #[new]
    #[pyo3(signature = (task, n, *, image_size=152, view="side", corruption="none", arm="visible", max_steps=None, render=true, seed=0, units="normalized"))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        task: &str,
        n: usize,
        image_size: usize,
        view: &str,
        corruption: &str,
        arm: &str,
        max_steps: Option<u32>,
        render: bool,
        seed: u64,
        units: &str,
    ) -> PyResult<Self> {
        guard(|| {
            if n == 0 {
                return Err(PyValueError::new_err("n: the number of envs must be at least 1"));
            }
            let config = args::env_config(task, image_size, view, corruption, arm, max_steps, render)?;
            let units = Units::parse(units)?;
            let envs = VecEnv::new(config.clone(), n).map_err(|e| sim_error(e, ""))?.envs;
            let slots = envs.into_iter().enumerate().map(|(k, e)| Slot::new(e, seed.wrapping_add(k as u64))).collect();
            Ok(SimVecEnv { slots: Mutex::new(slots), units, config })
        })
    }

    /// Number of envs.
    #[getter]
    fn num_envs(&self) -> PyResult<usize> {
        Ok(lock(&self.slots)?.len())
    }

    /// Resets every env (with `seed`: env k's episode seeds now come from `seed + k`); returns
    /// `(observations, arrays)` with a leading env axis.
    #[pyo3(signature = (seed=None))]
    fn reset<'py>(&self, py: Python<'py>, seed: Option<u64>) -> PyResult<(Bound<'py, PyDict>, Bound<'py, PyDict>)> {
        guard(|| {
            self.each(py, None, |k, s| {
                if let Some(seed) = seed {
                    s.seeds = Rng::new(seed.wrapping_add(k as u64));
                }
                s.reset()
            })
        })
    }

    /// Resets the envs `ids` only; the batch has their outcomes in `ids`' order.
    fn reset_envs<'py>(&self, py: Python<'py>, ids: Vec<usize>) -> PyResult<(Bound<'py, PyDict>, Bound<'py, PyDict>)> {
        guard(|| self.each(py, Some(&ids), |_, s| s.reset()))
    }

    /// Steps env k with `actions[k]` (float array (n, 5) in the env's units); `autoreset`: `off`,
    /// `next_step` (Gymnasium) or `same_step` (BulletArm).
    #[pyo3(signature = (actions, autoreset="next_step"))]
    fn step<'py>(
        &self,
        py: Python<'py>,
        actions: &Bound<'py, PyAny>,
        autoreset: &str,
    ) -> PyResult<(Bound<'py, PyDict>, Bound<'py, PyDict>)> {
        guard(|| {
            let mode = Autoreset::parse(autoreset)?;
            let n = lock(&self.slots)?.len();
            let acts: Vec<Action> =
                args::actions(actions, n, "actions")?.into_iter().map(|a| self.units.physical(a)).collect();
            self.each(py, None, |k, s| s.advance(&acts[k], mode))
        })
    }

    /// The expert planner's actions for the current states, (n, 5) in the env's units.
    fn expert_actions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        guard(|| {
            let slots = lock(&self.slots)?;
            let mut v = Vec::with_capacity(slots.len() * ACTION_DIM);
            for (k, s) in slots.iter().enumerate() {
                let a = s.env.expert_action().ok_or_else(|| ResetNeeded::new_err(format!("env {k}: not reset yet")))?;
                v.extend_from_slice(&self.units.express(a));
            }
            Ok(numpy::PyArrayMethods::reshape(&PyArray1::from_vec(py, v), [slots.len(), ACTION_DIM])?.into_any())
        })
    }

    /// Steps left before each env's step limit.
    fn steps_left(&self) -> PyResult<Vec<u32>> {
        guard(|| Ok(lock(&self.slots)?.iter().map(Slot::steps_left).collect()))
    }

    /// The envs' facts: `task`, `image_size`, `far`, `max_steps`, `render` (a dict).
    #[getter]
    fn facts<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        facts(py, &self.config)
    }
}
