//! `rlnav-sim`: a batched 2D simulator of differential-drive robots with a 2D lidar, and the
//! navigation task that reinforcement-learning policies are trained on.
//!
//! The pieces, bottom up:
//! - [`geometry`]: poses, angles and the obstacle shapes worlds are made of;
//! - [`world`]: a static world (walls and obstacles), footprint collision and clearance;
//! - [`map`]: occupancy-grid maps in the ROS `map_server` format, cast exactly and fast;
//! - [`lidar`]: [`LidarSpec`] and the ray caster (a culled hot loop, checked against parry2d);
//! - [`robot`]: [`RobotSpec`] presets and [`DiffDrive`] kinematics; [`urdf`]: robots from URDF,
//!   expanded from xacro by [`xacro`] when they are written in it;
//! - [`barn`]: the BARN Challenge worlds as scenarios, and the challenge's score;
//! - [`movers`] and [`people`]: moving obstacles, and pedestrians that avoid each other (ORCA);
//! - [`scenario`]: scenario files, the procedural generator and start/goal sampling;
//!   [`placement`]: start/goal candidates listed once per fixed map world;
//! - [`reachability`]: where a robot can drive, the shortest path past the static world, and
//!   the cheapest (the plan a Nav2 planner would give, keeping off obstacles);
//!   [`plan`]: following a global plan like a Nav2 controller (a subgoal a lookahead ahead);
//! - [`observation`]: the observation layout ([`ObservationLayout`]) and the builder that the
//!   simulator and deployed policies share;
//! - [`task`]: the navigation task (observation, action scaling, reward, termination);
//! - [`vec_env`]: [`VecEnv`], N environments stepped in parallel;
//! - [`controller`]: the [`Controller`] trait that joins evaluation, benchmark and deployment.
//!
//! Units are SI and frames follow REP-103/105 (x forward, y left, yaw counter-clockwise).
//!
//! ```
//! use rlnav_sim::task::EnvSetup;
//! use rlnav_sim::VecEnv;
//! use std::sync::Arc;
//!
//! // The article's training room with a Jetbot and the default task (124 observations).
//! let setup = Arc::new(EnvSetup::from_scenario_name("static-room")?);
//! let mut envs = VecEnv::new(setup, 8, 42, 2)?;
//! assert_eq!(envs.obs.len(), 8 * 124);
//! // Normalised actions in [-1, 1]: full speed ahead, no turn.
//! envs.step(&[[1.0, 0.0]; 8])?;
//! assert!(envs.rewards.iter().all(|r| r.is_finite()));
//! # Ok::<(), rlnav_sim::task::SimError>(())
//! ```

pub mod barn;
pub mod config;
pub mod controller;
pub mod escape;
pub mod geometry;
pub mod lidar;
pub mod map;
pub mod movers;
pub mod observation;
pub mod people;
pub mod placement;
pub mod plan;
pub mod reachability;
pub mod robot;
pub mod scenario;
pub mod task;
pub mod urdf;
pub mod vec_env;
pub mod world;
pub mod xacro;

pub use config::ConfigError;
pub use controller::{Controller, GreedyGoal, LaserScan, RobotObservation, StraightAhead, Twist};
pub use geometry::{Pose2, Vec2, wrap_angle};
pub use lidar::{Lidar, LidarSpec};
pub use robot::{DiffDrive, Footprint, RobotSpec};
pub use scenario::{Scenario, ScenarioSpec};
pub use task::{EpisodeStats, EvalSummary, NavEnv, ObservationLayout, Outcome, TaskConfig};
pub use vec_env::VecEnv;
pub use world::World;
