//! Equivariant layers on burn: [`EquivariantConv`] (e2cnn's `R2Conv`), [`relu`],
//! [`max_pool2`] (e2cnn's `PointwiseMaxPool`), [`group_pool`] (`GroupPooling`), [`concat()`]
//! (field-type direct sum), and [`transform`], the group action on feature maps used by the
//! equivariance tests and the diagnostic.
//!
//! Feature maps are `[batch, channels, height, width]` tensors whose channels are laid out by a
//! [`FieldType`]. The convolution's free weights times the solved basis give the dense kernel
//! inside the autodiff graph; our convolution kernels ([`crate::kernels`]) do the rest.
//!
//! Limitations: stride 1 only; kernel sizes 1 and 3 (see [`crate::basis`]); pointwise ReLU and
//! max-pooling are only equivariant for permutation representations (trivial, regular,
//! quotient) and are refused otherwise; exact image equivariance needs even sizes before each
//! 2×2 pool (docs/paper.md §1.4) and group elements that act on the pixel grid.

use crate::basis::{BasisError, kernel_basis};
use crate::group::Element;
use crate::init::Init;
use crate::kernels::MatmulPrecision;
use crate::repr::FieldType;
use burn::module::{Module, Param};
use burn::tensor::module::conv2d;
use burn::tensor::ops::ConvOptions;
use burn::tensor::{Device, Tensor, TensorData};
use thiserror::Error;

/// Errors building layers.
#[derive(Debug, Error)]
pub enum LayerError {
    /// The kernel basis could not be built.
    #[error("layer {path}: {cause}")]
    Basis {
        /// Parameter path of the layer.
        path: String,
        /// Cause.
        cause: BasisError,
    },
    /// Input and output field types belong to different groups.
    #[error("layer {path}: input type {input} and output type {output} have different groups")]
    GroupMismatch {
        /// Parameter path of the layer.
        path: String,
        /// Input field type.
        input: String,
        /// Output field type.
        output: String,
    },
}

/// How convolutions are computed (all give the same result up to float rounding).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ConvAlgo {
    /// Our kernels ([`crate::kernels`]): im2col + large GEMMs forward and backward, bias and
    /// ReLU fused, on `flex`; burn's `conv2d` on other backends. The default.
    #[default]
    Kernels,
    /// burn's `conv2d` (im2col + gemm forward; its backward is a transposed conv and a conv
    /// with an H×W kernel for the weight gradient): the reference the kernels are tested against.
    Burn,
    /// [`conv2d_unfold`]: 9 shifted slices + one batched matmul; autodiff through matmuls.
    /// NOTE: measured about 2× slower than `Burn` for a training step on flex (the slices, the
    /// stack and their backward are memory-bound), also in a channel-major variant with one
    /// large gemm; kept as a cross-check and for backends with faster slicing.
    Unfold,
}

/// How a layer computes its convolutions. Chosen in the network's config
/// ([`crate::nets::NetConfig::numerics`]) and kept by each layer, so that networks of one process
/// can differ (the tests compare the algorithms on the same weights; the learner sets the
/// precision from `agent.matmul`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Numerics {
    /// The convolution algorithm.
    pub conv: ConvAlgo,
    /// The precision of [`ConvAlgo::Kernels`]'s GEMMs (the other algorithms run in `f32`).
    pub matmul: MatmulPrecision,
}

impl Numerics {
    /// Our kernels in `f32` (the default).
    pub const DEFAULT: Numerics = Numerics { conv: ConvAlgo::Kernels, matmul: MatmulPrecision::F32 };

    /// Our kernels with their GEMMs in `matmul`.
    pub const fn kernels(matmul: MatmulPrecision) -> Self {
        Numerics { conv: ConvAlgo::Kernels, matmul }
    }

    /// `algo` with `f32` GEMMs.
    pub const fn algo(conv: ConvAlgo) -> Self {
        Numerics { conv, matmul: MatmulPrecision::F32 }
    }
}

/// Stride-1 convolution as `numerics` says, followed by ReLU when `relu` (fused into the kernels'
/// passes with [`ConvAlgo::Kernels`]).
pub fn conv2d_stride1(
    x: Tensor<4>,
    kernel: Tensor<4>,
    bias: Tensor<1>,
    padding: usize,
    relu: bool,
    numerics: Numerics,
) -> Tensor<4> {
    let y = match numerics.conv {
        ConvAlgo::Kernels => return crate::kernels::conv2d_fused(x, kernel, bias, padding, relu, numerics.matmul),
        ConvAlgo::Burn => conv2d(x, kernel, Some(bias), ConvOptions::new([1, 1], [padding, padding], [1, 1], 1)),
        ConvAlgo::Unfold => conv2d_unfold(x, kernel, Some(bias), padding),
    };
    if relu { self::relu(y) } else { y }
}

/// Structure of one (output run, input run) block of an equivariant conv.
#[derive(Clone, Debug)]
struct Block {
    out_fields: usize,
    in_fields: usize,
    dim_out: usize,
    dim_in: usize,
    /// Number of basis elements (0: the block is identically zero).
    len: usize,
}

/// Equivariant convolution `in_type → out_type` (e2cnn `R2Conv`), stride 1, square kernel of
/// size 1 or 3, zero padding `padding`.
///
/// - Input field type: `in_type` (any direct sum of representations of the group).
/// - Output field type: `out_type`.
/// - Parameters: per block of consecutive identical (output rep, input rep) fields, a weight
///   `[out_fields, in_fields, basis_len]`; per output run containing the trivial irrep, a bias
///   `[out_fields, multiplicity]` (bias only on trivial components, docs/paper.md §1.6).
#[derive(Module, Debug)]
pub struct EquivariantConv {
    /// Free weights, one per non-zero block, in block order (output runs outer, input runs inner).
    pub weight: Vec<Param<Tensor<3>>>,
    /// Biases, one per output run that contains the trivial irrep.
    pub bias: Vec<Param<Tensor<2>>>,
    /// Basis of each non-zero block, `[len, dim_out·dim_in·k·k]` (constant).
    basis: Vec<Tensor<2>>,
    /// Embedding of each bias run into channels, `[multiplicity, dim]` (constant).
    bias_embed: Vec<Tensor<2>>,
    /// Dense kernel cached for inference (see [`EquivariantConv::cache_kernel`]).
    cached: Option<Tensor<4>>,
    #[module(skip)]
    plan: Vec<Vec<Block>>,
    /// For each output run: (fields, dim, has bias).
    #[module(skip)]
    out_runs: Vec<(usize, usize, bool)>,
    #[module(skip)]
    numerics: Numerics,
    kernel_size: usize,
    padding: usize,
    in_channels: usize,
    out_channels: usize,
}

impl EquivariantConv {
    /// Build the layer: solve the kernel bases (once) and draw He-like initial weights from
    /// `init` for parameter path `path` (e.g. `actor.enc.conv1`); it convolves as `numerics` says.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        path: &str,
        in_type: &FieldType,
        out_type: &FieldType,
        kernel_size: usize,
        padding: usize,
        numerics: Numerics,
        init: &Init,
        device: &Device,
    ) -> Result<Self, LayerError> {
        if in_type.group() != out_type.group() {
            return Err(LayerError::GroupMismatch {
                path: path.into(),
                input: in_type.describe(),
                output: out_type.describe(),
            });
        }
        let in_runs = in_type.runs();
        let mut weight = Vec::new();
        let mut basis = Vec::new();
        let mut plan = Vec::new();
        let mut bias = Vec::new();
        let mut bias_embed = Vec::new();
        let mut out_runs = Vec::new();
        for ro in out_type.runs() {
            let mut row = Vec::new();
            let mut solved = Vec::new();
            for ri in &in_runs {
                let b = kernel_basis(&ri.rep, &ro.rep, kernel_size)
                    .map_err(|cause| LayerError::Basis { path: path.into(), cause })?;
                row.push(Block {
                    out_fields: ro.count,
                    in_fields: ri.count,
                    dim_out: b.dim_out,
                    dim_in: b.dim_in,
                    len: b.len,
                });
                solved.push(b);
            }
            // He-like: each dense output channel gets squared norm ≈ 2 in expectation, divided
            // by the kernel width.
            // NOTE: He's rule assumes uncorrelated inputs; camera images and feature maps are
            // smooth, and the band-limited basis (ring harmonics) sums neighbouring pixels with one
            // sign, so plain He grew the activations ~2× per 3×3 layer (head outputs ~90 on rendered
            // frames, saturating the actor's tanh so it could not learn); dividing by k² shrank
            // them ~2× per layer. Dividing the squared norm by k keeps the pre-activation RMS
            // within a small factor of the input's through all 8 layers (measured with
            // `cargo run -p equiarm_train --example init_scale`).
            let total: usize = row.iter().map(|b| b.in_fields * b.len).sum();
            let width = kernel_size as f64;
            let std = if total > 0 { (2.0 * ro.rep.dim() as f64 / total as f64 / width).sqrt() } else { 0.0 };
            for (b, s) in row.iter().zip(solved) {
                if b.len == 0 {
                    continue;
                }
                let name = format!("{path}.weight.{}", weight.len());
                let vals = init.normal(&name, b.out_fields * b.in_fields * b.len, std);
                weight.push(Param::from_tensor(Tensor::from_data(
                    TensorData::new(vals, [b.out_fields, b.in_fields, b.len]),
                    device,
                )));
                let data: Vec<f32> = s.data.iter().map(|&x| x as f32).collect();
                basis.push(Tensor::from_data(TensorData::new(data, [s.len, s.element_len()]), device));
            }
            plan.push(row);
            let (m, q) = ro.rep.invariant_basis();
            if m > 0 {
                bias.push(Param::from_tensor(Tensor::zeros([ro.count, m], device)));
                // q is d×m (columns orthonormal); store its transpose m×d, scaled so that an
                // invariant vector of all-equal entries gets the bias value itself.
                let d = ro.rep.dim();
                let mut qt = vec![0f32; m * d];
                for i in 0..d {
                    for j in 0..m {
                        qt[j * d + i] = q[i * m + j] as f32;
                    }
                }
                bias_embed.push(Tensor::from_data(TensorData::new(qt, [m, d]), device));
            }
            out_runs.push((ro.count, ro.rep.dim(), m > 0));
        }
        Ok(EquivariantConv {
            weight,
            bias,
            basis,
            bias_embed,
            cached: None,
            plan,
            out_runs,
            numerics,
            kernel_size,
            padding,
            in_channels: in_type.size(),
            out_channels: out_type.size(),
        })
    }

    /// The dense kernel `[out_channels, in_channels, k, k]` expanded from the free weights
    /// (differentiable with respect to them).
    pub fn kernel(&self) -> Tensor<4> {
        let k = self.kernel_size;
        let device = self.basis.first().map(|b| b.device()).or_else(|| self.bias_embed.first().map(|b| b.device()));
        let mut wi = 0;
        let mut rows = Vec::new();
        for row in &self.plan {
            let mut parts = Vec::new();
            for b in row {
                let (oc, ic) = (b.out_fields * b.dim_out, b.in_fields * b.dim_in);
                if b.len == 0 {
                    parts.push(Tensor::zeros([oc, ic, k, k], device.as_ref().expect("layer has tensors")));
                    continue;
                }
                let w = self.weight[wi].val().reshape([b.out_fields * b.in_fields, b.len]);
                let dense = w.matmul(self.basis[wi].clone()); // [Fo·Fi, do·di·k·k]
                wi += 1;
                let dense: Tensor<4> = dense.reshape([b.out_fields, b.in_fields, b.dim_out, b.dim_in * k * k]);
                let dense = dense.swap_dims(1, 2); // [Fo, do, Fi, di·k·k]
                parts.push(dense.reshape([oc, ic, k, k]));
            }
            rows.push(if parts.len() == 1 { parts.pop().unwrap() } else { Tensor::cat(parts, 1) });
        }
        if rows.len() == 1 { rows.pop().unwrap() } else { Tensor::cat(rows, 0) }
    }

    /// The dense bias `[out_channels]` (zero on non-trivial components).
    pub fn dense_bias(&self, device: &Device) -> Tensor<1> {
        let mut parts = Vec::new();
        let mut bi = 0;
        for &(fields, dim, has) in &self.out_runs {
            if has {
                let b = self.bias[bi].val().matmul(self.bias_embed[bi].clone()); // [fields, dim]
                bi += 1;
                parts.push(b.reshape([fields * dim]));
            } else {
                parts.push(Tensor::zeros([fields * dim], device));
            }
        }
        if parts.len() == 1 { parts.pop().unwrap() } else { Tensor::cat(parts, 0) }
    }

    /// Expand and store the dense kernel for inference: later forwards skip the expansion while
    /// the weights are not tracked by autodiff. Call it again after changing the weights; a
    /// module whose weights require gradients always expands afresh.
    pub fn cache_kernel(mut self) -> Self {
        self.cached = Some(self.kernel());
        self
    }

    /// Whether [`EquivariantConv::forward`] currently uses the cached dense kernel (a cache is
    /// present and the weights are not tracked by autodiff).
    pub fn uses_cached_kernel(&self) -> bool {
        self.cached.is_some() && !self.weight.first().is_some_and(|w| w.val().is_require_grad())
    }

    /// Forward pass: `[B, in_channels, H, W] → [B, out_channels, H + 2p − k + 1, W + 2p − k + 1]`.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        self.forward_act(x, false)
    }

    /// [`EquivariantConv::forward`] followed by [`relu`] (fused into the convolution's passes).
    pub fn forward_relu(&self, x: Tensor<4>) -> Tensor<4> {
        self.forward_act(x, true)
    }

    fn forward_act(&self, x: Tensor<4>, relu: bool) -> Tensor<4> {
        let kernel = match &self.cached {
            Some(k) if self.uses_cached_kernel() => k.clone(),
            _ => self.kernel(),
        };
        let bias = self.dense_bias(&x.device());
        conv2d_stride1(x, kernel, bias, self.padding, relu, self.numerics)
    }

    /// How it convolves.
    pub fn numerics(&self) -> Numerics {
        self.numerics
    }

    /// Number of input channels.
    pub fn in_channels(&self) -> usize {
        self.in_channels
    }

    /// Number of output channels.
    pub fn out_channels(&self) -> usize {
        self.out_channels
    }
}

/// Pointwise ReLU. Input and output field type: the same permutation-representation type
/// (trivial / regular / quotient fields), for which it is equivariant.
pub fn relu<const D: usize>(x: Tensor<D>) -> Tensor<D> {
    burn::tensor::activation::relu(x)
}

/// 2×2 max-pool with stride 2, per channel (e2cnn `PointwiseMaxPool`): our kernel on `flex`, burn's
/// `max_pool2d` elsewhere ([`crate::kernels::max_pool2x2`]). Field type unchanged; equivariant for
/// permutation representations and even spatial sizes.
pub fn max_pool2(x: Tensor<4>) -> Tensor<4> {
    crate::kernels::max_pool2x2(x)
}

/// Group pooling (e2cnn `GroupPooling`): max over the channels of each field. Input: `fields`
/// regular fields of dimension `dim`; output: `fields` trivial fields (invariant).
pub fn group_pool(x: Tensor<4>, fields: usize, dim: usize) -> Tensor<4> {
    let [b, c, h, w] = x.dims();
    assert_eq!(c, fields * dim, "group_pool: {c} channels is not {fields}×{dim}");
    let x: Tensor<5> = x.reshape([b, fields, dim, h, w]);
    x.max_dim(2).reshape([b, fields, h, w])
}

/// Field-type concatenation (direct sum) along channels: the output type is
/// `types[0] ⊕ types[1] ⊕ …` of the inputs.
pub fn concat(xs: Vec<Tensor<4>>) -> Tensor<4> {
    Tensor::cat(xs, 1)
}

/// The group action on a feature map of type `ft`: `(g·F)(p) = ρ(g) F(g⁻¹p)`, i.e. the image
/// is rotated / mirrored on the pixel grid and every field is multiplied by its representation.
/// Panics if `g` does not act on the pixel grid or the map is not square.
pub fn transform(x: Tensor<4>, ft: &FieldType, g: Element) -> Tensor<4> {
    let group = ft.group();
    let turns = group.quarter_turns(g).expect("element does not act on the pixel grid");
    let [b, c, h, w] = x.dims();
    assert_eq!(c, ft.size(), "transform: tensor has {c} channels, field type {}", ft.size());
    let mut y = x;
    if g.flip == 1 {
        y = y.flip([3]);
    }
    for _ in 0..turns {
        // rot90 counter-clockwise: new[i][j] = old[j][W−1−i]
        y = y.swap_dims(2, 3).flip([2]);
    }
    let [_, _, h2, w2] = y.dims();
    debug_assert_eq!((h2, w2), if turns % 2 == 1 { (w, h) } else { (h, w) });
    let m: Vec<f32> = ft.matrix(g).iter().map(|&v| v as f32).collect();
    let m: Tensor<2> = Tensor::from_data(TensorData::new(m, [c, c]), &y.device());
    let flat: Tensor<2> = y.permute([0, 2, 3, 1]).reshape([b * h2 * w2, c]);
    flat.matmul(m.transpose()).reshape([b, h2, w2, c]).permute([0, 3, 1, 2])
}

/// Stride-1 2-D convolution written as unfold (im2col by 9 shifted slices) + one batched matmul
/// on the backend's matmul, `[B, C, H, W] ⊛ [O, C, k, k] → [B, O, H', W']`. Its autodiff is
/// made of matmuls and slices, which on `flex` is cheaper than the generic conv backward (the
/// weight gradient becomes one large gemm instead of a convolution with an H×W kernel). Costs
/// k² times the input's memory for the unfolded copy. Same result as burn's `conv2d`.
pub fn conv2d_unfold(x: Tensor<4>, kernel: Tensor<4>, bias: Option<Tensor<1>>, padding: usize) -> Tensor<4> {
    use burn::tensor::ops::PadMode;
    let [b, c, h, w] = x.dims();
    let [o, ci, k, _] = kernel.dims();
    assert_eq!(c, ci, "conv2d_unfold: input has {c} channels, kernel expects {ci}");
    let p = padding;
    let (ho, wo) = (h + 2 * p + 1 - k, w + 2 * p + 1 - k);
    let xp = if p > 0 { x.pad((p, p, p, p), PadMode::Constant(0.0)) } else { x };
    let cols = if k == 1 {
        xp.reshape([b, c, ho * wo])
    } else {
        let mut slices = Vec::with_capacity(k * k);
        for dy in 0..k {
            for dx in 0..k {
                slices.push(xp.clone().slice([0..b, 0..c, dy..dy + ho, dx..dx + wo]));
            }
        }
        // [B, C, k², H', W'] → [B, C·k², H'·W'] (channel-major, then kernel row, column: the
        // layout of the kernel's [C, k, k])
        Tensor::stack::<5>(slices, 2).reshape([b, c * k * k, ho * wo])
    };
    let wmat: Tensor<3> = kernel.reshape([1, o, c * k * k]);
    let y = wmat.matmul(cols).reshape([b, o, ho, wo]);
    match bias {
        Some(bias) => y + bias.reshape([1, o, 1, 1]),
        None => y,
    }
}
