//! The SAC-from-demonstrations agent of docs/paper.md §2 (`sacfd`, with RAD or DrQ), over the
//! networks of `equiarm_nn`:
//!
//! - critic step: `y = r + γ·mask·(min Q_targ(s′, a′) − α·log π(a′|s′))`, `a′ ~ π(s′)`, loss
//!   `MSE(Q1, y) + MSE(Q2, y)`; TD error for PER `½(|Q1 − y| + |Q2 − y|)`;
//! - actor step: `mean(α·log π(ã|s) − min(Q1, Q2)(s, ã))` plus `expert_weight ×` the MSE between the
//!   *sampled* action ã and the stored action over the expert rows (only if the batch has some);
//! - α step: `−mean(log α · (log π + target_entropy))`, log α optimised;
//! - Polyak target update with τ.
//!
//! With DrQ (K next-observation crops, M observation crops) the target is the mean over the K
//! crops, and the critic, actor and α losses run over the M crops (docs/paper.md §1.11). RAD is K = M
//! = 1 with one crop shared by obs and next_obs (the caller builds the crops).
//!
//! Noise comes from the agent's own seeded RNG, so updates are bitwise repeatable on one machine.
//!
//! Device: [`Agent::new`] builds on the CPU (`flex`); [`Agent::new_on`] on any device of
//! [`equiarm_nn::device`] (e.g. a GPU through Vulkan in the GPU build, the `vulkan` feature). Everything the agent makes
//! lives there: weights, inputs, noise, Adam moments, loaded checkpoints. Noise is drawn on the
//! host from the same RNG on every device, and checkpoints load across devices.
//!
//! Limitations: the importance-sampling weights of PER are applied only when
//! [`AgentConfig::use_is_weights`] is set (the paper computes them and does not use them).

use std::path::Path;

use equiarm_nn::burn::module::Module;
use equiarm_nn::burn::optim::GradientsParams;
use equiarm_nn::burn::tensor::{Device, Tensor, TensorData};
use equiarm_nn::init::Init;
use equiarm_nn::kernels::MatmulPrecision;
use equiarm_nn::layers::Numerics;
use equiarm_nn::nets::{
    Actor, CnnActor, CnnCritic, Critic, CurlBilinear, EquiActor, EquiCritic, FermActor, FermCritic, FermEncoder,
    NetConfig, SenActor, SenCritic, gaussian_sample,
};
use rand::SeedableRng as _;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::optim::{Adam, AdamParams, ScalarAdam, polyak, polyak_by};
use equiarm_types::{ACTION_DIM, NormalizedAction, OBS_PLANES};

/// Errors of the agent.
#[derive(Debug, Error)]
pub enum AgentError {
    /// A network could not be built.
    #[error("building the {model} networks: {cause}")]
    Net {
        /// Model name.
        model: &'static str,
        /// Cause.
        cause: equiarm_nn::nets::NetError,
    },
    /// A batch has inconsistent sizes.
    #[error("bad batch: {0}")]
    Batch(String),
    /// Weights could not be saved or loaded.
    #[error(transparent)]
    Weights(#[from] equiarm_nn::checkpoint::CheckpointError),
    /// Optimiser state could not be saved or loaded.
    #[error(transparent)]
    Optim(#[from] crate::optim::OptimError),
    /// The device cannot be used.
    #[error(transparent)]
    Device(#[from] equiarm_nn::device::DeviceError),
    /// `matmul` asks for what this machine cannot do.
    #[error("agent.matmul: {0}")]
    Matmul(String),
    /// The agent state file is missing or wrong.
    #[error("{path}: {message}")]
    State {
        /// File.
        path: std::path::PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A loss became NaN or infinite.
    #[error("update {update}: {what} is not finite ({value})")]
    NonFinite {
        /// Update number.
        update: u64,
        /// Which quantity.
        what: &'static str,
        /// Its value.
        value: f32,
    },
}

pub use equiarm_types::ModelKind;

/// How the agent acts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ActMode {
    /// `tanh(mean + std·ε)`: exploration during training.
    Sample,
    /// `tanh(mean)`: evaluation (docs/paper.md §2).
    Greedy,
}

/// The paper's discount (docs/paper.md §2): SAC's γ by default, and the discount of every reported
/// discounted return (the sim node's `EpisodeResult`, the in-process evaluations).
pub const GAMMA: f64 = 0.99;

/// SAC hyper-parameters (docs/paper.md §2). Every field has the paper's value by default.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AgentConfig {
    /// Network family.
    pub model: ModelKind,
    /// Hidden size of the networks (paper 64; SEN 32).
    pub hidden: usize,
    /// Network input size in pixels after cropping (paper 128).
    pub input_size: usize,
    /// Adam learning rate of actor, critic and α.
    pub lr: f64,
    /// Where the learning rate ends: `None` keeps `lr` throughout (the paper); `Some(f)` anneals it
    /// from `lr` to `f` over the run's updates along a half cosine ([`crate::schedule::CosineSchedule`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lr_final: Option<f64>,
    /// Discount.
    pub gamma: f64,
    /// Polyak coefficient of the target critic.
    pub tau: f64,
    /// Initial entropy temperature α.
    pub init_alpha: f64,
    /// Target entropy (−action dimension).
    pub target_entropy: f64,
    /// Weight of the expert L2 term in the actor loss.
    pub expert_weight: f64,
    /// Multiply the critic loss per row by PER's importance weights (the paper does not).
    pub use_is_weights: bool,
    /// FERM only: contrastive (CURL) steps on the demonstrations before the first SAC update
    /// (docs/paper.md §1.10: 1,600).
    pub curl_pretrain_steps: usize,
    /// Precision of the convolutions' matrix products on the CPU: `f32` (the default, as the
    /// paper) or `bf16` (operands rounded to bfloat16, f32 sums, on Intel AMX; docs/backends.md).
    /// Process-wide: building an agent sets it for every convolution of the process.
    #[serde(skip_serializing_if = "MatmulPrecision::is_f32")]
    pub matmul: MatmulPrecision,
}

impl Default for AgentConfig {
    fn default() -> Self {
        AgentConfig {
            model: ModelKind::Equi,
            hidden: 64,
            input_size: 128,
            lr: 1e-3,
            lr_final: None,
            gamma: GAMMA,
            tau: 0.01,
            init_alpha: 1e-2,
            target_entropy: -(ACTION_DIM as f64),
            expert_weight: 1.0,
            use_is_weights: false,
            curl_pretrain_steps: 1600,
            matmul: MatmulPrecision::F32,
        }
    }
}

impl AgentConfig {
    /// The networks' configuration: their sizes, and our kernels with their GEMMs in `matmul`.
    pub fn net_config(&self) -> NetConfig {
        NetConfig::new(self.hidden, self.input_size, OBS_PLANES).with_numerics(Numerics::kernels(self.matmul))
    }
}

/// One training batch, already cropped: `obs` holds `obs_copies` copies of the `rows` transitions
/// (copy `j` of row `i` at index `j·rows + i`), each an image of [`OBS_PLANES`] × `size` × `size`
/// (docs/paper.md §1.1 channels); `next_obs` holds `next_copies` copies. Actions are normalised to
/// [−1, 1], [`ACTION_DIM`] values in the order (p, dx, dy, dz, dθ).
#[derive(Clone, Debug, Default)]
pub struct Batch {
    /// Transitions (B).
    pub rows: usize,
    /// Image side in pixels (S).
    pub size: usize,
    /// Copies of each observation (DrQ's M; 1 for RAD).
    pub obs_copies: usize,
    /// Copies of each next observation (DrQ's K; 1 for RAD).
    pub next_copies: usize,
    /// `[obs_copies·rows, OBS_PLANES, size, size]`.
    pub obs: Vec<f32>,
    /// `[next_copies·rows, OBS_PLANES, size, size]`.
    pub next_obs: Vec<f32>,
    /// `[rows, ACTION_DIM]`.
    pub action: Vec<f32>,
    /// `[rows]`.
    pub reward: Vec<f32>,
    /// `[rows]`: 0 where the bootstrap is cut (terminal), else 1.
    pub mask: Vec<f32>,
    /// `[rows]`: 1 for expert rows.
    pub expert: Vec<f32>,
    /// `[rows]`: PER importance weights (used only with `use_is_weights`).
    pub weight: Vec<f32>,
    /// FERM: the contrastive step's anchor and positive, two more independent crops of each obs,
    /// `[rows, OBS_PLANES, size, size]` each.
    pub curl: Option<(Vec<f32>, Vec<f32>)>,
}

impl Batch {
    fn check(&self) -> Result<(), AgentError> {
        let (b, m, k) = (self.rows, self.obs_copies, self.next_copies);
        let plane = OBS_PLANES * self.size * self.size;
        let bad = |what: &str, got: usize, want: usize| {
            Err(AgentError::Batch(format!("{what} has {got} values, expected {want}")))
        };
        if b == 0 || m == 0 || k == 0 {
            return Err(AgentError::Batch(format!("empty batch ({b} rows, {m} observation copies, {k} next copies)")));
        }
        if self.obs.len() != m * b * plane {
            return bad("obs", self.obs.len(), m * b * plane);
        }
        if self.next_obs.len() != k * b * plane {
            return bad("next_obs", self.next_obs.len(), k * b * plane);
        }
        if self.action.len() != ACTION_DIM * b {
            return bad("action", self.action.len(), ACTION_DIM * b);
        }
        for (what, v) in
            [("reward", &self.reward), ("mask", &self.mask), ("expert", &self.expert), ("weight", &self.weight)]
        {
            if v.len() != b {
                return bad(what, v.len(), b);
            }
        }
        if let Some((a, p)) = &self.curl {
            for (what, v) in [("curl anchor", a), ("curl positive", p)] {
                if v.len() != b * plane {
                    return bad(what, v.len(), b * plane);
                }
            }
        }
        Ok(())
    }
}

/// Scalars of one update, named as CleanRL names them.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Metrics {
    /// `losses/qf1_loss`.
    pub qf1_loss: f32,
    /// `losses/qf2_loss`.
    pub qf2_loss: f32,
    /// `losses/qf1_values`: mean Q1 on the batch.
    pub qf1_values: f32,
    /// `losses/actor_loss` (including the expert term).
    pub actor_loss: f32,
    /// `losses/expert_loss`: the expert L2 term alone (0 without expert rows).
    pub expert_loss: f32,
    /// `losses/alpha` after the α step.
    pub alpha: f32,
    /// `losses/alpha_loss`.
    pub alpha_loss: f32,
    /// `losses/entropy`: −mean log π of the actor's samples.
    pub entropy: f32,
    /// `losses/curl_loss`: FERM's contrastive loss of this update's step (`None` for the other models).
    pub curl_loss: Option<f32>,
    /// `losses/curl_pretrain_loss`: FERM's mean contrastive loss over the last 100 pre-training
    /// steps, on the update that ran the pre-training ([`crate::learner::Learner::update`]), else `None`.
    pub curl_pretrain_loss: Option<f32>,
}

impl Metrics {
    /// `(name, value)` pairs with CleanRL's names (FERM's contrastive losses where present).
    pub fn named(&self) -> Vec<(&'static str, f64)> {
        let mut named = vec![
            ("losses/qf1_loss", self.qf1_loss as f64),
            ("losses/qf2_loss", self.qf2_loss as f64),
            ("losses/qf1_values", self.qf1_values as f64),
            ("losses/actor_loss", self.actor_loss as f64),
            ("losses/expert_loss", self.expert_loss as f64),
            ("losses/alpha", self.alpha as f64),
            ("losses/alpha_loss", self.alpha_loss as f64),
            ("losses/entropy", self.entropy as f64),
        ];
        named.extend(self.curl_loss.map(|v| ("losses/curl_loss", v as f64)));
        named.extend(self.curl_pretrain_loss.map(|v| ("losses/curl_pretrain_loss", v as f64)));
        named
    }
}

/// An actor network the agent can train with critic `C`: the `equiarm_nn` actors.
pub trait ActorNet<C>: Actor + Module + Clone + Send + 'static {
    /// A copy for fast inference (cached equivariant kernels where the net has them).
    fn for_inference(&self) -> Self;

    /// The actor with the weights it shares with `critic` copied in (FERM's encoder convs);
    /// called whenever the critic changed. The others share nothing.
    fn tie(self, _critic: &C) -> Self {
        self
    }
}

/// A critic network the agent can train.
pub trait CriticNet: Critic + Module + Clone + Send + 'static {
    /// The target network's Polyak update (docs/paper.md §2: τ for every weight).
    fn soft_update(target: Self, online: &Self, tau: f64) -> Self {
        polyak(target, online, tau)
    }

    /// The encoder's features for a contrastive loss (FERM), `None` for critics without one.
    fn features(&self, _obs: Tensor<4>) -> Option<Tensor<2>> {
        None
    }
}

impl ActorNet<EquiCritic> for EquiActor {
    fn for_inference(&self) -> Self {
        self.valid().cache_kernels()
    }
}
impl ActorNet<CnnCritic> for CnnActor {
    fn for_inference(&self) -> Self {
        self.valid()
    }
}
impl ActorNet<SenCritic> for SenActor {
    fn for_inference(&self) -> Self {
        self.valid()
    }
}
impl ActorNet<FermCritic> for FermActor {
    fn for_inference(&self) -> Self {
        self.valid()
    }

    /// The critic's encoder convs, as CURL ties them (the actor's loss does not reach them).
    fn tie(self, critic: &FermCritic) -> Self {
        FermActor { enc: FermEncoder { convs: critic.enc.convs.clone(), ..self.enc }, ..self }
    }
}
impl CriticNet for EquiCritic {}
impl CriticNet for CnnCritic {}
impl CriticNet for SenCritic {}

/// FERM's Polyak coefficient of the target encoder (docs/paper.md §1.10; the Q heads keep τ).
pub const FERM_ENCODER_TAU: f64 = 0.05;

impl CriticNet for FermCritic {
    fn soft_update(target: Self, online: &Self, tau: f64) -> Self {
        polyak_by(target, online, &|path: &str| {
            if path.starts_with("enc.") { FERM_ENCODER_TAU } else { tau }
        })
    }

    fn features(&self, obs: Tensor<4>) -> Option<Tensor<2>> {
        Some(self.encode(obs))
    }
}

/// The agent's saved scalar state (`agent.json` in a checkpoint).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AgentState {
    /// Updates made.
    pub updates: u64,
    /// log α (as IEEE-754 bits: JSON numbers do not round-trip every f64 exactly).
    pub log_alpha_bits: u64,
    /// α optimiser: steps, first and second moment (bits).
    pub alpha_adam: (u64, u64, u64),
    /// Noise RNG: seed, stream and word position (decimal).
    pub rng: (String, u64, String),
    /// FERM: contrastive steps made (pre-training included).
    #[serde(default)]
    pub curl_steps: u64,
    /// FERM: the contrastive pre-training is done.
    #[serde(default)]
    pub curl_pretrained: bool,
}

/// FERM's contrastive part: the bilinear `W` and the optimisers of `W` and of the critic's
/// encoder under the contrastive loss (CURL's `cpc_optimizer` and `encoder_optimizer`).
struct Curl {
    w: CurlBilinear,
    w_opt: Adam,
    encoder_opt: Adam,
    steps: u64,
    pretrained: bool,
}

/// SAC agent over one actor/critic family.
pub struct Sac<A: ActorNet<C>, C: CriticNet> {
    cfg: AgentConfig,
    /// `plain` with autodiff: where the trained networks live.
    grad_device: Device,
    /// The chosen device without autodiff: inputs, targets, Adam moments, inference.
    plain: Device,
    actor: A,
    critic: C,
    target: C,
    actor_opt: Adam,
    critic_opt: Adam,
    log_alpha: f64,
    alpha_opt: ScalarAdam,
    rng: ChaCha8Rng,
    updates: u64,
    inference: Option<A>,
    curl: Option<Curl>,
}

/// Builds a network family.
pub type Builder<T> = fn(&NetConfig, &Init, &Device) -> Result<T, equiarm_nn::nets::NetError>;

impl<A: ActorNet<C>, C: CriticNet> Sac<A, C> {
    /// A fresh agent on the CPU (`flex`): weights from `Init::new(seed)`, noise RNG from `seed`.
    pub fn build(cfg: AgentConfig, seed: u64, actor: Builder<A>, critic: Builder<C>) -> Result<Self, AgentError> {
        Self::build_on(cfg, seed, &equiarm_nn::device::cpu(), actor, critic)
    }

    /// A fresh agent on `device` (with or without autodiff; the agent adds it for training), after
    /// [`equiarm_nn::device::check`] has opened it.
    pub fn build_on(
        cfg: AgentConfig,
        seed: u64,
        device: &Device,
        actor: Builder<A>,
        critic: Builder<C>,
    ) -> Result<Self, AgentError> {
        equiarm_nn::device::check(device)?;
        let plain = device.clone().without_autodiff();
        let device = plain.clone().autodiff();
        let net = cfg.net_config();
        let init = Init::new(seed);
        let model = cfg.model.name();
        let actor = actor(&net, &init, &device).map_err(|cause| AgentError::Net { model, cause })?;
        let critic = critic(&net, &init, &device).map_err(|cause| AgentError::Net { model, cause })?;
        let target = critic.valid();
        let actor = actor.tie(&critic);
        let adam = AdamParams::new(cfg.lr);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(0x5ac);
        let ferm = cfg.model == ModelKind::Ferm;
        let curl = ferm.then(|| Curl {
            w: CurlBilinear::new(&init, &device),
            w_opt: Adam::new(adam),
            encoder_opt: Adam::covering(adam, &critic, &plain),
            steps: 0,
            pretrained: false,
        });
        // FERM's actor convs never get a gradient (they are the critic's).
        let actor_opt = if ferm { Adam::covering(adam, &actor, &plain) } else { Adam::new(adam) };
        Ok(Sac {
            log_alpha: cfg.init_alpha.ln(),
            cfg,
            grad_device: device,
            plain,
            actor,
            critic,
            target,
            actor_opt,
            critic_opt: Adam::new(adam),
            alpha_opt: ScalarAdam::new(adam),
            rng,
            updates: 0,
            inference: None,
            curl,
        })
    }

    /// Configuration.
    pub fn config(&self) -> &AgentConfig {
        &self.cfg
    }

    /// Updates made.
    pub fn updates(&self) -> u64 {
        self.updates
    }

    /// Set the Adam step size of actor, critic and α for the following updates (the learner's
    /// learning-rate schedule). The moments are untouched.
    pub fn set_lr(&mut self, lr: f64) {
        self.actor_opt.set_lr(lr);
        self.critic_opt.set_lr(lr);
        self.alpha_opt.set_lr(lr);
        if let Some(c) = &mut self.curl {
            c.w_opt.set_lr(lr);
            c.encoder_opt.set_lr(lr);
        }
    }

    /// FERM: whether the contrastive pre-training is still to be done (false for the others).
    pub fn needs_curl_pretraining(&self) -> bool {
        self.curl.as_ref().is_some_and(|c| !c.pretrained)
    }

    /// FERM: mark the contrastive pre-training done.
    pub fn set_curl_pretrained(&mut self) {
        if let Some(c) = &mut self.curl {
            c.pretrained = true;
        }
    }

    /// FERM: contrastive steps made so far (0 for the others).
    pub fn curl_steps(&self) -> u64 {
        self.curl.as_ref().map_or(0, |c| c.steps)
    }

    /// FERM: one contrastive (CURL) step on `b` anchor and positive crops `[b, OBS_PLANES, s, s]` (two
    /// independent crops of the same observations): anchor features from the online critic's
    /// encoder, positive features from the target encoder (no gradient); the loss updates `W` and the
    /// critic's encoder. Returns the loss. An error for a model without a contrastive part.
    pub fn curl_step(&mut self, anchor: Vec<f32>, positive: Vec<f32>, b: usize) -> Result<f32, AgentError> {
        let s = self.cfg.input_size;
        if anchor.len() != b * OBS_PLANES * s * s || positive.len() != anchor.len() || b == 0 {
            return Err(AgentError::Batch(format!(
                "curl: {} and {} values for {b} crops of {OBS_PLANES}×{s}×{s}",
                anchor.len(),
                positive.len()
            )));
        }
        let (dev, plain) = (self.grad_device.clone(), self.plain.clone());
        let Some(curl) = self.curl.as_mut() else {
            return Err(AgentError::Batch(format!(
                "curl: the {} model has no contrastive part",
                self.cfg.model.name()
            )));
        };
        let xa = Tensor::<4>::from_data(TensorData::new(anchor, [b, OBS_PLANES, s, s]), &dev);
        let xp = Tensor::<4>::from_data(TensorData::new(positive, [b, OBS_PLANES, s, s]), &plain);
        let (Some(za), Some(zp)) = (self.critic.features(xa), self.target.features(xp)) else {
            return Err(AgentError::Batch("curl: the critic has no encoder features".into()));
        };
        let loss = curl.w.loss(za, Tensor::from_inner(zp));
        let value = scalar(loss.clone().inner());
        if !value.is_finite() {
            return Err(AgentError::NonFinite { update: self.updates, what: "curl loss", value });
        }
        let mut grads = loss.backward();
        let g_encoder = GradientsParams::from_module(&mut grads, &self.critic);
        let g_w = GradientsParams::from_module(&mut grads, &curl.w);
        self.critic = curl.encoder_opt.step(self.critic.clone(), g_encoder);
        curl.w = curl.w_opt.step(curl.w.clone(), g_w);
        curl.steps += 1;
        self.actor = self.actor.clone().tie(&self.critic);
        self.inference = None;
        Ok(value)
    }

    /// The device the agent's tensors live on (without autodiff).
    pub fn device(&self) -> &Device {
        &self.plain
    }

    /// Current α.
    pub fn alpha(&self) -> f64 {
        self.log_alpha.exp()
    }

    fn normal(&mut self, n: usize) -> Vec<f32> {
        crate::rng::normals(&mut self.rng, n)
    }

    fn image(&self, data: &[f32], n: usize, s: usize, device: &Device) -> Tensor<4> {
        Tensor::from_data(TensorData::new(data.to_vec(), [n, OBS_PLANES, s, s]), device)
    }

    /// Actions `[n, ACTION_DIM]` (normalised, in [−1, 1]) for `n` observations `[n, OBS_PLANES, s, s]`; `noise` is
    /// used in `Sample` mode (`[n, ACTION_DIM]` standard normals; drawn from the agent's RNG when `None`).
    pub fn act(
        &mut self,
        obs: &[f32],
        n: usize,
        mode: ActMode,
        noise: Option<&[f32]>,
    ) -> Result<Vec<NormalizedAction>, AgentError> {
        let s = self.cfg.input_size;
        if obs.len() != n * OBS_PLANES * s * s || n == 0 {
            return Err(AgentError::Batch(format!(
                "act: {} values for {n} observations of {OBS_PLANES}×{s}×{s}",
                obs.len()
            )));
        }
        let eps = match (mode, noise) {
            (ActMode::Greedy, _) => None,
            (ActMode::Sample, Some(e)) if e.len() == n * ACTION_DIM => Some(e.to_vec()),
            (ActMode::Sample, Some(e)) => {
                return Err(AgentError::Batch(format!("act: {} noise values for {n} actions", e.len())));
            }
            (ActMode::Sample, None) => Some(self.normal(n * ACTION_DIM)),
        };
        if self.inference.is_none() {
            self.inference = Some(self.actor.for_inference());
        }
        let plain = self.plain.clone();
        let x = self.image(obs, n, s, &plain);
        let actor = self.inference.as_ref().expect("set above");
        let (mean, log_std) = actor.forward(x);
        let a = match eps {
            None => mean.tanh(),
            Some(e) => gaussian_sample(mean, log_std, Tensor::from_data(TensorData::new(e, [n, ACTION_DIM]), &plain)).0,
        };
        let v = a.into_data().try_into_vec::<f32>().map_err(|e| AgentError::Batch(format!("act: {e:?}")))?;
        Ok(v.chunks_exact(ACTION_DIM).map(|c| [c[0], c[1], c[2], c[3], c[4]]).collect())
    }

    /// One SAC update (critic → actor → α → target) on `batch`, which it consumes (its images
    /// become the input tensors without a copy). Returns the metrics and the TD error per row (mean
    /// over the M copies), for PER priorities.
    pub fn update(&mut self, mut batch: Batch) -> Result<(Metrics, Vec<f32>), AgentError> {
        batch.check()?;
        let (b, s, m, k) = (batch.rows, batch.size, batch.obs_copies, batch.next_copies);
        if s != self.cfg.input_size {
            return Err(AgentError::Batch(format!("images are {s} px, the networks take {}", self.cfg.input_size)));
        }
        let dev = self.grad_device.clone();
        let plain = self.plain.clone();
        let alpha = self.log_alpha.exp();
        let gamma = self.cfg.gamma;
        let col =
            |v: &[f32], rows: usize, d: &Device| Tensor::<2>::from_data(TensorData::new(v.to_vec(), [rows, 1]), d);
        let repeat = |v: &[f32], times: usize| -> Vec<f32> { (0..times).flat_map(|_| v.iter().copied()).collect() };

        // --- critic target (no gradients): mean over the K next-observation crops.
        // The images move into the tensors (no copy of the batch's largest arrays).
        let next = Tensor::<4>::from_data(
            TensorData::new(std::mem::take(&mut batch.next_obs), [k * b, OBS_PLANES, s, s]),
            &plain,
        );
        let eps_next = self.normal(k * b * ACTION_DIM);
        let actor_plain = self.actor.valid();
        let (mn, ls) = actor_plain.forward(next.clone());
        let (a_next, logp_next, _) =
            gaussian_sample(mn, ls, Tensor::from_data(TensorData::new(eps_next, [k * b, ACTION_DIM]), &plain));
        let (q1t, q2t) = self.target.forward(next, a_next);
        let reward = col(&repeat(&batch.reward, k), k * b, &plain);
        let mask = col(&repeat(&batch.mask, k), k * b, &plain);
        let y = critic_target(reward, mask, q1t, q2t, logp_next, alpha, gamma, k);
        let y_m: Tensor<2> = Tensor::cat(vec![y; m], 0); // [m·b, 1]

        // --- critic step on the M observation crops.
        let obs =
            Tensor::<4>::from_data(TensorData::new(std::mem::take(&mut batch.obs), [m * b, OBS_PLANES, s, s]), &dev);
        let action = Tensor::<2>::from_data(TensorData::new(repeat(&batch.action, m), [m * b, ACTION_DIM]), &dev);
        let (q1, q2) = self.critic.forward(obs.clone(), action);
        let y_ad = Tensor::from_inner(y_m.clone());
        let d1 = q1.clone() - y_ad.clone();
        let d2 = q2.clone() - y_ad;
        let (l1, l2) = if self.cfg.use_is_weights {
            let w = Tensor::from_inner(col(&repeat(&batch.weight, m), m * b, &plain));
            ((d1.clone().powf_scalar(2.0) * w.clone()).mean(), (d2.clone().powf_scalar(2.0) * w).mean())
        } else {
            (d1.clone().powf_scalar(2.0).mean(), d2.clone().powf_scalar(2.0).mean())
        };
        let td_all = (d1.inner().abs() + d2.inner().abs()).mul_scalar(0.5); // [m·b, 1]
        let td = td_all.reshape([m, b]).mean_dim(0).reshape([b]);
        let qf1_values = scalar(q1.inner().mean());
        let critic_loss = l1.clone() + l2.clone();
        let (qf1_loss, qf2_loss) = (scalar(l1.inner()), scalar(l2.inner()));
        let grads = GradientsParams::from_grads(critic_loss.backward(), &self.critic);
        let critic = self.critic.clone();
        self.critic = self.critic_opt.step(critic, grads);
        self.actor = self.actor.clone().tie(&self.critic);

        // --- actor step (critic weights fixed) on the same M crops, expert L2 on the sampled action.
        let eps = self.normal(m * b * ACTION_DIM);
        let (mean, log_std) = self.actor.forward(obs.clone());
        let (a, logp, _) =
            gaussian_sample(mean, log_std, Tensor::from_data(TensorData::new(eps, [m * b, ACTION_DIM]), &dev));
        let frozen = self.critic.clone().no_grad();
        let (q1a, q2a) = frozen.forward(obs, a.clone());
        let mut actor_loss = (logp.clone().mul_scalar(alpha) - q1a.min_pair(q2a)).mean();
        let n_expert = batch.expert.iter().filter(|&&e| e > 0.5).count();
        let mut expert_loss = 0.0;
        if n_expert > 0 && self.cfg.expert_weight != 0.0 {
            let e = Tensor::from_inner(col(&repeat(&batch.expert, m), m * b, &plain));
            let target_a = Tensor::<2>::from_data(TensorData::new(repeat(&batch.action, m), [m * b, ACTION_DIM]), &dev);
            let se = (a - target_a).powf_scalar(2.0) * e;
            let l = se.sum().div_scalar((m * n_expert * ACTION_DIM) as f64);
            expert_loss = scalar(l.clone().inner());
            actor_loss = actor_loss + l.mul_scalar(self.cfg.expert_weight);
        }
        let actor_loss_v = scalar(actor_loss.clone().inner());
        let grads = GradientsParams::from_grads(actor_loss.backward(), &self.actor);
        let actor = self.actor.clone();
        self.actor = self.actor_opt.step(actor, grads);
        self.inference = None;

        // --- α step: d/d(log α) of −mean(log α · (log π + H̄)) = −mean(log π + H̄).
        let mean_logp = scalar(logp.inner().mean()) as f64;
        let g = -(mean_logp + self.cfg.target_entropy);
        let alpha_loss = -(self.log_alpha * (mean_logp + self.cfg.target_entropy));
        self.log_alpha = self.alpha_opt.step(self.log_alpha, g);

        // --- target.
        self.target = C::soft_update(self.target.clone(), &self.critic, self.cfg.tau);
        self.updates += 1;

        // --- FERM: one contrastive step on the batch's anchor and positive crops.
        let curl_loss = if self.curl.is_some() {
            let Some((anchor, positive)) = batch.curl.take() else {
                return Err(AgentError::Batch("FERM needs the batch's contrastive crops (Batch::curl)".into()));
            };
            Some(self.curl_step(anchor, positive, b)?)
        } else {
            None
        };

        let metrics = Metrics {
            qf1_loss,
            qf2_loss,
            qf1_values,
            actor_loss: actor_loss_v,
            expert_loss,
            alpha: self.log_alpha.exp() as f32,
            alpha_loss: alpha_loss as f32,
            entropy: -mean_logp as f32,
            curl_loss,
            curl_pretrain_loss: None,
        };
        for (what, v) in [("critic loss", qf1_loss + qf2_loss), ("actor loss", actor_loss_v), ("alpha", metrics.alpha)]
        {
            if !v.is_finite() {
                return Err(AgentError::NonFinite { update: self.updates, what, value: v });
            }
        }
        let td = td.into_data().try_into_vec::<f32>().map_err(|e| AgentError::Batch(format!("td: {e:?}")))?;
        Ok((metrics, td))
    }

    /// The actor (for broadcasting weights).
    pub fn actor(&self) -> &A {
        &self.actor
    }

    /// Trainable parameters of the actor and of one critic (both Q heads; the target is a copy).
    pub fn param_counts(&self) -> (usize, usize) {
        (self.actor.num_params(), self.critic.num_params())
    }

    /// Replace the actor's weights with those in a safetensors file (policy nodes).
    pub fn load_actor(&mut self, path: &Path) -> Result<(), AgentError> {
        let actor = self.actor.clone();
        self.actor = equiarm_nn::checkpoint::load(actor, path)?;
        self.inference = None;
        Ok(())
    }

    /// Replace the actor's weights with safetensors `bytes` (a `PolicyWeights` payload); `label`
    /// names the source in errors.
    pub fn load_actor_bytes(&mut self, bytes: Vec<u8>, label: &str) -> Result<(), AgentError> {
        let actor = self.actor.clone();
        self.actor = equiarm_nn::checkpoint::load_bytes(actor, bytes, label)?;
        self.inference = None;
        Ok(())
    }

    /// The actor's weights as safetensors bytes (what `PolicyWeights.data` carries).
    pub fn actor_bytes(&self) -> Result<Vec<u8>, AgentError> {
        Ok(equiarm_nn::checkpoint::to_bytes(&self.actor)?)
    }

    /// Save the actor's weights alone.
    pub fn save_actor(&self, path: &Path) -> Result<(), AgentError> {
        Ok(equiarm_nn::checkpoint::save(&self.actor, path)?)
    }

    /// Save weights, optimiser state and scalar state into directory `dir` (which must exist):
    /// `actor.safetensors`, `critic.safetensors`, `critic_target.safetensors`,
    /// `actor_optim.safetensors`, `critic_optim.safetensors`, `agent.json`.
    pub fn save(&self, dir: &Path) -> Result<(), AgentError> {
        equiarm_nn::checkpoint::save(&self.actor, &dir.join("actor.safetensors"))?;
        equiarm_nn::checkpoint::save(&self.critic, &dir.join("critic.safetensors"))?;
        equiarm_nn::checkpoint::save(&self.target, &dir.join("critic_target.safetensors"))?;
        self.actor_opt.save(&dir.join("actor_optim.safetensors"))?;
        self.critic_opt.save(&dir.join("critic_optim.safetensors"))?;
        let state = AgentState {
            updates: self.updates,
            log_alpha_bits: self.log_alpha.to_bits(),
            alpha_adam: (self.alpha_opt.step, self.alpha_opt.m.to_bits(), self.alpha_opt.v.to_bits()),
            rng: crate::rng::save_state(&self.rng),
            curl_steps: self.curl_steps(),
            curl_pretrained: self.curl.as_ref().is_some_and(|c| c.pretrained),
        };
        if let Some(c) = &self.curl {
            equiarm_nn::checkpoint::save(&c.w, &dir.join("curl.safetensors"))?;
            c.w_opt.save(&dir.join("curl_optim.safetensors"))?;
            c.encoder_opt.save(&dir.join("encoder_optim.safetensors"))?;
        }
        let path = dir.join("agent.json");
        let text = serde_json::to_string_pretty(&state)
            .map_err(|e| AgentError::State { path: path.clone(), message: e.to_string() })?;
        std::fs::write(&path, text).map_err(|e| AgentError::State { path, message: e.to_string() })
    }

    /// Restore everything [`Sac::save`] wrote (the agent must have been built with the same config).
    pub fn load(&mut self, dir: &Path) -> Result<(), AgentError> {
        let path = dir.join("agent.json");
        let text = std::fs::read_to_string(&path)
            .map_err(|e| AgentError::State { path: path.clone(), message: e.to_string() })?;
        let state: AgentState = serde_json::from_str(&text)
            .map_err(|e| AgentError::State { path: path.clone(), message: e.to_string() })?;
        let rng = crate::rng::load_state(&state.rng)
            .map_err(|e| AgentError::State { path: path.clone(), message: e.to_string() })?;
        let actor = equiarm_nn::checkpoint::load(self.actor.clone(), &dir.join("actor.safetensors"))?;
        let critic = equiarm_nn::checkpoint::load(self.critic.clone(), &dir.join("critic.safetensors"))?;
        let target = equiarm_nn::checkpoint::load(self.target.clone(), &dir.join("critic_target.safetensors"))?;
        let adam = AdamParams::new(self.cfg.lr);
        let actor_opt = Adam::load(adam, &actor, &dir.join("actor_optim.safetensors"), &self.plain)?;
        let critic_opt = Adam::load(adam, &critic, &dir.join("critic_optim.safetensors"), &self.plain)?;
        if let Some(c) = &mut self.curl {
            let w = equiarm_nn::checkpoint::load(c.w.clone(), &dir.join("curl.safetensors"))?;
            c.w_opt = Adam::load(adam, &w, &dir.join("curl_optim.safetensors"), &self.plain)?;
            c.encoder_opt = Adam::load(adam, &critic, &dir.join("encoder_optim.safetensors"), &self.plain)?;
            c.w = w;
            c.steps = state.curl_steps;
            c.pretrained = state.curl_pretrained;
        }
        self.actor = actor;
        self.critic = critic;
        self.target = target;
        self.actor_opt = actor_opt;
        self.critic_opt = critic_opt;
        self.log_alpha = f64::from_bits(state.log_alpha_bits);
        let (st, m, v) = state.alpha_adam;
        self.alpha_opt = ScalarAdam::with_state(adam, st, f64::from_bits(m), f64::from_bits(v));
        self.rng = rng;
        self.updates = state.updates;
        self.inference = None;
        Ok(())
    }
}

/// The SAC critic target `y = r + γ·mask·(min(Q1′, Q2′) − α·log π′)` for `k` stacked copies of `b`
/// rows (`[k·b, 1]` inputs, copy `j` of row `i` at `j·b + i`), averaged over the copies (DrQ's K;
/// `k = 1` for RAD): `[b, 1]`.
#[allow(clippy::too_many_arguments)]
pub fn critic_target(
    reward: Tensor<2>,
    mask: Tensor<2>,
    q1: Tensor<2>,
    q2: Tensor<2>,
    logp: Tensor<2>,
    alpha: f64,
    gamma: f64,
    k: usize,
) -> Tensor<2> {
    let [kb, _] = reward.dims();
    let b = kb / k.max(1);
    let y = reward + mask.mul_scalar(gamma) * (q1.min_pair(q2) - logp.mul_scalar(alpha));
    y.reshape([k, b]).mean_dim(0).reshape([b, 1])
}

fn scalar(t: Tensor<1>) -> f32 {
    t.into_data().convert::<f32>().try_into_vec::<f32>().ok().and_then(|v| v.first().copied()).unwrap_or(f32::NAN)
}

/// A SAC agent of any [`ModelKind`] (one per process: the size difference between the variants'
/// inline state does not matter, the tensors live on the heap).
#[allow(clippy::large_enum_variant)]
pub enum Agent {
    /// Equivariant (D4).
    Equi(Sac<EquiActor, EquiCritic>),
    /// CNN.
    Cnn(Sac<CnnActor, CnnCritic>),
    /// SEN.
    Sen(Sac<SenActor, SenCritic>),
    /// FERM.
    Ferm(Sac<FermActor, FermCritic>),
}

macro_rules! each {
    ($self:expr, $a:ident => $e:expr) => {
        match $self {
            Agent::Equi($a) => $e,
            Agent::Cnn($a) => $e,
            Agent::Sen($a) => $e,
            Agent::Ferm($a) => $e,
        }
    };
}

impl Agent {
    /// A fresh agent of `cfg.model` on the CPU (`flex`), weights and noise seeded with `seed`.
    pub fn new(cfg: AgentConfig, seed: u64) -> Result<Self, AgentError> {
        Self::new_on(cfg, seed, &equiarm_nn::device::cpu())
    }

    /// A fresh agent of `cfg.model` on `device` (see [`equiarm_nn::device`]), weights and noise
    /// seeded with `seed`. On the CPU this is [`Agent::new`], bit for bit.
    pub fn new_on(cfg: AgentConfig, seed: u64, device: &Device) -> Result<Self, AgentError> {
        cfg.matmul.supported().map_err(AgentError::Matmul)?;
        Ok(match cfg.model {
            ModelKind::Equi => Agent::Equi(Sac::build_on(cfg, seed, device, EquiActor::new, EquiCritic::new)?),
            ModelKind::Cnn => Agent::Cnn(Sac::build_on(cfg, seed, device, CnnActor::new, CnnCritic::new)?),
            ModelKind::Sen => Agent::Sen(Sac::build_on(cfg, seed, device, SenActor::new, SenCritic::new)?),
            ModelKind::Ferm => Agent::Ferm(Sac::build_on(cfg, seed, device, FermActor::new, FermCritic::new)?),
        })
    }

    /// See [`Sac::needs_curl_pretraining`].
    pub fn needs_curl_pretraining(&self) -> bool {
        each!(self, a => a.needs_curl_pretraining())
    }

    /// See [`Sac::param_counts`].
    pub fn param_counts(&self) -> (usize, usize) {
        each!(self, a => a.param_counts())
    }

    /// See [`Sac::set_curl_pretrained`].
    pub fn set_curl_pretrained(&mut self) {
        each!(self, a => a.set_curl_pretrained())
    }

    /// See [`Sac::curl_steps`].
    pub fn curl_steps(&self) -> u64 {
        each!(self, a => a.curl_steps())
    }

    /// See [`Sac::curl_step`].
    pub fn curl_step(&mut self, anchor: Vec<f32>, positive: Vec<f32>, b: usize) -> Result<f32, AgentError> {
        each!(self, a => a.curl_step(anchor, positive, b))
    }

    /// See [`Sac::device`].
    pub fn device(&self) -> &Device {
        each!(self, a => a.device())
    }

    /// Configuration.
    pub fn config(&self) -> &AgentConfig {
        each!(self, a => a.config())
    }

    /// Updates made.
    pub fn updates(&self) -> u64 {
        each!(self, a => a.updates())
    }

    /// Current α.
    pub fn alpha(&self) -> f64 {
        each!(self, a => a.alpha())
    }

    /// See [`Sac::set_lr`].
    pub fn set_lr(&mut self, lr: f64) {
        each!(self, a => a.set_lr(lr))
    }

    /// See [`Sac::act`].
    pub fn act(
        &mut self,
        obs: &[f32],
        n: usize,
        mode: ActMode,
        noise: Option<&[f32]>,
    ) -> Result<Vec<NormalizedAction>, AgentError> {
        each!(self, a => a.act(obs, n, mode, noise))
    }

    /// See [`Sac::update`].
    pub fn update(&mut self, batch: Batch) -> Result<(Metrics, Vec<f32>), AgentError> {
        each!(self, a => a.update(batch))
    }

    /// See [`Sac::save`].
    pub fn save(&self, dir: &Path) -> Result<(), AgentError> {
        each!(self, a => a.save(dir))
    }

    /// See [`Sac::load`].
    pub fn load(&mut self, dir: &Path) -> Result<(), AgentError> {
        each!(self, a => a.load(dir))
    }

    /// See [`Sac::save_actor`].
    pub fn save_actor(&self, path: &Path) -> Result<(), AgentError> {
        each!(self, a => a.save_actor(path))
    }

    /// See [`Sac::load_actor`].
    pub fn load_actor(&mut self, path: &Path) -> Result<(), AgentError> {
        each!(self, a => a.load_actor(path))
    }

    /// See [`Sac::actor_bytes`].
    pub fn actor_bytes(&self) -> Result<Vec<u8>, AgentError> {
        each!(self, a => a.actor_bytes())
    }

    /// See [`Sac::load_actor_bytes`].
    pub fn load_actor_bytes(&mut self, bytes: Vec<u8>, label: &str) -> Result<(), AgentError> {
        each!(self, a => a.load_actor_bytes(bytes, label))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t2(v: &[f32], rows: usize, cols: usize) -> Tensor<2> {
        Tensor::from_data(TensorData::new(v.to_vec(), [rows, cols]), &Device::flex())
    }

    fn vals(t: Tensor<2>) -> Vec<f32> {
        t.into_data().try_into_vec::<f32>().unwrap()
    }

    /// erf by Abramowitz–Stegun 7.1.26 (|error| < 1.5e-7).
    fn erf(x: f64) -> f64 {
        let s = x.signum();
        let x = x.abs();
        let t = 1.0 / (1.0 + 0.3275911 * x);
        let y = 1.0
            - (((((1.061405429 * t - 1.453152027) * t) + 1.421413741) * t - 0.284496736) * t + 0.254829592)
                * t
                * (-x * x).exp();
        s * y
    }

    fn phi(z: f64) -> f64 {
        0.5 * (1.0 + erf(z / std::f64::consts::SQRT_2))
    }

    #[test]
    fn log_prob_matches_the_numerical_density_of_the_squashed_gaussian() {
        let mean = [0.3f32, -1.2, 0.0, 2.0, -0.4];
        let log_std = [-0.5f32, 0.2, -1.5, -0.1, 0.4];
        let eps = [0.7f32, -0.3, 1.1, -0.9, 0.05];
        let (a, logp, greedy) = gaussian_sample(t2(&mean, 1, 5), t2(&log_std, 1, 5), t2(&eps, 1, 5));
        let a = vals(a);
        let logp = vals(logp)[0] as f64;
        // Density of a = tanh(x), x ~ N(μ, σ²), per dimension: P(a ∈ [a−h, a+h]) / 2h from the
        // Gaussian CDF at atanh of the interval ends; independent dimensions multiply.
        let mut log_numeric = 0.0;
        for i in 0..5 {
            let (mu, sd, ai) = (mean[i] as f64, (log_std[i] as f64).exp(), a[i] as f64);
            let h = 1e-5 * (1.0 - ai * ai);
            let p = phi(((ai + h).atanh() - mu) / sd) - phi(((ai - h).atanh() - mu) / sd);
            log_numeric += (p / (2.0 * h)).ln();
        }
        assert!((logp - log_numeric).abs() < 2e-3, "log π {logp} vs numerical {log_numeric}");
        let g = vals(greedy);
        for i in 0..5 {
            assert!((g[i] - mean[i].tanh()).abs() < 1e-6);
        }
    }

    #[test]
    fn critic_target_on_a_hand_made_batch() {
        // Two rows, two copies (DrQ K = 2): y = r + γ·mask·(min(q1, q2) − α·logp), mean over copies.
        let r = t2(&[1.0, 0.0, 1.0, 0.0], 4, 1);
        let mask = t2(&[0.0, 1.0, 0.0, 1.0], 4, 1);
        let q1 = t2(&[5.0, 2.0, 7.0, 4.0], 4, 1);
        let q2 = t2(&[6.0, 3.0, 1.0, 3.0], 4, 1);
        let logp = t2(&[-1.0, -2.0, -3.0, 1.0], 4, 1);
        let y = vals(critic_target(r, mask, q1, q2, logp, 0.1, 0.9, 2));
        // row 0: terminal, both copies give 1.0.
        // row 1: copy 0: 0.9·(2 + 0.2) = 1.98; copy 1: 0.9·(3 − 0.1) = 2.61; mean 2.295.
        assert!((y[0] - 1.0).abs() < 1e-6 && (y[1] - 2.295).abs() < 1e-5, "{y:?}");
        let y1 = vals(critic_target(
            t2(&[0.5], 1, 1),
            t2(&[1.0], 1, 1),
            t2(&[2.0], 1, 1),
            t2(&[1.5], 1, 1),
            t2(&[-5.0], 1, 1),
            0.01,
            0.99,
            1,
        ));
        assert!((y1[0] - (0.5 + 0.99 * (1.5 + 0.05))).abs() < 1e-6, "{y1:?}");
    }

    fn tiny(model: ModelKind) -> AgentConfig {
        AgentConfig { model, hidden: 8, input_size: 8, ..AgentConfig::default() }
    }

    fn batch(b: usize, s: usize, seed: u64) -> Batch {
        let mut rng = crate::rng::stream(seed, 9);
        Batch {
            rows: b,
            size: s,
            obs_copies: 1,
            next_copies: 1,
            obs: crate::rng::normals(&mut rng, b * OBS_PLANES * s * s),
            next_obs: crate::rng::normals(&mut rng, b * OBS_PLANES * s * s),
            action: crate::rng::normals(&mut rng, b * ACTION_DIM).iter().map(|x| x.tanh()).collect(),
            reward: (0..b).map(|i| (i % 2) as f32).collect(),
            mask: vec![1.0; b],
            expert: (0..b).map(|i| (i % 3 == 0) as u8 as f32).collect(),
            weight: vec![1.0; b],
            curl: None,
        }
    }

    /// A weights file's tensors sorted by name: compare tensors, not bytes (the safetensors header
    /// order is not fixed).
    fn sorted_tensors(p: &Path) -> Vec<(String, Vec<usize>, Vec<f32>)> {
        let mut t = crate::tensorfile::read(p).unwrap().tensors;
        t.sort_by(|a, b| a.0.cmp(&b.0));
        t
    }

    /// [`batch`] with FERM's contrastive crops.
    fn ferm_batch(b: usize, s: usize, seed: u64) -> Batch {
        let mut rng = crate::rng::stream(seed, 10);
        let n = b * OBS_PLANES * s * s;
        Batch { curl: Some((crate::rng::normals(&mut rng, n), crate::rng::normals(&mut rng, n))), ..batch(b, s, seed) }
    }

    #[test]
    fn ferm_learns_ties_its_actor_to_the_critic_and_resumes_bit_identically() {
        let batches: Vec<Batch> = (0..6).map(|i| ferm_batch(6, 8, 10 + i)).collect();
        let mut straight = Agent::new(tiny(ModelKind::Ferm), 5).unwrap();
        let first = straight.update(batches[0].clone()).unwrap().0;
        let mut last = first;
        for _ in 0..30 {
            last = straight.update(batches[0].clone()).unwrap().0;
        }
        assert!(last.qf1_loss < first.qf1_loss, "critic loss {} → {}", first.qf1_loss, last.qf1_loss);
        assert_eq!(straight.curl_steps(), 31, "one contrastive step per update");
        // the actor's convs are the critic's after every update; its head is its own
        let Agent::Ferm(sac) = &straight else { panic!("a FERM agent") };
        let (pa, pc) = (crate::optim::parameters(&sac.actor), crate::optim::parameters(&sac.critic));
        let vals1 = |t: &Tensor<1>| t.clone().into_data().try_into_vec::<f32>().unwrap();
        let convs: Vec<&String> = pa.keys().filter(|k| k.starts_with("enc.convs.")).collect();
        assert!(!convs.is_empty());
        for k in convs {
            assert_eq!(vals1(&pa[k]), vals1(&pc[k]), "{k}");
        }
        assert_ne!(vals1(&pa["enc.head.fc.weight"]), vals1(&pc["enc.head.fc.weight"]), "the actor's own encoder head");
        // a FERM batch without contrastive crops is refused; other models have no contrastive step
        let e = straight.update(batch(6, 8, 1)).unwrap_err().to_string();
        assert!(e.contains("contrastive crops"), "{e}");
        let mut cnn = Agent::new(tiny(ModelKind::Cnn), 5).unwrap();
        let (a, p) = batches[0].curl.clone().unwrap();
        assert!(cnn.curl_step(a, p, 6).unwrap_err().to_string().contains("no contrastive part"));

        // save after 3 updates, load into a fresh agent, 3 more: the same weights as 6 straight
        let dir_tmp = tempfile::tempdir().unwrap();
        let dir = dir_tmp.path();
        let mut straight = Agent::new(tiny(ModelKind::Ferm), 5).unwrap();
        straight.set_curl_pretrained();
        for b in &batches {
            straight.update(b.clone()).unwrap();
        }
        let mut first = Agent::new(tiny(ModelKind::Ferm), 5).unwrap();
        first.set_curl_pretrained();
        for b in &batches[..3] {
            first.update(b.clone()).unwrap();
        }
        first.save(dir).unwrap();
        let mut resumed = Agent::new(tiny(ModelKind::Ferm), 99).unwrap();
        assert!(resumed.needs_curl_pretraining());
        resumed.load(dir).unwrap();
        assert!(!resumed.needs_curl_pretraining(), "the pre-training is part of the checkpoint");
        for b in &batches[3..] {
            resumed.update(b.clone()).unwrap();
        }
        assert_eq!(resumed.curl_steps(), 6);
        let (p1, p2) = (dir.join("a.safetensors"), dir.join("b.safetensors"));
        straight.save_actor(&p1).unwrap();
        resumed.save_actor(&p2).unwrap();
        assert_eq!(sorted_tensors(&p1), sorted_tensors(&p2), "resumed FERM actor differs from the straight one");
    }

    #[test]
    fn updates_learn_a_fixed_batch_and_are_repeatable() {
        for model in [ModelKind::Equi, ModelKind::Cnn, ModelKind::Sen] {
            let data = batch(8, 8, 1);
            let mut a = Agent::new(tiny(model), 3).unwrap();
            let mut b = Agent::new(tiny(model), 3).unwrap();
            let first = a.update(data.clone()).unwrap().0;
            let mut last = first;
            for _ in 0..30 {
                last = a.update(data.clone()).unwrap().0;
            }
            assert!(last.qf1_loss < first.qf1_loss, "{model:?}: critic loss {} → {}", first.qf1_loss, last.qf1_loss);
            assert!(
                last.expert_loss < first.expert_loss,
                "{model:?}: expert loss {} → {}",
                first.expert_loss,
                last.expert_loss
            );
            for _ in 0..31 {
                b.update(data.clone()).unwrap();
            }
            let x = &data.obs[..5 * 64];
            assert_eq!(a.act(x, 1, ActMode::Greedy, None).unwrap(), b.act(x, 1, ActMode::Greedy, None).unwrap());
        }
    }

    #[test]
    fn an_agent_built_on_the_cpu_device_is_the_default_agent() {
        // `new_on` with the CPU device (given with or without autodiff) is `new`, bit for bit.
        let data = batch(6, 8, 4);
        let mut a = Agent::new(tiny(ModelKind::Cnn), 2).unwrap();
        let mut b = Agent::new_on(tiny(ModelKind::Cnn), 2, &Device::flex().autodiff()).unwrap();
        assert_eq!(b.device(), &Device::flex());
        assert!(!b.device().is_autodiff());
        for _ in 0..2 {
            assert_eq!(a.update(data.clone()).unwrap(), b.update(data.clone()).unwrap());
        }
        let x = &data.obs[..5 * 64];
        assert_eq!(a.act(x, 1, ActMode::Sample, None).unwrap(), b.act(x, 1, ActMode::Sample, None).unwrap());
    }

    #[test]
    fn bad_batches_are_errors() {
        let mut a = Agent::new(tiny(ModelKind::Cnn), 0).unwrap();
        let mut data = batch(4, 8, 0);
        data.reward.pop();
        assert!(matches!(a.update(data.clone()), Err(AgentError::Batch(_))));
        let data = batch(4, 16, 0);
        assert!(matches!(a.update(data.clone()), Err(AgentError::Batch(_))));
        assert!(a.act(&[0.0; 7], 1, ActMode::Greedy, None).is_err());
    }

    #[test]
    fn save_load_continues_bit_identically() {
        let dir_tmp = tempfile::tempdir().unwrap();
        let dir = dir_tmp.path();
        let batches: Vec<Batch> = (0..6).map(|i| batch(6, 8, 10 + i)).collect();
        let mut straight = Agent::new(tiny(ModelKind::Equi), 5).unwrap();
        for b in &batches {
            straight.update(b.clone()).unwrap();
        }
        let mut first = Agent::new(tiny(ModelKind::Equi), 5).unwrap();
        for b in &batches[..3] {
            first.update(b.clone()).unwrap();
        }
        first.save(dir).unwrap();
        drop(first);
        let mut resumed = Agent::new(tiny(ModelKind::Equi), 99).unwrap();
        resumed.load(dir).unwrap();
        for b in &batches[3..] {
            resumed.update(b.clone()).unwrap();
        }
        let (p1, p2) = (dir.join("a.safetensors"), dir.join("b.safetensors"));
        straight.save_actor(&p1).unwrap();
        resumed.save_actor(&p2).unwrap();
        let (ta, tb) = (sorted_tensors(&p1), sorted_tensors(&p2));
        assert!(!ta.is_empty() && ta == tb, "resumed actor differs from the straight one");
        assert_eq!(straight.alpha(), resumed.alpha());
        // A checkpoint of another architecture is refused, naming the file.
        let mut cnn = Agent::new(tiny(ModelKind::Cnn), 0).unwrap();
        let e = cnn.load(dir).unwrap_err().to_string();
        assert!(e.contains("actor.safetensors"), "{e}");
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn damaged_optimiser_state_is_refused_naming_the_file() {
        let dir_tmp = tempfile::tempdir().unwrap();
        let dir = dir_tmp.path();
        let mut a = Agent::new(tiny(ModelKind::Cnn), 1).unwrap();
        a.update(batch(4, 8, 3)).unwrap();
        a.save(dir).unwrap();
        // The saved moments are a safetensors file any reader takes: one `.m` and `.v` per parameter.
        let state = crate::tensorfile::read(&dir.join("critic_optim.safetensors")).unwrap();
        assert_eq!(state.meta.get("step").map(String::as_str), Some("1"));
        assert!(!state.tensors.is_empty() && state.tensors.len().is_multiple_of(2));
        assert!(state.tensors.iter().all(|(n, _, _)| n.ends_with(".m") || n.ends_with(".v")));
        // Cut short: the load fails, saying which file and why.
        let path = dir.join("critic_optim.safetensors");
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
        let e = Agent::new(tiny(ModelKind::Cnn), 1).unwrap().load(dir).unwrap_err().to_string();
        assert!(e.contains("critic_optim.safetensors") && e.contains("not a safetensors file"), "{e}");
    }
}
