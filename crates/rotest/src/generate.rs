//! Dataset generation (in parallel over pairs, each pair from its own seed) and the snapshot PNGs.

use std::path::{Path, PathBuf};

use equiarm_sim::Assets;
use equiarm_sim::rotest::{Corruptions, Pair, PairConfig, generate_pair};
use rayon::prelude::*;

use crate::dataset::{Dataset, Header, StoredImage, StoredPair, pair_seed};
use crate::error::{Result, RotestError};
use equiarm_types::files::at;

/// Largest number of pairs one dataset may hold.
pub const MAX_PAIRS: usize = 1_000_000;

/// Generates `pairs` pairs of `cfg` from `seed`: pair `i` from [`pair_seed`]`(seed, i)`, so the
/// result does not depend on the number of threads.
pub fn generate(cfg: &PairConfig, pairs: usize, seed: u64) -> Result<Dataset> {
    if !(1..=MAX_PAIRS).contains(&pairs) {
        return Err(RotestError::Config { field: "--pairs", message: format!("{pairs} must be in 1..={MAX_PAIRS}") });
    }
    cfg.validate()?;
    let assets = Assets::bundled()?;
    let generated: Vec<Pair> = (0..pairs as u64)
        .into_par_iter()
        .map(|i| generate_pair(&assets, cfg, pair_seed(seed, i)))
        .collect::<Result<_, _>>()?;
    let mut metas = Vec::with_capacity(pairs);
    let mut stored = Vec::with_capacity(pairs);
    for p in generated {
        stored.push(StoredPair { before: StoredImage::from_rgbd(&p.before), after: StoredImage::from_rgbd(&p.after) });
        metas.push(p.meta);
    }
    let header = Header {
        size: cfg.size,
        supersample: cfg.supersample,
        corrupt: cfg.corruptions.name(),
        seed,
        pairs: metas,
        chunks: Vec::new(),
    };
    Ok(Dataset { header, pairs: stored })
}

/// File-name form of a setting: commas become `+` (`side+grid.png`).
pub fn setting_file_stem(c: &Corruptions) -> String {
    c.name().replace(',', "+")
}

/// Writes `dir/<setting>.png`: one row per pair of `ds` (at most `rows`), each row the colour images
/// before and after, then the depth images before and after (grey, nearer is brighter, scaled per
/// image), separated by 4 white pixels.
pub fn write_snapshot(ds: &Dataset, rows: usize, dir: &Path, stem: &str) -> Result<PathBuf> {
    std::fs::create_dir_all(dir).map_err(at(dir))?;
    let path = dir.join(format!("{stem}.png"));
    let s = ds.header.size;
    let rows = rows.min(ds.len()).max(1);
    let gap = 4;
    let (w, h) = (4 * s + 3 * gap, rows * s + (rows - 1) * gap);
    let mut img = image::RgbImage::from_pixel(w as u32, h as u32, image::Rgb([255, 255, 255]));
    for (r, p) in ds.pairs.iter().take(rows).enumerate() {
        let y0 = r * (s + gap);
        for (k, im) in [&p.before, &p.after].into_iter().enumerate() {
            let x0 = k * (s + gap);
            for i in 0..s * s {
                let c = &im.color[i * 3..i * 3 + 3];
                img.put_pixel((x0 + i % s) as u32, (y0 + i / s) as u32, image::Rgb([c[0], c[1], c[2]]));
            }
            let d: Vec<f32> = im.depth.iter().map(|d| d.to_f32()).collect();
            let lo = d.iter().copied().fold(f32::INFINITY, f32::min);
            let hi = d.iter().copied().fold(f32::NEG_INFINITY, f32::max);
            let x0 = (2 + k) * (s + gap);
            for (i, v) in d.iter().enumerate() {
                let g = if hi > lo { (255.0 * (hi - v) / (hi - lo)).round() as u8 } else { 128 };
                img.put_pixel((x0 + i % s) as u32, (y0 + i / s) as u32, image::Rgb([g, g, g]));
            }
        }
    }
    img.save(&path).map_err(|e| RotestError::Image { path: path.clone(), message: e.to_string() })?;
    Ok(path)
}
