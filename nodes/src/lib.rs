//! equiarm's nodes: thin adapters between DDS topics and the library crates.
//!
//! [`ros`] is the only module that talks to ros2-client; each node maps topics to library calls.

pub mod ros;
pub mod echo;
pub mod recorder;
pub mod bag_tools;
pub mod player;
pub mod sim;
pub mod policy_eval;
