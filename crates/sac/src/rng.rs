//! The learner's random numbers: ChaCha8 streams (portable, seedable, and their exact position can
//! be saved in a checkpoint and restored), standard normals by Box–Muller.

use rand::{Rng as _, SeedableRng as _};
use rand_chacha::ChaCha8Rng;

/// `n` standard normal samples.
pub fn normals(rng: &mut ChaCha8Rng, n: usize) -> Vec<f32> {
    let mut out = Vec::with_capacity(n + 1);
    while out.len() < n {
        // u1 in (0, 1]: never ln(0).
        let u1 = 1.0 - rng.random::<f64>();
        let u2 = rng.random::<f64>();
        let r = (-2.0 * u1.ln()).sqrt();
        let t = 2.0 * std::f64::consts::PI * u2;
        out.push((r * t.cos()) as f32);
        out.push((r * t.sin()) as f32);
    }
    out.truncate(n);
    out
}

/// A seeded stream: `seed` picks the key, `stream` separates users of one seed.
pub fn stream(seed: u64, stream: u64) -> ChaCha8Rng {
    let mut r = ChaCha8Rng::seed_from_u64(seed);
    r.set_stream(stream);
    r
}

/// The exact state of `rng` as text: (hex key, stream, word position).
pub fn save_state(rng: &ChaCha8Rng) -> (String, u64, String) {
    let key: String = rng.get_seed().iter().map(|b| format!("{b:02x}")).collect();
    (key, rng.get_stream(), rng.get_word_pos().to_string())
}

/// A saved RNG state that [`load_state`] cannot restore.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum RngStateError {
    /// The key is not 64 hex digits.
    #[error("rng key `{0}` is not 64 hex digits")]
    Key(String),
    /// The word position is not a whole number.
    #[error("rng word position `{0}` is not a whole number")]
    Position(String),
}

/// Restore a state made by [`save_state`].
pub fn load_state(state: &(String, u64, String)) -> Result<ChaCha8Rng, RngStateError> {
    let (key, stream, pos) = state;
    if key.len() != 64 || !key.is_ascii() {
        return Err(RngStateError::Key(key.clone()));
    }
    let mut seed = [0u8; 32];
    for (i, b) in seed.iter_mut().enumerate() {
        *b = u8::from_str_radix(&key[2 * i..2 * i + 2], 16).map_err(|_| RngStateError::Key(key.clone()))?;
    }
    let pos: u128 = pos.parse().map_err(|_| RngStateError::Position(pos.clone()))?;
    let mut r = ChaCha8Rng::from_seed(seed);
    r.set_stream(*stream);
    r.set_word_pos(pos);
    Ok(r)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn state_round_trip_continues_the_stream() {
        let mut a = stream(7, 3);
        let _ = normals(&mut a, 11);
        let saved = save_state(&a);
        let mut b = load_state(&saved).unwrap();
        assert_eq!(normals(&mut a, 9), normals(&mut b, 9));
        assert!(load_state(&("zz".into(), 0, "0".into())).is_err());
    }

    #[test]
    fn normals_have_unit_moments() {
        let v = normals(&mut stream(1, 0), 200_000);
        let mean = v.iter().map(|&x| x as f64).sum::<f64>() / v.len() as f64;
        let var = v.iter().map(|&x| (x as f64 - mean).powi(2)).sum::<f64>() / v.len() as f64;
        assert!(mean.abs() < 0.01 && (var - 1.0).abs() < 0.01, "mean {mean} var {var}");
    }
}
