//! `equiarm`: the one command-line program of the suite. One subcommand per node or tool; each node
//! subcommand only builds its runtime and calls into `equiarm_nodes`.

use std::sync::atomic::Ordering;

use anyhow::{Context as _, bail};
use clap::{Parser, Subcommand};
use equiarm_msgs::{ALL_TYPES, TypeInfo};
use equiarm_nodes::echo::{QosChoice, echo};
use equiarm_nodes::ros::RosOptions;
use equiarm_types::OBS_PLANES;

#[derive(Parser)]
#[command(name = "equiarm", version, about = "ROS 2 node suite for robot learning with equivariant models")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Message types: list them, or show one's definition (like `ros2 interface`).
    #[command(after_help = "Examples:\n  equiarm msg list\n  equiarm msg show equiarm_msgs/msg/Observation")]
    #[command(subcommand)]
    Msg(MsgCommand),
    /// Topics: print a topic's messages.
    #[command(after_help = "Examples:\n  equiarm topic echo /episodes -t equiarm_msgs/msg/EpisodeResult --count 5")]
    #[command(subcommand)]
    Topic(TopicCommand),
    /// Simulated environment node: one of the paper's five tasks on the lock-step protocol.
    ///
    /// Publishes Observation on `observation` (relative to --namespace), waits for the GripperCommand
    /// on `gripper_cmd` naming its seq, steps, publishes Transition on /transitions and, at episode end,
    /// EpisodeResult on /episodes (discounted_return with gamma 0.99); camera images and CameraInfo on
    /// `camera/...`. Commands for another seq are ignored; commands with NaN/inf are rejected (nothing
    /// moves). Out-of-range values are clipped, as the paper's environments do: dx, dy, dz to
    /// +-0.05 m, dtheta to +-pi/4 rad, open_ratio to [0, 1], and the target position to the workspace.
    #[command(
        after_help = "Examples:\n  equiarm sim --task block_pulling --seed 0 --namespace /env0\n  equiarm sim --task drawer_opening --namespace /eval --eval\n  equiarm sim snapshot --task block_in_bowl --out snapshots"
    )]
    Sim(SimCommand),
    /// Records topics into a rosbag2-compatible MCAP bag until Ctrl-C (the recorder node).
    #[command(
        after_help = "Examples:\n  equiarm record -o runs/today --all\n  equiarm record -o runs/cmds /env0/gripper_cmd:equiarm_msgs/msg/GripperCommand --compression lz4"
    )]
    Record(RecordArgs),
    /// Bags: describe, evaluate, repair.
    #[command(
        after_help = "Examples:\n  equiarm bag info runs/today\n  equiarm bag eval runs/today --json\n  equiarm bag play runs/today --rate 2 --remap /env0/observation:/replay/observation\n  equiarm bag recover runs/killed runs/recovered"
    )]
    #[command(subcommand)]
    Bag(BagCommand),
    /// Trains SAC from demonstrations (docs/paper.md §2): in this process (`--in-process`), or as the
    /// trainer node over DDS (transitions from /transitions, weights out on /policy/weights).
    ///
    /// Writes metrics.csv/jsonl (CleanRL names), learning_curve.png, checkpoints/ and config.json into
    /// --run-dir; prints an evaluation table at the end. Ctrl-C stops with a checkpoint; --resume continues.
    #[command(
        after_help = "Examples:\n  equiarm train --in-process --task block_pulling --model equi --seed 0 --run-dir runs/pull_s0\n  equiarm train --resume runs/pull_s0\n  equiarm train --task block_pulling --num-envs 5 --run-dir runs/dds_s0\n  equiarm train --print-config --preset paper --task block_in_bowl"
    )]
    Train(Box<equiarm_nodes::train_cli::TrainArgs>),
    /// Policy node: answers each Observation on `observation` (relative to --namespace) with a
    /// GripperCommand on `gripper_cmd` naming its seq: the actor's sampled or greedy action, the
    /// expert's, or a random one. In sample/greedy mode it takes new actor weights from
    /// /policy/weights (transient-local) and logs `weights version N (updates U)` on each switch.
    #[command(
        after_help = "Examples:\n  equiarm policy --namespace /env0 --mode expert\n  equiarm policy --namespace /env0 --mode sample --expert-episodes 4 --max-lead 5\n  equiarm policy --namespace /eval --mode greedy --checkpoint runs/pull_s0"
    )]
    Policy(equiarm_nodes::policy_cli::PolicyArgs),
    /// Networks: diagnostics of saved (or freshly initialised) equivariant networks.
    #[command(after_help = "Examples:\n  equiarm nn check-equivariance --fresh --net equi-actor --config reduced")]
    #[command(subcommand)]
    Nn(NnCommand),
    /// The supervised rotation-estimation experiment (docs/rotest.md): datasets, training, the
    /// invariant bound, the report.
    #[command(
        subcommand,
        after_help = "Examples:\n  equiarm rotest data --corrupt grid,side --pairs 2000 --seed 0 -o data/rotest/side+grid\n  equiarm rotest snapshots -o docs/rotest\n  equiarm rotest bound data/rotest/condition_reverse\n  equiarm rotest train --data data/rotest/none --model equi --train-pairs 400 --seed 0 -o runs/rotest/none/equi/400/s0\n  equiarm rotest grid --data data/rotest --runs runs/rotest --sizes 100,400\n  equiarm rotest status --data data/rotest --runs runs/rotest --sizes 100,400\n  equiarm rotest invariance --data data/rotest/none runs/rotest/none/equi/400/s0\n  equiarm rotest report runs/rotest --data data/rotest"
    )]
    Rotest(equiarm_rotest::cli::RotestCommand),
    /// The paper's RL experiments as named grids of in-process runs (experiments/NAME.toml,
    /// docs/experiment_runner.md): run them a few at a time, resume after an interruption, report.
    #[command(
        subcommand,
        after_help = "Examples:\n  equiarm experiment run tasks --parallel 2\n  equiarm experiment status tasks\n  equiarm experiment report tasks"
    )]
    Experiment(equiarm_experiment::cli::ExperimentCommand),
    /// Times the learner on a device beside the CPU (median SAC update and batch-1 action per
    /// network family, peak device memory), then trains Equi SAC there for a few minutes
    /// (docs/backends.md, "GPU check"). Writes RUN_DIR/device_check.json.
    #[command(
        after_help = "Examples:\n  equiarm device-check --device vulkan --size paper --run-minutes 5\n  equiarm device-check --device vulkan:cpu --size reduced16 --reps 3 --run-minutes 1\n  equiarm device-check --device cpu --size reduced16 --no-cpu --run-minutes 0"
    )]
    DeviceCheck(equiarm_train::device_check::DeviceCheckArgs),
}

#[derive(clap::Args)]
struct RecordArgs {
    /// Bag directory to create (must not exist, or be empty).
    #[arg(short, long)]
    output: std::path::PathBuf,
    /// Topics to record, as TOPIC:TYPE (e.g. /env0/observation:equiarm_msgs/msg/Observation).
    topics: Vec<String>,
    /// Also record every topic of a known type that appears on the graph.
    #[arg(short, long)]
    all: bool,
    /// With --all: how often to look for new topics, in ms (as rosbag2's --polling-interval).
    #[arg(long, default_value_t = 100, value_parser = equiarm_nodes::cli_values::millis)]
    polling_interval_ms: u64,
    /// Chunk compression.
    #[arg(long, value_enum, default_value = "zstd")]
    compression: CompressionArg,
    /// Start a new file after this many MB of messages.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=1_000_000))]
    split_size_mb: Option<u64>,
    /// Start a new file after this many seconds.
    #[arg(long, value_parser = equiarm_nodes::cli_values::whole_seconds)]
    split_duration_s: Option<u64>,
    /// Flush interval in ms: a killed recorder loses at most about this much.
    #[arg(long, default_value_t = 250, value_parser = equiarm_nodes::cli_values::millis)]
    flush_ms: u64,
    /// Stop after this many seconds (default: until Ctrl-C / SIGTERM).
    #[arg(long, value_parser = equiarm_nodes::cli_values::seconds)]
    duration_s: Option<f64>,
    /// No live status line.
    #[arg(long, short)]
    quiet: bool,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum CompressionArg {
    None,
    Lz4,
    Zstd,
}

/// A network file's architecture when nothing records it (`nn check-equivariance`, `bag eval
/// --policy` on a bare actor file).
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
enum NetPreset {
    /// The paper's networks: hidden 64, 128 px input (the rotation experiment's for rot-equi).
    Paper,
    /// The networks crate's reduced size: hidden 16, 64 px input.
    Reduced,
}

impl NetPreset {
    fn config(self, kind: Option<equiarm_nn::diagnostics::NetKind>) -> equiarm_nn::nets::NetConfig {
        use equiarm_nn::nets::NetConfig;
        match (self, kind) {
            (NetPreset::Paper, Some(equiarm_nn::diagnostics::NetKind::RotEqui)) => NetConfig::paper_rotation(),
            (NetPreset::Paper, _) => NetConfig::paper(),
            (NetPreset::Reduced, _) => NetConfig::reduced_cpu(),
        }
    }
}

#[derive(Subcommand)]
enum NnCommand {
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
        /// Hidden size (regular fields of the encoder output).
        #[arg(long)]
        hidden: Option<usize>,
        /// Input size in pixels.
        #[arg(long)]
        size: Option<usize>,
        /// Input channels.
        #[arg(long)]
        channels: Option<usize>,
        /// Random inputs to average over.
        #[arg(long, default_value_t = 2)]
        batch: usize,
        /// Seed of the inputs (and of the fresh weights).
        #[arg(long, default_value_t = 0)]
        seed: u64,
    },
}

#[derive(Subcommand)]
enum BagCommand {
    /// Files, duration, topics with types, counts and sizes (like `ros2 bag info`).
    Info {
        /// Bag directory or .mcap file.
        bag: std::path::PathBuf,
    },
    /// Per-episode success and returns, success rates with Wilson 95 % intervals.
    Eval {
        /// Bag directory or .mcap file.
        bag: std::path::PathBuf,
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
        policy: Option<std::path::PathBuf>,
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
        bag: std::path::PathBuf,
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
    },
    /// Rewrites a bag whose recorder was killed as a complete, indexed bag.
    Recover {
        /// The damaged bag directory or .mcap file.
        input: std::path::PathBuf,
        /// The new bag directory.
        output: std::path::PathBuf,
    },
}

#[derive(clap::Args)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
struct SimCommand {
    #[command(subcommand)]
    sub: Option<SimSubcommand>,
    #[command(flatten)]
    args: equiarm_nodes::sim::SimArgs,
}

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
    },
}

#[derive(Subcommand)]
enum TopicCommand {
    /// Prints each message of a topic as one JSON line (long arrays summarised) until Ctrl-C.
    Echo {
        /// Topic name, e.g. `/env0/observation`.
        topic: String,
        /// Message type, e.g. `equiarm_msgs/msg/GripperCommand` (see `equiarm msg list`).
        #[arg(long = "type", short = 't')]
        type_name: String,
        /// Stop after this many messages.
        #[arg(long)]
        count: Option<u64>,
        /// QoS to subscribe with (must be compatible with the publisher's).
        #[arg(long, value_enum, default_value = "reliable")]
        qos: QosChoice,
    },
}

#[derive(Subcommand)]
enum MsgCommand {
    /// Lists every message type equiarm uses, with its DDS type name.
    List,
    /// Prints a type's complete definition (the rosbag2 schema text, nested types included).
    Show {
        /// Type name, e.g. `equiarm_msgs/msg/Observation` or `sensor_msgs/Image`.
        type_name: String,
        /// Print only this type's own `.msg` text, without the nested definitions.
        #[arg(long)]
        raw: bool,
    },
}

fn main() -> std::process::ExitCode {
    equiarm_nodes::ros::init_logging();
    match run(Cli::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Rotest(c) => {
            // burn materialises a loaded optimiser record (a rotest checkpoint's Adam state) on its
            // default device before moving it to the training device, and in the GPU build that
            // default is Vulkan: a resumed CPU run would start a Vulkan instance (or fail without a
            // driver). rotest names its device itself (--device), so the default is the CPU unless
            // the user set BURN_DEVICE. Set here, before any thread of this process reads the
            // environment.
            if std::env::var_os("BURN_DEVICE").is_none() {
                // SAFETY: no other thread runs yet: logging is set up, the subcommand not started.
                unsafe { std::env::set_var("BURN_DEVICE", "flex") };
            }
            // Only `train` and `grid` stop with a checkpoint on a signal; the other subcommands keep
            // the default action (end at once).
            let stop =
                c.stops_with_checkpoint().then(|| equiarm_nodes::signals::stop_flag(equiarm_rotest::cli::TRAIN_STOP));
            let code = equiarm_rotest::cli::run(c, &|| stop.as_ref().is_some_and(|s| s.load(Ordering::Relaxed)))?;
            if code != 0 {
                std::process::exit(code);
            }
        }
        Command::Experiment(c) => {
            let stop = equiarm_nodes::signals::stop_flag(equiarm_nodes::signals::CHECKPOINT_AND_STOP);
            let code = equiarm_experiment::cli::run(c, &move || stop.load(Ordering::Relaxed))?;
            if code != 0 {
                std::process::exit(code);
            }
        }
        Command::Msg(MsgCommand::List) => {
            for t in ALL_TYPES {
                println!("{:<36} {}", t.type_name, t.dds_type_name);
            }
        }
        Command::Msg(MsgCommand::Show { type_name, raw }) => {
            let Some(t) = TypeInfo::find(&type_name) else {
                let known: Vec<_> = ALL_TYPES.iter().map(|t| t.type_name).collect();
                bail!("unknown message type '{type_name}'; known types: {}", known.join(", "));
            };
            let text = if raw { own_text(t).context("splitting the definition")? } else { t.definition };
            print!("{text}");
        }
        Command::Topic(TopicCommand::Echo { topic, type_name, count, qos }) => {
            let opts = RosOptions::from_env()?;
            let rt = runtime()?;
            let n = equiarm_nodes::with_message_type!(&type_name, M => {
                rt.block_on(echo::<M>(&opts, &topic, qos, count, std::io::stdout().lock()))
            })??;
            log::info!("printed {n} messages from {topic}");
        }
        Command::DeviceCheck(a) => {
            equiarm_train::device_check::device_check(&a)?;
        }
        Command::Record(a) => {
            let mut topics = Vec::new();
            for t in &a.topics {
                let Some((name, ty)) = t.split_once(':') else {
                    bail!(
                        "topic '{t}' must be given as TOPIC:TYPE, e.g. /env0/observation:equiarm_msgs/msg/Observation"
                    );
                };
                topics.push((name.to_string(), ty.to_string()));
            }
            let writer = equiarm_bag::WriterOptions {
                compression: match a.compression {
                    CompressionArg::None => equiarm_bag::Compression::None,
                    CompressionArg::Lz4 => equiarm_bag::Compression::Lz4,
                    CompressionArg::Zstd => equiarm_bag::Compression::Zstd,
                },
                split_bytes: a.split_size_mb.map(|m| m * 1_000_000),
                split_duration: a.split_duration_s.map(|s| s * 1_000_000_000),
                flush_interval: a.flush_ms * 1_000_000,
                ..Default::default()
            };
            let cfg = equiarm_nodes::recorder::RecordConfig {
                output: a.output,
                topics,
                all: a.all,
                polling_interval: std::time::Duration::from_millis(a.polling_interval_ms.max(1)),
                writer,
                status_every: (!a.quiet).then(|| std::time::Duration::from_secs(1)),
                duration: a.duration_s.map(std::time::Duration::from_secs_f64),
            };
            let opts = RosOptions::from_env()?;
            runtime()?.block_on(equiarm_nodes::recorder::run(&opts, cfg))?;
        }
        Command::Nn(NnCommand::CheckEquivariance {
            checkpoint,
            fresh,
            net,
            config,
            hidden,
            size,
            channels,
            batch,
            seed,
        }) => {
            let kind: equiarm_nn::diagnostics::NetKind = net.parse()?;
            let mut cfg = config.config(Some(kind));
            cfg.hidden = hidden.unwrap_or(cfg.hidden);
            cfg.input_size = size.unwrap_or(cfg.input_size);
            cfg.in_channels = channels.unwrap_or(cfg.in_channels);
            if checkpoint.is_none() && !fresh {
                bail!("give a checkpoint file, or --fresh to check the seeded initial weights");
            }
            let device = equiarm_nn::burn::tensor::Device::flex();
            let errors =
                equiarm_nn::diagnostics::check_checkpoint(kind, &cfg, checkpoint.as_deref(), batch, seed, &device)
                    .with_context(|| format!("checking the equivariance of {net} ({config:?} config)"))?;
            println!("element (flip, rot)   relative error");
            for e in errors {
                println!("({}, {})                {:.3e}", e.element.flip, e.element.rot, e.relative_error);
            }
        }
        Command::Bag(BagCommand::Info { bag }) => {
            let info = equiarm_bag::Reader::open(&bag)?.info()?;
            print!("{}", equiarm_train::bag_report::info_text(&bag, &info));
        }
        Command::Bag(BagCommand::Eval { bag, policy: Some(ckpt), net, config, json, .. }) => {
            // A checkpoint or run directory names its architecture in its manifest.
            let (ckpt, net, cfg) = if equiarm_train::rundir::names_checkpoint(&ckpt) {
                let dir = equiarm_train::rundir::find_checkpoint(&ckpt)?;
                let m = equiarm_sac::learner::read_manifest(&dir)?;
                let a = &m.config.agent;
                let cfg =
                    equiarm_nn::nets::NetConfig { hidden: a.hidden, input_size: a.input_size, in_channels: OBS_PLANES };
                (dir.join("actor.safetensors"), a.model.name().to_string(), cfg)
            } else {
                (ckpt, net, config.config(None))
            };
            let a = equiarm_train::policy_eval::evaluate(&bag, &ckpt, &net, &cfg)
                .with_context(|| format!("evaluating {} on {}", ckpt.display(), bag.display()))?;
            if json {
                let dims: Vec<_> = (0..5)
                    .map(|d| {
                        serde_json::json!({"dim": equiarm_train::policy_eval::DIMS[d], "mae": a.mae[d],
                        "sign_agreement": a.sign[d], "correlation": a.corr[d]})
                    })
                    .collect();
                println!("{}", serde_json::json!({"transitions": a.n, "dims": dims}));
            } else {
                println!("{} transitions; policy (tanh of mean) vs recorded action, normalised units", a.n);
                println!("{:<8} {:>10} {:>14} {:>12}", "dim", "mean |d|", "same sign", "correlation");
                for d in 0..5 {
                    println!(
                        "{:<8} {:>10.4} {:>14.3} {:>12.3}",
                        equiarm_train::policy_eval::DIMS[d],
                        a.mae[d],
                        a.sign[d],
                        a.corr[d]
                    );
                }
            }
        }
        Command::Bag(BagCommand::Eval { bag, gamma, json, policy: None, .. }) => {
            let report = equiarm_train::bag_report::eval(&bag, gamma)?;
            if json {
                println!("{}", report.json()?);
            } else {
                print!("{}", report.table());
            }
        }
        Command::Bag(BagCommand::Play { bag, rate, remaps, wait_ms, lockstep }) => {
            let mut pairs = Vec::new();
            for r in &remaps {
                let Some((from, to)) = r.split_once(':') else { bail!("remap '{r}' must be FROM:TO") };
                pairs.push((from.to_string(), to.to_string()));
            }
            let cfg = equiarm_nodes::player::PlayConfig {
                bag,
                rate,
                remaps: pairs,
                wait_for_match: std::time::Duration::from_millis(wait_ms),
                lockstep: lockstep.map(std::time::Duration::from_millis),
            };
            let opts = RosOptions::from_env()?;
            let (published, skipped) = runtime()?.block_on(equiarm_nodes::player::run(&opts, cfg))?;
            println!("published {published} messages ({skipped} skipped)");
        }
        Command::Bag(BagCommand::Recover { input, output }) => {
            let r = equiarm_bag::recover(&input, &output, equiarm_bag::WriterOptions::default())?;
            for (p, why) in &r.truncated {
                eprintln!("{}: read up to the last complete chunk ({why})", p.display());
            }
            for l in &r.lost {
                eprintln!("{}", equiarm_train::bag_report::lost_text(l));
            }
            println!("recovered {} messages into {}", r.summary.messages, r.summary.dir.display());
        }
        Command::Sim(SimCommand { sub: Some(SimSubcommand::Snapshot { task, out, seed, steps, view }), .. }) => {
            for f in equiarm_nodes::sim::snapshot(task, seed, steps, view, &out)? {
                println!("{}", f.display());
            }
        }
        Command::Train(args) => {
            let cfg = args.build_config()?;
            if args.print_config {
                println!("{}", serde_json::to_string_pretty(&cfg)?);
                return Ok(());
            }
            let summary = if args.in_process {
                equiarm_nodes::train_cli::run_in_process(&args, cfg)?
            } else {
                let opts = RosOptions::from_env()?;
                runtime()?.block_on(equiarm_nodes::trainer::run(&args, cfg, &opts))?
            };
            println!("{summary}");
        }
        Command::Policy(args) => {
            let opts = RosOptions::from_env()?;
            runtime()?.block_on(equiarm_nodes::policy::run(&args, &opts))?;
        }
        Command::Sim(SimCommand { sub: None, args }) => {
            let opts = RosOptions::from_env()?;
            runtime()?.block_on(equiarm_nodes::sim::run(&args, &opts))?;
        }
    }
    Ok(())
}

/// The multi-threaded tokio runtime every node runs on.
fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread().enable_all().build().context("starting the tokio runtime")
}

/// The root type's own text: everything before the first nested definition.
fn own_text(t: &TypeInfo) -> Option<&'static str> {
    let sep = format!("\n{}\nMSG: ", "=".repeat(80));
    Some(t.definition.split(sep.as_str()).next().unwrap_or(t.definition))
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    /// The example lines of a command's `--help` (its `after_help`, lines starting with `equiarm `).
    fn examples(cmd: &clap::Command) -> Vec<String> {
        let text = cmd.get_after_help().map(|h| h.to_string()).unwrap_or_default();
        text.lines().map(str::trim).filter(|l| l.starts_with("equiarm ")).map(str::to_string).collect()
    }

    #[test]
    fn every_subcommand_help_has_examples_that_parse() {
        let root = Cli::command();
        for sub in root.get_subcommands() {
            let lines = examples(sub);
            assert!(!lines.is_empty(), "`equiarm {} --help` has no example", sub.get_name());
            for line in &lines {
                let argv: Vec<&str> = line.split_whitespace().collect();
                assert_eq!(argv[1], sub.get_name(), "example '{line}' is not for `equiarm {}`", sub.get_name());
                if let Err(e) = Cli::try_parse_from(&argv) {
                    panic!("example '{line}' does not parse: {e}");
                }
            }
            // Every leaf command under it is shown by at least one example (hidden, internal ones
            // such as `experiment run-one` excepted).
            for leaf in sub.get_subcommands().filter(|c| c.get_name() != "help" && !c.is_hide_set()) {
                let shown = lines.iter().any(|l| l.split_whitespace().nth(2) == Some(leaf.get_name()));
                assert!(shown, "no example of `equiarm {} {}`", sub.get_name(), leaf.get_name());
            }
        }
    }

    #[test]
    fn the_example_check_sees_a_bad_example() {
        assert!(Cli::try_parse_from(["equiarm", "train", "--no-such-flag"]).is_err());
        assert!(Cli::try_parse_from(["equiarm", "bag", "info", "x"]).is_ok());
    }
}
