//! `rlnav-bench`: running any [`Controller`](rlnav_sim::Controller) through episodes and
//! showing what happened.
//!
//! - [`batch`]: a policy acting for many episodes at once (a network in Python) on the same
//!   seeded episodes;
//! - [`controllers`]: controllers by name (`greedy`, `straight`);
//! - [`episode`]: one episode run and recorded frame by frame;
//! - [`evaluate`]: a controller through seeded episodes in parallel, with the summary figures;
//! - [`latency`]: per-cycle compute time of a controller, as percentiles;
//! - [`suite`]: scenario suites, several controllers on the same seeded episodes, the table;
//! - [`plots`]: distance to goal over time and trajectories coloured by lidar range (SVG);
//! - [`report`]: `report.html`, the whole benchmark on one self-contained page;
//! - [`record`]: episodes as MCAP recordings of ROS 2 messages;
//! - [`render`]: pictures of a scene or an episode (PNG, SVG) and animations (GIF).

pub mod batch;
pub mod controllers;
pub mod episode;
pub mod evaluate;
pub mod latency;
pub mod plots;
pub mod record;
pub mod render;
pub mod report;
pub mod suite;
