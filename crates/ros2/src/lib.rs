//! rlnav's ROS 2 layer, in pure Rust (ros2-client over RustDDS; no ROS installation needed):
//!
//! - [`msg`] and [`sim_topics`]: the ROS 2 message types and a simulated robot's state as
//!   messages (from `rlnav-msgs`, which the benchmark's MCAP recordings share);
//! - [`bus`]: the thin layer over DDS (participant, QoS, typed endpoints);
//! - [`node`]: the policy node that drives a robot (`rlnav ros2 node`);
//! - [`follow_path`]: Nav2's `FollowPath` action, served by the node in controller_server's place;
//! - [`ros_args`]: ROS 2's `--ros-args` (remapping, namespaces, parameters);
//! - [`bridge`]: the simulator as a ROS 2 robot (`rlnav ros2 sim`).

pub mod bridge;
pub mod bus;
pub mod follow_path;
pub mod node;
pub mod ros_args;

pub use rlnav_msgs::{msg, sim_topics};
