//! Building and reading the two image encodings equiarm publishes: `rgb8` colour and `32FC1` depth
//! in metres (little endian), both row-major with row 0 at the top.

use crate::{sensor_msgs::Image, std_msgs::Header};

/// Why an [`Image`] cannot be read as the requested encoding.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum ImageError {
    /// The image's `encoding` is not the one asked for.
    #[error("image encoding is '{found}', expected '{expected}'")]
    Encoding {
        /// The encoding asked for: `rgb8` or `32FC1`.
        expected: &'static str,
        /// The image's `encoding` field.
        found: String,
    },
    /// `step` or the length of `data` does not match `height`, `width` and the encoding's bytes per pixel.
    #[error(
        "{encoding} image of {height}x{width} must have step {expected_step} and {expected_len} data bytes, has step {step} and {len}"
    )]
    Size {
        /// The encoding checked: `rgb8` (3 bytes per pixel) or `32FC1` (4 bytes per pixel).
        encoding: &'static str,
        /// The image's height, rows.
        height: u32,
        /// The image's width, pixels per row.
        width: u32,
        /// The row length it should have, bytes: width × bytes per pixel.
        expected_step: u64,
        /// The data length it should have, bytes: `expected_step` × height.
        expected_len: u64,
        /// The image's `step` field, bytes per row.
        step: u32,
        /// The length of the image's `data`, bytes.
        len: usize,
    },
    /// The image has `is_bigendian` set; only little-endian data of the named encoding (`32FC1`) is read.
    #[error("image is big-endian; only little-endian {0} is supported")]
    BigEndian(&'static str),
}

impl Image {
    /// An `rgb8` image from `height * width * 3` bytes (R, G, B per pixel).
    pub fn rgb8(header: Header, height: u32, width: u32, data: Vec<u8>) -> Result<Self, ImageError> {
        let img = Image { header, height, width, encoding: "rgb8".into(), is_bigendian: 0, step: width * 3, data };
        img.check("rgb8", 3)?;
        Ok(img)
    }

    /// A `32FC1` image (little-endian float32, e.g. depth in metres) from `height * width` values.
    pub fn float32(header: Header, height: u32, width: u32, values: &[f32]) -> Result<Self, ImageError> {
        let mut data = Vec::with_capacity(values.len() * 4);
        for v in values {
            data.extend_from_slice(&v.to_le_bytes());
        }
        let img = Image { header, height, width, encoding: "32FC1".into(), is_bigendian: 0, step: width * 4, data };
        img.check("32FC1", 4)?;
        Ok(img)
    }

    /// The pixels of an `rgb8` image, `height * width * 3` bytes, after checking encoding and size.
    pub fn rgb8_data(&self) -> Result<&[u8], ImageError> {
        self.check("rgb8", 3)?;
        Ok(&self.data)
    }

    /// The values of a little-endian `32FC1` image, row-major, after checking encoding and size.
    pub fn float32_values(&self) -> Result<Vec<f32>, ImageError> {
        self.check("32FC1", 4)?;
        if self.is_bigendian != 0 {
            return Err(ImageError::BigEndian("32FC1"));
        }
        Ok(self.data.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect())
    }

    fn check(&self, encoding: &'static str, bytes_per_px: u64) -> Result<(), ImageError> {
        if self.encoding != encoding {
            return Err(ImageError::Encoding { expected: encoding, found: self.encoding.clone() });
        }
        let expected_step = self.width as u64 * bytes_per_px;
        let expected_len = expected_step * self.height as u64;
        if self.step as u64 != expected_step || self.data.len() as u64 != expected_len {
            return Err(ImageError::Size {
                encoding,
                height: self.height,
                width: self.width,
                expected_step,
                expected_len,
                step: self.step,
                len: self.data.len(),
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn float32_round_trip_keeps_bits() {
        let v = [f32::NAN, -0.0, f32::INFINITY, 1.5, f32::MIN_POSITIVE / 2.0, 0.25];
        let img = Image::float32(Header::default(), 2, 3, &v).unwrap();
        assert_eq!(img.step, 12);
        let back = img.float32_values().unwrap();
        assert!(v.iter().zip(&back).all(|(a, b)| a.to_bits() == b.to_bits()));
    }

    #[test]
    fn wrong_sizes_and_encodings_are_reported() {
        assert!(matches!(Image::rgb8(Header::default(), 2, 2, vec![0; 11]), Err(ImageError::Size { .. })));
        let img = Image::rgb8(Header::default(), 1, 1, vec![1, 2, 3]).unwrap();
        assert_eq!(img.float32_values().unwrap_err(), ImageError::Encoding { expected: "32FC1", found: "rgb8".into() });
    }
}
