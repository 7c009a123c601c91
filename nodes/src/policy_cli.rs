//! `equiarm policy`'s options and the actor architecture they describe (a checkpoint's manifest, or
//! the flags over the default preset (`reduced16`)).

use std::path::PathBuf;

use anyhow::bail;
use equiarm_sac::agent::AgentConfig;
use equiarm_sac::config::{Preset, TrainConfig};
use equiarm_types::{ModelKind, TaskKind};

use equiarm_train::policy::PolicyMode;

/// Options of `equiarm policy`.
#[derive(Clone, Debug, clap::Args)]
pub struct PolicyArgs {
    /// Namespace of the node and its relative topics (the env's namespace).
    #[arg(long, default_value = "/env0", value_parser = crate::cli_values::env_namespace)]
    pub namespace: String,
    /// How to act.
    #[arg(long, value_enum, default_value = "sample")]
    pub mode: PolicyMode,
    /// Initial actor: an actor .safetensors file, a checkpoint directory, or a run directory (its
    /// latest checkpoint). Directories give the architecture from their manifest.
    #[arg(long)]
    pub checkpoint: Option<PathBuf>,
    /// Network family when there is no manifest (default: the default preset's).
    #[arg(long, value_enum)]
    pub model: Option<ModelKind>,
    /// Hidden size when there is no manifest (default: the default preset's).
    #[arg(long)]
    pub hidden: Option<usize>,
    /// Frame and network input size as FRAME:INPUT when there is no manifest (default: the default preset's).
    #[arg(long, value_name = "FRAME:INPUT")]
    pub image: Option<crate::cli_values::ImageSizes>,
    /// Seed of the initial weights, the sampling noise and the random mode.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Topic of the trainer's weights.
    #[arg(long, default_value = "/policy/weights")]
    pub weights_topic: String,
    /// Answer the first K episodes of the env with the expert's action (source EXPERT): the
    /// demonstrations of docs/paper.md §2 (the trainer keeps only the successful ones).
    #[arg(long, default_value_t = 0)]
    pub expert_episodes: u32,
    /// Flow control for the paper's update-to-data ratio: once the trainer has started updating,
    /// act at most this many policy steps ahead of its update count (from /trainer/status);
    /// 0 = no limit. With N envs and one update per N transitions, each env then makes about one
    /// step per update, as in the paper's synchronous loop.
    #[arg(long, default_value_t = 0, value_parser = crate::cli_values::steps)]
    pub max_lead: u64,
    /// With --max-lead: policy steps allowed per trainer update (1 for training envs; an eval env
    /// needs about eval_episodes × episode length / eval_every).
    #[arg(long, default_value_t = 1, value_parser = crate::cli_values::positive_steps)]
    pub steps_per_update: u64,
    /// Lock-step with a trainer run with --deterministic: the k-th observation answered (from 0,
    /// expert steps included) waits for weights version k + 1. Needs mode sample or greedy; excludes --max-lead.
    #[arg(long)]
    pub deterministic: bool,
    /// The evaluation env's pacing: start episodes only in evaluation windows, --eval-episodes of
    /// them once the weights in use were taken at the next multiple of N updates (the trainer's
    /// evaluations), and wait at an episode's first observation in between. Needs mode sample or
    /// greedy; excludes --max-lead and --deterministic.
    #[arg(long, value_name = "N", value_parser = crate::cli_values::positive_updates, conflicts_with_all = ["max_lead", "deterministic"])]
    pub eval_every: Option<u64>,
    /// With --eval-every: episodes per evaluation window (the trainer's eval_episodes).
    #[arg(long, value_name = "K", default_value_t = 20, value_parser = crate::cli_values::positive_episodes, requires = "eval_every")]
    pub eval_episodes: u64,
    /// No latency lines.
    #[arg(long, short)]
    pub quiet: bool,
}

/// The actor's architecture and initial weights the options describe: (agent config, frame size,
/// actor file). A directory's manifest wins over the flags.
pub fn architecture(args: &PolicyArgs) -> anyhow::Result<(AgentConfig, usize, Option<PathBuf>)> {
    if let Some(path) = args.checkpoint.as_ref().filter(|p| equiarm_train::rundir::names_checkpoint(p)) {
        let dir = equiarm_train::rundir::find_checkpoint(path)?;
        let m = equiarm_sac::learner::read_manifest(&dir)?;
        return Ok((m.config.agent.clone(), m.config.image_size, Some(dir.join("actor.safetensors"))));
    }
    let preset = TrainConfig::preset(Preset::DEFAULT, TaskKind::BlockPulling);
    let mut agent = preset.agent.clone();
    let mut frame = preset.image_size;
    if let Some(m) = args.model {
        agent.model = m;
    }
    agent.hidden = args.hidden.unwrap_or(agent.hidden);
    if let Some(img) = args.image {
        (frame, agent.input_size) = (img.frame, img.input);
    }
    if agent.input_size > frame {
        bail!("--image: the network input {} is larger than the frame {frame}", agent.input_size);
    }
    Ok((agent, frame, args.checkpoint.clone()))
}
