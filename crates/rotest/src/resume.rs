//! A training run's checkpoint, from which it continues exactly where it stopped (docs/rotest.md,
//! "Checkpoints and resume"):
//!
//! ```text
//! RUN/resume/state.json         the config, epochs finished, the RNG state, the history, the best epoch
//! RUN/resume/model.safetensors  the weights being trained
//! RUN/resume/best.safetensors   the weights of the best validation epoch so far
//! RUN/resume/adam.safetensors   Adam's moments by parameter path and its step count (equiarm_sac::optim)
//! ```
//!
//! A checkpoint is written to `RUN/resume.tmp/` (`state.json` last) and then renamed to
//! `RUN/resume/`, so a run killed while writing keeps its previous checkpoint; one killed between
//! the two renames leaves a complete `resume.tmp/`, which is read instead. Both go once the run has
//! written `run.json`.
//!
//! The optimiser is the SAC learner's ([`equiarm_sac::optim::Adam`]): its state is keyed by parameter
//! path, so it loads into the network a resumed process rebuilds, on the device that process names.

use std::path::{Path, PathBuf};

use equiarm_nn::burn::module::Module;
use equiarm_nn::burn::tensor::Device;
use equiarm_sac::optim::{Adam, AdamParams};
use rand_chacha::ChaCha8Rng;

use crate::error::{Result, RotestError};
use crate::train::{EpochRecord, RotestConfig};
use equiarm_types::files::at;

/// The checkpoint directory below a run directory.
pub const RESUME_DIR: &str = "resume";
const TMP_DIR: &str = "resume.tmp";
const STATE: &str = "state.json";
const MODEL: &str = "model.safetensors";
const BEST: &str = "best.safetensors";
const ADAM: &str = "adam.safetensors";
/// Adam's state as equiarm 0.1 before the shared optimiser wrote it (burn's record).
const ADAM_BEFORE: &str = "adam.bpk";

/// What `state.json` holds.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ResumeState {
    /// The run's configuration (a checkpoint resumes only the same configuration).
    pub config: RotestConfig,
    /// Epochs finished.
    pub epoch: usize,
    /// The state of the run's random stream (batch order, crops): hex key, stream, word position.
    pub rng: (String, u64, String),
    /// Every epoch finished.
    pub history: Vec<EpochRecord>,
    /// Validation accuracy and epoch of the best validation epoch so far.
    pub best: Option<(f64, usize)>,
}

/// The checkpoint directory of `run_dir` to read: `resume/`, or a complete `resume.tmp/` whose
/// rename was cut short. `None` when the run has no checkpoint.
pub fn find(run_dir: &Path) -> Option<PathBuf> {
    [RESUME_DIR, TMP_DIR].iter().map(|d| run_dir.join(d)).find(|d| d.join(STATE).is_file())
}

/// Reads the state of the checkpoint `dir` (from [`find`]).
pub fn read_state(dir: &Path) -> Result<ResumeState> {
    let path = dir.join(STATE);
    let bytes = std::fs::read(&path).map_err(at(&path))?;
    serde_json::from_slice(&bytes)
        .map_err(|e| RotestError::Format { path, message: format!("not a rotest checkpoint state: {e}") })
}

/// A checkpoint being written or read: the files of the network, the best network and the
/// optimiser.
pub struct Files {
    dir: PathBuf,
}

impl Files {
    /// The checkpoint directory `dir`.
    pub fn at(dir: &Path) -> Self {
        Files { dir: dir.to_path_buf() }
    }

    /// The weights being trained.
    pub fn model(&self) -> PathBuf {
        self.dir.join(MODEL)
    }

    /// The best weights so far (absent before the first epoch, which a checkpoint never precedes).
    pub fn best(&self) -> PathBuf {
        self.dir.join(BEST)
    }

    /// Loads Adam's state for `model`, its moments on `device` (the plain one).
    pub fn load_optim<M: Module>(&self, params: AdamParams, model: &M, device: &Device) -> Result<Adam> {
        let path = self.dir.join(ADAM);
        if !path.exists() && self.dir.join(ADAM_BEFORE).exists() {
            return Err(RotestError::Format {
                path: self.dir.join(ADAM_BEFORE),
                message: "a checkpoint of an earlier equiarm, whose optimiser state this one does not read: \
                          delete the run's `resume` directory to start the run over"
                    .into(),
            });
        }
        Ok(Adam::load(params, model, &path, device)?)
    }
}

/// Writes a checkpoint of `run_dir` and replaces the previous one: `save_nets` writes the two
/// networks' files (into the [`Files`] it is given), then the optimiser and the state follow.
pub fn write(
    run_dir: &Path,
    state: &ResumeState,
    optim: &Adam,
    save_nets: impl FnOnce(&Files) -> Result<()>,
) -> Result<()> {
    let tmp = run_dir.join(TMP_DIR);
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).map_err(at(&tmp))?;
    }
    std::fs::create_dir_all(&tmp).map_err(at(&tmp))?;
    let files = Files::at(&tmp);
    save_nets(&files)?;
    optim.save(&tmp.join(ADAM))?;
    let path = tmp.join(STATE);
    let json = serde_json::to_vec_pretty(state)
        .map_err(|e| RotestError::Format { path: path.clone(), message: e.to_string() })?;
    std::fs::write(&path, json).map_err(at(&path))?;
    let dir = run_dir.join(RESUME_DIR);
    if dir.exists() {
        std::fs::remove_dir_all(&dir).map_err(at(&dir))?;
    }
    Ok(std::fs::rename(&tmp, &dir).map_err(at(&dir))?)
}

/// Removes the checkpoint of a finished run.
pub fn remove(run_dir: &Path) -> Result<()> {
    for d in [RESUME_DIR, TMP_DIR] {
        let dir = run_dir.join(d);
        if dir.exists() {
            std::fs::remove_dir_all(&dir).map_err(at(&dir))?;
        }
    }
    Ok(())
}

/// `rng`'s exact state, as [`ResumeState::rng`] holds it.
pub fn rng_state(rng: &ChaCha8Rng) -> (String, u64, String) {
    equiarm_sac::rng::save_state(rng)
}

/// Restores a state made by [`rng_state`]; `path` names the file in the error.
pub fn rng_from(state: &(String, u64, String), path: &Path) -> Result<ChaCha8Rng> {
    equiarm_sac::rng::load_state(state)
        .map_err(|e| RotestError::Format { path: path.join(STATE), message: e.to_string() })
}
