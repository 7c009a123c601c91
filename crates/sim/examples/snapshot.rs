//! Writes colour, depth (16-bit mm) and segmentation PNGs of a reset scene, per task.
//!
//! cargo run --release -p equiarm_sim --example snapshot -- OUT_DIR [task] [seed] [steps] [preset]
//!
//! `steps` expert steps are taken before the snapshot (default 0); `preset` is a camera preset name
//! (side, angle15 … angle90).

use std::path::PathBuf;

use equiarm_sim::snapshot::snapshot_task;
use equiarm_sim::{EnvConfig, TaskKind, ViewPreset};

fn main() -> Result<(), equiarm_sim::SimError> {
    let args: Vec<String> = std::env::args().collect();
    let out = PathBuf::from(args.get(1).map(String::as_str).unwrap_or("snapshots"));
    let only = args.get(2).and_then(|s| TaskKind::from_name(s));
    let seed: u64 = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(0);
    let steps: u32 = args.get(4).and_then(|s| s.parse().ok()).unwrap_or(0);
    let preset = args.get(5).and_then(|s| ViewPreset::from_name(s)).unwrap_or(ViewPreset::Side);
    for task in TaskKind::ALL {
        if only.is_some_and(|t| t != task) {
            continue;
        }
        let mut cfg = EnvConfig::new(task);
        cfg.camera = preset.config();
        let files = snapshot_task(cfg, seed, steps, &out)?;
        println!("{}: {}", task.name(), files.color.display());
    }
    Ok(())
}
