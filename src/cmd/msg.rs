//! `equiarm msg`: the message types (like `ros2 interface`).

use std::process::ExitCode;

use anyhow::{Context as _, bail};
use clap::Subcommand;
use equiarm_msgs::{ALL_TYPES, TypeInfo};

/// `equiarm msg` subcommands.
#[derive(Subcommand)]
pub enum MsgCommand {
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

/// Runs `equiarm msg`.
pub fn run(c: MsgCommand) -> anyhow::Result<ExitCode> {
    match c {
        MsgCommand::List => {
            for t in ALL_TYPES {
                println!("{:<36} {}", t.type_name, t.dds_type_name);
            }
        }
        MsgCommand::Show { type_name, raw } => {
            let Some(t) = TypeInfo::find(&type_name) else {
                let known: Vec<_> = ALL_TYPES.iter().map(|t| t.type_name).collect();
                bail!("unknown message type '{type_name}'; known types: {}", known.join(", "));
            };
            let text = if raw { own_text(t).context("splitting the definition")? } else { t.definition };
            print!("{text}");
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// The root type's own text: everything before the first nested definition.
fn own_text(t: &TypeInfo) -> Option<&'static str> {
    let sep = format!("\n{}\nMSG: ", "=".repeat(80));
    Some(t.definition.split(sep.as_str()).next().unwrap_or(t.definition))
}
