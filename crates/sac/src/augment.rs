//! Crop augmentation and batch assembly for the networks (docs/paper.md §1.1, §1.11): the RAD random
//! crop (one uniform offset in `{0..=size-out}²` per transition), the centre crop used for acting and
//! evaluation, and the `[B, 5, out, out]` input batch built from stored frames.
//!
//! ## Limitations
//!
//! - Only integer-offset crops (RAD/DrQ `crop`); no padding-shift, colour jitter or rotations.
//! - Which transitions share an offset (obs and next_obs of one transition in RAD, independent draws
//!   for DrQ's K and M copies) is the caller's choice.
//! - Batch assembly is single-threaded: about 1 ms for 128 crops of 64 px and 6-9 ms for 128 crops
//!   of 128 px into a reused buffer ([`network_input_into`]) on the 2-core dev machine under load.

use crate::frame::{FrameError, PLANES, StoredFrame};

/// Errors from building a network input batch.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum AugmentError {
    /// `frames` and `offsets` have different lengths.
    #[error("{frames} frames but {offsets} crop offsets")]
    LengthMismatch {
        /// Number of frames.
        frames: usize,
        /// Number of offsets.
        offsets: usize,
    },
    /// The crop side is 0 or larger than a frame.
    #[error("frame {index}: crop of {out} px does not fit a {size} px frame")]
    CropTooLarge {
        /// Index of the frame in the batch.
        index: usize,
        /// Frame side.
        size: usize,
        /// Crop side.
        out: usize,
    },
    /// Decoding one frame failed (for example an offset outside the frame).
    #[error("frame {index}: {cause}")]
    Frame {
        /// Index of the frame in the batch.
        index: usize,
        /// What went wrong.
        cause: FrameError,
    },
}

/// Offset of the centre crop: `(size - out) / 2` (152 → 128 gives 12, rows/cols 12..139).
/// Returns 0 when `out >= size`.
pub fn center_offset(size: usize, out: usize) -> usize {
    size.saturating_sub(out) / 2
}

/// The network input of `frames` centre-cropped to `out` (acting, evaluation and `bag eval`: the
/// frames as the networks see them outside training, docs/paper.md §1.1).
pub fn centre_input(frames: &[&StoredFrame], out: usize) -> Result<Vec<f32>, AugmentError> {
    let offsets: Vec<(usize, usize)> = frames
        .iter()
        .map(|f| {
            let c = center_offset(f.size(), out);
            (c, c)
        })
        .collect();
    network_input(frames, &offsets, out)
}

/// A RAD crop offset `(row0, col0)`, uniform in `{0..=size-out}²`. Returns `(0, 0)` when
/// `out >= size` ([`network_input`] then reports a crop that does not fit).
pub fn random_offset(rng: &mut impl rand::Rng, size: usize, out: usize) -> (usize, usize) {
    let span = size.saturating_sub(out);
    (rng.random_range(0..=span), rng.random_range(0..=span))
}

/// Builds the network input batch `[B, 5, out, out]` (row-major `f32`, B = `frames.len()`) with
/// frame `i` cropped at `offsets[i]` = `(row0, col0)`; see [`StoredFrame::write_planes`].
///
/// Errors if the lengths differ, `out` is 0 or larger than a frame, or a window does not fit.
pub fn network_input(
    frames: &[&StoredFrame],
    offsets: &[(usize, usize)],
    out: usize,
) -> Result<Vec<f32>, AugmentError> {
    let mut batch = Vec::new();
    network_input_into(frames, offsets, out, &mut batch)?;
    Ok(batch)
}

/// Like [`network_input`] but writes into `dst`, resized to `B·5·out·out`, so a caller can reuse
/// one buffer across updates.
///
/// NOTE: a fresh allocation of a paper-size batch (128 × 5 × 128², 42 MB) costs more in page faults
/// than the decoding itself (measured ≈ 5× on the dev machine), hence this variant.
pub fn network_input_into(
    frames: &[&StoredFrame],
    offsets: &[(usize, usize)],
    out: usize,
    dst: &mut Vec<f32>,
) -> Result<(), AugmentError> {
    if frames.len() != offsets.len() {
        return Err(AugmentError::LengthMismatch { frames: frames.len(), offsets: offsets.len() });
    }
    if let Some((index, f)) = frames.iter().enumerate().find(|(_, f)| out == 0 || out > f.size()) {
        return Err(AugmentError::CropTooLarge { index, size: f.size(), out });
    }
    let per = PLANES * out * out;
    dst.resize(frames.len() * per, 0.0);
    for (index, ((frame, &(row0, col0)), dst)) in frames.iter().zip(offsets).zip(dst.chunks_exact_mut(per)).enumerate()
    {
        frame.write_planes(row0, col0, out, dst).map_err(|cause| AugmentError::Frame { index, cause })?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn pattern(size: usize, holding: bool, salt: u8) -> StoredFrame {
        let mut color = Vec::with_capacity(size * size * 3);
        let mut depth = Vec::with_capacity(size * size);
        for r in 0..size {
            for c in 0..size {
                color.extend_from_slice(&[r as u8, c as u8, salt]);
                depth.push(0.5 + r as f32 * 0.125);
            }
        }
        StoredFrame::new(size, color, &depth, holding).unwrap()
    }

    #[test]
    fn centre_crop_of_152_to_128_starts_at_12() {
        assert_eq!(center_offset(152, 128), 12);
        assert_eq!(center_offset(152, 128) + 127, 139);
        assert_eq!(center_offset(64, 64), 0);
        assert_eq!(center_offset(10, 20), 0);
    }

    #[test]
    fn random_offsets_cover_the_range_uniformly() {
        let (size, out) = (152, 128);
        let span = size - out + 1; // 25 values
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let draws = 250_000;
        let mut rows = vec![0usize; span + 5];
        let mut cols = vec![0usize; span + 5];
        for _ in 0..draws {
            let (r, c) = random_offset(&mut rng, size, out);
            rows[r] += 1;
            cols[c] += 1;
        }
        assert!(rows[span..].iter().chain(&cols[span..]).all(|&n| n == 0), "offset beyond size-out");
        let expect = draws as f64 / span as f64; // 10_000
        for counts in [&rows, &cols] {
            for &n in &counts[..span] {
                // Binomial sd is about 98; 6 sd either way.
                assert!((n as f64 - expect).abs() < 600.0, "count {n} vs {expect}");
            }
        }
        assert_eq!(random_offset(&mut rng, 10, 10), (0, 0));
        assert_eq!(random_offset(&mut rng, 10, 12), (0, 0));
    }

    #[test]
    fn batch_holds_each_frames_window() {
        let a = pattern(12, false, 9);
        let b = pattern(12, true, 200);
        let out = 5;
        let offsets = [(0, 7), (7, 2)];
        let x = network_input(&[&a, &b], &offsets, out).unwrap();
        let p = out * out;
        assert_eq!(x.len(), 2 * PLANES * p);
        for (n, ((r0, c0), salt, hold)) in [((0, 7), 9u8, 0.0), ((7, 2), 200u8, 1.0)].into_iter().enumerate() {
            let s = &x[n * PLANES * p..(n + 1) * PLANES * p];
            for i in 0..out {
                for j in 0..out {
                    let k = i * out + j;
                    assert_eq!(s[k], (r0 + i) as f32 / 255.0);
                    assert_eq!(s[p + k], (c0 + j) as f32 / 255.0);
                    assert_eq!(s[2 * p + k], salt as f32 / 255.0);
                    assert_eq!(s[3 * p + k], 0.5 + (r0 + i) as f32 * 0.125);
                    assert_eq!(s[4 * p + k], hold);
                }
            }
        }
    }

    #[test]
    fn batch_errors_name_the_frame() {
        let a = pattern(12, false, 0);
        assert_eq!(
            network_input(&[&a, &a], &[(0, 0)], 4).unwrap_err(),
            AugmentError::LengthMismatch { frames: 2, offsets: 1 }
        );
        assert_eq!(
            network_input(&[&a], &[(0, 0)], 13).unwrap_err(),
            AugmentError::CropTooLarge { index: 0, size: 12, out: 13 }
        );
        assert!(matches!(
            network_input(&[&a, &a], &[(0, 0), (0, 9)], 4),
            Err(AugmentError::Frame { index: 1, cause: FrameError::Window { .. } })
        ));
        assert!(network_input(&[], &[], 4).unwrap().is_empty());
    }

    #[test]
    fn reused_buffer_is_resized_and_fully_overwritten() {
        let a = pattern(12, true, 3);
        let fresh = network_input(&[&a, &a], &[(1, 2), (3, 4)], 6).unwrap();
        let mut buf = vec![f32::NAN; 7];
        network_input_into(&[&a, &a], &[(1, 2), (3, 4)], 6, &mut buf).unwrap();
        assert_eq!(buf, fresh);
        let mut big = vec![f32::NAN; 10_000];
        network_input_into(&[&a, &a], &[(1, 2), (3, 4)], 6, &mut big).unwrap();
        assert_eq!(big, fresh);
    }
}
