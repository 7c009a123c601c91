//! The learner: agent + prioritised replay + crops + checkpoints, fed transitions by whoever runs
//! the environments (the in-process loop of `equiarm_train` or the DDS trainer node).
//!
//! A checkpoint is a directory with the agent's files (see [`crate::agent::Sac::save`]),
//! `replay.bin.zst`, `learner.json` (counters and RNG position) and `manifest.json` (config,
//! versions, counters). [`Learner::resume`] refuses a manifest whose config differs from the run's
//! (other than `total_updates`, which may be extended), naming the first differing field.
//!
//! The device (CPU or a GPU, [`Learner::with_device`]) is not part of the config: a checkpoint
//! written on one device resumes on another.
//!
//! Limitations: frames must all have the configured `image_size`.

use std::path::{Path, PathBuf};

use equiarm_nn::burn::tensor::Device;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::agent::{ActMode, Agent, AgentError, Batch, Metrics, ModelKind};
use crate::augment::{center_offset, centre_input, network_input, random_offset};
use crate::config::{Augmentation, TrainConfig};
use crate::frame::StoredFrame;
use crate::replay::{Replay, Stored};
use crate::schedule::{CosineSchedule, LinearSchedule};
use equiarm_types::NormalizedAction;
use equiarm_types::files::{FileError, at, replace};

/// Version of the checkpoint layout written by this crate.
pub const CHECKPOINT_FORMAT: u32 = 1;

/// Learner errors.
#[derive(Debug, Error)]
pub enum LearnerError {
    /// The agent failed.
    #[error(transparent)]
    Agent(#[from] AgentError),
    /// The replay buffer failed.
    #[error(transparent)]
    Replay(#[from] crate::replay::ReplayError),
    /// Building network input failed.
    #[error(transparent)]
    Augment(#[from] crate::augment::AugmentError),
    /// The configuration is invalid.
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    /// A checkpoint is missing, unreadable or made by another run.
    #[error("checkpoint {path}: {message}")]
    Checkpoint {
        /// Directory or file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

/// What `manifest.json` records.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Manifest {
    /// [`CHECKPOINT_FORMAT`].
    pub format: u32,
    /// equiarm version that wrote it.
    pub equiarm_version: String,
    /// Tensor library.
    pub burn_version: String,
    /// Network family (written as its name: `equi`, `cnn`, …).
    pub model: ModelKind,
    /// The run's full config.
    pub config: TrainConfig,
    /// Gradient updates made.
    pub updates: u64,
    /// Transitions received.
    pub transitions: u64,
    /// Transitions in the replay.
    pub replay_len: usize,
    /// Expert transitions in the replay.
    pub expert_len: usize,
}

/// Counters and RNG position (`learner.json`).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct LearnerState {
    updates: u64,
    transitions: u64,
    rng: (String, u64, String),
}

/// Agent + replay + the sampling RNG.
pub struct Learner {
    cfg: TrainConfig,
    agent: Agent,
    replay: Replay,
    rng: ChaCha8Rng,
    beta: LinearSchedule,
    /// The Adam step per update when the config anneals it (`agent.lr_final`).
    lr: Option<CosineSchedule>,
    transitions: u64,
    last: Option<Metrics>,
}

impl Learner {
    /// A fresh learner for `cfg` (validated here), its agent on the CPU (`flex`).
    pub fn new(cfg: TrainConfig) -> Result<Self, LearnerError> {
        Self::with_device(cfg, equiarm_nn::device::cpu())
    }

    /// A fresh learner for `cfg` (validated here), its agent on `device` (see
    /// [`equiarm_nn::device`]; checked before the networks are built). Replay, crops and the
    /// sampling RNG stay on the host.
    pub fn with_device(cfg: TrainConfig, device: Device) -> Result<Self, LearnerError> {
        cfg.validate()?;
        let agent = Agent::new_on(cfg.agent.clone(), cfg.seed, &device)?;
        let replay = Replay::new(cfg.replay.clone())?;
        let beta = LinearSchedule { start: cfg.replay.beta_start, end: cfg.replay.beta_end, steps: cfg.total_updates };
        let lr = cfg.agent.lr_final.map(|end| CosineSchedule { start: cfg.agent.lr, end, steps: cfg.total_updates });
        Ok(Learner {
            rng: crate::rng::stream(cfg.seed, 0x7265_706c),
            cfg,
            agent,
            replay,
            beta,
            lr,
            transitions: 0,
            last: None,
        })
    }

    /// The config.
    pub fn config(&self) -> &TrainConfig {
        &self.cfg
    }

    /// The agent.
    pub fn agent(&self) -> &Agent {
        &self.agent
    }

    /// The agent, mutably (acting).
    pub fn agent_mut(&mut self) -> &mut Agent {
        &mut self.agent
    }

    /// The replay buffer.
    pub fn replay(&self) -> &Replay {
        &self.replay
    }

    /// Updates made.
    pub fn updates(&self) -> u64 {
        self.agent.updates()
    }

    /// Transitions received.
    pub fn transitions(&self) -> u64 {
        self.transitions
    }

    /// Metrics of the last update.
    pub fn last_metrics(&self) -> Option<Metrics> {
        self.last
    }

    /// Store one transition (new transitions get the maximal priority).
    pub fn push(&mut self, t: Stored) -> Result<(), LearnerError> {
        self.replay.push(t)?;
        self.transitions += 1;
        Ok(())
    }

    /// True when the replay holds enough transitions to update (`training_starts`).
    pub fn ready(&self) -> bool {
        self.replay.len() >= self.cfg.training_starts.max(1)
    }

    /// Actions for `frames` with a centre crop (acting and evaluation, docs/paper.md §1.1).
    pub fn act(&mut self, frames: &[&StoredFrame], mode: ActMode) -> Result<Vec<NormalizedAction>, LearnerError> {
        act_on(&mut self.agent, frames, self.cfg.agent.input_size, mode)
    }

    /// Sample a batch, crop it, update the agent and the priorities. FERM's first call first makes
    /// the contrastive pre-training ([`Learner::curl_pretrain`]).
    pub fn update(&mut self) -> Result<Metrics, LearnerError> {
        let pretrain = if self.agent.needs_curl_pretraining() { Some(self.curl_pretrain()?) } else { None };
        let beta = self.beta.value(self.agent.updates());
        if let Some(lr) = &self.lr {
            self.agent.set_lr(lr.value(self.agent.updates()));
        }
        let sample = self.replay.sample(self.cfg.batch_size, beta, &mut self.rng)?;
        let batch = self.build_batch(&sample.slots, &sample.weights)?;
        let (mut metrics, td) = self.agent.update(batch)?;
        metrics.curl_pretrain_loss = pretrain.as_deref().and_then(tail_mean);
        self.replay.update_priorities(&sample.slots, &td)?;
        self.last = Some(metrics);
        Ok(metrics)
    }

    /// FERM's contrastive pre-training (docs/paper.md §1.10): `agent.curl_pretrain_steps` contrastive
    /// steps on batches drawn uniformly (with replacement) from the replay's expert transitions (all
    /// transitions if it holds none), each with two independent random crops per observation.
    /// Returns each step's contrastive loss and logs the mean of the first and of the last 100.
    pub fn curl_pretrain(&mut self) -> Result<Vec<f32>, LearnerError> {
        use rand::Rng as _;
        let mut pool: Vec<usize> =
            (0..self.replay.len()).filter(|&i| self.replay.get(i).is_some_and(|t| t.expert)).collect();
        if pool.is_empty() {
            pool = (0..self.replay.len()).collect();
        }
        if pool.is_empty() {
            return Err(
                AgentError::Batch("FERM's contrastive pre-training needs transitions in the replay".into()).into()
            );
        }
        let mut losses = Vec::with_capacity(self.cfg.agent.curl_pretrain_steps);
        for _ in 0..self.cfg.agent.curl_pretrain_steps {
            let slots: Vec<usize> =
                (0..self.cfg.batch_size).map(|_| pool[self.rng.random_range(0..pool.len())]).collect();
            let (anchor, positive) = self.curl_crops(&slots)?;
            losses.push(self.agent.curl_step(anchor, positive, slots.len())?);
        }
        self.agent.set_curl_pretrained();
        if let (Some(first), Some(last)) = (mean(&losses[..losses.len().min(PRETRAIN_LOSS_WINDOW)]), tail_mean(&losses))
        {
            log::info!(
                "FERM pre-training: {} contrastive steps on {} transitions, loss {first:.4} (mean of the first {n}) -> {last:.4} (mean of the last {n})",
                losses.len(),
                pool.len(),
                n = losses.len().min(PRETRAIN_LOSS_WINDOW),
            );
        }
        Ok(losses)
    }

    /// Two independent random crops of the obs of each of `slots` (FERM's anchor and positive).
    fn curl_crops(&mut self, slots: &[usize]) -> Result<(Vec<f32>, Vec<f32>), LearnerError> {
        let s = self.cfg.agent.input_size;
        let size = self.cfg.image_size;
        let mut frames = Vec::with_capacity(slots.len());
        for &i in slots {
            let t = self
                .replay
                .get(i)
                .ok_or(crate::replay::ReplayError::SlotOutOfRange { slot: i, len: self.replay.len() })?;
            frames.push(t.obs.clone());
        }
        let refs: Vec<&StoredFrame> = frames.iter().map(|f| &**f).collect();
        let off_a: Vec<(usize, usize)> = slots.iter().map(|_| random_offset(&mut self.rng, size, s)).collect();
        let off_p: Vec<(usize, usize)> = slots.iter().map(|_| random_offset(&mut self.rng, size, s)).collect();
        Ok((network_input(&refs, &off_a, s)?, network_input(&refs, &off_p, s)?))
    }

    /// The cropped batch for replay `slots` (RAD: one offset per transition shared by obs and
    /// next_obs; DrQ: independent offsets per copy; centre: no randomness; FERM also gets its
    /// contrastive crops).
    pub fn build_batch(&mut self, slots: &[usize], weights: &[f32]) -> Result<Batch, LearnerError> {
        let s = self.cfg.agent.input_size;
        let size = self.cfg.image_size;
        let rows: Vec<&Stored> = slots
            .iter()
            .map(|&i| {
                self.replay.get(i).ok_or(crate::replay::ReplayError::SlotOutOfRange { slot: i, len: self.replay.len() })
            })
            .collect::<Result<_, _>>()?;
        let b = rows.len();
        let (k, m) = match self.cfg.augmentation {
            Augmentation::Drq { k, m } => (k, m),
            _ => (1, 1),
        };
        let mut obs_frames = Vec::with_capacity(m * b);
        let mut obs_off = Vec::with_capacity(m * b);
        let mut next_frames = Vec::with_capacity(k * b);
        let mut next_off = Vec::with_capacity(k * b);
        match self.cfg.augmentation {
            Augmentation::Rad => {
                for r in &rows {
                    let o = random_offset(&mut self.rng, size, s);
                    obs_frames.push(&*r.obs);
                    obs_off.push(o);
                    next_frames.push(&*r.next_obs);
                    next_off.push(o);
                }
            }
            Augmentation::Center => {
                let c = center_offset(size, s);
                for r in &rows {
                    obs_frames.push(&*r.obs);
                    obs_off.push((c, c));
                    next_frames.push(&*r.next_obs);
                    next_off.push((c, c));
                }
            }
            Augmentation::Drq { .. } => {
                for _ in 0..m {
                    for r in &rows {
                        obs_frames.push(&*r.obs);
                        obs_off.push(random_offset(&mut self.rng, size, s));
                    }
                }
                for _ in 0..k {
                    for r in &rows {
                        next_frames.push(&*r.next_obs);
                        next_off.push(random_offset(&mut self.rng, size, s));
                    }
                }
            }
        }
        let obs = network_input(&obs_frames, &obs_off, s)?;
        let next_obs = network_input(&next_frames, &next_off, s)?;
        let action = rows.iter().flat_map(|r| r.action).collect();
        let reward = rows.iter().map(|r| r.reward).collect();
        let mask = rows.iter().map(|r| if r.done { 0.0 } else { 1.0 }).collect();
        let expert = rows.iter().map(|r| if r.expert { 1.0 } else { 0.0 }).collect();
        let curl = if self.cfg.agent.model == ModelKind::Ferm { Some(self.curl_crops(slots)?) } else { None };
        Ok(Batch {
            rows: b,
            size: s,
            obs_copies: m,
            next_copies: k,
            obs,
            next_obs,
            action,
            reward,
            mask,
            expert,
            weight: weights.to_vec(),
            curl,
        })
    }

    /// Write a checkpoint into `dir` (created; an existing one is replaced file by file).
    pub fn save(&self, dir: &Path) -> Result<(), LearnerError> {
        let ck = |e: &dyn std::fmt::Display| LearnerError::Checkpoint { path: dir.into(), message: e.to_string() };
        std::fs::create_dir_all(dir).map_err(|e| ck(&e))?;
        self.agent.save(dir)?;
        self.replay.save(&dir.join("replay.bin.zst"))?;
        let state = LearnerState {
            updates: self.agent.updates(),
            transitions: self.transitions,
            rng: crate::rng::save_state(&self.rng),
        };
        write_json(&dir.join("learner.json"), &state).map_err(|e| ck(&e))?;
        let manifest = Manifest {
            format: CHECKPOINT_FORMAT,
            equiarm_version: env!("CARGO_PKG_VERSION").into(),
            burn_version: "0.22.1".into(),
            model: self.cfg.agent.model,
            config: self.cfg.clone(),
            updates: self.agent.updates(),
            transitions: self.transitions,
            replay_len: self.replay.len(),
            expert_len: self.replay.expert_len(),
        };
        write_json(&dir.join("manifest.json"), &manifest).map_err(|e| ck(&e))
    }

    /// Restore a checkpoint written by [`Learner::save`] into this learner (built with the same
    /// config, except possibly `total_updates`).
    pub fn resume(&mut self, dir: &Path) -> Result<(), LearnerError> {
        let manifest = read_manifest(dir)?;
        let mut theirs = manifest.config.clone();
        theirs.total_updates = self.cfg.total_updates;
        if theirs != self.cfg {
            let a = serde_json::to_value(&theirs).unwrap_or_default();
            let b = serde_json::to_value(&self.cfg).unwrap_or_default();
            let field = first_difference(&a, &b, "");
            return Err(LearnerError::Checkpoint {
                path: dir.into(),
                message: format!(
                    "made with another config (first difference: `{field}`); resume with the checkpoint's config or start a new run"
                ),
            });
        }
        let ck = |e: &dyn std::fmt::Display| LearnerError::Checkpoint { path: dir.into(), message: e.to_string() };
        let state: LearnerState = read_json(&dir.join("learner.json")).map_err(|e| ck(&e))?;
        self.agent.load(dir)?;
        self.replay = Replay::load(&dir.join("replay.bin.zst"))?;
        self.rng = crate::rng::load_state(&state.rng).map_err(|e| ck(&e))?;
        self.transitions = state.transitions;
        if state.updates != self.agent.updates() {
            return Err(LearnerError::Checkpoint {
                path: dir.into(),
                message: format!("learner.json says {} updates, agent.json {}", state.updates, self.agent.updates()),
            });
        }
        Ok(())
    }
}

/// Centre-cropped greedy/sampled actions of `agent` for `frames`.
pub fn act_on(
    agent: &mut Agent,
    frames: &[&StoredFrame],
    s: usize,
    mode: ActMode,
) -> Result<Vec<NormalizedAction>, LearnerError> {
    let x = centre_input(frames, s)?;
    Ok(agent.act(&x, frames.len(), mode, None)?)
}

/// Read `manifest.json` of a checkpoint directory.
pub fn read_manifest(dir: &Path) -> Result<Manifest, LearnerError> {
    let m: Manifest = read_json(&dir.join("manifest.json"))
        .map_err(|e| LearnerError::Checkpoint { path: dir.into(), message: e.to_string() })?;
    if m.format != CHECKPOINT_FORMAT {
        return Err(LearnerError::Checkpoint {
            path: dir.into(),
            message: format!("checkpoint format {} (this build reads {CHECKPOINT_FORMAT})", m.format),
        });
    }
    Ok(m)
}

/// A JSON file of a run or checkpoint that could not be written or read, naming the file.
#[derive(Debug, Error)]
pub enum JsonFileError {
    /// Reading, writing or renaming the file failed (the file, and the cause).
    #[error(transparent)]
    Io(#[from] FileError),
    /// The file's text is not the JSON expected (or the value cannot be serialised).
    #[error("{}: {cause}", path.display())]
    Json {
        /// The file.
        path: PathBuf,
        /// The cause.
        cause: serde_json::Error,
    },
}

/// Serialise `v` to `path` as pretty JSON, whole or not at all ([`equiarm_types::files::replace`]).
pub fn write_json<T: Serialize>(path: &Path, v: &T) -> Result<(), JsonFileError> {
    let text = serde_json::to_string_pretty(v).map_err(|cause| JsonFileError::Json { path: path.into(), cause })?;
    Ok(replace(path, text)?)
}

/// Read JSON from `path`, errors naming the file.
pub fn read_json<T: for<'de> Deserialize<'de>>(path: &Path) -> Result<T, JsonFileError> {
    let text = std::fs::read_to_string(path).map_err(at(path))?;
    serde_json::from_str(&text).map_err(|cause| JsonFileError::Json { path: path.into(), cause })
}

/// The dotted path of the first field in which two JSON values (configs) differ, below `prefix`.
pub fn first_difference(a: &serde_json::Value, b: &serde_json::Value, prefix: &str) -> String {
    match (a, b) {
        (serde_json::Value::Object(x), serde_json::Value::Object(y)) => {
            for (k, va) in x {
                let p = if prefix.is_empty() { k.clone() } else { format!("{prefix}.{k}") };
                match y.get(k) {
                    Some(vb) if vb == va => {}
                    Some(vb) => return first_difference(va, vb, &p),
                    None => return p,
                }
            }
            prefix.to_string()
        }
        _ => prefix.to_string(),
    }
}

/// How many pre-training losses [`Learner::curl_pretrain`] averages at each end.
const PRETRAIN_LOSS_WINDOW: usize = 100;

/// The mean of `v` (`None` for none).
fn mean(v: &[f32]) -> Option<f32> {
    (!v.is_empty()).then(|| v.iter().sum::<f32>() / v.len() as f32)
}

/// The mean of the last [`PRETRAIN_LOSS_WINDOW`] values (`None` for none).
fn tail_mean(v: &[f32]) -> Option<f32> {
    mean(&v[v.len().saturating_sub(PRETRAIN_LOSS_WINDOW)..])
}
