//! The dataset file: `pairs.rotest`, one file per corruption setting, written by
//! [`Dataset::write`] and read by [`Dataset::read`].
//!
//! Layout (all integers little-endian):
//!
//! | bytes | content |
//! |---|---|
//! | 8 | magic `EQROTEST` |
//! | 4 | format version (1) |
//! | 8 | header length `n` |
//! | n | header, JSON ([`Header`]): sizes, setting, seed, and per pair its label, poses and the byte range of its chunk |
//! | … | one zstd frame (with its content checksum) per pair: colour of image 1 (`size²·3` bytes, rgb8, row-major), depth of image 1 (`size²` f16, metres), then image 2 the same way |
//!
//! One frame per pair lets the reader decompress pairs in parallel and check each against its
//! declared length; a 152 px pair is 231 KB raw and about 10–25 KB compressed (flat-shaded colour and
//! smooth depth compress well). Depth in f16 keeps 0.5 mm at 1 m.

use std::io::Write;
use std::path::{Path, PathBuf};

use equiarm_sim::rotest::{PairMeta, RgbdImage};
use half::f16;
use rayon::prelude::*;

use crate::error::{Result, RotestError};
use equiarm_types::files::at;

/// The file's magic bytes.
pub const MAGIC: &[u8; 8] = b"EQROTEST";
/// The format version written and read.
pub const VERSION: u32 = 1;
/// The file name inside a dataset directory.
pub const FILE_NAME: &str = "pairs.rotest";
/// zstd level of the chunks.
const ZSTD_LEVEL: i32 = 3;

/// One image as stored: rgb8 colour and f16 depth.
#[derive(Clone, Debug, PartialEq)]
pub struct StoredImage {
    /// rgb8, `size × size × 3`, row-major.
    pub color: Vec<u8>,
    /// Planar depth, m, `size × size`.
    pub depth: Vec<f16>,
}

impl StoredImage {
    /// The image of a generated pair, depth rounded to f16.
    pub fn from_rgbd(img: &RgbdImage) -> Self {
        Self { color: img.color.clone(), depth: img.depth.iter().map(|&d| f16::from_f32(d)).collect() }
    }
}

/// One stored pair.
#[derive(Clone, Debug, PartialEq)]
pub struct StoredPair {
    /// The image before the rotation.
    pub before: StoredImage,
    /// The image after the rotation.
    pub after: StoredImage,
}

/// Where one pair's chunk lies, relative to the end of the header.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Chunk {
    /// Offset, bytes.
    pub offset: u64,
    /// Compressed length, bytes.
    pub len: u64,
}

/// The JSON header.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Header {
    /// Image side, pixels.
    pub size: usize,
    /// Supersampling factor the images were rendered with.
    pub supersample: usize,
    /// The corruption setting (canonical name, e.g. `side,grid`).
    pub corrupt: String,
    /// The generator seed (pair `i` is generated from [`pair_seed`]`(seed, i)`).
    pub seed: u64,
    /// Labels, rotations, poses and light colour of each pair.
    pub pairs: Vec<PairMeta>,
    /// Each pair's chunk.
    pub chunks: Vec<Chunk>,
}

/// A dataset in memory.
#[derive(Clone, Debug, PartialEq)]
pub struct Dataset {
    /// Sizes, setting, seed and per-pair metadata (the chunk list is only meaningful in a file).
    pub header: Header,
    /// The images, indexed like `header.pairs`.
    pub pairs: Vec<StoredPair>,
}

/// The seed of pair `i` of a dataset generated with `seed`.
pub fn pair_seed(seed: u64, i: u64) -> u64 {
    equiarm_sim::rng::Rng::new(seed ^ i.rotate_left(32) ^ 0x00dd_ba11).next_u64()
}

fn encode_pair(p: &StoredPair, size: usize) -> Result<Vec<u8>, std::io::Error> {
    let mut raw = Vec::with_capacity(pair_bytes(size));
    for img in [&p.before, &p.after] {
        raw.extend_from_slice(&img.color);
        for d in &img.depth {
            raw.extend_from_slice(&d.to_le_bytes());
        }
    }
    // With zstd's content checksum, a damaged chunk fails to decompress instead of giving wrong pixels.
    let mut c = zstd::bulk::Compressor::new(ZSTD_LEVEL)?;
    c.set_parameter(zstd::zstd_safe::CParameter::ChecksumFlag(true))?;
    c.compress(&raw)
}

/// Uncompressed bytes of one pair of `size`² images.
pub fn pair_bytes(size: usize) -> usize {
    2 * size * size * 5
}

fn decode_image(raw: &[u8], size: usize) -> StoredImage {
    let n = size * size;
    let color = raw[..3 * n].to_vec();
    let depth = raw[3 * n..5 * n].chunks_exact(2).map(|b| f16::from_le_bytes([b[0], b[1]])).collect();
    StoredImage { color, depth }
}

impl Dataset {
    /// Number of pairs.
    pub fn len(&self) -> usize {
        self.pairs.len()
    }

    /// Whether there is no pair.
    pub fn is_empty(&self) -> bool {
        self.pairs.is_empty()
    }

    /// Writes `dir/pairs.rotest` (creating `dir`); returns the file's path.
    pub fn write(&self, dir: &Path) -> Result<PathBuf> {
        std::fs::create_dir_all(dir).map_err(at(dir))?;
        let path = dir.join(FILE_NAME);
        let size = self.header.size;
        let blobs: Vec<Vec<u8>> =
            self.pairs.par_iter().map(|p| encode_pair(p, size)).collect::<Result<_, _>>().map_err(at(&path))?;
        let mut header = self.header.clone();
        let mut offset = 0u64;
        header.chunks = blobs
            .iter()
            .map(|b| {
                let c = Chunk { offset, len: b.len() as u64 };
                offset += b.len() as u64;
                c
            })
            .collect();
        let json = serde_json::to_vec(&header)
            .map_err(|e| RotestError::Format { path: path.clone(), message: e.to_string() })?;
        equiarm_types::files::write_atomically(&path, |f| {
            f.write_all(MAGIC)?;
            f.write_all(&VERSION.to_le_bytes())?;
            f.write_all(&(json.len() as u64).to_le_bytes())?;
            f.write_all(&json)?;
            blobs.iter().try_for_each(|b| f.write_all(b))
        })?;
        Ok(path)
    }

    /// Reads only the header of a dataset file (or of `path/pairs.rotest`): labels and poses, no images.
    pub fn read_header(path: &Path) -> Result<Header> {
        use std::io::Read;
        let path = if path.is_dir() { path.join(FILE_NAME) } else { path.to_path_buf() };
        let bad = |message: String| RotestError::Format { path: path.clone(), message };
        let mut f = std::fs::File::open(&path).map_err(at(&path))?;
        let mut head = [0u8; 20];
        f.read_exact(&mut head).map_err(|_| bad("shorter than a dataset header".into()))?;
        if &head[..8] != MAGIC {
            return Err(bad("not a rotation-estimation dataset (no `EQROTEST` magic)".into()));
        }
        let version = u32::from_le_bytes(head[8..12].try_into().expect("4 bytes"));
        if version != VERSION {
            return Err(bad(format!("format version {version}; this program reads version {VERSION}")));
        }
        let n = u64::from_le_bytes(head[12..20].try_into().expect("8 bytes"));
        let mut json = Vec::new();
        (&mut f).take(n).read_to_end(&mut json).map_err(at(&path))?;
        if json.len() as u64 != n {
            return Err(bad(format!("header of {n} bytes runs past the end of the file (truncated?)")));
        }
        let header: Header = serde_json::from_slice(&json).map_err(|e| bad(format!("header: {e}")))?;
        // checked as `read` checks it, so no reader takes a header that training refuses
        let file_len = f.metadata().map_err(at(&path))?.len();
        check_header(&header, file_len.saturating_sub(20 + n)).map_err(bad)?;
        Ok(header)
    }

    /// Reads a dataset: `path` is the file or the directory holding `pairs.rotest`. Only the first
    /// `limit` pairs are decompressed when `limit` is given. A file that is not a dataset, of
    /// another version, truncated, or with a damaged chunk is a [`RotestError::Format`] naming the
    /// file and the pair.
    pub fn read(path: &Path, limit: Option<usize>) -> Result<Self> {
        let path = if path.is_dir() { path.join(FILE_NAME) } else { path.to_path_buf() };
        let bytes = std::fs::read(&path).map_err(at(&path))?;
        let bad = |message: String| RotestError::Format { path: path.clone(), message };
        if bytes.len() < 20 || &bytes[..8] != MAGIC {
            return Err(bad(format!("not a rotation-estimation dataset (no `{}` magic)", "EQROTEST")));
        }
        let version = u32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes"));
        if version != VERSION {
            return Err(bad(format!("format version {version}; this program reads version {VERSION}")));
        }
        let n = u64::from_le_bytes(bytes[12..20].try_into().expect("8 bytes")) as usize;
        let body = 20usize.checked_add(n).filter(|&e| e <= bytes.len()).ok_or_else(|| {
            bad(format!("header of {n} bytes runs past the end of the {}-byte file (truncated?)", bytes.len()))
        })?;
        let mut header: Header = serde_json::from_slice(&bytes[20..body]).map_err(|e| bad(format!("header: {e}")))?;
        check_header(&header, (bytes.len() - body) as u64).map_err(bad)?;
        let count = limit.map_or(header.pairs.len(), |l| l.min(header.pairs.len()));
        header.pairs.truncate(count);
        header.chunks.truncate(count);
        let data = &bytes[body..];
        let raw_len = pair_bytes(header.size);
        let pairs = header
            .chunks
            .par_iter()
            .enumerate()
            .map(|(i, c)| {
                let s = usize::try_from(c.offset).ok();
                let e = s.and_then(|s| s.checked_add(c.len as usize)).filter(|&e| e <= data.len());
                let (Some(s), Some(e)) = (s, e) else {
                    return Err(bad(format!("pair {i}: chunk runs past the end of the file (truncated?)")));
                };
                let chunk = &data[s..e];
                // the size the chunk says it holds, before anything is allocated for it
                match zstd::zstd_safe::get_frame_content_size(chunk) {
                    Ok(Some(n)) if n == raw_len as u64 => {}
                    Ok(Some(n)) => return Err(bad(format!("pair {i}: chunk holds {n} bytes, expected {raw_len}"))),
                    Ok(None) => return Err(bad(format!("pair {i}: damaged chunk: its header does not give its size"))),
                    Err(_) => return Err(bad(format!("pair {i}: damaged chunk: no zstd frame header"))),
                }
                let raw = zstd::bulk::decompress(chunk, raw_len + 1)
                    .map_err(|err| bad(format!("pair {i}: damaged chunk: {err}")))?;
                if raw.len() != raw_len {
                    return Err(bad(format!("pair {i}: {} bytes, expected {raw_len}", raw.len())));
                }
                let half = raw_len / 2;
                Ok(StoredPair {
                    before: decode_image(&raw[..half], header.size),
                    after: decode_image(&raw[half..], header.size),
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Self { header, pairs })
    }
}

/// What a header must hold for its pairs to be read (by training, `bound`, everything): one chunk per
/// pair, the chunks one after another filling the `data_len` bytes after the header, an image size
/// the pairs can have, and labels and rotations among the 8 angles.
fn check_header(header: &Header, data_len: u64) -> std::result::Result<(), String> {
    if header.chunks.len() != header.pairs.len() {
        return Err(format!("{} pairs but {} chunks in the header", header.pairs.len(), header.chunks.len()));
    }
    if !(1..=equiarm_sim::rotest::pair::MAX_SIZE).contains(&header.size) {
        return Err(format!("image size {} in the header", header.size));
    }
    if let Some(bad_label) = header.pairs.iter().position(|m| m.label >= 8 || m.idx >= 8) {
        return Err(format!("pair {bad_label}: label or rotation outside 0..8"));
    }
    if let Some(i) = header.chunks.iter().position(|c| c.offset.checked_add(c.len).is_none_or(|e| e > data_len)) {
        return Err(format!("pair {i}: chunk runs past the end of the file (truncated?)"));
    }
    // The writer puts the chunks one after another; a header pointing many pairs at one small chunk
    // (which may decompress to 10 MB) would make the reader's memory grow with pairs, not bytes.
    let mut end = 0;
    for (i, c) in header.chunks.iter().enumerate() {
        if c.offset != end {
            return Err(format!(
                "pair {i}: chunk at byte {} after the header; the previous one ends at {end}",
                c.offset
            ));
        }
        end += c.len;
    }
    if end != data_len {
        return Err(format!("{} bytes after the last chunk", data_len - end));
    }
    Ok(())
}
