//! Writes colour, depth (16-bit mm) and segmentation PNGs of a reset scene, per task.
//!
//! cargo run --release -p equiarm_sim --example snapshot -- OUT_DIR [task] [seed] [steps] [preset]
//!
//! `steps` expert steps are taken before the snapshot (default 0); `preset` is a camera preset name
//! (`--help` lists them).

use std::path::PathBuf;

use clap::Parser;
use equiarm_sim::snapshot::snapshot_task;
use equiarm_sim::{EnvConfig, TaskKind, ViewPreset};

/// Colour, depth and segmentation PNGs of a reset scene, per task.
#[derive(Parser, Debug)]
#[command(name = "snapshot")]
struct Args {
    /// Directory the PNGs are written to.
    #[arg(default_value = "snapshots")]
    out_dir: PathBuf,
    /// Only this task (`all`: every task, the default).
    #[arg(default_value = "all")]
    task: String,
    /// Episode seed of the reset.
    #[arg(default_value_t = 0)]
    seed: u64,
    /// Expert steps taken before the snapshot.
    #[arg(default_value_t = 0)]
    steps: u32,
    /// Camera preset.
    #[arg(value_enum, default_value_t = ViewPreset::Side)]
    preset: ViewPreset,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let (out, seed, steps, preset) = (args.out_dir, args.seed, args.steps, args.preset);
    let tasks = TaskKind::select(&args.task)?;
    for task in tasks {
        let mut cfg = EnvConfig::new(task);
        cfg.camera = preset.into();
        let files = snapshot_task(cfg, seed, steps, &out)?;
        println!("{}: {}", task.name(), files.color.display());
    }
    Ok(())
}
