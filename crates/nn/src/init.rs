//! Seeded weight initialisation: our own RNG (ChaCha8), so that weights are bitwise reproducible
//! across runs, thread counts and backends (burn's own initialisers draw from the backend's RNG).
//!
//! [`Init`] hands out one independent stream per parameter path, so adding a layer does not
//! change the weights of the others.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A seeded source of initial weights.
#[derive(Clone, Debug)]
pub struct Init {
    seed: u64,
}

impl Init {
    /// A source for `seed`.
    pub fn new(seed: u64) -> Self {
        Init { seed }
    }

    /// The seed.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// An RNG for the parameter named `path` (stream derived from the seed and a hash of the path).
    pub fn rng(&self, path: &str) -> ChaCha8Rng {
        // FNV-1a: stable across Rust versions (unlike `DefaultHasher`).
        let mut h: u64 = 0xcbf29ce484222325;
        for b in path.bytes() {
            h ^= b as u64;
            h = h.wrapping_mul(0x100000001b3);
        }
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        rng.set_stream(h);
        rng
    }

    /// `len` samples of N(0, std²) for the parameter `path` (Box–Muller).
    pub fn normal(&self, path: &str, len: usize, std: f64) -> Vec<f32> {
        let mut rng = self.rng(path);
        let mut out = Vec::with_capacity(len + 1);
        while out.len() < len {
            let u1: f64 = 1.0 - rng.random::<f64>(); // (0, 1]
            let u2: f64 = rng.random::<f64>();
            let r = (-2.0 * u1.ln()).sqrt() * std;
            let t = 2.0 * std::f64::consts::PI * u2;
            out.push((r * t.cos()) as f32);
            out.push((r * t.sin()) as f32);
        }
        out.truncate(len);
        out
    }

    /// `len` samples of U(−bound, bound) for the parameter `path`.
    pub fn uniform(&self, path: &str, len: usize, bound: f64) -> Vec<f32> {
        let mut rng = self.rng(path);
        (0..len).map(|_| ((rng.random::<f64>() * 2.0 - 1.0) * bound) as f32).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_are_reproducible_and_distinct() {
        let a = Init::new(7).normal("enc.conv1.weight", 1000, 1.0);
        assert_eq!(a, Init::new(7).normal("enc.conv1.weight", 1000, 1.0));
        assert_ne!(a, Init::new(8).normal("enc.conv1.weight", 1000, 1.0));
        assert_ne!(a, Init::new(7).normal("enc.conv2.weight", 1000, 1.0));
        let mean: f64 = a.iter().map(|&x| x as f64).sum::<f64>() / 1000.0;
        let var: f64 = a.iter().map(|&x| (x as f64 - mean).powi(2)).sum::<f64>() / 1000.0;
        assert!(mean.abs() < 0.1 && (var - 1.0).abs() < 0.15, "mean {mean} var {var}");
    }
}
