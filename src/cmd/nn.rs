//! `equiarm nn`: diagnostics of saved (or freshly initialised) equivariant networks.

use std::process::ExitCode;

use anyhow::{Context as _, bail};
use clap::Subcommand;
use equiarm_nn::diagnostics::NetKind;
use equiarm_nn::nets::NetConfig;

/// A network file's architecture when nothing records it (`nn check-equivariance`, `bag eval
/// --policy` on a bare actor file).
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum NetPreset {
    /// The paper's networks: hidden 64, 128 px input (the rotation experiment's for rot-equi).
    Paper,
    /// The networks crate's reduced size: hidden 16, 64 px input.
    Reduced,
}

impl NetPreset {
    /// The architecture of the preset for a network of `kind` (any, when not known).
    pub fn config(self, kind: Option<NetKind>) -> NetConfig {
        match (self, kind) {
            (NetPreset::Paper, Some(NetKind::RotEqui)) => NetConfig::paper_rotation(),
            (NetPreset::Paper, _) => NetConfig::paper(),
            (NetPreset::Reduced, _) => NetConfig::reduced_cpu(),
        }
    }
}

/// `equiarm nn` subcommands.
#[derive(Subcommand)]
pub enum NnCommand {
    /// Measures a network's equivariance error ||f(g.x) - g.f(x)|| / ||f(x)|| per group element on
    /// random inputs: near 1e-6 for a correct equivariant network, trained or not.
    CheckEquivariance {
        /// safetensors checkpoint of the network (omit with --fresh).
        checkpoint: Option<std::path::PathBuf>,
        /// Check the seeded initial weights instead of a file.
        #[arg(long, conflicts_with = "checkpoint")]
        fresh: bool,
        /// Which network the file holds: equi-actor, equi-critic or rot-equi.
        #[arg(long, default_value = "equi-actor")]
        net: String,
        /// Architecture: `paper` (hidden 64, 128 px) or `reduced` (hidden 16, 64 px); the flags below override it.
        #[arg(long, value_enum, default_value_t = NetPreset::Paper)]
        config: NetPreset,
        /// Hidden size (regular fields of the encoder output), 8..=512.
        #[arg(long, value_parser = |s: &str| within(s, "fields", 8, equiarm_sac::config::MAX_HIDDEN))]
        hidden: Option<usize>,
        /// Input size in pixels, 8..=256.
        #[arg(long, value_parser = |s: &str| within(s, "px", 8, 256))]
        size: Option<usize>,
        /// Input channels, 1..=16.
        #[arg(long, value_parser = |s: &str| within(s, "channels", 1, 16))]
        channels: Option<usize>,
        /// Random inputs to average over, 1..=64.
        #[arg(long, default_value_t = 2, value_parser = |s: &str| within(s, "inputs", 1, 64))]
        batch: usize,
        /// Seed of the inputs (and of the fresh weights).
        #[arg(long, default_value_t = 0)]
        seed: u64,
    },
}

/// A size flag of `nn check-equivariance` in `min ..= max`: every size allocates the network's
/// tensors before any check, so a typo must fail at the flag.
fn within(s: &str, unit: &str, min: usize, max: usize) -> Result<usize, equiarm_nodes::cli_values::BadValue> {
    equiarm_nodes::cli_values::bounded(s, unit, min as u64, max as u64).map(|v| v as usize)
}

/// Runs `equiarm nn`.
pub fn run(c: NnCommand) -> anyhow::Result<ExitCode> {
    let NnCommand::CheckEquivariance { checkpoint, fresh, net, config, hidden, size, channels, batch, seed } = c;
    let kind: NetKind = net.parse()?;
    let mut cfg = config.config(Some(kind));
    cfg.hidden = hidden.unwrap_or(cfg.hidden);
    cfg.input_size = size.unwrap_or(cfg.input_size);
    cfg.in_channels = channels.unwrap_or(cfg.in_channels);
    if checkpoint.is_none() && !fresh {
        bail!("give a checkpoint file, or --fresh to check the seeded initial weights");
    }
    let device = equiarm_nn::burn::tensor::Device::flex();
    let errors = equiarm_nn::diagnostics::check_checkpoint(kind, &cfg, checkpoint.as_deref(), batch, seed, &device)
        .with_context(|| format!("checking the equivariance of {net} ({config:?} config)"))?;
    println!("element (flip, rot)   relative error");
    for e in errors {
        println!("({}, {})                {:.3e}", e.element.flip, e.element.rot, e.relative_error);
    }
    Ok(ExitCode::SUCCESS)
}
