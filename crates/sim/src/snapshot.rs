//! PNG snapshots of a frame: colour as RGB, depth as 16-bit grey (millimetres, so values are metric
//! and lossless to 1 mm up to 65 m), segmentation as a false-colour RGB image.

use std::path::{Path, PathBuf};

use crate::env::{Env, EnvConfig};
use crate::error::{Result, SimError};
use crate::render::Frame;

/// Paths of the three files written by [`write_pngs`].
#[derive(Clone, Debug)]
pub struct SnapshotFiles {
    /// `<prefix>_color.png`: the colour image, 8-bit RGB.
    pub color: PathBuf,
    /// `<prefix>_depth.png`: planar depth as 16-bit grey in millimetres (clamped to 0..=65535).
    pub depth: PathBuf,
    /// `<prefix>_seg.png`: the segmentation ids in false colour ([`seg_color`]), 8-bit RGB.
    pub segmentation: PathBuf,
    /// Steps taken before the picture ([`snapshot_task`]: fewer than asked when the episode ended).
    pub steps: u32,
}

fn save(path: &Path, bytes: &[u8], w: usize, h: usize, ty: image::ExtendedColorType) -> Result<()> {
    image::save_buffer(path, bytes, w as u32, h as u32, ty)
        .map_err(|e| SimError::Image { file: path.to_path_buf(), message: e.to_string() })
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
        steps: 0,
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

/// Resets an env with `config` and `seed`, takes `expert_steps` expert steps (stopping early when the
/// episode ends: [`SnapshotFiles::steps`] says how many were taken), and writes the uncorrupted
/// colour, depth and segmentation PNGs of the scene into `dir` as `<task>_color.png`,
/// `<task>_depth.png`, `<task>_seg.png`. More steps than an episode has (`config.max_steps`) are
/// refused. For `equiarm sim snapshot`.
pub fn snapshot_task(config: EnvConfig, seed: u64, expert_steps: u32, dir: &Path) -> Result<SnapshotFiles> {
    if expert_steps > config.max_steps {
        let message = format!("{expert_steps} is more than the {} steps an episode has", config.max_steps);
        return Err(SimError::Config { field: "steps", message });
    }
    let task = config.task;
    let mut env = Env::new(config)?;
    let mut obs = env.reset(seed)?;
    let mut taken = 0;
    while taken < expert_steps {
        let r = env.step(&obs.expert_action)?;
        obs = r.observation;
        taken += 1;
        if r.done {
            break;
        }
    }
    let frame = env.render().ok_or(SimError::NotReset)?;
    Ok(SnapshotFiles { steps: taken, ..write_pngs(&frame, dir, task.name())? })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tasks::TaskKind;

    #[test]
    fn snapshot_writes_three_readable_pngs() {
        let dir = std::env::temp_dir().join(format!("equiarm_sim_snapshot_test_{}", std::process::id()));
        let files = snapshot_task(EnvConfig::new(TaskKind::BlockPushing), 1, 0, &dir).unwrap();
        let color = image::open(&files.color).unwrap();
        assert_eq!((color.width(), color.height()), (152, 152));
        let depth = image::open(&files.depth).unwrap().into_luma16();
        // Depth in millimetres: the workspace centre is about 0.8 m from the eye.
        let centre = depth.get_pixel(76, 76).0[0];
        assert!((600..1000).contains(&centre), "centre depth {centre} mm");
        image::open(&files.segmentation).unwrap();
        std::fs::remove_dir_all(&dir).ok();
    }
}

#[cfg(test)]
mod steps_tests {
    use super::*;
    use crate::tasks::TaskKind;

    /// Regression (issue 61): `sim snapshot --steps 4294967295` stopped silently at the episode's end.
    /// More steps than an episode has are refused, naming the flag; an episode that ends early says
    /// how many steps it took.
    #[test]
    fn snapshot_refuses_more_steps_than_an_episode_has_and_says_when_it_ended_early() {
        let dir = std::env::temp_dir().join(format!("equiarm_sim_snapshot_steps_{}", std::process::id()));
        let e = snapshot_task(EnvConfig::new(TaskKind::BlockPulling), 0, u32::MAX, &dir).unwrap_err();
        assert!(e.to_string().contains("`steps`") && e.to_string().contains("4294967295"), "{e}");
        // the expert pulls the block within 50 steps: the episode ends before the 50th
        let files = snapshot_task(EnvConfig::new(TaskKind::BlockPulling), 0, 50, &dir).unwrap();
        assert!(files.steps > 0 && files.steps < 50, "{}", files.steps);
        std::fs::remove_dir_all(&dir).ok();
    }
}
