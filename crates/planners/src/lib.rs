//! `rlnav-planners`: the classical baseline the RL policy is benchmarked against, modelled on
//! the ROS 2 navigation stack (Nav2):
//!
//! - [`costmap`]: a layered costmap (static layer from the scenario's world or map, obstacle
//!   layer from the live lidar with ray-traced clearing, inflation around both);
//! - [`astar`]: an A* global planner on the costmap (8-connected, cost-aware);
//! - [`dwa`]: a DWA local planner after Nav2's DWB (velocity samples in the dynamic window,
//!   forward simulation, DWB's critics with Nav2's default weights), replanning the global path
//!   when it is blocked; it implements `Controller`.

pub mod astar;
pub mod costmap;
pub mod dwa;

pub use costmap::{Costmap, CostmapConfig};
pub use dwa::{Dwa, DwaConfig};
