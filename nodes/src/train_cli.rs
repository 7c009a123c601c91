//! `equiarm train`: the options shared by the in-process loop (`--in-process`) and the trainer node
//! over DDS, turned into one validated [`TrainConfig`], and the in-process runner.
//!
//! The config is built in this order: the preset (`--preset reduced|reduced16|paper`, for `--task`), then a
//! JSON file (`--config`, which replaces the preset), then the individual flags. `--print-config`
//! shows the result without running.

use std::path::PathBuf;

use anyhow::{Context as _, bail};
use equiarm_nn::burn::tensor::Device;
use equiarm_sac::config::{Preset, TrainConfig};
use equiarm_train::inprocess::RunOptions;
use equiarm_train::record::RunSummary;
use equiarm_types::{Augmentation, AugmentationKind, Corruption, ModelKind, TaskKind, ViewPreset};

use crate::signals::{CHECKPOINT_AND_STOP, stop_flag};

/// Options of `equiarm train`.
#[derive(Clone, Debug, clap::Args)]
pub struct TrainArgs {
    /// Run the envs inside this process (no DDS): the transport-free loop.
    #[arg(long)]
    pub in_process: bool,
    /// Preset: `reduced16` (38 → 32 px frames, hidden 16, 1.5× the paper's update count: about
    /// 45 min of training on 2 cores), `reduced` (the same frames at hidden 8 and a quarter of the
    /// paper's updates: fast, learns little) or `paper` (docs/paper.md §2; meant for a GPU).
    #[arg(long, value_enum, default_value_t = Preset::DEFAULT)]
    pub preset: Preset,
    /// JSON config file (replaces the preset; flags below still override it).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Task (default: block_pulling).
    #[arg(long, value_enum)]
    pub task: Option<TaskKind>,
    /// Network family (FERM also sets --augmentation to independent crops).
    #[arg(long, value_enum)]
    pub model: Option<ModelKind>,
    /// Base seed.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Gradient updates to train for.
    #[arg(long)]
    pub total_updates: Option<u64>,
    /// Training envs (in-process) / expected sim+policy pairs (over DDS).
    #[arg(long)]
    pub num_envs: Option<usize>,
    /// Evaluate every N updates (0: never).
    #[arg(long)]
    pub eval_every: Option<u64>,
    /// Episodes per evaluation.
    #[arg(long)]
    pub eval_episodes: Option<usize>,
    /// Successful expert episodes preloaded (in-process) / expected from expert pairs (over DDS).
    #[arg(long)]
    pub demo_episodes: Option<usize>,
    /// Batch size.
    #[arg(long)]
    pub batch_size: Option<usize>,
    /// Hidden size of the networks.
    #[arg(long)]
    pub hidden: Option<usize>,
    /// Adam learning rate of the critic, actor and α (the paper's: 1e-3).
    #[arg(long)]
    pub lr: Option<f64>,
    /// Anneal the learning rate from --lr to this value over the run (half cosine); `none` keeps it
    /// constant (the paper).
    #[arg(long, value_name = "LR|none")]
    pub lr_final: Option<crate::cli_values::LrFinal>,
    /// Precision of the convolutions' matrix products: f32 (the default) or bf16 (Intel AMX:
    /// operands rounded to bfloat16, f32 sums; faster where the CPU has AMX). Part of the config
    /// (`agent.matmul`).
    #[arg(long)]
    pub matmul: Option<equiarm_nn::kernels::MatmulPrecision>,
    /// Rendered frame size and network input size, as FRAME:INPUT (e.g. 76:64, 152:128).
    #[arg(long, value_name = "FRAME:INPUT")]
    pub image: Option<crate::cli_values::ImageSizes>,
    /// Camera preset: side (the paper's oblique view), angle15 … angle90 (the view-angle sweep).
    #[arg(long, value_enum)]
    pub view: Option<ViewPreset>,
    /// Symmetry corruptions (docs/paper.md §5).
    #[arg(long, value_name = "none|NAME,…", help = crate::cli_values::corruption_help())]
    pub corrupt: Option<Corruption>,
    /// Augmentation (drq: K = M = 2).
    #[arg(long, value_enum)]
    pub augmentation: Option<AugmentationKind>,
    /// Checkpoint every N updates.
    #[arg(long)]
    pub checkpoint_every: Option<u64>,
    /// In-process: also checkpoint whenever this many minutes of training passed since the last
    /// checkpoint (for slow configs, whose checkpoint_every updates take long).
    #[arg(long, value_parser = crate::cli_values::positive_minutes)]
    pub checkpoint_minutes: Option<f64>,
    /// In-process: film every Nth evaluation, one MP4 per episode in RUN_DIR/videos/update_NNNNNNN/
    /// (colour beside depth, a caption with step, reward and outcome; as `equiarm bag video`).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub video_every: Option<u64>,
    /// Transitions in the replay before the first update.
    #[arg(long)]
    pub training_starts: Option<usize>,
    /// Run directory (metrics, learning curve, checkpoints, config). Default: with --resume, the
    /// run directory being resumed (the run continues in place); otherwise runs/latest.
    #[arg(long)]
    pub run_dir: Option<PathBuf>,
    /// Resume from a checkpoint directory, or from a run directory's latest checkpoint.
    #[arg(long)]
    pub resume: Option<PathBuf>,
    /// Where the learner's networks, batches and Adam state live: cpu (default), or in the GPU
    /// build (`--features vulkan`) vulkan, vulkan:N (discrete GPU N) or vulkan:cpu (a CPU Vulkan
    /// driver such as lavapipe). Checked at start. Not part of the config: checkpoints resume on any.
    #[arg(long, default_value = "cpu", value_parser = equiarm_nn::device::open)]
    pub device: Device,
    /// Print the resulting config as JSON and exit.
    #[arg(long)]
    pub print_config: bool,
    /// No progress line.
    #[arg(long, short)]
    pub quiet: bool,
    /// Over DDS: publish the actor's weights on /policy/weights every N updates.
    #[arg(long, default_value_t = 50, value_parser = crate::cli_values::positive_steps)]
    pub weights_every: u64,
    /// Over DDS: namespace of the evaluation sim+policy pair (its episodes carry eval = true).
    #[arg(long, default_value = "/eval", value_parser = crate::cli_values::env_namespace)]
    pub eval_namespace: String,
    /// Over DDS: namespaces of the training envs, whose `observation` topics carry the frames the
    /// Transitions name (default: /env0 … /env{N-1} for --num-envs N).
    #[arg(long, value_delimiter = ',', value_parser = crate::cli_values::env_namespace)]
    pub envs: Vec<String>,
    /// Over DDS: exit when no transition arrived for this many seconds after the first one.
    #[arg(long, default_value_t = 60.0, value_parser = crate::cli_values::seconds)]
    pub idle_timeout_s: f64,
    /// Over DDS: lock-step rounds (the policies need --deterministic too). Round r is every training
    /// env's r-th transition, processed in env-name order, then one update (once the replay is ready)
    /// and the next weights version; --weights-every is ignored. With one seed, two runs make the
    /// same transitions and the same weights. Not with --resume.
    #[arg(long)]
    pub deterministic: bool,
    /// A new run in a --run-dir that already holds a run (metrics, checkpoints) moves that run
    /// aside to RUN_DIR.old-N instead of refusing to start.
    #[arg(long)]
    pub force: bool,
}

impl TrainArgs {
    /// The run directory: `--run-dir`, else the directory of the run given to `--resume`, else
    /// `runs/latest`.
    pub fn run_dir(&self) -> PathBuf {
        self.run_dir
            .clone()
            .or_else(|| self.resume.as_deref().and_then(equiarm_train::rundir::run_dir_of))
            .unwrap_or_else(|| PathBuf::from("runs/latest"))
    }

    /// The training envs' namespaces: `--envs`, else /env0 … /env{n-1}.
    pub fn env_namespaces(&self, n: usize) -> Vec<String> {
        match self.envs.is_empty() {
            true => (0..n).map(|i| format!("/env{i}")).collect(),
            false => self.envs.clone(),
        }
    }

    /// The validated config these options describe.
    pub fn build_config(&self) -> anyhow::Result<TrainConfig> {
        let mut cfg = match &self.config {
            Some(path) => {
                let text =
                    std::fs::read_to_string(path).with_context(|| format!("reading config {}", path.display()))?;
                TrainConfig::from_json(&text).map_err(|e| anyhow::anyhow!("config {}: {e}", path.display()))?
            }
            None => TrainConfig::preset(self.preset, self.task.unwrap_or(TaskKind::BlockPulling)),
        };
        if let Some(m) = self.model {
            cfg.agent.model = m;
            if m == ModelKind::Ferm && self.augmentation.is_none() {
                // FERM crops obs and next_obs independently (docs/paper.md §1.10).
                cfg.augmentation = Augmentation::FERM;
            }
        }
        macro_rules! set {
            ($($flag:ident => $($field:ident).+),* $(,)?) => { $( if let Some(v) = self.$flag { cfg.$($field).+ = v; } )* };
        }
        set!(task => task, seed => seed, total_updates => total_updates, num_envs => num_envs, eval_every => eval_every,
             eval_episodes => eval_episodes, demo_episodes => demo_episodes, batch_size => batch_size,
             hidden => agent.hidden, lr => agent.lr, checkpoint_every => checkpoint_every, training_starts => training_starts,
             matmul => agent.matmul, view => view, corrupt => corruption);
        if let Some(f) = self.lr_final {
            cfg.agent.lr_final = f.0;
        }
        if let Some(img) = self.image {
            (cfg.image_size, cfg.agent.input_size) = (img.frame, img.input);
        }
        if let Some(a) = self.augmentation {
            cfg.augmentation = a.into();
        }
        equiarm_train::config::check(&cfg)?;
        Ok(cfg)
    }
}

/// Run the in-process loop; Ctrl-C / SIGTERM stop it after the current step with a checkpoint.
pub fn run_in_process(args: &TrainArgs, cfg: TrainConfig) -> anyhow::Result<RunSummary> {
    if args.deterministic {
        bail!(
            "--deterministic is for the trainer node over DDS; the in-process loop (--in-process) is deterministic already"
        );
    }
    let stop = stop_flag(CHECKPOINT_AND_STOP);
    let resume = match &args.resume {
        Some(p) => Some(equiarm_train::rundir::find_checkpoint(p)?),
        None => None,
    };
    let opts = RunOptions {
        run_dir: args.run_dir(),
        resume,
        stop_at: None,
        progress: !args.quiet,
        device: args.device.clone(),
        force: args.force,
        checkpoint_secs: args.checkpoint_minutes.map(|m| m * 60.0),
        video_every: args.video_every,
    };
    Ok(equiarm_train::inprocess::run(cfg, &opts, &move || stop.load(std::sync::atomic::Ordering::Relaxed))?)
}

#[cfg(test)]
mod tests {
    use clap::Parser as _;

    use super::*;

    #[derive(clap::Parser)]
    struct Cli {
        #[command(flatten)]
        train: TrainArgs,
    }

    fn config(args: &[&str]) -> anyhow::Result<TrainConfig> {
        let cli = Cli::try_parse_from(std::iter::once("train").chain(args.iter().copied()))?;
        cli.train.build_config()
    }

    #[test]
    fn flags_override_the_preset() {
        let base = config(&[]).unwrap();
        assert_eq!(base, TrainConfig::reduced16(TaskKind::BlockPulling));
        let cfg = config(&["--task", "drawer_opening", "--lr", "0.003", "--hidden", "16", "--image", "76:64"]).unwrap();
        assert_eq!(cfg.task, TaskKind::DrawerOpening);
        assert_eq!(cfg.agent.lr, 0.003);
        assert_eq!(cfg.agent.hidden, 16);
        assert_eq!((cfg.image_size, cfg.agent.input_size), (76, 64));
        assert_eq!(cfg.batch_size, base.batch_size);
        let cfg = config(&["--view", "angle30", "--corrupt", "gripper_only,random_reflection"]).unwrap();
        assert_eq!(
            (cfg.view, cfg.corruption.to_string().as_str()),
            (ViewPreset::Angle30, "random_reflection,gripper_only")
        );
    }

    #[test]
    fn resume_continues_in_the_resumed_run_directory() {
        let root = std::env::temp_dir().join(format!("equiarm_train_cli_run_dir_{}", std::process::id()));
        let ck = root.join("run").join("checkpoints").join("step_0000010");
        std::fs::create_dir_all(&ck).unwrap();
        std::fs::write(ck.join("manifest.json"), "{}").unwrap();
        let run_dir = |args: &[&str]| {
            Cli::try_parse_from(std::iter::once("train").chain(args.iter().copied())).unwrap().train.run_dir()
        };
        let (run, ck_s) = (root.join("run"), ck.to_string_lossy().into_owned());
        let run_s = run.to_string_lossy().into_owned();
        assert_eq!(run_dir(&[]), PathBuf::from("runs/latest"));
        assert_eq!(run_dir(&["--resume", &run_s]), run);
        assert_eq!(run_dir(&["--resume", &ck_s]), run);
        assert_eq!(run_dir(&["--resume", &ck_s, "--run-dir", "elsewhere"]), PathBuf::from("elsewhere"));
        std::fs::remove_dir_all(&root).ok();
    }

    #[test]
    fn bad_flags_name_the_option() {
        let e = config(&["--lr", "0"]).unwrap_err().to_string();
        assert!(e.contains("agent.lr"), "{e}");
        let e = config(&["--image", "76"]).unwrap_err().to_string();
        assert!(e.contains("--image"), "{e}");
        let e = config(&["--lr-final", "0.01"]).unwrap_err().to_string();
        assert!(e.contains("agent.lr_final") && e.contains("at most agent.lr"), "{e}");
        let e = config(&["--lr-final", "fast"]).unwrap_err().to_string();
        assert!(e.contains("--lr-final") && e.contains("fast"), "{e}");
        assert_eq!(config(&["--lr-final", "none"]).unwrap().agent.lr_final, None);
        assert_eq!(config(&["--lr-final", "1e-4"]).unwrap().agent.lr_final, Some(1e-4));
        let e = config(&["--corrupt", "mirror"]).unwrap_err().to_string();
        assert!(e.contains("corruption") && e.contains("`mirror`"), "{e}");
        let e = config(&["--view", "top"]).unwrap_err().to_string();
        assert!(e.contains("--view") && e.contains("top") && e.contains("angle90"), "{e}");
        let e = config(&["--preset", "huge"]).unwrap_err().to_string();
        assert!(e.contains("huge"), "{e}");
    }
}
