//! `equiarm topic`: print a topic's messages.

use std::process::ExitCode;

use clap::Subcommand;
use equiarm_nodes::echo::{QosChoice, echo};
use equiarm_nodes::ros::RosOptions;

/// `equiarm topic` subcommands.
#[derive(Subcommand)]
pub enum TopicCommand {
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

/// Runs `equiarm topic`.
pub fn run(c: TopicCommand) -> anyhow::Result<ExitCode> {
    let TopicCommand::Echo { topic, type_name, count, qos } = c;
    let opts = RosOptions::from_env()?;
    let rt = super::runtime()?;
    let n = equiarm_nodes::with_message_type!(&type_name, M => {
        rt.block_on(echo::<M>(&opts, &topic, qos, count, std::io::stdout().lock()))
    })??;
    log::info!("printed {n} messages from {topic}");
    Ok(ExitCode::SUCCESS)
}
