//! The paper's networks (docs/paper.md §1.4–1.9, §4), parameterised by hidden size and input size so
//! that one code base serves the paper config (GPU) and a reduced CPU config.
//!
//! - [`EquiActor`], [`EquiCritic`]: Equivariant SAC, group D4 (§1.4, §1.5).
//! - [`CnnActor`], [`CnnCritic`]: the CNN SAC baseline, 'conv' variant (§1.8).
//! - [`SenActor`], [`SenCritic`]: SEN fc2, a CNN encoder with equivariant heads (§1.9).
//! - [`FermActor`], [`FermCritic`], [`CurlBilinear`]: FERM, CURL's encoder, MLP heads and
//!   contrastive loss (§1.10).
//! - [`RotEquiNet`], [`RotCnnNet`]: the C8 rotation-estimation classifiers (§4).
//!
//! Input size: `8·2^p` pixels with `0 ≤ p ≤ 4` (128 in the paper). The paper's encoders pool
//! 128 → 8 in their first four layers before an unpadded tail (8 → 6 → 3 → 1); a smaller input
//! drops the first `4 − p` layers, as the authors' `EquivariantEncoder64` drops the 128×128 one.
//! At 128 px the layer structure is exactly the paper's. Actions are `(p, dx, dy, dz, dθ)`
//! (docs/paper.md §1.2).
//!
//! Limitations: the SAC sampling helper is in [`gaussian_sample`]; losses and the update live in
//! the trainer, not here.

use crate::group::Group;
use crate::init::Init;
use crate::layers::{EquivariantConv, LayerError, Numerics, concat, group_pool, max_pool2, relu};
use crate::plain::{Conv, Linear};
use crate::repr::{FieldType, Representation};
use burn::module::Module;
use burn::tensor::{Device, Tensor};
use equiarm_types::{ACTION_DIM, OBS_PLANES};
use thiserror::Error;

/// Errors building a network.
#[derive(Debug, Error)]
pub enum NetError {
    /// The configuration cannot be built.
    #[error("invalid network config: {0}")]
    Config(String),
    /// A layer failed to build.
    #[error(transparent)]
    Layer(#[from] LayerError),
}

/// Log-std clamp range (SAC, docs/paper.md §1.4).
pub const LOG_STD_MIN: f32 = -20.0;
/// Upper log-std clamp.
pub const LOG_STD_MAX: f32 = 2.0;

/// Network size configuration.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NetConfig {
    /// Hidden size `n`: regular fields of the equivariant encoder output (paper 64; SEN paper 32).
    /// For CNNs the channel widths scale with it (paper 64 ⇒ 16…256). A multiple of 8.
    pub hidden: usize,
    /// Input height = width in pixels, `8·2^p`, `p ≤ 4` (paper 128).
    pub input_size: usize,
    /// Input channels (paper: 5 = RGBD + holding plane for SAC, 8 for rotation estimation).
    pub in_channels: usize,
    /// How every convolution of the network computes (default: our kernels in `f32`).
    pub numerics: Numerics,
}

impl NetConfig {
    /// Paper settings for the SAC nets: hidden 64, 128 px, 5 channels.
    pub const fn paper() -> Self {
        NetConfig { hidden: 64, input_size: 128, in_channels: OBS_PLANES, numerics: Numerics::DEFAULT }
    }

    /// Paper settings for SEN fc2: hidden 32, 128 px, 5 channels.
    pub const fn paper_sen() -> Self {
        NetConfig { hidden: 32, input_size: 128, in_channels: OBS_PLANES, numerics: Numerics::DEFAULT }
    }

    /// Paper settings for the rotation-estimation nets: hidden 64, 128 px, 8 channels.
    pub const fn paper_rotation() -> Self {
        NetConfig { hidden: 64, input_size: 128, in_channels: 8, numerics: Numerics::DEFAULT }
    }

    /// Reduced CPU config: hidden 16, 64 px, 5 channels (the paper layers from 64×64 on).
    pub const fn reduced_cpu() -> Self {
        NetConfig { hidden: 16, input_size: 64, in_channels: OBS_PLANES, numerics: Numerics::DEFAULT }
    }

    /// `hidden`, `input_size` and `in_channels` with the default numerics.
    pub const fn new(hidden: usize, input_size: usize, in_channels: usize) -> Self {
        NetConfig { hidden, input_size, in_channels, numerics: Numerics::DEFAULT }
    }

    /// The same sizes, convolving as `numerics` says.
    pub const fn with_numerics(self, numerics: Numerics) -> Self {
        NetConfig { numerics, ..self }
    }

    /// Number of 2×2 pools before the 8×8 map: `input_size = 8·2^p`.
    fn pools(&self) -> Result<usize, NetError> {
        if self.hidden == 0 || !self.hidden.is_multiple_of(8) {
            return Err(NetError::Config(format!("hidden size {} must be a positive multiple of 8", self.hidden)));
        }
        if self.in_channels == 0 {
            return Err(NetError::Config("in_channels must be positive".into()));
        }
        (0..=4)
            .find(|&p| 8 << p == self.input_size)
            .ok_or_else(|| NetError::Config(format!("input size {} must be 8, 16, 32, 64 or 128", self.input_size)))
    }

    /// The layers a 128 px encoder keeps at this input size, as `(width, pad, pool after)`.
    ///
    /// `layers` are the paper's layers at 128 px, whose first four each end with a 2×2 pool
    /// (128 → 8). At `8·2^p` px the first `4 − p` of them are dropped, the rule of the authors'
    /// own smaller encoders (`EquivariantEncoder64` is `EquivariantEncoder128` minus its 128×128
    /// layer): every kept layer runs at the resolution, and with the width, it has in the paper.
    fn kept<const L: usize>(&self, layers: [(usize, usize, bool); L]) -> Result<Vec<(usize, usize, bool)>, NetError> {
        let p = self.pools()?;
        Ok(layers[4 - p..].to_vec())
    }
}

/// The paper's 7-layer encoders at 128 px as `(width, pad, pool after)`: 3×3 convs, layers 1–4
/// padded and pooled (128 → 8), layer 5 padded at 8×8, layer 6 unpadded (8 → 6) and pooled, layer 7
/// unpadded (3 → 1).
fn paper_layers(w: [usize; 7]) -> [(usize, usize, bool); 7] {
    [
        (w[0], 1, true),
        (w[1], 1, true),
        (w[2], 1, true),
        (w[3], 1, true),
        (w[4], 1, false),
        (w[5], 0, true),
        (w[6], 0, false),
    ]
}

/// The pool-after flags of `(width, pad, pool after)` layers.
fn pool_flags(layers: &[(usize, usize, bool)]) -> Vec<bool> {
    layers.iter().map(|l| l.2).collect()
}

/// Plain 3×3 convs from the config's input channels through `layers`, named `{prefix}{i}`; with the
/// last width.
fn plain_convs(
    prefix: &str,
    cfg: &NetConfig,
    layers: &[(usize, usize, bool)],
    init: &Init,
    device: &Device,
) -> (Vec<Conv>, usize) {
    let mut cin = cfg.in_channels;
    let mut convs = Vec::new();
    for (i, &(w, pad, _)) in layers.iter().enumerate() {
        convs.push(Conv::new(&format!("{prefix}{i}"), cin, w, 3, pad, cfg.numerics, init, device));
        cin = w;
    }
    (convs, cin)
}

/// The 7-layer equivariant encoder `EquivariantEncoder128` (docs/paper.md §1.4 layers 1–7).
///
/// Input field type: `in_channels × trivial`; output: `hidden × regular` at 1×1.
#[derive(Module, Debug)]
pub struct EquiEncoder {
    /// Layers 1–7.
    pub convs: Vec<EquivariantConv>,
    pools: Vec<bool>,
    out_fields: usize,
}

impl EquiEncoder {
    /// Build for `group` (D4 for SAC, C8 for rotation estimation).
    pub fn new(path: &str, group: Group, cfg: &NetConfig, init: &Init, device: &Device) -> Result<Self, NetError> {
        let n = cfg.hidden;
        let layers = cfg.kept(paper_layers([n / 8, n / 4, n / 2, n, 2 * n, n, n]))?;
        let mut in_type = FieldType::trivial(group, cfg.in_channels);
        let mut convs = Vec::new();
        for (i, &(f, pad, _)) in layers.iter().enumerate() {
            let out_type = FieldType::regular(group, f);
            convs.push(EquivariantConv::new(
                &format!("{path}.convs.{i}"),
                &in_type,
                &out_type,
                3,
                pad,
                cfg.numerics,
                init,
                device,
            )?);
            in_type = out_type;
        }
        Ok(EquiEncoder { convs, pools: pool_flags(&layers), out_fields: n })
    }

    /// `[B, in_channels, S, S] → [B, 8·hidden (|G|·hidden), 1, 1]`.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let mut x = x;
        for (conv, &pool) in self.convs.iter().zip(&self.pools) {
            x = conv.forward_relu(x);
            if pool {
                x = max_pool2(x);
            }
        }
        x
    }

    /// Number of regular output fields.
    pub fn out_fields(&self) -> usize {
        self.out_fields
    }

    /// Expand and cache every dense kernel (inference only).
    pub fn cache_kernels(self) -> Self {
        let EquiEncoder { convs, pools, out_fields } = self;
        EquiEncoder { convs: convs.into_iter().map(|c| c.cache_kernel()).collect(), pools, out_fields }
    }
}

/// The field type of the Equi SAC actor's output (11 channels): `irrep(1,1)` (dx, dy) ⊕
/// `quotient(C4)` (θ, −θ parts) ⊕ 7 × trivial (p, dz, 5 log-stds). docs/paper.md §1.4.
pub fn actor_out_type(group: Group) -> FieldType {
    FieldType::new(group, vec![Representation::irrep(group, 1, 1), Representation::quotient_by_rotations(group)])
        .concat(&FieldType::trivial(group, 7))
}

/// The equivariant actors' head: a 1×1 convolution from the encoder's regular fields to the
/// action's field types ([`actor_out_type`]).
fn actor_head(g: Group, cfg: &NetConfig, init: &Init, device: &Device) -> Result<EquivariantConv, NetError> {
    Ok(EquivariantConv::new(
        "head",
        &FieldType::regular(g, cfg.hidden),
        &actor_out_type(g),
        1,
        0,
        cfg.numerics,
        init,
        device,
    )?)
}

/// The field type of the lifted action (6 channels): 2 × trivial (p, dz) ⊕ `irrep(1,1)` (dx, dy)
/// ⊕ `quotient(C4)` (dθ, −dθ). docs/paper.md §1.5.
pub fn action_type(group: Group) -> FieldType {
    FieldType::trivial(group, 2).concat(&FieldType::new(
        group,
        vec![Representation::irrep(group, 1, 1), Representation::quotient_by_rotations(group)],
    ))
}

/// Lift actions `[B, 5]` in order `(p, dx, dy, dz, dθ)` into the field type [`action_type`]:
/// `[B, 6, 1, 1] = (p, dz, dx, dy, dθ, −dθ)`.
pub fn lift_action(a: Tensor<2>) -> Tensor<4> {
    let [b, _] = a.dims();
    let col = |i: usize| a.clone().narrow(1, i, 1);
    let theta = col(4);
    Tensor::cat(vec![col(0), col(3), col(1), col(2), theta.clone(), theta.neg()], 1).reshape([b, 6, 1, 1])
}

/// Decode an actor head's 11 channels `[B, 11]` into `(mean, log_std)`, both `[B, 5]` in action
/// order (docs/paper.md §1.4 `getOutput`).
fn decode_equi(raw: Tensor<2>) -> (Tensor<2>, Tensor<2>) {
    let col = |i: usize| raw.clone().narrow(1, i, 1);
    let dtheta = col(2) - col(3);
    let mean = Tensor::cat(vec![col(4), col(0), col(1), col(5), dtheta], 1);
    let log_std = raw.clone().narrow(1, 6, 5).clamp(LOG_STD_MIN, LOG_STD_MAX);
    (mean, log_std)
}

/// A SAC Gaussian policy network: observation → (mean, log_std), each `[B, 5]`.
pub trait Actor {
    /// `[B, C, S, S] → (mean [B, 5], log_std [B, 5])` (log_std clamped to [−20, 2]).
    fn forward(&self, obs: Tensor<4>) -> (Tensor<2>, Tensor<2>);
}

/// A SAC twin critic: (observation, action) → (Q1, Q2), each `[B, 1]`.
pub trait Critic {
    /// `([B, C, S, S], [B, 5]) → (Q1 [B, 1], Q2 [B, 1])`.
    fn forward(&self, obs: Tensor<4>, action: Tensor<2>) -> (Tensor<2>, Tensor<2>);
}

/// Equivariant SAC actor `EquivariantSACActorDihedral` (D4). Input: `in_channels × trivial`;
/// head output: [`actor_out_type`].
#[derive(Module, Debug)]
pub struct EquiActor {
    /// Encoder, layers 1–7.
    pub enc: EquiEncoder,
    /// 1×1 head, `hidden × regular → actor_out_type`.
    pub head: EquivariantConv,
}

impl EquiActor {
    /// Build with weights from `init`.
    pub fn new(cfg: &NetConfig, init: &Init, device: &Device) -> Result<Self, NetError> {
        let g = Group::dihedral(4);
        let enc = EquiEncoder::new("enc", g, cfg, init, device)?;
        Ok(EquiActor { enc, head: actor_head(g, cfg, init, device)? })
    }

    /// The head's 11 geometric output channels `[B, 11]` (type [`actor_out_type`]).
    pub fn forward_raw(&self, obs: Tensor<4>) -> Tensor<2> {
        let y = self.head.forward(self.enc.forward(obs));
        let [b, c, _, _] = y.dims();
        y.reshape([b, c])
    }

    /// Expand and cache every dense kernel for fast inference (do not train the result).
    pub fn cache_kernels(self) -> Self {
        EquiActor { enc: self.enc.cache_kernels(), head: self.head.cache_kernel() }
    }
}

impl Actor for EquiActor {
    fn forward(&self, obs: Tensor<4>) -> (Tensor<2>, Tensor<2>) {
        decode_equi(self.forward_raw(obs))
    }
}

/// One equivariant Q head: `1×1 (mixed type → hidden × regular) → ReLU → group pooling →
/// 1×1 (hidden × trivial → 1 trivial)`. Output invariant.
#[derive(Module, Debug)]
pub struct EquiQHead {
    /// Mixed type → regular.
    pub conv1: EquivariantConv,
    /// Trivial → 1 trivial.
    pub conv2: EquivariantConv,
    fields: usize,
    dim: usize,
}

impl EquiQHead {
    fn new(path: &str, in_type: &FieldType, cfg: &NetConfig, init: &Init, device: &Device) -> Result<Self, NetError> {
        let (g, hidden) = (in_type.group(), cfg.hidden);
        let conv1 = EquivariantConv::new(
            &format!("{path}.conv1"),
            in_type,
            &FieldType::regular(g, hidden),
            1,
            0,
            cfg.numerics,
            init,
            device,
        )?;
        let conv2 = EquivariantConv::new(
            &format!("{path}.conv2"),
            &FieldType::trivial(g, hidden),
            &FieldType::trivial(g, 1),
            1,
            0,
            cfg.numerics,
            init,
            device,
        )?;
        Ok(EquiQHead { conv1, conv2, fields: hidden, dim: g.order() })
    }

    fn forward(&self, x: Tensor<4>) -> Tensor<2> {
        let h = group_pool(self.conv1.forward_relu(x), self.fields, self.dim);
        let q = self.conv2.forward(h);
        let [b, _, _, _] = q.dims();
        q.reshape([b, 1])
    }
}

/// Equivariant SAC twin critic `EquivariantSACCriticDihedral` (D4). Input: observation
/// (`in_channels × trivial`) and the action lifted by [`lift_action`]; each head's input type is
/// `hidden × regular ⊕ action_type`; outputs Q1, Q2 invariant.
#[derive(Module, Debug)]
pub struct EquiCritic {
    /// Encoder (not shared with the actor).
    pub enc: EquiEncoder,
    /// Q1 head.
    pub q1: EquiQHead,
    /// Q2 head.
    pub q2: EquiQHead,
}

/// The twin heads `q1`, `q2` shared by the critics whose encoder ends in `hidden × regular` D4
/// fields (Equi and SEN): input type `hidden × regular ⊕` [`action_type`].
fn equi_twin_heads(cfg: &NetConfig, init: &Init, device: &Device) -> Result<(EquiQHead, EquiQHead), NetError> {
    let g = Group::dihedral(4);
    let t = FieldType::regular(g, cfg.hidden).concat(&action_type(g));
    Ok((EquiQHead::new("q1", &t, cfg, init, device)?, EquiQHead::new("q2", &t, cfg, init, device)?))
}

/// Both heads on the encoder output with the lifted action appended.
fn equi_twin_forward(q1: &EquiQHead, q2: &EquiQHead, enc_out: Tensor<4>, action: Tensor<2>) -> (Tensor<2>, Tensor<2>) {
    let x = concat(vec![enc_out, lift_action(action)]);
    (q1.forward(x.clone()), q2.forward(x))
}

impl EquiCritic {
    /// Build with weights from `init`.
    pub fn new(cfg: &NetConfig, init: &Init, device: &Device) -> Result<Self, NetError> {
        let enc = EquiEncoder::new("enc", Group::dihedral(4), cfg, init, device)?;
        let (q1, q2) = equi_twin_heads(cfg, init, device)?;
        Ok(EquiCritic { enc, q1, q2 })
    }
}

impl Critic for EquiCritic {
    fn forward(&self, obs: Tensor<4>, action: Tensor<2>) -> (Tensor<2>, Tensor<2>) {
        equi_twin_forward(&self.q1, &self.q2, self.enc.forward(obs), action)
    }
}

/// The plain CNN encoder `SACEncoderFullyConv` (docs/paper.md §1.8): widths `n/4, n/2, n, 2n, 2n,
/// 4n, 4n` (paper n = 64: 16 … 256).
#[derive(Module, Debug)]
pub struct CnnEncoder {
    /// Layers 1–7.
    pub convs: Vec<Conv>,
    pools: Vec<bool>,
}

impl CnnEncoder {
    fn new(path: &str, cfg: &NetConfig, widths: [usize; 7], init: &Init, device: &Device) -> Result<Self, NetError> {
        let layers = cfg.kept(paper_layers(widths))?;
        let (convs, _) = plain_convs(&format!("{path}.convs."), cfg, &layers, init, device);
        Ok(CnnEncoder { convs, pools: pool_flags(&layers) })
    }

    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let mut x = x;
        for (conv, &pool) in self.convs.iter().zip(&self.pools) {
            x = conv.forward_relu(x);
            if pool {
                x = max_pool2(x);
            }
        }
        x
    }
}

fn cnn_widths(n: usize) -> [usize; 7] {
    [n / 4, n / 2, n, 2 * n, 2 * n, 4 * n, 4 * n]
}

/// CNN SAC actor `SACGaussianPolicyFullyConv`: encoder + 1×1 conv to 10 channels
/// (mean = 0..5, log_std = 5..10).
#[derive(Module, Debug)]
pub struct CnnActor {
    /// Encoder.
    pub enc: CnnEncoder,
    /// 1×1 head.
    pub head: Conv,
}

impl CnnActor {
    /// Build with weights from `init`.
    pub fn new(cfg: &NetConfig, init: &Init, device: &Device) -> Result<Self, NetError> {
        let w = cnn_widths(cfg.hidden);
        Ok(CnnActor {
            enc: CnnEncoder::new("enc", cfg, w, init, device)?,
            head: Conv::new("head", w[6], 2 * ACTION_DIM, 1, 0, cfg.numerics, init, device),
        })
    }
}

impl Actor for CnnActor {
    fn forward(&self, obs: Tensor<4>) -> (Tensor<2>, Tensor<2>) {
        let y = self.head.forward(self.enc.forward(obs));
        let [b, c, _, _] = y.dims();
        let y: Tensor<2> = y.reshape([b, c]);
        (y.clone().narrow(1, 0, ACTION_DIM), y.narrow(1, ACTION_DIM, ACTION_DIM).clamp(LOG_STD_MIN, LOG_STD_MAX))
    }
}

/// One plain Q head: 1×1 conv (enc + 5 → width) → ReLU → 1×1 conv (width → 1).
#[derive(Module, Debug)]
pub struct CnnQHead {
    /// First 1×1 conv.
    pub conv1: Conv,
    /// Second 1×1 conv.
    pub conv2: Conv,
}

impl CnnQHead {
    fn forward(&self, x: Tensor<4>) -> Tensor<2> {
        let q = self.conv2.forward(self.conv1.forward_relu(x));
        let [b, _, _, _] = q.dims();
        q.reshape([b, 1])
    }
}

/// CNN SAC twin critic `SACCriticFullyConv`.
#[derive(Module, Debug)]
pub struct CnnCritic {
    /// Encoder.
    pub enc: CnnEncoder,
    /// Q1 head.
    pub q1: CnnQHead,
    /// Q2 head.
    pub q2: CnnQHead,
}

impl CnnCritic {
    /// Build with weights from `init`.
    pub fn new(cfg: &NetConfig, init: &Init, device: &Device) -> Result<Self, NetError> {
        let w = cnn_widths(cfg.hidden);
        let head = |name: &str| CnnQHead {
            conv1: Conv::new(&format!("{name}.conv1"), w[6] + ACTION_DIM, w[6], 1, 0, cfg.numerics, init, device),
            conv2: Conv::new(&format!("{name}.conv2"), w[6], 1, 1, 0, cfg.numerics, init, device),
        };
        Ok(CnnCritic { enc: CnnEncoder::new("enc", cfg, w, init, device)?, q1: head("q1"), q2: head("q2") })
    }
}

impl Critic for CnnCritic {
    fn forward(&self, obs: Tensor<4>, action: Tensor<2>) -> (Tensor<2>, Tensor<2>) {
        let [b, a] = action.dims();
        let x = Tensor::cat(vec![self.enc.forward(obs), action.reshape([b, a, 1, 1])], 1);
        (self.q1.forward(x.clone()), self.q2.forward(x))
    }
}

/// SEN fc2 encoder `SACEncoderSimFC2` (docs/paper.md §1.9): convs of widths `n/2, n, 2n, 4n`
/// (3×3, pad 1, pooled down to 8×8), `2n` at 8×8, flatten, Linear → `8n` + ReLU, declared as
/// `n` regular D4 fields at 1×1 (paper n = 32).
#[derive(Module, Debug)]
pub struct SenEncoder {
    /// The 5 convs.
    pub convs: Vec<Conv>,
    /// The linear layer.
    pub fc: Linear,
    pools: Vec<bool>,
}

impl SenEncoder {
    fn new(path: &str, cfg: &NetConfig, init: &Init, device: &Device) -> Result<Self, NetError> {
        let n = cfg.hidden;
        let w = [n / 2, n, 2 * n, 4 * n, 2 * n];
        let layers =
            cfg.kept([(w[0], 1, true), (w[1], 1, true), (w[2], 1, true), (w[3], 1, true), (w[4], 1, false)])?;
        let (convs, _) = plain_convs(&format!("{path}.convs."), cfg, &layers, init, device);
        let fc = Linear::new(&format!("{path}.fc"), 2 * n * 64, 8 * n, init, device);
        Ok(SenEncoder { convs, fc, pools: pool_flags(&layers) })
    }

    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let mut x = x;
        for (conv, &pool) in self.convs.iter().zip(&self.pools) {
            x = conv.forward_relu(x);
            if pool {
                x = max_pool2(x);
            }
        }
        let [b, c, h, w] = x.dims();
        let y = relu(self.fc.forward(x.reshape([b, c * h * w])));
        let [_, f] = y.dims();
        y.reshape([b, f, 1, 1])
    }
}

/// SEN fc2 actor: [`SenEncoder`] + the Equi actor head (`hidden × regular → actor_out_type`).
#[derive(Module, Debug)]
pub struct SenActor {
    /// Non-equivariant encoder.
    pub enc: SenEncoder,
    /// Equivariant 1×1 head.
    pub head: EquivariantConv,
}

impl SenActor {
    /// Build with weights from `init` (paper: [`NetConfig::paper_sen`]).
    pub fn new(cfg: &NetConfig, init: &Init, device: &Device) -> Result<Self, NetError> {
        let g = Group::dihedral(4);
        Ok(SenActor { enc: SenEncoder::new("enc", cfg, init, device)?, head: actor_head(g, cfg, init, device)? })
    }
}

impl Actor for SenActor {
    fn forward(&self, obs: Tensor<4>) -> (Tensor<2>, Tensor<2>) {
        let y = self.head.forward(self.enc.forward(obs));
        let [b, c, _, _] = y.dims();
        decode_equi(y.reshape([b, c]))
    }
}

/// SEN fc2 twin critic: [`SenEncoder`] + two Equi Q heads.
#[derive(Module, Debug)]
pub struct SenCritic {
    /// Non-equivariant encoder.
    pub enc: SenEncoder,
    /// Q1 head.
    pub q1: EquiQHead,
    /// Q2 head.
    pub q2: EquiQHead,
}

impl SenCritic {
    /// Build with weights from `init` (paper: [`NetConfig::paper_sen`]).
    pub fn new(cfg: &NetConfig, init: &Init, device: &Device) -> Result<Self, NetError> {
        let enc = SenEncoder::new("enc", cfg, init, device)?;
        let (q1, q2) = equi_twin_heads(cfg, init, device)?;
        Ok(SenCritic { enc, q1, q2 })
    }
}

impl Critic for SenCritic {
    fn forward(&self, obs: Tensor<4>, action: Tensor<2>) -> (Tensor<2>, Tensor<2>) {
        equi_twin_forward(&self.q1, &self.q2, self.enc.forward(obs), action)
    }
}

/// C8 rotation-estimation classifier (docs/paper.md §4 "Equi"): [`EquiEncoder`] over C8 + 1×1
/// `hidden × regular → 8 × trivial` (class logits, invariant).
#[derive(Module, Debug)]
pub struct RotEquiNet {
    /// Encoder (group C8).
    pub enc: EquiEncoder,
    /// 1×1 head.
    pub head: EquivariantConv,
}

impl RotEquiNet {
    /// Build with weights from `init` (paper: [`NetConfig::paper_rotation`]).
    pub fn new(cfg: &NetConfig, init: &Init, device: &Device) -> Result<Self, NetError> {
        let g = Group::cyclic(8);
        Ok(RotEquiNet {
            enc: EquiEncoder::new("enc", g, cfg, init, device)?,
            head: EquivariantConv::new(
                "head",
                &FieldType::regular(g, cfg.hidden),
                &FieldType::trivial(g, 8),
                1,
                0,
                cfg.numerics,
                init,
                device,
            )?,
        })
    }

    /// `[B, in_channels, S, S] → logits [B, 8]`.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<2> {
        let y = self.head.forward(self.enc.forward(x));
        let [b, c, _, _] = y.dims();
        y.reshape([b, c])
    }
}

/// Rotation-estimation CNN (`cnn_sim`, docs/paper.md §4): widths `n/4, n/2, n, 2n` (pooled to 8×8),
/// `4n` pad 1, `4n` pad 0, pool, `2n` pad 0, 1×1 → 8 logits (paper n = 64).
#[derive(Module, Debug)]
pub struct RotCnnNet {
    /// The 7 3×3 convs.
    pub convs: Vec<Conv>,
    /// 1×1 head.
    pub head: Conv,
    pools: Vec<bool>,
}

impl RotCnnNet {
    /// Build with weights from `init` (paper: [`NetConfig::paper_rotation`]).
    pub fn new(cfg: &NetConfig, init: &Init, device: &Device) -> Result<Self, NetError> {
        let n = cfg.hidden;
        let layers = cfg.kept(paper_layers([n / 4, n / 2, n, 2 * n, 4 * n, 4 * n, 2 * n]))?;
        let (convs, cin) = plain_convs("convs.", cfg, &layers, init, device);
        Ok(RotCnnNet {
            convs,
            head: Conv::new("head", cin, 8, 1, 0, cfg.numerics, init, device),
            pools: pool_flags(&layers),
        })
    }

    /// `[B, in_channels, S, S] → logits [B, 8]`.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<2> {
        let mut x = x;
        for (conv, &pool) in self.convs.iter().zip(&self.pools) {
            x = conv.forward_relu(x);
            if pool {
                x = max_pool2(x);
            }
        }
        let y = self.head.forward(x);
        let [b, c, _, _] = y.dims();
        y.reshape([b, c])
    }
}

/// SAC's squashed Gaussian sample (docs/paper.md §1.4): with noise `eps ~ N(0, 1)` `[B, 5]`,
/// `x = mean + std·eps`, `a = tanh(x)`, `log π = Σ_i [log N(x_i; mean_i, std_i) − log(1 − a_i² + 1e-6)]`.
/// Returns `(a, log π [B, 1], tanh(mean))`.
pub fn gaussian_sample(mean: Tensor<2>, log_std: Tensor<2>, eps: Tensor<2>) -> (Tensor<2>, Tensor<2>, Tensor<2>) {
    let std = log_std.clone().exp();
    let x = mean.clone() + std * eps.clone();
    let a = x.tanh();
    let half_log_2pi = 0.5 * (2.0 * std::f32::consts::PI).ln();
    let log_n = eps.powf_scalar(2.0).mul_scalar(-0.5) - log_std - half_log_2pi;
    let corr = (a.clone().powf_scalar(2.0).neg() + 1.0 + 1e-6).log();
    let log_pi = (log_n - corr).sum_dim(1);
    (a, log_pi, mean.tanh())
}

/// The FERM encoder's conv layers at 128 px as `(width, pad, pool after)` (`CURLSACEncoder3`,
/// docs/paper.md §1.10): 3×3 padded convs `n/4, n/2, n, 2n` each followed by a 2×2 pool
/// (128 → 8), then `4n` padded, without a pool (paper n = 64: 16 … 256, an 8×8 map).
fn ferm_layers(n: usize) -> [(usize, usize, bool); 5] {
    [(n / 4, 1, true), (n / 2, 1, true), (n, 1, true), (2 * n, 1, true), (4 * n, 1, false)]
}

/// The output size of the FERM encoder (its `z_dim`, the paper's 50).
pub const FERM_Z_DIM: usize = 50;

/// Width of the FERM actor's and critic's MLPs: `8n` (the paper's 512 at n = 64).
pub fn ferm_mlp_width(hidden: usize) -> usize {
    8 * hidden
}

/// The conv part of the FERM encoder (the part the actor shares with the critic).
#[derive(Module, Debug)]
pub struct FermConvs {
    /// 3×3 convs with ReLU.
    pub convs: Vec<Conv>,
    pools: Vec<bool>,
}

impl FermConvs {
    fn new(path: &str, cfg: &NetConfig, init: &Init, device: &Device) -> Result<(Self, usize), NetError> {
        let layers = cfg.kept(ferm_layers(cfg.hidden))?;
        let (convs, width) = plain_convs(&format!("{path}.convs."), cfg, &layers, init, device);
        Ok((FermConvs { convs, pools: pool_flags(&layers) }, width * 8 * 8))
    }

    /// `[B, C, S, S] → [B, 4n·8·8]` (flattened).
    pub fn forward(&self, x: Tensor<4>) -> Tensor<2> {
        let mut x = x;
        for (conv, &pool) in self.convs.iter().zip(&self.pools) {
            x = conv.forward_relu(x);
            if pool {
                x = max_pool2(x);
            }
        }
        x.flatten(1, 3)
    }
}

/// Layer normalisation over the last dimension, `ε = 1e-5`, with a learnt scale (1 at start) and
/// shift (0), as PyTorch's `nn.LayerNorm`.
#[derive(Module, Debug)]
pub struct LayerNorm {
    /// Scale.
    pub gamma: burn::module::Param<Tensor<1>>,
    /// Shift.
    pub beta: burn::module::Param<Tensor<1>>,
}

impl LayerNorm {
    /// Over `dim` features.
    pub fn new(dim: usize, device: &Device) -> Self {
        LayerNorm {
            gamma: burn::module::Param::from_tensor(Tensor::ones([dim], device)),
            beta: burn::module::Param::from_tensor(Tensor::zeros([dim], device)),
        }
    }

    /// `[B, D] → [B, D]`.
    pub fn forward(&self, x: Tensor<2>) -> Tensor<2> {
        let mean = x.clone().mean_dim(1);
        let centred = x - mean;
        let var = centred.clone().powf_scalar(2.0).mean_dim(1);
        let normed = centred / (var + 1e-5).sqrt();
        normed * self.gamma.val().unsqueeze::<2>() + self.beta.val().unsqueeze::<2>()
    }
}

/// The FERM encoder head on the flattened convs: Linear → [`FERM_Z_DIM`], LayerNorm.
#[derive(Module, Debug)]
pub struct FermHead {
    /// Linear to `z_dim`.
    pub fc: Linear,
    /// LayerNorm.
    pub ln: LayerNorm,
}

impl FermHead {
    fn new(path: &str, din: usize, init: &Init, device: &Device) -> Self {
        FermHead {
            fc: Linear::new(&format!("{path}.fc"), din, FERM_Z_DIM, init, device),
            ln: LayerNorm::new(FERM_Z_DIM, device),
        }
    }

    /// `[B, D] → [B, z_dim]`.
    pub fn forward(&self, h: Tensor<2>) -> Tensor<2> {
        self.ln.forward(self.fc.forward(h))
    }
}

/// A 3-layer MLP `din → w → w → dout` with ReLU between.
#[derive(Module, Debug)]
pub struct Mlp {
    /// The three linear layers.
    pub layers: Vec<Linear>,
}

impl Mlp {
    fn new(path: &str, din: usize, w: usize, dout: usize, init: &Init, device: &Device) -> Self {
        let dims = [(din, w), (w, w), (w, dout)];
        Mlp {
            layers: dims
                .iter()
                .enumerate()
                .map(|(i, &(a, b))| Linear::new(&format!("{path}.{i}"), a, b, init, device))
                .collect(),
        }
    }

    /// `[B, din] → [B, dout]`.
    pub fn forward(&self, x: Tensor<2>) -> Tensor<2> {
        let last = self.layers.len() - 1;
        self.layers.iter().enumerate().fold(x, |x, (i, l)| if i < last { relu(l.forward(x)) } else { l.forward(x) })
    }
}

/// FERM's encoder `CURLSACEncoder3`: the convs, then Linear → [`FERM_Z_DIM`] and LayerNorm.
#[derive(Module, Debug)]
pub struct FermEncoder {
    /// The convs (the part the actor shares with the critic).
    pub convs: FermConvs,
    /// Linear + LayerNorm.
    pub head: FermHead,
}

impl FermEncoder {
    /// Build with weights from `init`, parameter paths below `path`.
    pub fn new(path: &str, cfg: &NetConfig, init: &Init, device: &Device) -> Result<Self, NetError> {
        let (convs, flat) = FermConvs::new(&format!("{path}.convs"), cfg, init, device)?;
        Ok(FermEncoder { convs, head: FermHead::new(&format!("{path}.head"), flat, init, device) })
    }

    /// `[B, C, S, S] → [B, z_dim]`; with `detach_convs` no gradient reaches the convs (CURL's
    /// `detach_encoder`).
    pub fn forward(&self, obs: Tensor<4>, detach_convs: bool) -> Tensor<2> {
        let h = self.convs.forward(obs);
        self.head.forward(if detach_convs { h.detach() } else { h })
    }
}

/// FERM's actor (docs/paper.md §1.10): an encoder whose convs are the critic's (the trainer copies
/// them in, and the actor's loss does not reach them) with its own Linear + LayerNorm, and separate
/// mean and log-std MLPs `50 → 8n → 8n → 5`.
#[derive(Module, Debug)]
pub struct FermActor {
    /// Encoder (convs copied from the critic's).
    pub enc: FermEncoder,
    /// Mean MLP.
    pub mean: Mlp,
    /// Log-std MLP.
    pub log_std: Mlp,
}

impl FermActor {
    /// Build with weights from `init`.
    pub fn new(cfg: &NetConfig, init: &Init, device: &Device) -> Result<Self, NetError> {
        let w = ferm_mlp_width(cfg.hidden);
        Ok(FermActor {
            enc: FermEncoder::new("enc", cfg, init, device)?,
            mean: Mlp::new("mean", FERM_Z_DIM, w, ACTION_DIM, init, device),
            log_std: Mlp::new("log_std", FERM_Z_DIM, w, ACTION_DIM, init, device),
        })
    }
}

impl Actor for FermActor {
    /// The conv features are detached: the actor's loss trains its own head and MLPs only.
    fn forward(&self, obs: Tensor<4>) -> (Tensor<2>, Tensor<2>) {
        let z = self.enc.forward(obs, true);
        (self.mean.forward(z.clone()), self.log_std.forward(z).clamp(LOG_STD_MIN, LOG_STD_MAX))
    }
}

/// FERM's critic: the encoder and twin Q MLPs `50 + 5 → 8n → 8n → 1`.
#[derive(Module, Debug)]
pub struct FermCritic {
    /// Encoder.
    pub enc: FermEncoder,
    /// Q1 MLP.
    pub q1: Mlp,
    /// Q2 MLP.
    pub q2: Mlp,
}

impl FermCritic {
    /// Build with weights from `init`.
    pub fn new(cfg: &NetConfig, init: &Init, device: &Device) -> Result<Self, NetError> {
        let w = ferm_mlp_width(cfg.hidden);
        Ok(FermCritic {
            enc: FermEncoder::new("enc", cfg, init, device)?,
            q1: Mlp::new("q1", FERM_Z_DIM + 5, w, 1, init, device),
            q2: Mlp::new("q2", FERM_Z_DIM + 5, w, 1, init, device),
        })
    }

    /// The encoder's features `z` `[B, 50]` (CURL's anchor and positive).
    pub fn encode(&self, obs: Tensor<4>) -> Tensor<2> {
        self.enc.forward(obs, false)
    }
}

impl Critic for FermCritic {
    fn forward(&self, obs: Tensor<4>, action: Tensor<2>) -> (Tensor<2>, Tensor<2>) {
        let x = Tensor::cat(vec![self.encode(obs), action], 1);
        (self.q1.forward(x.clone()), self.q2.forward(x))
    }
}

/// CURL's bilinear similarity `W` `[z, z]` (docs/paper.md §1.10), initialised uniform in ±1/√z.
#[derive(Module, Debug)]
pub struct CurlBilinear {
    /// `W`.
    pub w: burn::module::Param<Tensor<2>>,
}

impl CurlBilinear {
    /// Build with weights from `init`.
    pub fn new(init: &Init, device: &Device) -> Self {
        let z = FERM_Z_DIM;
        let w = init.uniform("curl.w", z * z, 1.0 / (z as f64).sqrt());
        CurlBilinear {
            w: burn::module::Param::from_tensor(Tensor::from_data(burn::tensor::TensorData::new(w, [z, z]), device)),
        }
    }

    /// CURL's contrastive loss: logits `z_a · W · z_posᵀ` `[B, B]` with each row's maximum
    /// subtracted (a detached constant, for stability), cross-entropy against the diagonal (each
    /// anchor's positive is its own row's).
    pub fn loss(&self, z_anchor: Tensor<2>, z_pos: Tensor<2>) -> Tensor<1> {
        let logits = z_anchor.matmul(self.w.val().matmul(z_pos.transpose()));
        let [b, _] = logits.dims();
        let logits = logits.clone() - logits.detach().max_dim(1);
        let log_p = burn::tensor::activation::log_softmax(logits, 1);
        let eye = Tensor::<2>::eye(b, &log_p.device());
        (log_p * eye).sum().div_scalar(b as f64).neg()
    }
}
