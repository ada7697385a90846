//! rlnav's ROS 2 layer, in pure Rust (ros2-client over RustDDS; no ROS installation needed):
//!
//! - [`msg`]: the ROS 2 message types, byte-exact CDR;
//! - [`sim_topics`]: a simulated robot's state as the messages a robot publishes;
//! - [`bus`]: the thin layer over DDS (participant, QoS, typed endpoints);
//! - [`node`]: the policy node that drives a robot (`rlnav ros2 node`);
//! - [`bridge`]: the simulator as a ROS 2 robot (`rlnav ros2 sim`).

pub mod bridge;
pub mod bus;
pub mod msg;
pub mod node;
pub mod sim_topics;
