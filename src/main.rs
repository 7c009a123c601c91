//! `equiarm`: the one command-line program of the suite. One subcommand per node or tool; each node
//! subcommand only builds its runtime and calls into `equiarm_nodes`.

use anyhow::{Context as _, bail};
use clap::{Parser, Subcommand};
use equiarm_msgs::{ALL_TYPES, TypeInfo};
use equiarm_nodes::echo::{QosChoice, echo};
use equiarm_nodes::ros::RosOptions;

#[derive(Parser)]
#[command(name = "equiarm", version, about = "ROS 2 node suite for robot learning with equivariant models")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Message types: list them, or show one's definition (like `ros2 interface`).
    #[command(subcommand)]
    Msg(MsgCommand),
    /// Topics: print a topic's messages.
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
    Sim(SimCommand),
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
        /// Task name (see `equiarm sim --help`).
        #[arg(long)]
        task: String,
        /// Output folder (created if missing); files are `<task>_color.png`, `_depth.png`, `_seg.png`.
        #[arg(long)]
        out: std::path::PathBuf,
        /// Seed of the reset.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Expert steps to take before the picture.
        #[arg(long, default_value_t = 0)]
        steps: u32,
        /// Camera preset (side, angle15 … angle90).
        #[arg(long)]
        view: Option<String>,
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
        Command::Sim(SimCommand { sub: Some(SimSubcommand::Snapshot { task, out, seed, steps, view }), .. }) => {
            for f in equiarm_nodes::sim::snapshot(&task, seed, steps, view.as_deref(), &out)? {
                println!("{}", f.display());
            }
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
