//! ROS 2 messages without DDS: what `rlnav-ros2` sends over the wire and what `rlnav-bench`
//! writes into MCAP recordings, in one place so that both carry the same bytes.
//!
//! - [`msg`]: the ROS 2 message types, byte-exact CDR;
//! - [`sim_topics`]: a simulated robot's state as the messages a robot publishes.

pub mod msg;
pub mod sim_topics;
