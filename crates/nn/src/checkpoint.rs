//! Save and load network weights as safetensors files with readable parameter names (the module
//! path, e.g. `enc.convs.0.weight.0`, `q1.conv1.bias.0`).
//!
//! The same weights always give the same bytes (file or [`to_bytes`]), so two runs can be compared
//! file by file.
//!
//! Loading checks the file against the module first and refuses a file made for another
//! architecture, naming the first mismatching tensor (missing, wrong shape or unexpected), so a
//! mismatch never loads half a network, and refuses weights that hold NaN or an infinity (the
//! module handed in is then dropped: the caller keeps its own copy of the old weights).
//!
//! Limitations: weights only. Optimiser state, replay buffer and RNG state belong to the trainer's
//! checkpoint; constant tensors (kernel bases) are rebuilt at construction and not stored.

use burn::module::Module;
use burn::store::{ModuleSnapshot, ModuleStore, SafetensorsStore};
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Errors saving or loading weights.
#[derive(Debug, Error)]
pub enum CheckpointError {
    /// The underlying store failed (I/O, format).
    #[error("{path}: {message}")]
    Store {
        /// File.
        path: PathBuf,
        /// What the store said.
        message: String,
    },
    /// A tensor the network needs is not in the file.
    #[error(
        "{path}: tensor `{name}` (shape {expected:?}) is missing from the file: it was saved from another architecture"
    )]
    Missing {
        /// File.
        path: PathBuf,
        /// Parameter name.
        name: String,
        /// Shape the network needs.
        expected: Vec<usize>,
    },
    /// A tensor has a different shape in the file.
    #[error(
        "{path}: tensor `{name}` has shape {found:?} in the file but the network needs {expected:?}: it was saved from another architecture or size"
    )]
    Shape {
        /// File.
        path: PathBuf,
        /// Parameter name.
        name: String,
        /// Shape the network needs.
        expected: Vec<usize>,
        /// Shape in the file.
        found: Vec<usize>,
    },
    /// A tensor holds NaN or an infinity: weights of a diverged run or a corrupt file, which would
    /// make the network output NaN.
    #[error("{path}: tensor `{name}` holds {value} at index {index}: refusing weights that are not finite")]
    NonFinite {
        /// File.
        path: PathBuf,
        /// Parameter name.
        name: String,
        /// Index of the first non-finite value (row-major).
        index: usize,
        /// That value.
        value: f32,
    },
    /// The file has a tensor the network does not.
    #[error(
        "{path}: the file has tensor `{name}`, which this network does not have: it was saved from another architecture"
    )]
    Unexpected {
        /// File.
        path: PathBuf,
        /// Parameter name.
        name: String,
    },
}

/// Names and shapes of a module's parameters, in module order.
pub fn parameter_shapes<M: Module>(module: &M) -> Vec<(String, Vec<usize>)> {
    module.collect(None, None, false).into_iter().map(|t| (t.name.clone(), t.shape.to_vec())).collect()
}

/// A store for saving with one metadata entry (`format: safetensors`).
// NOTE: burn's default metadata (format, producer, version) is a HashMap serialised in its random
// iteration order, so two saves of the same weights differed in their header bytes; with a single
// entry the header is canonical. The checkpoint manifest records the burn version instead.
fn canonical(store: SafetensorsStore) -> SafetensorsStore {
    store.clear_metadata().metadata("format", "safetensors")
}

/// Save `module`'s parameters to `path` (overwriting an existing file).
pub fn save<M: Module>(module: &M, path: &Path) -> Result<(), CheckpointError> {
    let mut store = canonical(SafetensorsStore::from_file(path).overwrite(true));
    module.save_into(&mut store).map_err(|e| CheckpointError::Store { path: path.into(), message: e.to_string() })
}

/// Load parameters from `path` into `module`, after checking that every tensor name and shape
/// matches (the first mismatch is reported).
pub fn load<M: Module>(module: M, path: &Path) -> Result<M, CheckpointError> {
    load_checked(module, SafetensorsStore::from_file(path), path)
}

/// `module`'s parameters as safetensors bytes (what a weights message carries).
pub fn to_bytes<M: Module>(module: &M) -> Result<Vec<u8>, CheckpointError> {
    let label = Path::new("<memory>");
    let store_err = |e: &dyn std::fmt::Display| CheckpointError::Store { path: label.into(), message: e.to_string() };
    let mut store = canonical(SafetensorsStore::from_bytes(None));
    module.save_into(&mut store).map_err(|e| store_err(&e))?;
    store.get_bytes().map_err(|e| store_err(&e))
}

/// Load safetensors `bytes` into `module` with the checks of [`load`]; `label` names the source in
/// errors (e.g. "PolicyWeights version 3").
pub fn load_bytes<M: Module>(module: M, bytes: Vec<u8>, label: &str) -> Result<M, CheckpointError> {
    load_checked(module, SafetensorsStore::from_bytes(Some(bytes)), Path::new(label))
}

fn load_checked<M: Module>(module: M, store: SafetensorsStore, path: &Path) -> Result<M, CheckpointError> {
    let devices = module.devices();
    let loaded = load_into(module, store, path);
    // burn's autodiff (0.22) forgets the graph nodes of parameters that were replaced only during a
    // backward pass (`runtime/server.rs`), so a process that loads weights into a trainable module
    // and never trains (a policy node, one load per weights message) kept about 20 kB per load of
    // the reduced actor. A one-element backward on that device lets it collect them.
    for device in devices.iter().filter(|d| d.is_autodiff()) {
        let one = burn::tensor::Tensor::<1>::from_floats([1.0f32], device).require_grad();
        let _ = one.sum().backward();
    }
    loaded
}

fn load_into<M: Module>(mut module: M, mut store: SafetensorsStore, path: &Path) -> Result<M, CheckpointError> {
    let store_err = |e: &dyn std::fmt::Display| CheckpointError::Store { path: path.into(), message: e.to_string() };
    let in_file: Vec<(String, Vec<usize>)> = store
        .get_all_tensors()
        .map_err(|e| store_err(&e))?
        .values()
        .map(|t| (t.name.clone(), t.shape.to_vec()))
        .collect();
    let expected = parameter_shapes(&module);
    for (name, shape) in &expected {
        match in_file.iter().find(|(n, _)| n == name) {
            None => {
                return Err(CheckpointError::Missing {
                    path: path.into(),
                    name: name.clone(),
                    expected: shape.clone(),
                });
            }
            Some((_, found)) if found != shape => {
                return Err(CheckpointError::Shape {
                    path: path.into(),
                    name: name.clone(),
                    expected: shape.clone(),
                    found: found.clone(),
                });
            }
            Some(_) => {}
        }
    }
    if let Some((name, _)) = in_file.iter().find(|(n, _)| !expected.iter().any(|(e, _)| e == n)) {
        return Err(CheckpointError::Unexpected { path: path.into(), name: name.clone() });
    }
    let result = module.load_from(&mut store).map_err(|e| store_err(&e))?;
    if !result.errors.is_empty() || !result.missing.is_empty() {
        return Err(CheckpointError::Store { path: path.into(), message: format!("{result}") });
    }
    for t in module.collect(None, None, false) {
        let name = t.name.clone();
        let data = burn::store::bridge::into_data(t).map_err(|e| store_err(&e))?;
        let Ok(values) = data.try_to_vec::<f32>() else { continue };
        if let Some(index) = values.iter().position(|v| !v.is_finite()) {
            return Err(CheckpointError::NonFinite { path: path.into(), name, index, value: values[index] });
        }
    }
    Ok(module)
}
