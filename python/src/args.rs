//! Arguments from Python, parsed once here with the domain types' own parsers; every error is a
//! `ValueError` or `TypeError` whose message starts with the argument's name.

use std::str::FromStr;

use equiarm_sim::{CameraConfig, EnvConfig};
use equiarm_types::{ACTION_DIM, Action, ArmView, Corruption, TaskKind, ViewPreset};
use numpy::{PyArrayDescrMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;

/// Largest image side accepted (the camera's own limit is larger; an RGBD frame of this side is
/// already 16 MB).
pub const MAX_IMAGE_SIZE: usize = 2048;

/// A named value parsed by its type's `FromStr`; the error names the argument.
pub fn parse<T: FromStr>(text: &str, arg: &str) -> PyResult<T>
where
    T::Err: std::fmt::Display,
{
    text.parse::<T>().map_err(|e| PyValueError::new_err(format!("{arg}: {e}")))
}

/// The env config of `equiarm.make`'s arguments: the task's own episode limit unless `max_steps`
/// is given; images of `image_size` pixels from the `view` preset.
pub fn env_config(
    task: &str,
    image_size: usize,
    view: &str,
    corruption: &str,
    arm: &str,
    max_steps: Option<u32>,
    render: bool,
) -> PyResult<EnvConfig> {
    let task: TaskKind = parse(task, "task")?;
    let view: ViewPreset = parse(view, "view")?;
    let corruption: Corruption = parse(corruption, "corruption")?;
    let arm: ArmView = parse(arm, "arm")?;
    if !(1..=MAX_IMAGE_SIZE).contains(&image_size) {
        return Err(PyValueError::new_err(format!("image_size: {image_size} must be 1..={MAX_IMAGE_SIZE} pixels")));
    }
    let max_steps = max_steps.unwrap_or(task.paper_episode_steps());
    if !(1..=equiarm_sim::env::MAX_EPISODE_STEPS).contains(&max_steps) {
        return Err(PyValueError::new_err(format!(
            "max_steps: {max_steps} must be 1..={} (the paper's limit is {})",
            equiarm_sim::env::MAX_EPISODE_STEPS,
            task.paper_episode_steps()
        )));
    }
    let mut cfg = EnvConfig::new(task);
    cfg.camera = CameraConfig::from(view);
    (cfg.camera.width, cfg.camera.height) = (image_size, image_size);
    cfg.corruption = corruption;
    cfg.arm = arm;
    cfg.max_steps = max_steps;
    cfg.render = render;
    Ok(cfg)
}

/// Checks that `obj` is a numpy array of a floating dtype and the given shape.
fn float_array<'a, 'py>(
    obj: &'a Bound<'py, PyAny>,
    arg: &str,
    shape: &[usize],
) -> PyResult<&'a Bound<'py, PyUntypedArray>> {
    let arr = obj.cast::<PyUntypedArray>().map_err(|_| {
        let ty = obj.get_type().name().map(|n| n.to_string()).unwrap_or_else(|_| "?".into());
        PyTypeError::new_err(format!("{arg}: expected a numpy array of shape {shape:?} and a float dtype, got {ty}"))
    })?;
    let dtype = arr.dtype();
    if dtype.kind() != b'f' {
        return Err(PyTypeError::new_err(format!("{arg}: dtype {dtype} is not a float dtype (float32 or float64)")));
    }
    if arr.shape() != shape {
        return Err(PyValueError::new_err(format!("{arg}: shape {:?}, expected {shape:?}", arr.shape())));
    }
    Ok(arr)
}

/// Components named in errors, in the action's order.
const COMPONENTS: [&str; ACTION_DIM] = ["p", "dx", "dy", "dz", "dtheta"];

fn finite(v: [f32; ACTION_DIM], arg: &str) -> PyResult<Action> {
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        return Err(PyValueError::new_err(format!("{arg}: component {i} ({}) is {}", COMPONENTS[i], v[i])));
    }
    Ok(Action::new(v[0], v[1], v[2], v[3], v[4]))
}

/// One action (a float array of shape (5,)), finite; its components as given (no unit conversion).
pub fn action(obj: &Bound<'_, PyAny>, arg: &str) -> PyResult<Action> {
    let arr = float_array(obj, arg, &[ACTION_DIM])?;
    let a: PyReadonlyArray1<'_, f32> = arr.call_method1("astype", ("float32",))?.extract()?;
    let mut v = [0f32; ACTION_DIM];
    v.copy_from_slice(a.as_slice()?);
    finite(v, arg)
}

/// `n` actions (a float array of shape (n, 5)), each finite.
pub fn actions(obj: &Bound<'_, PyAny>, n: usize, arg: &str) -> PyResult<Vec<Action>> {
    let arr = float_array(obj, arg, &[n, ACTION_DIM])?;
    let a: PyReadonlyArray2<'_, f32> = arr.call_method1("astype", ("float32",))?.extract()?;
    let a = a.as_array();
    (0..n)
        .map(|k| {
            let mut v = [0f32; ACTION_DIM];
            for (d, x) in v.iter_mut().enumerate() {
                *x = a[[k, d]];
            }
            finite(v, &format!("{arg}[{k}]"))
        })
        .collect()
}

/// How an action's numbers are read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Units {
    /// The agent's [-1, 1]^5 (Gymnasium's action space).
    Normalized,
    /// Metres and radians, p in [0, 1] (BulletArm's actions and the expert's).
    Physical,
}

impl Units {
    /// From the `units` argument.
    pub fn parse(text: &str) -> PyResult<Self> {
        match text {
            "normalized" => Ok(Units::Normalized),
            "physical" => Ok(Units::Physical),
            other => Err(PyValueError::new_err(format!("units: `{other}`: use normalized or physical"))),
        }
    }

    /// The physical action of `a` read in these units.
    pub fn physical(self, a: Action) -> Action {
        match self {
            Units::Normalized => Action::from_normalized(a.to_array()),
            Units::Physical => a,
        }
    }

    /// A physical action in these units.
    pub fn express(self, a: Action) -> [f32; ACTION_DIM] {
        match self {
            Units::Normalized => a.to_normalized(),
            Units::Physical => a.to_array(),
        }
    }
}
