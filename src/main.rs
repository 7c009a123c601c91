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
