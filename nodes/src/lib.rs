//! equiarm's nodes: thin adapters between DDS topics and the library crates.
//!
//! [`ros`] makes the ROS 2 node, its publishers and subscriptions (ros2-client behind one API);
//! [`endpoints`] wraps ros2-client's publisher and subscription, and the nodes that pick QoS per topic
//! or read message metadata ([`echo`], [`player`], [`recorder`], [`policy`]) name ros2-client's QoS and
//! `MessageInfo` types. Each node maps topics to library calls.

#[cfg(not(any(feature = "jazzy", feature = "humble")))]
compile_error!("equiarm_nodes needs a ROS 2 distro feature: `jazzy` (the default) or `humble`");

pub mod camera;
pub mod cli_values;
pub mod echo;
pub mod endpoints;
pub mod live;
pub mod player;
pub mod policy;
pub mod policy_cli;
pub mod recorder;
pub mod ros;
pub mod secure;
pub mod signals;
pub mod sim;
pub mod topic_watch;
pub mod train_cli;
pub mod trainer;
