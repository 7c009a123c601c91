//! `equiarm sim`: the simulated environment node, and `sim snapshot`.

use std::process::ExitCode;

use clap::Subcommand;
use equiarm_nodes::ros::RosOptions;

/// `equiarm sim`'s arguments: the node's options, or a subcommand.
#[derive(clap::Args)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct SimCommand {
    #[command(subcommand)]
    sub: Option<SimSubcommand>,
    #[command(flatten)]
    args: equiarm_nodes::sim::SimArgs,
}

/// `equiarm sim` subcommands.
#[derive(Subcommand)]
enum SimSubcommand {
    /// Writes the colour, depth (16-bit, mm) and segmentation PNGs of a task's reset scene.
    Snapshot {
        /// Task.
        #[arg(long, value_enum)]
        task: equiarm_types::TaskKind,
        /// Output folder (created if missing); files are `<task>_color.png`, `_depth.png`, `_seg.png`.
        #[arg(long)]
        out: std::path::PathBuf,
        /// Seed of the reset.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Expert steps to take before the picture.
        #[arg(long, default_value_t = 0)]
        steps: u32,
        /// Camera preset.
        #[arg(long, value_enum)]
        view: Option<equiarm_types::ViewPreset>,
        /// Whether the arm carrying the gripper is drawn (default visible).
        #[arg(long, value_enum)]
        arm: Option<equiarm_types::ArmView>,
    },
}

/// Runs `equiarm sim`: the node until SIGINT/SIGTERM, or a snapshot.
pub fn run(c: SimCommand) -> anyhow::Result<ExitCode> {
    match c.sub {
        Some(SimSubcommand::Snapshot { task, out, seed, steps, view, arm }) => {
            for f in equiarm_nodes::sim::snapshot(task, seed, steps, view, arm, &out)? {
                println!("{}", f.display());
            }
        }
        None => {
            let opts = RosOptions::from_env()?;
            super::runtime()?.block_on(equiarm_nodes::sim::run(&c.args, &opts))?;
        }
    }
    Ok(ExitCode::SUCCESS)
}
