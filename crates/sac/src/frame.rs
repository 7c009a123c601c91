//! One square camera frame stored compactly for the replay buffer (docs/architecture.md#memory-budget): colour as rgb8,
//! depth in metres as `f16`, and the gripper's holding flag, plus the decoder that writes the 5-plane
//! network input of docs/paper.md §1.1 (`[R/255, G/255, B/255, depth m, holding]`) for a crop window.
//!
//! ## Limitations
//!
//! - Frames are square (`size × size`); a non-square image is rejected, not padded.
//! - Depth is kept as `f16`: about 1 mm resolution at 1-2 m and 2 mm at 2-4 m, which is below the
//!   renderer's own precision for the paper's 0.1-3 m range. A depth whose `f16` is not finite
//!   (above 65504 m) is rejected.
//! - Sizes above [`StoredFrame::MAX_SIZE`] are refused so a corrupted checkpoint cannot request a huge
//!   allocation.

use half::f16;
use half::slice::HalfFloatSliceExt;

/// Errors from building a [`StoredFrame`] or decoding a window of it.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum FrameError {
    /// The frame size is 0 or above [`StoredFrame::MAX_SIZE`].
    #[error("frame size {size} is outside 1..={max}")]
    BadSize {
        /// The size asked for.
        size: usize,
        /// The largest size accepted.
        max: usize,
    },
    /// The image is not square.
    #[error("frame must be square, got {width}×{height}")]
    NotSquare {
        /// Image width in pixels.
        width: usize,
        /// Image height in pixels.
        height: usize,
    },
    /// A buffer has the wrong number of elements.
    #[error("{what} has {got} elements, expected {expected}")]
    Length {
        /// Which buffer (`"color"`, `"depth"`, `"dst"`).
        what: &'static str,
        /// The length required.
        expected: usize,
        /// The length given.
        got: usize,
    },
    /// A depth value is NaN, infinite, or too large for `f16`.
    #[error("depth at pixel {index} (row {row}, col {col}) is not finite in f16: {value}")]
    NonFiniteDepth {
        /// Row-major pixel index.
        index: usize,
        /// Pixel row.
        row: usize,
        /// Pixel column.
        col: usize,
        /// The offending value, in metres.
        value: f32,
    },
    /// The requested crop window does not fit in the frame.
    #[error("window of {out}×{out} at (row {row0}, col {col0}) does not fit in a {size}×{size} frame")]
    Window {
        /// First row of the window.
        row0: usize,
        /// First column of the window.
        col0: usize,
        /// Window side.
        out: usize,
        /// Frame side.
        size: usize,
    },
}

/// A square camera frame: rgb8 colour (row-major, `size*size*3`), depth in metres as `f16`
/// (row-major, `size*size`) and the holding flag.
#[derive(Clone, PartialEq)]
pub struct StoredFrame {
    size: usize,
    color: Vec<u8>,
    depth: Vec<f16>,
    holding: bool,
}

impl std::fmt::Debug for StoredFrame {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Frame").field("size", &self.size).field("holding", &self.holding).finish_non_exhaustive()
    }
}

/// Number of planes in the network input (docs/paper.md §1.1): R, G, B, depth, holding.
pub const PLANES: usize = 5;

/// `LUT[v] = v / 255` exactly as a division rounds (not a multiplication by 1/255).
static U8_TO_UNIT: [f32; 256] = {
    let mut t = [0.0f32; 256];
    let mut i = 0;
    while i < 256 {
        t[i] = i as f32 / 255.0;
        i += 1;
    }
    t
};

impl StoredFrame {
    /// The largest frame side accepted (4096 px: 84 MB per frame).
    pub const MAX_SIZE: usize = 4096;

    /// Builds a frame from rgb8 colour (`size*size*3`, row-major) and depth in metres
    /// (`size*size`, row-major), converting depth to `f16`.
    ///
    /// Errors: size 0 or above [`StoredFrame::MAX_SIZE`], a wrong buffer length (naming expected and
    /// got), or a depth that is not finite after conversion (naming the pixel).
    pub fn new(size: usize, color: Vec<u8>, depth_m: &[f32], holding: bool) -> Result<StoredFrame, FrameError> {
        check_size(size)?;
        let n = size * size;
        check_len("depth", n, depth_m.len())?;
        let mut depth = vec![f16::ZERO; n];
        depth.convert_from_f32_slice(depth_m);
        StoredFrame::from_f16(size, color, depth, holding).map_err(|e| match e {
            // Report the metres the caller gave, not the f16 infinity they became.
            FrameError::NonFiniteDepth { index, row, col, .. } => {
                FrameError::NonFiniteDepth { index, row, col, value: depth_m[index] }
            }
            other => other,
        })
    }

    /// Like [`StoredFrame::new`] for a `width × height` image; errors unless `width == height`.
    pub fn from_image(
        width: usize,
        height: usize,
        color: Vec<u8>,
        depth_m: &[f32],
        holding: bool,
    ) -> Result<StoredFrame, FrameError> {
        if width != height {
            return Err(FrameError::NotSquare { width, height });
        }
        StoredFrame::new(width, color, depth_m, holding)
    }

    /// Builds a frame from depth already in `f16` metres (used when loading checkpoints); the same
    /// checks as [`StoredFrame::new`].
    pub fn from_f16(size: usize, color: Vec<u8>, depth: Vec<f16>, holding: bool) -> Result<StoredFrame, FrameError> {
        check_size(size)?;
        let n = size * size;
        check_len("color", n * 3, color.len())?;
        check_len("depth", n, depth.len())?;
        if let Some(index) = depth.iter().position(|d| !d.is_finite()) {
            return Err(FrameError::NonFiniteDepth {
                index,
                row: index / size,
                col: index % size,
                value: depth[index].to_f32(),
            });
        }
        Ok(StoredFrame { size, color, depth, holding })
    }

    /// Side of the square frame in pixels.
    pub fn size(&self) -> usize {
        self.size
    }

    /// rgb8 colour, row-major, `size*size*3` bytes.
    pub fn color(&self) -> &[u8] {
        &self.color
    }

    /// Depth in metres as `f16`, row-major, `size*size` values.
    pub fn depth(&self) -> &[f16] {
        &self.depth
    }

    /// Whether the gripper holds an object (the 5th input plane).
    pub fn holding(&self) -> bool {
        self.holding
    }

    /// Heap bytes owned by this frame (colour and depth buffers; not the struct itself).
    pub fn heap_bytes(&self) -> usize {
        self.color.capacity() + self.depth.capacity() * std::mem::size_of::<f16>()
    }

    /// Writes the network input for the `out × out` window whose top-left pixel is
    /// (`row0`, `col0`): 5 planes `[R/255, G/255, B/255, depth m, holding 0/1]`, each `out*out`
    /// row-major, into `dst` (length `5*out*out`).
    ///
    /// Errors if the window does not fit (or `out` is 0) or `dst` has the wrong length.
    pub fn write_planes(&self, row0: usize, col0: usize, out: usize, dst: &mut [f32]) -> Result<(), FrameError> {
        let size = self.size;
        let fits = out > 0
            && row0.checked_add(out).is_some_and(|e| e <= size)
            && col0.checked_add(out).is_some_and(|e| e <= size);
        if !fits {
            return Err(FrameError::Window { row0, col0, out, size });
        }
        let plane = out * out;
        check_len("dst", PLANES * plane, dst.len())?;
        let (r, rest) = dst.split_at_mut(plane);
        let (g, rest) = rest.split_at_mut(plane);
        let (b, rest) = rest.split_at_mut(plane);
        let (d, h) = rest.split_at_mut(plane);
        for (i, (((r, g), b), d)) in r
            .chunks_exact_mut(out)
            .zip(g.chunks_exact_mut(out))
            .zip(b.chunks_exact_mut(out))
            .zip(d.chunks_exact_mut(out))
            .enumerate()
        {
            let start = (row0 + i) * size + col0;
            let src = &self.color[start * 3..(start + out) * 3];
            for (((px, r), g), b) in src.chunks_exact(3).zip(r.iter_mut()).zip(g.iter_mut()).zip(b.iter_mut()) {
                *r = U8_TO_UNIT[px[0] as usize];
                *g = U8_TO_UNIT[px[1] as usize];
                *b = U8_TO_UNIT[px[2] as usize];
            }
            self.depth[start..start + out].convert_to_f32_slice(d);
        }
        h.fill(if self.holding { 1.0 } else { 0.0 });
        Ok(())
    }
}

fn check_size(size: usize) -> Result<(), FrameError> {
    if size == 0 || size > StoredFrame::MAX_SIZE {
        return Err(FrameError::BadSize { size, max: StoredFrame::MAX_SIZE });
    }
    Ok(())
}

fn check_len(what: &'static str, expected: usize, got: usize) -> Result<(), FrameError> {
    if expected != got {
        return Err(FrameError::Length { what, expected, got });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame whose colour encodes the pixel position and whose depth is `row + col/1000`-ish.
    fn pattern(size: usize, holding: bool) -> StoredFrame {
        let mut color = Vec::with_capacity(size * size * 3);
        let mut depth = Vec::with_capacity(size * size);
        for r in 0..size {
            for c in 0..size {
                color.extend_from_slice(&[r as u8, c as u8, (r * 7 + c * 3) as u8]);
                depth.push(0.25 * ((r + c) % 8) as f32);
            }
        }
        StoredFrame::new(size, color, &depth, holding).unwrap()
    }

    #[test]
    fn new_rejects_wrong_lengths_and_non_finite_depth() {
        let e = StoredFrame::new(4, vec![0; 47], &[0.0; 16], false).unwrap_err();
        assert_eq!(e, FrameError::Length { what: "color", expected: 48, got: 47 });
        let e = StoredFrame::new(4, vec![0; 48], &[0.0; 15], false).unwrap_err();
        assert_eq!(e, FrameError::Length { what: "depth", expected: 16, got: 15 });
        let mut d = [1.0f32; 16];
        d[6] = f32::NAN;
        match StoredFrame::new(4, vec![0; 48], &d, false).unwrap_err() {
            FrameError::NonFiniteDepth { index, row, col, .. } => assert_eq!((index, row, col), (6, 1, 2)),
            e => panic!("unexpected {e}"),
        }
        d[6] = 1.0e6; // overflows f16
        assert!(matches!(
            StoredFrame::new(4, vec![0; 48], &d, false),
            Err(FrameError::NonFiniteDepth { index: 6, .. })
        ));
        assert!(matches!(StoredFrame::new(0, vec![], &[], false), Err(FrameError::BadSize { .. })));
        assert_eq!(
            StoredFrame::from_image(4, 3, vec![0; 36], &[0.0; 12], false).unwrap_err(),
            FrameError::NotSquare { width: 4, height: 3 }
        );
        assert!(StoredFrame::from_image(4, 4, vec![0; 48], &[0.5; 16], true).is_ok());
    }

    #[test]
    fn write_planes_gives_the_window_in_all_five_planes() {
        let size = 20;
        let f = pattern(size, true);
        let (row0, col0, out) = (3, 5, 7);
        let mut dst = vec![f32::NAN; PLANES * out * out];
        f.write_planes(row0, col0, out, &mut dst).unwrap();
        let p = out * out;
        for i in 0..out {
            for j in 0..out {
                let (r, c) = (row0 + i, col0 + j);
                let k = i * out + j;
                assert_eq!(dst[k], r as f32 / 255.0);
                assert_eq!(dst[p + k], c as f32 / 255.0);
                assert_eq!(dst[2 * p + k], ((r * 7 + c * 3) as u8) as f32 / 255.0);
                assert_eq!(dst[3 * p + k], 0.25 * ((r + c) % 8) as f32);
                assert_eq!(dst[4 * p + k], 1.0);
            }
        }
        let g = pattern(size, false);
        g.write_planes(row0, col0, out, &mut dst).unwrap();
        assert!(dst[4 * p..].iter().all(|&v| v == 0.0));
    }

    #[test]
    fn write_planes_rejects_bad_windows() {
        let f = pattern(10, false);
        let mut dst = vec![0.0; PLANES * 16];
        assert!(f.write_planes(6, 6, 4, &mut dst).is_ok());
        assert!(matches!(f.write_planes(7, 0, 4, &mut dst), Err(FrameError::Window { .. })));
        assert!(matches!(f.write_planes(0, 7, 4, &mut dst), Err(FrameError::Window { .. })));
        assert!(matches!(f.write_planes(usize::MAX, 0, 4, &mut dst), Err(FrameError::Window { .. })));
        assert!(matches!(f.write_planes(0, 0, 3, &mut dst), Err(FrameError::Length { what: "dst", .. })));
    }

    #[test]
    fn heap_bytes_counts_colour_and_depth() {
        let f = pattern(8, false);
        assert_eq!(f.heap_bytes(), 8 * 8 * 3 + 8 * 8 * 2);
    }
}
