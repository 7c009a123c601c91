//! Ordinary (non-equivariant) layers for the CNN and SEN baselines, with the authors' initialisation
//! (their `weights_init`, docs/paper.md §1.8: a conv gets xavier-normal weights and keeps PyTorch's
//! default bias, U(±1/√fan_in); a linear layer gets xavier-uniform weights and a zero bias) drawn
//! from our own seeded RNG, so that they are reproducible like the equivariant ones.

use crate::init::Init;
use crate::layers::Numerics;
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
    #[module(skip)]
    numerics: Numerics,
}

impl Conv {
    /// A `k×k` conv `cin → cout` with padding `padding`, convolving as `numerics` says, weights for
    /// parameter path `path`.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        path: &str,
        cin: usize,
        cout: usize,
        k: usize,
        padding: usize,
        numerics: Numerics,
        init: &Init,
        device: &Device,
    ) -> Self {
        let (fan_in, fan_out) = (cin * k * k, cout * k * k);
        let std = (2.0 / (fan_in + fan_out) as f64).sqrt();
        let w = init.normal(&format!("{path}.weight"), cout * cin * k * k, std);
        let b = init.uniform(&format!("{path}.bias"), cout, 1.0 / (fan_in as f64).sqrt());
        Conv {
            weight: Param::from_tensor(Tensor::from_data(TensorData::new(w, [cout, cin, k, k]), device)),
            bias: Param::from_tensor(Tensor::from_data(TensorData::new(b, [cout]), device)),
            padding,
            numerics,
        }
    }

    /// How it convolves.
    pub fn numerics(&self) -> Numerics {
        self.numerics
    }

    /// `[B, in, H, W] → [B, out, H + 2p − k + 1, W + 2p − k + 1]`.
    pub fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        crate::layers::conv2d_stride1(x, self.weight.val(), self.bias.val(), self.padding, false, self.numerics)
    }

    /// [`Conv::forward`] followed by ReLU (fused into the convolution's passes).
    pub fn forward_relu(&self, x: Tensor<4>) -> Tensor<4> {
        crate::layers::conv2d_stride1(x, self.weight.val(), self.bias.val(), self.padding, true, self.numerics)
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

#[cfg(test)]
mod tests {
    use super::*;

    fn values<const D: usize>(t: Tensor<D>) -> Vec<f32> {
        t.into_data().try_to_vec::<f32>().expect("f32 tensor")
    }

    #[test]
    fn conv_init_is_xavier_normal_with_pytorchs_default_bias() {
        let dev = Device::flex();
        let (cin, cout, k) = (64, 128, 3);
        let conv = Conv::new("c", cin, cout, k, 1, Numerics::DEFAULT, &Init::new(0), &dev);
        let w = values(conv.weight.val());
        let n = w.len() as f64;
        let mean = w.iter().map(|&x| x as f64).sum::<f64>() / n;
        let std = (w.iter().map(|&x| (x as f64 - mean).powi(2)).sum::<f64>() / n).sqrt();
        let expected = (2.0 / ((cin + cout) * k * k) as f64).sqrt();
        assert!(mean.abs() < 0.02 * expected, "mean {mean}");
        assert!((std / expected - 1.0).abs() < 0.02, "std {std}, xavier-normal {expected}");
        // A normal, not a uniform: some weights lie beyond the xavier-uniform bound √3·std.
        assert!(w.iter().any(|&x| (x as f64).abs() > 3f64.sqrt() * expected));
        let b = values(conv.bias.val());
        let bound = 1.0 / ((cin * k * k) as f64).sqrt();
        assert!(b.iter().all(|&x| (x as f64).abs() <= bound), "bias beyond ±1/√fan_in");
        assert!(b.iter().filter(|&&x| x != 0.0).count() == b.len(), "bias left at zero");
    }

    #[test]
    fn linear_init_is_xavier_uniform_with_zero_bias() {
        let dev = Device::flex();
        let lin = Linear::new("l", 256, 10, &Init::new(0), &dev);
        let bound = (6.0 / 266f64).sqrt() as f32;
        let w = values(lin.weight.val());
        assert!(w.iter().all(|x| x.abs() <= bound));
        assert!(w.iter().any(|x| x.abs() > 0.9 * bound), "spread over the whole interval");
        assert!(values(lin.bias.val()).iter().all(|&x| x == 0.0));
    }
}
