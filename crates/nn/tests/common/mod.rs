//! Helpers shared by the integration tests.
#![allow(dead_code)]

use equiarm_nn::burn::tensor::{Device, Tensor, TensorData};
use equiarm_nn::init::Init;

/// The test device: flex (CPU).
pub fn device() -> Device {
    Device::flex()
}

/// A random N(0,1) tensor of the given shape from a seeded stream.
pub fn randn<const D: usize>(seed: u64, name: &str, shape: [usize; D], device: &Device) -> Tensor<D> {
    let len = shape.iter().product();
    Tensor::from_data(TensorData::new(Init::new(seed).normal(name, len, 1.0), shape), device)
}

/// All values of a tensor as f32.
pub fn values<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data().try_to_vec::<f32>().expect("f32 tensor")
}

/// Relative L2 error ‖a − b‖ / ‖b‖.
pub fn rel_err<const D: usize>(a: Tensor<D>, b: Tensor<D>) -> f64 {
    let (a, b) = (values(a), values(b));
    assert_eq!(a.len(), b.len());
    let num: f64 = a.iter().zip(&b).map(|(x, y)| ((x - y) as f64).powi(2)).sum();
    let den: f64 = b.iter().map(|y| (*y as f64).powi(2)).sum();
    (num / den.max(1e-30)).sqrt()
}
