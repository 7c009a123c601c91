//! `equiarm bag`: describe, evaluate, play and repair bags.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use anyhow::{Context as _, bail};
use clap::Subcommand;
use equiarm_nodes::ros::RosOptions;
use equiarm_types::OBS_PLANES;

use super::nn::NetPreset;

/// `equiarm bag` subcommands.
#[derive(Subcommand)]
pub enum BagCommand {
    /// Files, duration, topics with types, counts and sizes (like `ros2 bag info`).
    Info {
        /// Bag directory or .mcap file.
        bag: PathBuf,
    },
    /// Per-episode success and returns, success rates with Wilson 95 % intervals.
    Eval {
        /// Bag directory or .mcap file.
        bag: PathBuf,
        /// Discount for episodes reconstructed from transitions.
        #[arg(long, default_value_t = equiarm_sac::agent::GAMMA)]
        gamma: f64,
        /// Print JSON instead of a table.
        #[arg(long)]
        json: bool,
        /// Instead of episode metrics: run this actor over the recorded Transitions and report its
        /// agreement with the recorded actions per dimension. A checkpoint or run directory (its
        /// latest checkpoint) gives the architecture from its manifest; an actor .safetensors
        /// file needs --net and --config.
        #[arg(long, value_name = "CKPT")]
        policy: Option<PathBuf>,
        /// The checkpoint's network: equi or cnn.
        #[arg(long, default_value = "equi")]
        net: String,
        /// An actor file's architecture: paper (hidden 64, 128 px) or reduced (the networks
        /// crate's reduced size: hidden 16, 64 px).
        #[arg(long, value_enum, default_value_t = NetPreset::Paper)]
        config: NetPreset,
    },
    /// Re-publishes a bag's messages on their topics at the recorded pace (like `ros2 bag play`).
    Play {
        /// Bag directory or .mcap file.
        bag: PathBuf,
        /// Speed factor (2 = twice as fast; 0 = as fast as possible).
        #[arg(long, default_value_t = 1.0, value_parser = equiarm_nodes::cli_values::rate)]
        rate: f64,
        /// Publish topic FROM on TO instead, given as FROM:TO (repeatable).
        #[arg(long = "remap", value_name = "FROM:TO")]
        remaps: Vec<String>,
        /// Milliseconds to wait after creating publishers before the first message, so subscribers
        /// can match.
        #[arg(long, default_value_t = 1000, value_parser = equiarm_nodes::cli_values::millis_or_zero)]
        wait_ms: u64,
        /// Lock-step: after each Observation wait for the GripperCommand naming its seq on the sibling
        /// gripper_cmd topic (re-publishing every this many ms), instead of the recorded pace.
        #[arg(long, value_name = "MS", value_parser = equiarm_nodes::cli_values::millis)]
        lockstep: Option<u64>,
        /// Refuse a damaged or truncated bag (exit 1) instead of playing what is readable; without
        /// it the damage is warned, as `bag info` reports it, and play goes on.
        #[arg(long)]
        strict: bool,
    },
    /// Writes the bag's steps in a format other tools read: `lerobot`, a LeRobotDataset v3.0
    /// directory (one row per step: colour and depth, holding, the normalised action, reward, done,
    /// success, task and where the action came from; docs/nodes.md, "Exports").
    Export {
        /// Bag directory or .mcap file.
        bag: PathBuf,
        /// The format.
        #[arg(long, value_enum)]
        format: ExportFormat,
        /// The new directory (refused if it exists and is not empty).
        out: PathBuf,
    },
    /// Writes one MP4 per episode: colour beside depth, a caption with the step, reward and action
    /// source, one frame per step plus the last, at the simulated rate (docs/nodes.md, "Exports").
    Video {
        /// Bag directory or .mcap file.
        bag: PathBuf,
        /// The directory for the videos (created), named ENV_epNNNN.mp4.
        #[arg(long)]
        out: PathBuf,
        /// Only these episodes: a comma-separated list of ENV:EPISODE, ENV (all of it) and eval
        /// (every evaluation episode), e.g. `env0:3,eval`.
        #[arg(long, value_parser = equiarm_export::video::Selection::parse)]
        episodes: Option<equiarm_export::video::Selection>,
    },
    /// Rewrites a bag whose recorder was killed as a complete, indexed bag.
    Recover {
        /// The damaged bag directory or .mcap file.
        input: PathBuf,
        /// The new bag directory.
        output: PathBuf,
    },
}

/// What `equiarm bag export` writes.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum ExportFormat {
    /// A LeRobotDataset v3.0 directory (Parquet), for LeRobot's `LeRobotDataset(repo_id, root=OUT)`.
    Lerobot,
}

/// Runs `equiarm bag`.
pub fn run(c: BagCommand) -> anyhow::Result<ExitCode> {
    match c {
        BagCommand::Info { bag } => {
            let info = equiarm_bag::Reader::open(&bag)?.info()?;
            print!("{}", equiarm_train::bag_report::info_text(&bag, &info));
        }
        BagCommand::Eval { bag, policy: Some(ckpt), net, config, json, .. } => {
            let a = eval_policy(&bag, ckpt, net, config)?;
            if json {
                println!("{}", a.json());
            } else {
                print!("{}", a.table());
            }
        }
        BagCommand::Eval { bag, gamma, json, policy: None, .. } => {
            let report = equiarm_train::bag_report::eval(&bag, gamma)?;
            if json {
                println!("{}", report.json()?);
            } else {
                print!("{}", report.table());
            }
        }
        BagCommand::Play { bag, rate, remaps, wait_ms, lockstep, strict } => {
            let mut pairs = Vec::new();
            for r in &remaps {
                let Some((from, to)) = r.split_once(':') else { bail!("remap '{r}' must be FROM:TO") };
                pairs.push((from.to_string(), to.to_string()));
            }
            let cfg = equiarm_nodes::player::PlayConfig {
                bag,
                rate,
                remaps: pairs,
                wait_for_match: Duration::from_millis(wait_ms),
                lockstep: lockstep.map(Duration::from_millis),
                strict,
            };
            let opts = RosOptions::from_env()?;
            let (published, skipped) = super::runtime()?.block_on(equiarm_nodes::player::run(&opts, cfg))?;
            println!("published {published} messages ({skipped} skipped)");
        }
        BagCommand::Export { bag, format: ExportFormat::Lerobot, out } => {
            let r = equiarm_export::lerobot::export(&bag, &out)?;
            for d in &r.steps.damage {
                log::warn!("{}: {d} (skipped)", bag.display());
            }
            let s = &r.steps;
            println!(
                "{}: {} episodes ({} cut short), {} frames of {}x{} px at {} fps, {} task(s) → {}",
                bag.display(),
                r.episodes,
                s.episodes.1,
                r.frames,
                r.size.0,
                r.size.1,
                r.fps,
                r.tasks.len(),
                out.display()
            );
            println!(
                "transitions joined {}, unmatched {}, duplicate observations {}, undecodable messages {}",
                s.joined, s.unmatched, s.duplicates, s.undecodable
            );
        }
        BagCommand::Video { bag, out, episodes } => {
            let r = equiarm_export::video::bag_videos(&bag, &out, &episodes.unwrap_or_default())?;
            for d in &r.steps.damage {
                log::warn!("{}: {d} (skipped)", bag.display());
            }
            for (p, frames) in &r.files {
                println!("{} ({frames} frames)", p.display());
            }
            println!("{} video(s) in {}", r.files.len(), out.display());
        }
        BagCommand::Recover { input, output } => {
            let r = equiarm_bag::recover(&input, &output, equiarm_bag::WriterOptions::default())?;
            for (p, why) in &r.truncated {
                eprintln!("{}: read up to the last complete chunk ({why})", p.display());
            }
            for l in &r.lost {
                eprintln!("{}", equiarm_train::bag_report::lost_text(l));
            }
            for d in &r.damaged_channels {
                eprintln!(
                    "{}: channel {} ({}) is damaged: {}; its {} messages are not copied",
                    input.display(),
                    equiarm_msgs::shown(&d.topic),
                    equiarm_msgs::shown(&d.type_name),
                    d.reason,
                    d.messages
                );
            }
            for f in &r.missing_files {
                eprintln!(
                    "{}: metadata.yaml lists {f}, which is not in the bag directory: its messages are lost",
                    input.display()
                );
            }
            println!("recovered {} messages into {}", r.summary.messages, r.summary.dir.display());
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// The agreement of the actor `ckpt` with the bag's recorded actions; a checkpoint or run
/// directory names its architecture in its manifest, a bare actor file takes `net` and `preset`.
fn eval_policy(
    bag: &std::path::Path,
    ckpt: PathBuf,
    net: String,
    preset: NetPreset,
) -> anyhow::Result<equiarm_train::policy_eval::Agreement> {
    let (ckpt, net, cfg) = if equiarm_train::rundir::names_checkpoint(&ckpt) {
        let dir = equiarm_train::rundir::find_checkpoint(&ckpt)?;
        let m = equiarm_sac::learner::read_manifest(&dir)?;
        let a = &m.config.agent;
        let cfg = equiarm_nn::nets::NetConfig::new(a.hidden, a.input_size, OBS_PLANES);
        (dir.join("actor.safetensors"), a.model.name().to_string(), cfg)
    } else {
        (ckpt, net, preset.config(None))
    };
    equiarm_train::policy_eval::evaluate(bag, &ckpt, &net, &cfg)
        .with_context(|| format!("evaluating {} on {}", ckpt.display(), bag.display()))
}
