//! `equiarm device-check`: what a device does for the learner, in one command (`bench/gpu_check.sh`
//! runs it on a GPU machine).
//!
//! It prints the device it opened; for each network family, the median time of one SAC update (of
//! `--reps`, after `--warmup` untimed ones that compile the kernels) and of one batch-1 greedy
//! action, on the device and on this machine's CPU, and the device's peak memory; then an
//! in-process SAC run of the Equi model on `--task` for as many updates as fit in
//! `--run-minutes`, with its evaluations. Everything printed is also written to
//! `RUN_DIR/device_check.json`.
//!
//! The update is the learner's ([`equiarm_sac::timing`], as the update benchmark times it) on a
//! random batch of the preset's size: paper (hidden 64, 128 px crops, batch 128) or reduced16
//! (hidden 16, 32 px, batch 64).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context as _, bail};
use equiarm_nn::burn::tensor::Device;
use equiarm_sac::agent::{AgentConfig, ModelKind};
use equiarm_sac::config::{Preset, TrainConfig};
use equiarm_sac::timing::{UpdateTiming, random_batch, time_update};
use serde_json::json;

use crate::inprocess::{RunOptions, run};
use equiarm_types::TaskKind;

/// The network and batch sizes to time.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Size {
    /// The paper's: hidden 64, 128 px crops, batch 128.
    Paper,
    /// reduced16: hidden 16, 32 px crops, batch 64 (what 2 CPU cores can train).
    Reduced16,
}

impl Size {
    fn preset(self) -> Preset {
        match self {
            Size::Paper => Preset::Paper,
            Size::Reduced16 => Preset::Reduced16,
        }
    }
}

/// The options of `equiarm device-check`.
#[derive(Clone, Debug, clap::Args)]
pub struct DeviceCheckArgs {
    /// The device to check: vulkan, vulkan:N, vulkan:cpu (the GPU build), or cpu.
    #[arg(long, default_value = "vulkan")]
    pub device: String,
    /// Network and batch sizes.
    #[arg(long, value_enum, default_value_t = Size::Paper)]
    pub size: Size,
    /// Network families to time, comma-separated.
    #[arg(long, value_enum, value_delimiter = ',', default_value = "equi,cnn")]
    pub models: Vec<ModelKind>,
    /// Untimed updates before the timed ones (the first compile the device's kernels).
    #[arg(long, default_value_t = 2)]
    pub warmup: usize,
    /// Timed updates per model and device; the median is reported.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..=10_000))]
    pub reps: u64,
    /// Timed batch-1 greedy actions per model and device.
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u64).range(1..=100_000))]
    pub act_reps: u64,
    /// Threads of the CPU comparison (default: every core of this machine).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=1024))]
    pub cpu_threads: Option<u64>,
    /// Timed updates of the CPU comparison (the CPU is slow at the paper's size).
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u64).range(1..=10_000))]
    pub cpu_reps: u64,
    /// Skip the CPU comparison.
    #[arg(long)]
    pub no_cpu: bool,
    /// Minutes of the in-process Equi SAC run on the device (0: no run).
    #[arg(long, default_value_t = 5.0, value_parser = minutes)]
    pub run_minutes: f64,
    /// The run's task.
    #[arg(long, value_enum, default_value_t = TaskKind::BlockPulling)]
    pub task: TaskKind,
    /// The run evaluates the greedy policy every this many updates.
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u64).range(1..))]
    pub eval_every: u64,
    /// Episodes per evaluation.
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u64).range(1..=10_000))]
    pub eval_episodes: u64,
    /// The run's directory (replaced if it holds an earlier check's run), and where
    /// device_check.json goes.
    #[arg(long, default_value = "runs/device_check")]
    pub run_dir: PathBuf,
}

fn minutes(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(m) if m.is_finite() && (0.0..=24.0 * 60.0).contains(&m) => Ok(m),
        _ => Err(format!("`{s}` is not a number of minutes between 0 and 1440")),
    }
}

fn mib(bytes: Option<u64>) -> Option<f64> {
    bytes.map(|b| b as f64 / (1024.0 * 1024.0))
}

fn timing_json(t: &UpdateTiming) -> serde_json::Value {
    json!({
        "update_median_s": t.update_median(),
        "updates_s": t.updates_s,
        "act_b1_median_s": t.act_median(),
        "peak_device_mib": mib(t.peak_device_bytes),
    })
}

/// Runs the check and prints it; returns what it wrote to `device_check.json`.
pub fn device_check(args: &DeviceCheckArgs) -> anyhow::Result<serde_json::Value> {
    let device = equiarm_nn::device::open(&args.device).with_context(|| format!("--device {}", args.device))?;
    let described = equiarm_nn::device::describe(&device);
    println!("device: {} = {described}", args.device);
    let base = TrainConfig::preset(args.size.preset(), args.task);
    crate::config::check(&base).with_context(|| format!("--task {}", args.task))?;
    let (b, s) = (base.batch_size, base.agent.input_size);
    println!(
        "size: {} (hidden {}, {s} px crops, batch {b}); {} timed updates after {} warm-up, {} actions",
        args.size.preset().name(),
        base.agent.hidden,
        args.reps,
        args.warmup,
        args.act_reps
    );
    let cpu_threads = args
        .cpu_threads
        .map(|t| t as usize)
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let pool = rayon::ThreadPoolBuilder::new().num_threads(cpu_threads).build().context("CPU thread pool")?;
    let batch = random_batch(b, s, 3);
    let mut models = Vec::new();
    println!(
        "{:<5} | {:>15} {:>15} {:>7} | {:>13} {:>13} | {:>15}",
        "model", "update (device)", "update (CPU)", "ratio", "act (device)", "act (CPU)", "peak device MiB"
    );
    for &model in &args.models {
        let cfg = AgentConfig { model, ..base.agent.clone() };
        let started = Instant::now();
        let dev = time_update(&cfg, &batch, &device, args.warmup, args.reps as usize, args.act_reps as usize, |_| {})
            .with_context(|| format!("{} update on {}", model.name(), args.device))?;
        let dev_wall = started.elapsed().as_secs_f64();
        let cpu = if args.no_cpu {
            None
        } else {
            let cpu_device = equiarm_nn::device::cpu();
            let reps = args.cpu_reps as usize;
            Some(
                pool.install(|| time_update(&cfg, &batch, &cpu_device, 1, reps, args.act_reps as usize, |_| {}))
                    .with_context(|| format!("{} update on the CPU", model.name()))?,
            )
        };
        let (cu, ca) = cpu.as_ref().map_or((f64::NAN, f64::NAN), |c| (c.update_median(), c.act_median()));
        println!(
            "{:<5} | {:>13.4} s {:>13.4} s {:>7.2} | {:>10.2} ms {:>10.2} ms | {:>15}",
            model.name(),
            dev.update_median(),
            cu,
            cu / dev.update_median(),
            1e3 * dev.act_median(),
            1e3 * ca,
            mib(dev.peak_device_bytes).map_or("(not reported)".to_string(), |m| format!("{m:.0}"))
        );
        models.push(json!({
            "model": model.name(),
            "device": timing_json(&dev),
            "device_wall_s_with_warmup": dev_wall,
            "cpu": cpu.as_ref().map(timing_json),
            "cpu_over_device": cu / dev.update_median(),
        }));
    }
    if !args.no_cpu {
        println!("(CPU: {cpu_threads} threads, median of {} after 1 warm-up)", args.cpu_reps);
    }

    let mut report = json!({
        "device_name": args.device,
        "device": described,
        "size": args.size.preset().name(),
        "hidden": base.agent.hidden,
        "input_px": s,
        "batch": b,
        "warmup": args.warmup,
        "reps": args.reps,
        "cpu_threads": cpu_threads,
        "cpu_reps": args.cpu_reps,
        "models": models,
    });
    std::fs::create_dir_all(&args.run_dir).with_context(|| format!("creating {}", args.run_dir.display()))?;
    if args.run_minutes > 0.0 {
        report["run"] = training_run(args, &base, &device)?;
    }
    let path = args.run_dir.join("device_check.json");
    std::fs::write(&path, serde_json::to_string_pretty(&report)?)
        .with_context(|| format!("writing {}", path.display()))?;
    println!("wrote {}", path.display());
    Ok(report)
}

/// The in-process Equi SAC run on the device, stopped after `--run-minutes`.
fn training_run(args: &DeviceCheckArgs, base: &TrainConfig, device: &Device) -> anyhow::Result<serde_json::Value> {
    let mut cfg = base.clone();
    cfg.agent.model = ModelKind::Equi;
    cfg.eval_every = args.eval_every;
    cfg.eval_episodes = args.eval_episodes as usize;
    crate::config::check(&cfg).context("the run's config")?;
    let run_dir = args.run_dir.join("run");
    if run_dir.exists() {
        std::fs::remove_dir_all(&run_dir).with_context(|| format!("removing the earlier {}", run_dir.display()))?;
    }
    println!(
        "\nin-process Equi SAC on {} at this size, on {}, for {} min (evaluations every {} updates over {} episodes): {}",
        cfg.task,
        args.device,
        args.run_minutes,
        cfg.eval_every,
        cfg.eval_episodes,
        run_dir.display()
    );
    let opts = RunOptions {
        run_dir: run_dir.clone(),
        device: device.clone(),
        progress: std::io::IsTerminal::is_terminal(&std::io::stderr()),
        checkpoint_secs: Some(120.0),
        ..RunOptions::default()
    };
    let budget = args.run_minutes * 60.0;
    let started = Instant::now();
    let stop = || started.elapsed().as_secs_f64() >= budget;
    let summary = run(cfg, &opts, &stop).context("the in-process run")?;
    if summary.updates == 0 {
        bail!(
            "the in-process run made no update in {} min (demonstrations and the first steps took it all)",
            args.run_minutes
        );
    }
    println!("{summary}");
    println!(
        "{} updates in {:.0} s of training ({:.2} updates/s, demonstrations included)",
        summary.updates,
        summary.wall_s,
        summary.updates as f64 / summary.wall_s
    );
    Ok(json!({
        "task": base.task,
        "run_dir": run_dir,
        "minutes": args.run_minutes,
        "updates": summary.updates,
        "env_steps": summary.global_step,
        "wall_s": summary.wall_s,
        "evals": summary.evals,
        "last_checkpoint": summary.last_checkpoint,
    }))
}
