//! # equiarm_py
//!
//! The extension module `equiarm._equiarm` behind the Python package `equiarm` (python/equiarm):
//! the simulator ([`env::SimEnv`], [`env::SimVecEnv`]), its expert planners and trained policies
//! ([`policy::Policy`]), in-process, without DDS. The binding is thin: tasks, views, corruptions,
//! actions and their validation are the Rust crates' ([`equiarm_types`]), and the names Python shows
//! come from them (the module function `names`).
//!
//! Every entry point runs inside [`guard`]: a Rust panic never crosses into Python, it becomes a
//! `RuntimeError` saying it is a bug.
//!
//! ## Limitations
//! The simulator's envs hold rapier worlds: an env object is used by one Python thread at a time
//! (each call locks it).

pub mod args;
pub mod env;
pub mod obs;
pub mod policy;

use std::panic::{AssertUnwindSafe, catch_unwind};

use equiarm_types::{ACTION_DIM, Action, CorruptionKind, MAX_DPOS, MAX_DROT, TaskKind, ViewPreset};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

pyo3::create_exception!(
    _equiarm,
    ResetNeeded,
    PyValueError,
    "An env was stepped after its episode ended (or before its first reset): call reset first."
);

/// Runs `f`, turning a Rust panic into a Python `RuntimeError` (a panic is a bug of equiarm's; the
/// message says so and carries the panic's text).
pub fn guard<T>(f: impl FnOnce() -> PyResult<T>) -> PyResult<T> {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(r) => r,
        Err(payload) => {
            let text = payload
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "a panic without a message".into());
            Err(PyRuntimeError::new_err(format!("internal error in equiarm (a bug; please report it): {text}")))
        }
    }
}

/// The names Python shows, from the domain types: `tasks`, `views`, `corruptions` (lists),
/// `bulletarm` (BulletArm environment name → task name), `objects` (task → objects in its scene)
/// and `episode_steps` (task → the paper's episode step limit).
#[pyfunction]
fn names(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("tasks", TaskKind::ALL.map(TaskKind::name).to_vec())?;
    d.set_item("views", ViewPreset::ALL.map(ViewPreset::name).to_vec())?;
    d.set_item("corruptions", CorruptionKind::ALL.map(CorruptionKind::name).to_vec())?;
    let (bulletarm, objects, steps) = (PyDict::new(py), PyDict::new(py), PyDict::new(py));
    for t in TaskKind::ALL {
        bulletarm.set_item(t.bulletarm_name(), t.name())?;
        objects.set_item(t.name(), t.object_count())?;
        steps.set_item(t.name(), t.paper_episode_steps())?;
    }
    d.set_item("bulletarm", bulletarm)?;
    d.set_item("objects", objects)?;
    d.set_item("episode_steps", steps)?;
    Ok(d)
}

/// The action's facts: its dimension, the largest position and yaw steps, and the workspace
/// bounds (m, `[[x0, x1], [y0, y1], [z0, z1]]`).
#[pyfunction]
fn action_facts(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("dim", ACTION_DIM)?;
    d.set_item("max_dpos", MAX_DPOS)?;
    d.set_item("max_drot", MAX_DROT)?;
    d.set_item("workspace", equiarm_sim::gripper::WORKSPACE.map(|r| r.to_vec()).to_vec())?;
    Ok(d)
}

/// The agent's normalised action of a physical one (after clipping).
#[pyfunction]
fn to_normalized(action: &Bound<'_, PyAny>) -> PyResult<Vec<f32>> {
    guard(|| Ok(args::action(action, "action")?.to_normalized().to_vec()))
}

/// The physical action of a normalised one (values outside [-1, 1] clipped).
#[pyfunction]
fn from_normalized(action: &Bound<'_, PyAny>) -> PyResult<Vec<f32>> {
    guard(|| {
        let u = args::action(action, "action")?.to_array();
        Ok(Action::from_normalized(u).to_array().to_vec())
    })
}

/// The seed of episode `episode` of env `env` in a training run seeded `seed` (the in-process
/// trainer's rule; demonstrations use env `2**32 - 1`).
#[pyfunction]
fn episode_seed(seed: u64, env: u32, episode: u64) -> u64 {
    equiarm_train::env::episode_seed(seed, env, episode)
}

/// The benchmark's Rust-only loop (bench/python_env.py): `steps` steps of one env of `task` with
/// `image_size`-pixel frames, each with the expert's action (an ended episode is reset, untimed);
/// returns each step's seconds. The same loop as `equiarm.make`'s driven from Python, without Python.
#[pyfunction]
fn bench_rust_steps(py: Python<'_>, task: &str, image_size: usize, steps: usize, seed: u64) -> PyResult<Vec<f64>> {
    guard(|| {
        let cfg = args::env_config(task, image_size, "side", "none", "visible", None, true)?;
        py.detach(|| {
            let fail = |e: equiarm_sim::SimError| PyRuntimeError::new_err(e.to_string());
            let mut env = equiarm_sim::Env::new(cfg).map_err(fail)?;
            let mut seeds = equiarm_sim::rng::Rng::new(seed);
            let mut obs = env.reset(seeds.next_u64()).map_err(fail)?;
            let mut times = Vec::with_capacity(steps);
            for _ in 0..steps {
                let t0 = std::time::Instant::now();
                let r = env.step(&obs.expert_action).map_err(fail)?;
                times.push(t0.elapsed().as_secs_f64());
                obs = if r.done { env.reset(seeds.next_u64()).map_err(fail)? } else { r.observation };
            }
            Ok(times)
        })
    })
}

/// Panics inside [`guard`]: the test that a panic reaches Python as a `RuntimeError`.
#[pyfunction]
fn _panic_for_test() -> PyResult<()> {
    guard(|| panic!("forced by _panic_for_test"))
}

/// The module `equiarm._equiarm`.
#[pymodule]
fn _equiarm(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<env::SimEnv>()?;
    m.add_class::<env::SimVecEnv>()?;
    m.add_class::<policy::Policy>()?;
    m.add("ResetNeeded", m.py().get_type::<ResetNeeded>())?;
    m.add_function(wrap_pyfunction!(names, m)?)?;
    m.add_function(wrap_pyfunction!(action_facts, m)?)?;
    m.add_function(wrap_pyfunction!(to_normalized, m)?)?;
    m.add_function(wrap_pyfunction!(from_normalized, m)?)?;
    m.add_function(wrap_pyfunction!(episode_seed, m)?)?;
    m.add_function(wrap_pyfunction!(bench_rust_steps, m)?)?;
    m.add_function(wrap_pyfunction!(_panic_for_test, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
