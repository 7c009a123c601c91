//! PNG snapshots of a frame: colour as RGB, depth as 16-bit grey (millimetres, so values are metric
//! and lossless to 1 mm up to 65 m), segmentation as a false-colour RGB image.

use std::path::{Path, PathBuf};

use crate::error::{Result, SimError};
use crate::render::Frame;

/// Paths of the three files written by [`write_pngs`].
#[derive(Clone, Debug)]
pub struct SnapshotFiles {
    pub color: PathBuf,
    pub depth: PathBuf,
    pub segmentation: PathBuf,
}

fn save(path: &Path, bytes: &[u8], w: usize, h: usize, ty: image::ExtendedColorType) -> Result<()> {
    image::save_buffer(path, bytes, w as u32, h as u32, ty).map_err(|e| SimError::Image {
        file: path.to_path_buf(),
        message: e.to_string(),
    })
}

/// False colour of a segmentation id (0 = black).
pub fn seg_color(id: u16) -> [u8; 3] {
    if id == 0 {
        return [0, 0, 0];
    }
    let x = (id as u32).wrapping_mul(2_654_435_761);
    [(x >> 24) as u8 | 0x30, (x >> 16) as u8 | 0x30, (x >> 8) as u8 | 0x30]
}

/// Writes `<prefix>_color.png`, `<prefix>_depth.png` (16-bit, mm) and `<prefix>_seg.png` into `dir`.
pub fn write_pngs(frame: &Frame, dir: &Path, prefix: &str) -> Result<SnapshotFiles> {
    std::fs::create_dir_all(dir).map_err(|e| SimError::Image { file: dir.to_path_buf(), message: e.to_string() })?;
    let files = SnapshotFiles {
        color: dir.join(format!("{prefix}_color.png")),
        depth: dir.join(format!("{prefix}_depth.png")),
        segmentation: dir.join(format!("{prefix}_seg.png")),
    };
    let (w, h) = (frame.width, frame.height);
    save(&files.color, &frame.color, w, h, image::ExtendedColorType::Rgb8)?;
    let mut d16 = Vec::with_capacity(w * h * 2);
    for &z in &frame.depth {
        let mm = (z * 1000.0).round().clamp(0.0, 65535.0) as u16;
        d16.extend_from_slice(&mm.to_ne_bytes());
    }
    save(&files.depth, &d16, w, h, image::ExtendedColorType::L16)?;
    let seg: Vec<u8> = frame.segmentation.iter().flat_map(|&s| seg_color(s)).collect();
    save(&files.segmentation, &seg, w, h, image::ExtendedColorType::Rgb8)?;
    Ok(files)
}
