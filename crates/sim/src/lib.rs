//! `rlnav-sim`: a batched 2D simulator of differential-drive robots with a 2D lidar, and the
//! navigation task that reinforcement-learning policies are trained on.
//!
//! The pieces, bottom up:
//! - [`geometry`]: poses, angles and the obstacle shapes worlds are made of;
//! - [`world`]: a static world (walls and obstacles), footprint collision and clearance;
//! - [`lidar`]: [`LidarSpec`] and the ray caster (a culled hot loop, checked against parry2d);
//! - [`robot`]: [`RobotSpec`] presets and [`DiffDrive`] kinematics;
//! - [`scenario`]: scenario files, the procedural generator and start/goal sampling;
//! - [`task`]: the navigation task (observation layout, action scaling, reward, termination);
//! - [`vec_env`]: [`VecEnv`], N environments stepped in parallel;
//! - [`controller`]: the [`Controller`] trait that joins evaluation, benchmark and deployment.
//!
//! Units are SI and frames follow REP-103/105 (x forward, y left, yaw counter-clockwise).

pub mod config;
pub mod controller;
pub mod geometry;
pub mod lidar;
pub mod reachability;
pub mod robot;
pub mod scenario;
pub mod task;
pub mod vec_env;
pub mod world;

pub use config::ConfigError;
pub use controller::{Controller, GreedyGoal, LaserScan, RobotObservation, StraightAhead, Twist};
pub use geometry::{Pose2, Vec2, wrap_angle};
pub use lidar::{Lidar, LidarSpec};
pub use robot::{DiffDrive, Footprint, RobotSpec};
pub use scenario::{Scenario, ScenarioSpec};
pub use task::{EpisodeStats, NavEnv, ObservationLayout, Outcome, TaskConfig};
pub use vec_env::VecEnv;
pub use world::World;
