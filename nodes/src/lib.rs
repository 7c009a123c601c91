//! equiarm's nodes: thin adapters between DDS topics and the library crates.
//!
//! [`ros`] is the only module that talks to ros2-client; each node maps topics to library calls.

#[cfg(not(any(feature = "jazzy", feature = "humble")))]
compile_error!("equiarm_nodes needs a ROS 2 distro feature: `jazzy` (the default) or `humble`");

pub mod cli_values;
pub mod echo;
pub mod endpoints;
pub mod player;
pub mod policy;
pub mod policy_cli;
pub mod recorder;
pub mod ros;
pub mod signals;
pub mod sim;
pub mod train_cli;
pub mod trainer;
