//! Ordinary (non-equivariant) layers for the CNN and SEN baselines, with the authors'
//! initialisation (xavier-uniform weights, zero bias, docs/paper.md §1.8) drawn from our own seeded
//! RNG, so that they are reproducible like the equivariant ones.

use crate::init::Init;
use burn::module::{Module, Param};
use burn::tensor::{Device, Tensor, TensorData};

/// Plain 2-D convolution, stride 1, square kernel, zero padding.
#[derive(Module, Debug)]
pub struct Conv {
    /// `[out, in, k, k]`.
    pub weight: Param<Tensor<4>>,
    /// `[out]`.
    pub bias: Param<Tensor<1>>,
    padding: usize,
}

impl Conv {
    /// A `k×k` conv `cin → cout` with padding `padding`, weights for parameter path `path`.
    pub fn new(path: &str, cin: usize, cout: usize, k: usize, padding: usize, init: &Init, device: &Device) -> Self {
        let bound = (6.0 / ((cin + cout) * k * k) as f64).sqrt();
        let w = init.uniform(&format!("{path}.weight"), cout * cin * k * k, bound);
        Conv {
            weight: Param::from_tensor(Tensor::from_data(TensorData::new(w, [cout, cin, k, k]), device)),
            bias: Param::from_tensor(Tensor::zeros([cout], device)),
            padding,
        }
    }

    /// `[B, in, H, W] → [B, out, H + 2p − k + 1, W + 2p − k + 1]`.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        crate::layers::conv2d_stride1(x, self.weight.val(), self.bias.val(), self.padding, false)
    }

    /// [`Conv::forward`] followed by ReLU (fused into the convolution's passes).
    pub fn forward_relu(&self, x: Tensor<4>) -> Tensor<4> {
        crate::layers::conv2d_stride1(x, self.weight.val(), self.bias.val(), self.padding, true)
    }
}

/// Plain fully connected layer `y = x Wᵀ + b`.
#[derive(Module, Debug)]
pub struct Linear {
    /// `[out, in]` (PyTorch layout).
    pub weight: Param<Tensor<2>>,
    /// `[out]`.
    pub bias: Param<Tensor<1>>,
}

impl Linear {
    /// `din → dout`, weights for parameter path `path`.
    pub fn new(path: &str, din: usize, dout: usize, init: &Init, device: &Device) -> Self {
        let bound = (6.0 / (din + dout) as f64).sqrt();
        let w = init.uniform(&format!("{path}.weight"), dout * din, bound);
        Linear {
            weight: Param::from_tensor(Tensor::from_data(TensorData::new(w, [dout, din]), device)),
            bias: Param::from_tensor(Tensor::zeros([dout], device)),
        }
    }

    /// `[B, in] → [B, out]`.
    pub fn forward(&self, x: Tensor<2>) -> Tensor<2> {
        x.matmul(self.weight.val().transpose()) + self.bias.val().unsqueeze::<2>()
    }
}
