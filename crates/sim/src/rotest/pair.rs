//! One sample of the experiment: an RGBD image of the scene, the scene rotated by idx·45° about the
//! workspace centre and settled again, a second image, and the label.

use crate::assets::Assets;
use crate::error::{Result, SimError};
use crate::render::{Frame, MeshCache, RenderOptions, rasterize_with};
use crate::rng::Rng;

use super::corruption::{Corruptions, PairCorruption};
use super::scene::{DuckPose, RotScene, camera, sample_placement};

/// Largest stored image side, pixels.
pub const MAX_SIZE: usize = 1024;
/// Largest supersampling factor.
pub const MAX_SUPERSAMPLE: usize = 8;

/// An RGBD image: colour rgb8 and planar depth in metres, row-major, `size` × `size`.
#[derive(Clone, Debug, PartialEq)]
pub struct RgbdImage {
    /// Side, pixels.
    pub size: usize,
    /// rgb8, `size × size × 3` (row, column, channel).
    pub color: Vec<u8>,
    /// Planar depth, m, `size × size`.
    pub depth: Vec<f32>,
}

impl RgbdImage {
    /// Mirrors the image left↔right (columns), colour and depth.
    pub fn reflect(&mut self) {
        crate::corrupt::reflect(&mut self.color, 3, self.size, self.size, true, false);
        crate::corrupt::reflect(&mut self.depth, 1, self.size, self.size, true, false);
    }

    /// Area (box-filter) downsampling of a square frame by the integer factor `frame.width / size`:
    /// each output pixel is the mean of its block (colour rounded to the nearest integer).
    pub fn downsample(frame: &Frame, size: usize) -> Self {
        let f = frame.width / size;
        let n = (f * f) as f32;
        let mut color = vec![0u8; size * size * 3];
        let mut depth = vec![0f32; size * size];
        for r in 0..size {
            for c in 0..size {
                let (mut acc, mut d) = ([0f32; 3], 0f32);
                for rr in r * f..(r + 1) * f {
                    for cc in c * f..(c + 1) * f {
                        let i = rr * frame.width + cc;
                        for (a, &v) in acc.iter_mut().zip(&frame.color[i * 3..i * 3 + 3]) {
                            *a += v as f32;
                        }
                        d += frame.depth[i];
                    }
                }
                let o = r * size + c;
                for k in 0..3 {
                    color[o * 3 + k] = (acc[k] / n).round() as u8;
                }
                depth[o] = d / n;
            }
        }
        Self { size, color, depth }
    }
}

/// What is known about a generated pair besides its images.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PairMeta {
    /// Rotation applied, in units of 45° (0..8), counter-clockwise seen from above.
    pub idx: u8,
    /// Class label: `idx`, or with invert-label and duck 0 left of duck 1, (8 − idx) mod 8.
    pub label: u8,
    /// Duck poses in the first image (after settling).
    pub before: [DuckPose; 3],
    /// Duck poses in the second image (after rotating and settling again).
    pub after: [DuckPose; 3],
    /// Light colour of the pair (white unless `random_light_color`).
    pub light_color: [f32; 3],
}

/// A generated pair.
#[derive(Clone, Debug, PartialEq)]
pub struct Pair {
    /// Image before the rotation.
    pub before: RgbdImage,
    /// Image after the rotation.
    pub after: RgbdImage,
    /// Label and poses.
    pub meta: PairMeta,
}

/// How pairs are rendered.
#[derive(Clone, Debug, PartialEq)]
pub struct PairConfig {
    /// Stored image side, pixels (152 in the paper).
    pub size: usize,
    /// Images are rendered at `size · supersample` and area-downsampled (the paper renders 512² and
    /// downsamples to 152²).
    pub supersample: usize,
    /// The corruption setting.
    pub corruptions: Corruptions,
}

impl PairConfig {
    /// Checks the sizes: `size` in 8..=[`MAX_SIZE`], `supersample` in 1..=[`MAX_SUPERSAMPLE`].
    pub fn validate(&self) -> Result<()> {
        if !(8..=MAX_SIZE).contains(&self.size) {
            return Err(SimError::Config {
                field: "size",
                message: format!("{} must be in 8..={MAX_SIZE}", self.size),
            });
        }
        if !(1..=MAX_SUPERSAMPLE).contains(&self.supersample) {
            return Err(SimError::Config {
                field: "supersample",
                message: format!("{} must be in 1..={MAX_SUPERSAMPLE}", self.supersample),
            });
        }
        Ok(())
    }
}

/// The base light of the experiment: straight down (so the clean scene has no preferred direction),
/// white, ambient 0.35, diffuse 0.65; 0.2 m checker tiles for `grid`.
pub fn base_light() -> RenderOptions {
    RenderOptions { light_dir: [0.0, 0.0, 1.0], checker_tile: 0.2, ..RenderOptions::default() }
}

/// Renders the scene under the corruptions' camera and light, downsampled, mirrored with `reflect`.
pub fn render(rs: &RotScene, cfg: &PairConfig, light_color: [f32; 3]) -> Result<RgbdImage> {
    let c = &cfg.corruptions;
    let hi = cfg.size * cfg.supersample;
    let cam = camera(hi, c.has(PairCorruption::Side), c.has(PairCorruption::Squeeze))?;
    let meshes = MeshCache::new(&rs.scene);
    let mut opts = base_light();
    opts.light_color = light_color;
    if c.has(PairCorruption::LightEffect) {
        opts.light_dir = [-1.0, 0.0, 0.7];
        opts.specular = 0.5;
        opts.shadows = true;
    }
    let draw = |o: &RenderOptions| {
        let mut f = Frame::new(hi, hi, cam.config.far as f32);
        rasterize_with(&rs.scene, &meshes, &cam, o, &mut f);
        f
    };
    // Two halves rendered under two settings: left columns from `a`, right columns from `b`.
    let halves = |a: RenderOptions, b: RenderOptions| {
        let (mut left, right) = (draw(&a), draw(&b));
        for row in 0..hi {
            let s = (row * hi + hi / 2) * 3;
            let e = (row + 1) * hi * 3;
            left.color[s..e].copy_from_slice(&right.color[s..e]);
        }
        left
    };
    // The two halves' settings: light colour (two_light_color) and specular (two_specular).
    let (mut left, mut right) = (opts.clone(), opts.clone());
    if c.has(PairCorruption::TwoLightColor) {
        left.light_color = [1.0, 0.2, 0.2];
        right.light_color = [0.2, 0.2, 1.0];
    }
    if c.has(PairCorruption::TwoSpecular) {
        left.specular = 0.0;
        right.specular = 0.2;
    }
    let frame = if c.has(PairCorruption::TwoLightColor) || c.has(PairCorruption::TwoSpecular) {
        halves(left, right)
    } else {
        draw(&opts)
    };
    let mut img = RgbdImage::downsample(&frame, cfg.size);
    if c.has(PairCorruption::Reflect) {
        img.reflect();
    }
    Ok(img)
}

/// Generates one pair from `seed`: place and settle the ducks, render; draw idx ∈ 0..8, rotate the
/// scene by idx·45° about the workspace centre (yaws too), settle, render; label by the corruption
/// setting. The same seed, config and build give the same pair.
pub fn generate_pair(assets: &Assets, cfg: &PairConfig, seed: u64) -> Result<Pair> {
    cfg.validate()?;
    let c = &cfg.corruptions;
    let mut rng = Rng::new(seed);
    let placement = sample_placement(&mut rng, c.has(PairCorruption::FullCircle));
    let idx = (rng.next_u64() % 8) as u8;
    // Drawn last, so that a seed gives the same scene and rotation under every setting.
    let light_color =
        if c.has(PairCorruption::RandomLightColor) { [0; 3].map(|_| rng.uniform(0.2, 1.0)) } else { [1.0; 3] };
    let mut rs = RotScene::new(assets, &placement, c.has(PairCorruption::Grid), c.has(PairCorruption::Occlusion))?;
    rs.settle();
    let before_poses = rs.poses();
    let before = render(&rs, cfg, light_color)?;
    rs.rotate_scene(idx as f32 * std::f32::consts::FRAC_PI_4);
    rs.settle();
    let after_poses = rs.poses();
    let after = render(&rs, cfg, light_color)?;
    let label = c.label(idx, before_poses[0].y, before_poses[1].y);
    Ok(Pair { before, after, meta: PairMeta { idx, label, before: before_poses, after: after_poses, light_color } })
}

/// The rotation (in units of 45°, 0..8) that best maps the `before` poses onto the `after` poses
/// about the workspace centre: the k minimising the summed squared distance between the rotated
/// `before` positions and the `after` positions.
pub fn recover_idx(before: &[DuckPose; 3], after: &[DuckPose; 3]) -> u8 {
    let cx = super::scene::CENTRE;
    let err = |k: u8| -> f32 {
        let (s, c) = (k as f32 * std::f32::consts::FRAC_PI_4).sin_cos();
        before
            .iter()
            .zip(after)
            .map(|(b, a)| {
                let (dx, dy) = (b.x - cx[0], b.y - cx[1]);
                let (x, y) = (cx[0] + c * dx - s * dy, cx[1] + s * dx + c * dy);
                (x - a.x).powi(2) + (y - a.y).powi(2)
            })
            .sum()
    };
    (0..8u8).min_by(|&a, &b| err(a).total_cmp(&err(b))).unwrap_or(0)
}
