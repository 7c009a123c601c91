//! Our own convolution for the CPU backend (`flex`): a custom op of burn's backend-extension
//! mechanism with a hand-written backward, used by [`crate::layers::EquivariantConv`] and
//! [`crate::plain::Conv`] through [`crate::layers::conv2d_stride1`].
//!
//! - [`gemm_conv`]: forward, input gradient and weight gradient as large GEMMs (im2col, the
//!   `gemm` crate, bias and ReLU fused), parallel over the batch, deterministic at a given thread
//!   count.
//! - [`conv2d_fused`]: `act(conv2d(x, weight) + bias)` on tensors. On `flex` (with or without
//!   autodiff) it runs the kernels above; its backward computes only the gradients the autodiff
//!   graph asks for (none for an input that is not tracked, as the first layer's observation).
//!   On other backends it is burn's `conv2d` followed by `relu`.
//!
//! - [`pool`], [`max_pool2x2`]: 2×2 max-pooling, forward with the argmax and a backward that
//!   routes the gradient to it (burn's generic pooling was a seventh of an update).
//!
//! - [`amx`]: the GEMMs in bfloat16 on Intel AMX, when the layer's [`MatmulPrecision`] is
//!   [`MatmulPrecision::Bf16`] (the config's `agent.matmul`, carried by the network's config to each
//!   layer and by the op into its backward); `f32` through the `gemm` crate otherwise.
//!
//! Limitations: stride 1, square kernels, `f32` tensors only (the default float type; bf16 is
//! only the GEMMs' operand rounding).

pub mod amx;
pub mod gemm_conv;
pub mod pool;

use burn::backend::TensorMetadata;
use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::flex::FlexTensor;
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend, Dispatch, Flex, backend_extension};
use burn::tensor::module::conv2d;
use burn::tensor::ops::ConvOptions;
use burn::tensor::{DType, Device, Shape, Tensor, TensorData};
use gemm_conv::{ConvShape, Wanted};

/// How the convolution kernels multiply matrices. Each layer holds its own (from the network's
/// config); the op keeps it in its autodiff state, so the backward pass uses the forward's.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MatmulPrecision {
    /// `f32` throughout (the `gemm` crate's kernels). The default.
    #[default]
    F32,
    /// Operands rounded to bfloat16, products accumulated in `f32`, on Intel AMX ([`amx`]): about
    /// 3 significant digits per operand instead of 7, several times faster on CPUs that have AMX.
    Bf16,
}

impl MatmulPrecision {
    /// Every precision.
    pub const ALL: [MatmulPrecision; 2] = [MatmulPrecision::F32, MatmulPrecision::Bf16];

    /// The names its `FromStr` takes (case-insensitive), for help texts and errors.
    pub const CHOICES: &str = "`f32` (the default) or `bf16` (Intel AMX)";

    /// Its name: what `FromStr` and the config (serde, lowercase) read.
    pub fn name(self) -> &'static str {
        match self {
            MatmulPrecision::F32 => "f32",
            MatmulPrecision::Bf16 => "bf16",
        }
    }

    /// True for the default, `f32` (for `skip_serializing_if`).
    pub fn is_f32(&self) -> bool {
        *self == MatmulPrecision::F32
    }

    /// Whether this machine can run it: `bf16` needs AMX ([`amx::available`]).
    pub fn supported(self) -> Result<(), String> {
        match self {
            MatmulPrecision::F32 => Ok(()),
            MatmulPrecision::Bf16 if amx::available() => Ok(()),
            MatmulPrecision::Bf16 => Err(
                "bf16 needs Intel AMX (Xeon Sapphire Rapids or later, Linux 5.16 or later), which this machine does not offer: use f32"
                    .into(),
            ),
        }
    }
}

impl std::str::FromStr for MatmulPrecision {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let lower = s.trim().to_ascii_lowercase();
        MatmulPrecision::ALL
            .into_iter()
            .find(|p| p.name() == lower)
            .ok_or_else(|| format!("unknown precision `{s}`: use {}", MatmulPrecision::CHOICES))
    }
}

/// The custom op, routed by burn's dispatch to `Flex` or `Autodiff<Flex>`.
#[backend_extension(Flex, Autodiff)]
pub trait ConvKernelOps: Backend {
    /// `act(conv2d(x, weight) + bias)`, stride 1, zero padding `padding`; `act` is ReLU when
    /// `relu`; GEMMs in `precision`. `x` `[B, C, H, W]`, `weight` `[O, C, k, k]`, `bias` `[O]`.
    fn fused_conv2d(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        padding: usize,
        relu: bool,
        precision: MatmulPrecision,
    ) -> FloatTensor<Self>;

    /// 2×2 max-pooling with stride 2 of `x` `[B, C, H, W]` → `[B, C, H/2, W/2]`.
    fn max_pool2x2(x: FloatTensor<Self>) -> FloatTensor<Self>;
}

/// The contiguous `f32` values of a flex tensor (a copy only when it is a strided view).
fn values(t: &FlexTensor) -> std::borrow::Cow<'_, [f32]> {
    match t.as_slice::<f32>() {
        Some(s) => std::borrow::Cow::Borrowed(s),
        None => std::borrow::Cow::Owned(t.to_contiguous().as_slice::<f32>().expect("contiguous f32").to_vec()),
    }
}

fn flex_tensor(data: Vec<f32>, shape: Vec<usize>) -> FlexTensor {
    FlexTensor::from_data(TensorData::new(data, shape))
}

/// The convolution shape of `x` and `weight`, checked.
fn conv_shape(x: &FlexTensor, weight: &FlexTensor, padding: usize) -> ConvShape {
    assert_eq!(x.dtype(), DType::F32, "fused_conv2d: input dtype {:?}, the kernels take f32", x.dtype());
    assert_eq!(weight.dtype(), DType::F32, "fused_conv2d: weight dtype {:?}, the kernels take f32", weight.dtype());
    let xs = dims4(&x.shape());
    let ws = dims4(&weight.shape());
    assert_eq!(xs[1], ws[1], "fused_conv2d: input has {} channels, the kernel expects {}", xs[1], ws[1]);
    assert_eq!(ws[2], ws[3], "fused_conv2d: kernel {}×{} is not square", ws[2], ws[3]);
    let s = ConvShape { batch: xs[0], cin: xs[1], h: xs[2], w: xs[3], cout: ws[0], k: ws[2], pad: padding };
    assert!(s.is_valid(), "fused_conv2d: {}×{} input, kernel {}, padding {padding}: empty output", s.h, s.w, s.k);
    s
}

fn dims4(shape: &Shape) -> [usize; 4] {
    let d: Vec<usize> = shape.iter().copied().collect();
    d.try_into().unwrap_or_else(|d: Vec<usize>| panic!("fused_conv2d: expected a 4-D tensor, got shape {d:?}"))
}

/// How a fused convolution runs besides its tensors: padding, ReLU, precision.
#[derive(Clone, Copy, Debug)]
struct Fused {
    padding: usize,
    relu: bool,
    precision: MatmulPrecision,
}

fn flex_forward(x: &FlexTensor, weight: &FlexTensor, bias: &FlexTensor, f: Fused) -> FlexTensor {
    let s = conv_shape(x, weight, f.padding);
    let mut y = vec![0f32; s.batch * s.cout * s.out_h() * s.out_w()];
    gemm_conv::forward(&s, f.precision, &values(x), &values(weight), &values(bias), f.relu, &mut y);
    flex_tensor(y, vec![s.batch, s.cout, s.out_h(), s.out_w()])
}

/// The pooled tensor and the argmax of each output.
fn flex_pool(x: &FlexTensor) -> (FlexTensor, Vec<u8>) {
    assert_eq!(x.dtype(), DType::F32, "max_pool2x2: input dtype {:?}, the kernels take f32", x.dtype());
    let [b, c, h, w] = dims4(&x.shape());
    let (y, idx) = pool::forward(&values(x), b * c, h, w);
    let (ho, wo) = pool::out_size(h, w);
    (flex_tensor(y, vec![b, c, ho, wo]), idx)
}

impl ConvKernelOps for Flex {
    fn fused_conv2d(
        x: FlexTensor,
        weight: FlexTensor,
        bias: FlexTensor,
        padding: usize,
        relu: bool,
        precision: MatmulPrecision,
    ) -> FlexTensor {
        flex_forward(&x, &weight, &bias, Fused { padding, relu, precision })
    }

    fn max_pool2x2(x: FlexTensor) -> FlexTensor {
        flex_pool(&x).0
    }
}

#[derive(Debug)]
struct MaxPoolBackward;

impl Backward<Flex, 1> for MaxPoolBackward {
    /// The argmax of each output and the input's shape.
    type State = (std::sync::Arc<Vec<u8>>, [usize; 4]);

    fn backward(self, ops: Ops<Self::State, 1>, grads: &mut Gradients, _checkpointer: &mut Checkpointer) {
        let [node_x] = ops.parents;
        let dy = grads.consume::<Flex>(&ops.node);
        let (idx, [b, c, h, w]) = ops.state;
        if let Some(node) = node_x {
            let dx = pool::backward(&values(&dy), &idx, b * c, h, w);
            grads.register::<Flex>(node.id, flex_tensor(dx, vec![b, c, h, w]));
        }
    }
}

#[derive(Debug)]
struct FusedConvBackward;

/// What the backward step keeps: the input, the weight, the output (for the ReLU mask) and how the
/// forward ran (padding, ReLU, precision).
type FusedState = (FlexTensor, FlexTensor, Option<FlexTensor>, Fused);

impl Backward<Flex, 3> for FusedConvBackward {
    type State = FusedState;

    fn backward(self, ops: Ops<Self::State, 3>, grads: &mut Gradients, _checkpointer: &mut Checkpointer) {
        let [node_x, node_w, node_b] = ops.parents;
        let dy = grads.consume::<Flex>(&ops.node);
        let (x, weight, y, f) = ops.state;
        let want = Wanted { x: node_x.is_some(), weight: node_w.is_some(), bias: node_b.is_some() };
        if !(want.x || want.weight || want.bias) {
            return;
        }
        let s = conv_shape(&x, &weight, f.padding);
        let y_vals = y.as_ref().map(values);
        let (xv, wv, dyv) = (values(&x), values(&weight), values(&dy));
        let g = gemm_conv::backward(&s, f.precision, &xv, &wv, y_vals.as_deref(), &dyv, f.relu, want);
        if let (Some(node), Some(dx)) = (node_x, g.x) {
            grads.register::<Flex>(node.id, flex_tensor(dx, vec![s.batch, s.cin, s.h, s.w]));
        }
        if let (Some(node), Some(dw)) = (node_w, g.weight) {
            grads.register::<Flex>(node.id, flex_tensor(dw, vec![s.cout, s.cin, s.k, s.k]));
        }
        if let (Some(node), Some(db)) = (node_b, g.bias) {
            grads.register::<Flex>(node.id, flex_tensor(db, vec![s.cout]));
        }
    }
}

impl<C: CheckpointStrategy> ConvKernelOps for Autodiff<Flex, C> {
    fn fused_conv2d(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        padding: usize,
        relu: bool,
        precision: MatmulPrecision,
    ) -> FloatTensor<Self> {
        let f = Fused { padding, relu, precision };
        match FusedConvBackward.prepare::<C>([x.node(), weight.node(), bias.node()]).compute_bound().stateful() {
            OpsKind::Tracked(prep) => {
                let (xp, wp, bp) = (x.into_primitive(), weight.into_primitive(), bias.into_primitive());
                let y = flex_forward(&xp, &wp, &bp, f);
                let saved = relu.then(|| y.clone());
                prep.finish((xp, wp, saved, f), y)
            }
            OpsKind::UnTracked(prep) => {
                prep.finish(flex_forward(x.primitive(), weight.primitive(), bias.primitive(), f))
            }
        }
    }

    fn max_pool2x2(x: FloatTensor<Self>) -> FloatTensor<Self> {
        match MaxPoolBackward.prepare::<C>([x.node()]).compute_bound().stateful() {
            OpsKind::Tracked(prep) => {
                let shape = dims4(&x.primitive().shape());
                let (y, idx) = flex_pool(x.primitive());
                prep.finish((std::sync::Arc::new(idx), shape), y)
            }
            OpsKind::UnTracked(prep) => prep.finish(flex_pool(x.primitive()).0),
        }
    }
}

/// Whether tensors on `device` run our kernels (the `flex` CPU backend, with or without
/// autodiff).
pub fn runs_kernels(device: &Device) -> bool {
    device.clone().without_autodiff() == Device::flex()
}

/// 2×2 max-pooling with stride 2 (`[B, C, H, W] → [B, C, H/2, W/2]`): our kernel on `flex`,
/// burn's `max_pool2d` elsewhere.
pub fn max_pool2x2(x: Tensor<4>) -> Tensor<4> {
    if runs_kernels(&x.device()) {
        Tensor::from_dispatch(<Dispatch as ConvKernelOps>::max_pool2x2(x.into_dispatch()))
    } else {
        burn::tensor::module::max_pool2d(x, burn::tensor::ops::MaxPoolOptions::new([2, 2]))
    }
}

/// `act(conv2d(x, weight) + bias)`, stride 1, zero padding `padding`, `act` = ReLU when `relu`:
/// our kernels on `flex` with their GEMMs in `precision`, burn's `conv2d` (+ `relu`, in `f32`)
/// elsewhere. `x` `[B, C, H, W]`, `weight` `[O, C, k, k]` (square), `bias` `[O]`.
pub fn conv2d_fused(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Tensor<1>,
    padding: usize,
    relu: bool,
    precision: MatmulPrecision,
) -> Tensor<4> {
    if runs_kernels(&x.device()) {
        let out = <Dispatch as ConvKernelOps>::fused_conv2d(
            x.into_dispatch(),
            weight.into_dispatch(),
            bias.into_dispatch(),
            padding,
            relu,
            precision,
        );
        Tensor::from_dispatch(out)
    } else {
        let y = conv2d(x, weight, Some(bias), ConvOptions::new([1, 1], [padding, padding], [1, 1], 1));
        if relu { burn::tensor::activation::relu(y) } else { y }
    }
}

#[cfg(test)]
mod tests {
    use super::MatmulPrecision;

    #[test]
    fn precision_names_read_back() {
        for p in MatmulPrecision::ALL {
            assert_eq!(p.name().parse::<MatmulPrecision>(), Ok(p));
        }
        assert_eq!(" BF16 ".parse::<MatmulPrecision>(), Ok(MatmulPrecision::Bf16));
        let e = "half".parse::<MatmulPrecision>().unwrap_err();
        assert!(e.contains("`half`") && e.contains(MatmulPrecision::CHOICES), "{e}");
    }
}
