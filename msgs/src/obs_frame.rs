//! The camera frame inside an [`Observation`]: `height`, `width` and two planes, each compressed as
//! one zstd frame (with its content size): `color` holds rgb8 pixels (3 bytes each), `depth` planar
//! depth in metres as little-endian IEEE 754 half floats (2 bytes each), both row-major with row 0 at
//! the top.
//!
//! Why compressed: a reliable DDS writer keeps what it published until its readers acknowledge it
//! and its cache is cleaned (every 6 s in RustDDS 0.15), so the bytes per step set the sim node's
//! memory and the suite's bandwidth. A rendered 152 × 152 frame is 69 kB of colour and 46 kB of
//! half-float depth, and a few kB compressed (flat-shaded scenes compress very well). Why half
//! floats: that is the precision every consumer uses (the replay stores depth as `f16`, and the one
//! network-input function reads it from there), so nothing is lost that anyone reads, and training
//! in-process and over DDS sees the same numbers.
//!
//! Decoding checks the sides (at most [`MAX_SIDE`]) and each plane's content size against them
//! before anything is allocated, so a peer's message cannot make a reader allocate more than the
//! frame it claims.

use half::f16;

use crate::msg::Observation;
use crate::sensor_msgs::Image;
use crate::std_msgs::Header;

/// Largest `height` or `width` of an Observation's frame, pixels (the camera's own bound).
pub const MAX_SIDE: u32 = 8192;

/// zstd level of the planes: 1, the fastest; rendered frames compress about 40 × at it.
const LEVEL: i32 = 1;

/// Why an Observation's frame cannot be built or read.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum ObsFrameError {
    /// A side is larger than [`MAX_SIDE`].
    #[error("frame of {height} x {width} pixels: each side must be at most {MAX_SIDE}")]
    Side {
        /// Rows.
        height: u32,
        /// Columns.
        width: u32,
    },
    /// A plane given to [`Observation::set_frame`] has the wrong length.
    #[error("{plane}: {got} values for a {height} x {width} frame, expected {expected}")]
    Input {
        /// `color` or `depth`.
        plane: &'static str,
        /// Rows.
        height: u32,
        /// Columns.
        width: u32,
        /// Values expected.
        expected: usize,
        /// Values given.
        got: usize,
    },
    /// A plane is not one zstd frame of the size the sides give.
    #[error("{plane}: not a zstd frame of {expected} bytes ({height} x {width} pixels): {reason}")]
    Plane {
        /// `color` or `depth`.
        plane: &'static str,
        /// Rows.
        height: u32,
        /// Columns.
        width: u32,
        /// Bytes the plane holds uncompressed.
        expected: usize,
        /// What is wrong.
        reason: String,
    },
    /// Compressing failed (zstd's own error).
    #[error("{plane}: compressing failed: {reason}")]
    Compress {
        /// `color` or `depth`.
        plane: &'static str,
        /// zstd's error.
        reason: String,
    },
}

impl Observation {
    /// Sets `height`, `width`, `color` (rgb8, `height * width * 3` bytes) and `depth` (metres,
    /// `height * width` values, stored as half floats) of the frame.
    pub fn set_frame(&mut self, height: u32, width: u32, color: &[u8], depth_m: &[f32]) -> Result<(), ObsFrameError> {
        let n = pixels(height, width)?;
        let input = |plane, expected, got| ObsFrameError::Input { plane, height, width, expected, got };
        if color.len() != n * 3 {
            return Err(input("color", n * 3, color.len()));
        }
        if depth_m.len() != n {
            return Err(input("depth", n, depth_m.len()));
        }
        let depth: Vec<u8> = depth_m.iter().flat_map(|d| f16::from_f32(*d).to_le_bytes()).collect();
        let compress = |plane, raw: &[u8]| {
            zstd::bulk::compress(raw, LEVEL).map_err(|e| ObsFrameError::Compress { plane, reason: e.to_string() })
        };
        self.color = compress("color", color)?;
        self.depth = compress("depth", &depth)?;
        (self.height, self.width) = (height, width);
        Ok(())
    }

    /// The rgb8 pixels, `height * width * 3` bytes.
    pub fn color_rgb8(&self) -> Result<Vec<u8>, ObsFrameError> {
        let n = pixels(self.height, self.width)?;
        self.plane("color", &self.color, n * 3)
    }

    /// The depth in metres, as sent (half floats), `height * width` values.
    pub fn depth_f16(&self) -> Result<Vec<f16>, ObsFrameError> {
        let n = pixels(self.height, self.width)?;
        let raw = self.plane("depth", &self.depth, n * 2)?;
        Ok(raw.chunks_exact(2).map(|b| f16::from_le_bytes([b[0], b[1]])).collect())
    }

    /// The depth in metres as `f32` (each value exactly its half float), `height * width` values.
    pub fn depth_m(&self) -> Result<Vec<f32>, ObsFrameError> {
        Ok(self.depth_f16()?.into_iter().map(f16::to_f32).collect())
    }

    /// The colour as a `sensor_msgs/Image` (rgb8) with `header`, for the camera topics.
    pub fn color_image(&self, header: Header) -> Result<Image, ObsFrameError> {
        let data = self.color_rgb8()?;
        Ok(Image::rgb8(header, self.height, self.width, data).expect("the plane's size was checked"))
    }

    /// The depth as a `sensor_msgs/Image` (32FC1, metres) with `header`, for the camera topics.
    pub fn depth_image(&self, header: Header) -> Result<Image, ObsFrameError> {
        let depth = self.depth_m()?;
        Ok(Image::float32(header, self.height, self.width, &depth).expect("the plane's size was checked"))
    }

    fn plane(&self, plane: &'static str, data: &[u8], expected: usize) -> Result<Vec<u8>, ObsFrameError> {
        let (height, width) = (self.height, self.width);
        let bad = |reason: String| ObsFrameError::Plane { plane, height, width, expected, reason };
        // The size the frame says it holds, before anything is allocated for it.
        match zstd::zstd_safe::get_frame_content_size(data) {
            Ok(Some(n)) if n == expected as u64 => {}
            Ok(Some(n)) => return Err(bad(format!("it holds {n} bytes"))),
            Ok(None) => return Err(bad("its header does not give its size".into())),
            Err(_) => return Err(bad("no zstd frame header".into())),
        }
        let raw = zstd::bulk::decompress(data, expected).map_err(|e| bad(e.to_string()))?;
        if raw.len() != expected {
            return Err(bad(format!("it decompresses to {} bytes", raw.len())));
        }
        Ok(raw)
    }
}

/// `height * width`, after checking the sides.
fn pixels(height: u32, width: u32) -> Result<usize, ObsFrameError> {
    if height > MAX_SIDE || width > MAX_SIDE {
        return Err(ObsFrameError::Side { height, width });
    }
    Ok(height as usize * width as usize)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(h: u32, w: u32) -> (Vec<u8>, Vec<f32>) {
        let n = (h * w) as usize;
        let color = (0..n * 3).map(|i| (i * 7 % 251) as u8).collect();
        let depth = (0..n).map(|i| 0.3 + i as f32 * 1e-3).collect();
        (color, depth)
    }

    #[test]
    fn a_frame_reads_back_with_depth_at_half_precision() {
        let (color, depth) = frame(5, 7);
        let mut o = Observation::default();
        o.set_frame(5, 7, &color, &depth).unwrap();
        assert_eq!((o.height, o.width), (5, 7));
        assert_eq!(o.color_rgb8().unwrap(), color);
        let back = o.depth_m().unwrap();
        for (a, b) in depth.iter().zip(&back) {
            assert_eq!(*b, f16::from_f32(*a).to_f32());
            assert!((a - b).abs() <= a * 1e-3);
        }
        let img = o.depth_image(Header::default()).unwrap();
        assert_eq!((img.encoding.as_str(), img.height, img.width), ("32FC1", 5, 7));
        assert_eq!(img.float32_values().unwrap(), back);
        assert_eq!(o.color_image(Header::default()).unwrap().data, color);
        // an empty frame is a frame too
        o.set_frame(0, 0, &[], &[]).unwrap();
        assert!(o.color_rgb8().unwrap().is_empty() && o.depth_m().unwrap().is_empty());
    }

    #[test]
    fn rendered_frames_compress() {
        // a flat floor and one block, as the renderer draws them
        let (h, w) = (152u32, 152u32);
        let n = (h * w) as usize;
        let mut color = vec![0u8; n * 3];
        let mut depth = vec![0f32; n];
        for r in 0..h as usize {
            for c in 0..w as usize {
                let block = (60..80).contains(&r) && (70..90).contains(&c);
                color[(r * w as usize + c) * 3..][..3].copy_from_slice(if block {
                    &[200, 30, 30]
                } else {
                    &[90, 90, 90]
                });
                depth[r * w as usize + c] = if block { 0.8 } else { 0.6 + r as f32 * 0.004 };
            }
        }
        let mut o = Observation::default();
        o.set_frame(h, w, &color, &depth).unwrap();
        let raw = n * 5;
        assert!(o.color.len() + o.depth.len() < raw / 20, "{} + {} bytes of {raw}", o.color.len(), o.depth.len());
    }

    #[test]
    fn bad_frames_are_refused_before_allocating() {
        let (color, depth) = frame(4, 4);
        let mut o = Observation::default();
        assert!(matches!(o.set_frame(4, 4, &color[1..], &depth), Err(ObsFrameError::Input { plane: "color", .. })));
        assert!(matches!(o.set_frame(4, 5, &color, &depth), Err(ObsFrameError::Input { plane: "color", .. })));
        o.set_frame(4, 4, &color, &depth).unwrap();
        let good = o.clone();
        // sides that do not match the planes
        o.width = 5;
        let e = o.color_rgb8().unwrap_err();
        assert!(e.to_string().contains("holds 48 bytes"), "{e}");
        // a side beyond the bound: refused whatever the planes hold
        o.width = MAX_SIDE + 1;
        assert!(matches!(o.depth_m(), Err(ObsFrameError::Side { .. })));
        // not zstd, truncated, empty
        let mut o = good.clone();
        o.color = vec![1, 2, 3, 4, 5, 6, 7, 8];
        assert!(o.color_rgb8().unwrap_err().to_string().contains("no zstd frame header"));
        let mut o = good.clone();
        o.depth.truncate(o.depth.len() - 3);
        assert!(matches!(o.depth_f16(), Err(ObsFrameError::Plane { plane: "depth", .. })));
        let mut o = good.clone();
        o.color.clear();
        assert!(o.color_rgb8().is_err());
        // a frame that claims the right size but is corrupt
        let mut o = good;
        let last = o.color.len() - 1;
        o.color[last] ^= 0xff;
        let _ = o.color_rgb8(); // an error or, if the damage is in literal bytes, other pixels: never a panic
    }
}
