//! The navigation task: what the policy observes, how its action becomes a velocity command,
//! the reward, and when an episode ends. One [`NavEnv`] is one robot in one world.

use crate::config::{ConfigError, Invalid, Validate, check_interval, check_positive, check_range, from_yaml_file};
use crate::controller::{Controller, LaserScan, RobotObservation, Twist};
use crate::geometry::{Pose2, Vec2, point_segment_distance_squared, wrap_angle};
use crate::lidar::{Lidar, RayGeometry};
use crate::movers::Mover;
pub use crate::observation::{HistoryFill, HistoryOrder, ObsTerm, ObservationLayout};
use crate::observation::{ObservationBuilder, ObservationInputs};
use crate::people::{Crowd, Person};
use crate::reachability::ReachabilityGrid;
use crate::robot::{DiffDrive, DriveParams, Footprint, RobotSpec};
use crate::scenario::{NoEpisode, Scenario, ScenarioSpec};
use crate::world::World;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use rand_pcg::Pcg64Mcg;
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::sync::Arc;

/// How the policy's action in `[-1, 1]²` maps to a velocity command.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ActionConfig {
    /// Linear velocity range `[min, max]` (m/s), default the article's [0.1, 0.5]; with
    /// `linear_relative`, fractions of the robot's top speed.
    pub linear: [f32; 2],
    /// Angular velocity range `[min, max]` (rad/s), default [-0.5, 0.5].
    pub angular: [f32; 2],
    /// `linear` is in fractions of the robot's nominal top speed (its spec's `max_linear`),
    /// not m/s: the same action is the same share of the robot's speed on every robot. In m/s,
    /// a policy for several robots spends most of its range above a slow robot's top speed
    /// (on a 0.22 m/s TurtleBot3 Burger, 70% of [0.1, 0.5] gives the same command).
    pub linear_relative: bool,
}

impl Default for ActionConfig {
    fn default() -> Self {
        Self { linear: [0.1, 0.5], angular: [-0.5, 0.5], linear_relative: false }
    }
}

impl ActionConfig {
    /// The ranges in m/s for a robot whose top speed is `top_speed`: itself when `linear`
    /// is in m/s already.
    pub fn for_top_speed(&self, top_speed: f32) -> Self {
        if !self.linear_relative {
            return self.clone();
        }
        Self { linear: self.linear.map(|v| v * top_speed), angular: self.angular, linear_relative: false }
    }

    /// Clips an action to `[-1, 1]` and rescales it to the velocity ranges. A non-finite
    /// component maps to the middle of its range.
    #[inline]
    pub fn to_twist(&self, a: [f32; 2]) -> Twist {
        let scale = |x: f32, r: [f32; 2]| {
            let x = if x.is_finite() { x.clamp(-1.0, 1.0) } else { 0.0 };
            r[0] + (x + 1.0) * 0.5 * (r[1] - r[0])
        };
        Twist::new(scale(a[0], self.linear), scale(a[1], self.angular))
    }

    /// The action that produces `t` (clipped to the ranges): the inverse of [`Self::to_twist`].
    pub fn to_action(&self, t: Twist) -> [f32; 2] {
        let unscale = |x: f32, r: [f32; 2]| {
            if r[1] > r[0] { ((x - r[0]) / (r[1] - r[0]) * 2.0 - 1.0).clamp(-1.0, 1.0) } else { 0.0 }
        };
        [unscale(t.linear, self.linear), unscale(t.angular, self.angular)]
    }
}

/// Reward weights and thresholds (defaults follow the reference article).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RewardConfig {
    /// Weight of the progress term `d_{t-1} - d_t` (default 1).
    pub progress: f32,
    /// Pay progress as if every robot's top speed were this (m/s, default 0: off): the
    /// progress term is multiplied by `progress_reference_speed / max_linear` (the robot's
    /// nominal top speed). A step at top speed then earns the same on a 0.22 m/s TurtleBot3
    /// Burger as on a 0.5 m/s Jetbot, where in metres it earns the Burger less than half,
    /// against the same social and proximity charges per step.
    pub progress_reference_speed: f32,
    /// Proximity penalty weight (default 1): each control step while `r_min < proximity_range`,
    /// `-proximity` times the [`ProximityShape`]'s value.
    pub proximity: f32,
    /// Lidar distance below which the proximity penalty applies (m, default 0.5).
    pub proximity_range: f32,
    /// How the proximity penalty grows as the nearest return closes in (default `exp`, the
    /// reference article's).
    pub proximity_shape: ProximityShape,
    /// Look-ahead of the proximity penalty (s, default 0: the nearest return now): the
    /// penalty is charged on the nearest any return comes if the robot drove straight on at
    /// its measured speed for this long, the returns held still. A robot running at a post
    /// pays before the post is close, and pays less for slowing down or turning away; one
    /// driving along a wall pays what it pays now.
    pub proximity_horizon: f32,
    /// Reward for reaching the goal (default 30).
    pub goal: f32,
    /// Extra goal reward per control step left before the time limit (default 0.01).
    pub goal_time_bonus: f32,
    /// Reward on collision (default -30).
    pub collision: f32,
    /// Reward on time-out (default -30).
    pub timeout: f32,
    /// Social-safety penalty weight (default 0: off). Every control step, for each person
    /// closer than `social_radius` (gap from the robot's circumscribed circle to the body):
    /// `-social * (social_radius - gap) / social_radius`, 0 at the edge, `-social` at contact.
    pub social: f32,
    /// Radius of a person's personal space for the social penalty (m, default 1.0).
    pub social_radius: f32,
    /// Whether the social penalty also counts the moving obstacles (carts, boxes), with the
    /// same radius, not only people (default false). A policy that passes a cart as closely
    /// as a wall's corner meets it 0.2-0.4 m off its line when it comes head-on.
    pub social_movers: bool,
    /// Look-ahead of the social penalty (s, default 0: the gap now): each gap is measured at
    /// the nearest approach within this many seconds if the robot and the body keep their
    /// velocities, so that a course that will cross a mover's costs before it is close, and
    /// one that has passed it costs only the gap now. Ground-truth velocities: a training
    /// signal only.
    pub social_horizon: f32,
    /// Penalty per control step while the robot's measured forward speed is below
    /// `idle_speed` (default 0: off). For action ranges that let the robot stop: without it,
    /// standing until the time limit costs next to nothing once discounted (γ = 0.99 puts a
    /// time-out 1,000 steps away at 4·10^-5 of its weight), and a policy learns to freeze
    /// where moving on risks a collision.
    pub idle: f32,
    /// Forward speed below which a step counts as idle (m/s, default 0.05).
    pub idle_speed: f32,
    /// Penalty per metre of cross-track error beyond `plan_deviation_band`, each control step
    /// of a task that follows a plan (default 0: off). Progress along the plan pays for
    /// cutting a corner as much as for keeping to the path, and a robot that strays 0.2 m
    /// from a plan that keeps 0.44 m from a row of table legs passes them at the collision
    /// range; this charges the straying, while a detour round an obstacle the plan runs
    /// through (a map that lacks it, a mover) still costs far less than a collision.
    pub plan_deviation: f32,
    /// Cross-track error charged nothing by `plan_deviation` (m, default 0.1).
    pub plan_deviation_band: f32,
}

/// The shape of the proximity penalty inside `proximity_range`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ProximityShape {
    /// `exp(-r_min)`, the reference article's: 0.61-0.78 between 0.5 m and 0.25 m, nearly a
    /// constant charge for being inside the range, so a pass 0.26 m from a post costs little
    /// more than one 0.45 m away.
    #[default]
    Exp,
    /// `(proximity_range - r_min) / (proximity_range - collision_range)`: 0 at the edge of the
    /// range, 1 at the collision range; it pays to keep to the middle of a gap.
    Linear,
}

impl ProximityShape {
    /// The penalty's value (before the weight) at the nearest return `r_min`, for a penalty that
    /// starts at `range` and a collision at `collision_range`.
    #[inline]
    pub fn value(self, r_min: f32, range: f32, collision_range: f32) -> f32 {
        match self {
            Self::Exp => (-r_min).exp(),
            // Validation keeps range > collision_range for this shape.
            Self::Linear => ((range - r_min) / (range - collision_range)).clamp(0.0, 1.0),
        }
    }
}

impl Default for RewardConfig {
    fn default() -> Self {
        Self {
            progress: 1.0,
            progress_reference_speed: 0.0,
            proximity: 1.0,
            proximity_range: 0.5,
            proximity_shape: ProximityShape::Exp,
            goal: 30.0,
            goal_time_bonus: 0.01,
            collision: -30.0,
            timeout: -30.0,
            social: 0.0,
            social_radius: 1.0,
            social_movers: false,
            social_horizon: 0.0,
            proximity_horizon: 0.0,
            idle: 0.0,
            idle_speed: 0.05,
            plan_deviation: 0.0,
            plan_deviation_band: 0.1,
        }
    }
}

/// Domain randomisation, every term off (0) by default. With all terms off no random draws
/// are made, so episodes are bit-identical to a run without this section.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RandomizationConfig {
    /// Gaussian noise added to each lidar value of the observation (m).
    pub obs_lidar_std: f32,
    /// Gaussian noise added to the observed goal distance (m).
    pub obs_goal_distance_std: f32,
    /// Gaussian noise added to the observed goal bearing (rad).
    pub obs_goal_bearing_std: f32,
    /// Gaussian noise added to the normalised action before scaling.
    pub action_std: f32,
    /// Control latency: a command is applied this many control steps after it is given.
    pub latency_steps: usize,
    /// Probability that a beam reads no return (on top of the lidar's own dropout).
    pub lidar_dropout: f32,
    /// Per-episode relative jitter of the wheel radius (0.05: ±5%).
    pub wheel_radius_jitter: f32,
    /// Per-episode relative jitter of the wheel separation.
    pub wheel_separation_jitter: f32,
    /// Per-episode relative jitter of the robot's speed limits (linear and angular).
    pub speed_limit_jitter: f32,
}

impl RandomizationConfig {
    fn validate(&self) -> Result<(), Invalid> {
        check_range("randomization.obs_lidar_std", self.obs_lidar_std, 0.0, 10.0)?;
        check_range("randomization.obs_goal_distance_std", self.obs_goal_distance_std, 0.0, 10.0)?;
        check_range("randomization.obs_goal_bearing_std", self.obs_goal_bearing_std, 0.0, 3.2)?;
        check_range("randomization.action_std", self.action_std, 0.0, 10.0)?;
        if self.latency_steps > 100 {
            return Err(Invalid::new("randomization.latency_steps", "an integer in [0, 100]"));
        }
        check_range("randomization.lidar_dropout", self.lidar_dropout, 0.0, 1.0)?;
        check_range("randomization.wheel_radius_jitter", self.wheel_radius_jitter, 0.0, 0.9)?;
        check_range("randomization.wheel_separation_jitter", self.wheel_separation_jitter, 0.0, 0.9)?;
        check_range("randomization.speed_limit_jitter", self.speed_limit_jitter, 0.0, 0.9)
    }
}

/// The task: timing, termination, action scaling, reward and observation layout.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TaskConfig {
    /// Physics step (s, default 0.02).
    pub physics_dt: f32,
    /// Control period (s, default 0.1: the rate real lidars publish at); a whole number of
    /// physics steps.
    pub control_period: f32,
    /// Control steps before a time-out (default 1200).
    pub max_steps: u32,
    /// Distance to the goal that counts as reached (m, default 0.3).
    pub goal_tolerance: f32,
    /// A lidar reading below this is a collision (m, default 0.25); footprint contact is one too.
    pub collision_range: f32,
    /// Action scaling.
    pub action: ActionConfig,
    /// Reward.
    pub reward: RewardConfig,
    /// Observation layout.
    pub observation: ObservationLayout,
    /// Domain randomisation (all off by default).
    pub randomization: RandomizationConfig,
    /// Follow a global plan like a Nav2 controller (off by default): the episode's plan past
    /// the static world ([`crate::Scenario::global_plan`]) is made at reset, the observation's
    /// goal terms describe the point `lookahead` ahead along it, and progress is rewarded along
    /// the path.
    pub plan: Option<PlanConfig>,
}

/// How a task follows its global plan.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanConfig {
    /// Distance along the plan to the point the policy steers to (m).
    pub lookahead: f32,
}

impl Validate for PlanConfig {
    fn validate(&self) -> Result<(), Invalid> {
        check_range("lookahead", self.lookahead, 0.1, 100.0)
    }
}

impl Default for TaskConfig {
    fn default() -> Self {
        Self {
            physics_dt: 0.02,
            control_period: 0.1,
            max_steps: 1200,
            goal_tolerance: 0.3,
            collision_range: 0.25,
            action: ActionConfig::default(),
            reward: RewardConfig::default(),
            observation: ObservationLayout::default(),
            randomization: RandomizationConfig::default(),
            plan: None,
        }
    }
}

impl Validate for TaskConfig {
    fn validate(&self) -> Result<(), Invalid> {
        check_range("physics_dt", self.physics_dt, 1e-4, 1.0)?;
        check_range("control_period", self.control_period, self.physics_dt, 10.0)?;
        let ratio = self.control_period / self.physics_dt;
        if (ratio - ratio.round()).abs() > 1e-3 {
            return Err(Invalid::new(
                "control_period",
                format!("a whole multiple of physics_dt ({}), got {}", self.physics_dt, self.control_period),
            ));
        }
        if self.max_steps == 0 {
            return Err(Invalid::new("max_steps", "at least 1"));
        }
        check_positive("goal_tolerance", self.goal_tolerance)?;
        check_range("collision_range", self.collision_range, 0.0, 10.0)?;
        if let Some(p) = &self.plan {
            p.validate().map_err(|e| e.under("plan"))?;
        }
        let linear_max = if self.action.linear_relative { 1.0 } else { 100.0 };
        check_interval("action.linear", self.action.linear, -linear_max, linear_max)?;
        check_interval("action.angular", self.action.angular, -100.0, 100.0)?;
        let r = &self.reward;
        for (k, v) in [
            ("reward.progress", r.progress),
            ("reward.proximity", r.proximity),
            ("reward.goal", r.goal),
            ("reward.goal_time_bonus", r.goal_time_bonus),
            ("reward.collision", r.collision),
            ("reward.timeout", r.timeout),
        ] {
            check_range(k, v, -1e4, 1e4)?;
        }
        check_range("reward.progress_reference_speed", r.progress_reference_speed, 0.0, 20.0)?;
        check_range("reward.proximity_range", r.proximity_range, 0.0, 100.0)?;
        if r.proximity_shape == ProximityShape::Linear && r.proximity_range <= self.collision_range {
            return Err(Invalid::new(
                "reward.proximity_range",
                format!(
                    "above collision_range ({}) for proximity_shape linear, got {}",
                    self.collision_range, r.proximity_range
                ),
            ));
        }
        check_range("reward.social", r.social, 0.0, 1e4)?;
        check_range("reward.social_radius", r.social_radius, 0.01, 100.0)?;
        check_range("reward.social_horizon", r.social_horizon, 0.0, 60.0)?;
        check_range("reward.proximity_horizon", r.proximity_horizon, 0.0, 60.0)?;
        check_range("reward.idle", r.idle, 0.0, 1e4)?;
        check_range("reward.idle_speed", r.idle_speed, 0.0, 100.0)?;
        check_range("reward.plan_deviation", r.plan_deviation, 0.0, 1e4)?;
        check_range("reward.plan_deviation_band", r.plan_deviation_band, 0.0, 100.0)?;
        self.randomization.validate()?;
        self.observation.check()
    }
}

impl TaskConfig {
    /// Reads a task file.
    pub fn from_file(path: &Path) -> Result<Self, ConfigError> {
        from_yaml_file(path)
    }

    /// The tightest circle the action ranges drive (m) on a robot whose top speed is
    /// `top_speed`: `v_min / w_max`, 0 for a robot that may stop and turn on the spot. Starts
    /// keep this much extra room from obstacles.
    pub fn turning_radius(&self, top_speed: f32) -> f32 {
        let a = self.action.for_top_speed(top_speed);
        let (v_min, w_max) = (a.linear[0].max(0.0), a.angular[0].abs().max(a.angular[1].abs()));
        if v_min > 0.0 && w_max > 0.0 { v_min / w_max } else { 0.0 }
    }
}

/// How an episode ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    /// Reached the goal.
    Success,
    /// Touched an obstacle or came closer than the collision range.
    Collision,
    /// Ran out of time.
    Timeout,
}

/// What one finished episode measured.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct EpisodeStats {
    /// How it ended.
    pub outcome: Outcome,
    /// Sum of rewards.
    pub episode_return: f32,
    /// Control steps.
    pub length: u32,
    /// Simulated time (s).
    pub time: f32,
    /// Smallest lidar reading seen (m).
    pub min_range: f32,
    /// Mean linear speed over the episode (m/s).
    pub mean_speed: f32,
    /// Distance driven (m).
    pub path_length: f32,
    /// Start-to-goal distance (m).
    pub initial_distance: f32,
    /// Final distance to the goal (m).
    pub final_distance: f32,
    /// This episode's wheel radius after randomisation (m).
    pub wheel_radius: f32,
    /// This episode's wheel separation after randomisation (m).
    pub wheel_separation: f32,
    /// This episode's speed-limit scale after randomisation.
    pub speed_scale: f32,
    /// Smallest gap between the robot's circumscribed circle and a person (m; +inf without
    /// people).
    pub min_person_gap: f32,
    /// Mean absolute angular acceleration of the body (rad/s², from the measured yaw rate at
    /// each control step): how smoothly it turned.
    #[serde(default)]
    pub mean_angular_acceleration: f32,
    /// Shortest path from start to goal that keeps the robot's clearance, past the static
    /// world (m; NaN when not measured: only [`NavEnv::run_to_end`] measures it).
    #[serde(default = "nan", deserialize_with = "null_as_nan")]
    pub optimal_path_length: f32,
}

/// What a set of finished episodes measured: the rates and means that training's periodic
/// evaluations, `rlnav eval` and `rlnav bench` all report.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct EvalSummary {
    /// Episodes run.
    pub episodes: usize,
    /// Share that reached the goal.
    pub success_rate: f32,
    /// Share that collided.
    pub collision_rate: f32,
    /// Share that ran out of time.
    pub timeout_rate: f32,
    /// Mean return.
    #[serde(default)]
    pub mean_return: f32,
    /// Mean time to the goal over successful episodes (s; NaN without any, `null` in JSON).
    /// Files written before this name read their `mean_success_time`.
    #[serde(alias = "mean_success_time", default = "nan", deserialize_with = "null_as_nan")]
    pub mean_task_time: f32,
    /// Mean over episodes of the smallest lidar range seen (m; a scan with no return counts 0).
    #[serde(default)]
    pub mean_min_range: f32,
    /// Mean over episodes of the mean linear speed (m/s).
    #[serde(default)]
    pub mean_speed: f32,
    /// Mean path length (m).
    #[serde(default)]
    pub mean_path_length: f32,
    /// 95% Wilson score interval of the success rate.
    #[serde(default)]
    pub success_ci95: [f32; 2],
    /// 95% Wilson score interval of the collision rate.
    #[serde(default)]
    pub collision_ci95: [f32; 2],
    /// Success weighted by path length (Anderson et al. 2018): the mean over episodes of
    /// success × L / max(P, L), L the shortest path past the static world, P the path driven
    /// (NaN when L was not measured).
    #[serde(default = "nan", deserialize_with = "null_as_nan")]
    pub spl: f32,
    /// Mean absolute angular acceleration (rad/s²): lower is smoother.
    #[serde(default)]
    pub mean_angular_acceleration: f32,
}

/// The 95% Wilson score interval of a rate of `k` in `n` (`[0, 1]` for no trials): unlike
/// the normal approximation it stays inside [0, 1] and is honest at 0% and 100%.
pub fn wilson_interval(k: usize, n: usize) -> [f32; 2] {
    if n == 0 {
        return [0.0, 1.0];
    }
    let (n, p, z) = (n as f64, k as f64 / n as f64, 1.959_963_984_540_054_f64);
    let centre = (p + z * z / (2.0 * n)) / (1.0 + z * z / n);
    let half = z / (1.0 + z * z / n) * (p * (1.0 - p) / n + z * z / (4.0 * n * n)).sqrt();
    [(centre - half).max(0.0) as f32, (centre + half).min(1.0) as f32]
}

fn nan() -> f32 {
    f32::NAN
}

/// JSON has no NaN: serde_json writes it as `null`, which reads back as NaN.
fn null_as_nan<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f32, D::Error> {
    Ok(Option::<f32>::deserialize(d)?.unwrap_or(f32::NAN))
}

impl EvalSummary {
    /// The summary of these episodes.
    pub fn of(eps: &[EpisodeStats]) -> Self {
        let n = eps.len().max(1) as f32;
        let rate = |o: Outcome| eps.iter().filter(|e| e.outcome == o).count() as f32 / n;
        let mean = |f: &dyn Fn(&EpisodeStats) -> f32| eps.iter().map(f).sum::<f32>() / n;
        let wins: Vec<f32> = eps.iter().filter(|e| e.outcome == Outcome::Success).map(|e| e.time).collect();
        let count = |o: Outcome| eps.iter().filter(|e| e.outcome == o).count();
        Self {
            episodes: eps.len(),
            success_rate: rate(Outcome::Success),
            collision_rate: rate(Outcome::Collision),
            timeout_rate: rate(Outcome::Timeout),
            mean_return: mean(&|e| e.episode_return),
            mean_task_time: if wins.is_empty() { f32::NAN } else { wins.iter().sum::<f32>() / wins.len() as f32 },
            mean_min_range: mean(&|e| if e.min_range.is_finite() { e.min_range } else { 0.0 }),
            mean_speed: mean(&|e| e.mean_speed),
            mean_path_length: mean(&|e| e.path_length),
            success_ci95: wilson_interval(count(Outcome::Success), eps.len()),
            collision_ci95: wilson_interval(count(Outcome::Collision), eps.len()),
            spl: if eps.is_empty() || eps.iter().any(|e| !e.optimal_path_length.is_finite()) {
                f32::NAN
            } else {
                mean(&|e| {
                    let l = e.optimal_path_length;
                    if e.outcome == Outcome::Success { l / e.path_length.max(l).max(1e-6) } else { 0.0 }
                })
            },
            mean_angular_acceleration: mean(&|e| e.mean_angular_acceleration),
        }
    }
}

/// What the environment reports after each control step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepOutcome {
    /// Reward for this step.
    pub reward: f32,
    /// The episode ended by success or collision (no bootstrapping).
    pub terminated: bool,
    /// The episode was cut by the time limit (bootstrap from the final observation).
    pub truncated: bool,
}

/// Errors building or running an environment.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// A configuration problem.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The task's observation does not fit the robot's lidar.
    #[error("task observation does not fit robot `{robot}`: {message}")]
    Incompatible {
        /// The robot.
        robot: String,
        /// What does not fit.
        message: String,
    },
    /// No episode could be drawn.
    #[error(transparent)]
    NoEpisode(#[from] NoEpisode),
}

/// Everything environments share, read-only: scenario, robot, task, compiled lidar.
#[derive(Debug)]
pub struct EnvSetup {
    /// The scenario, compiled for this robot.
    pub scenario: Scenario,
    /// The robot.
    pub robot: RobotSpec,
    /// The task, its action ranges in m/s for this robot ([`ActionConfig::for_top_speed`]).
    pub task: TaskConfig,
    /// The robot's lidar, compiled.
    pub lidar: Lidar,
    /// The robot's footprint, compiled.
    pub footprint: Footprint,
    /// The scenario at evenly spaced difficulties from 0 to 1, for an automatic curriculum
    /// (empty unless built with [`Self::with_difficulty_levels`]).
    pub levels: Vec<Scenario>,
    substeps: u32,
    obs_dim: usize,
}

impl EnvSetup {
    /// Checks that the pieces fit and compiles them.
    pub fn new(scenario: ScenarioSpec, robot: RobotSpec, mut task: TaskConfig) -> Result<Self, SimError> {
        task.validate().map_err(|e| e.in_file("<task>"))?;
        robot.validate().map_err(|e| e.in_file(&format!("<robot {}>", robot.name)))?;
        // Everything past here (commands, clipping, turning room, DWA labels) works in m/s.
        task.action = task.action.for_top_speed(robot.max_linear);
        let beams = robot.lidar.beams;
        for (key, b) in task.observation.lidar_terms() {
            if beams % b != 0 {
                return Err(SimError::Incompatible {
                    robot: robot.name.clone(),
                    message: format!(
                        "{key}: the lidar term wants {b} beams, which does not divide the robot's {beams}"
                    ),
                });
            }
        }
        let footprint = robot.footprint();
        let clearance = footprint.radius().max(task.collision_range);
        // A robot that cannot turn on the spot (v_min > 0) needs its turning radius of room
        // at the start, or a start facing a wall is a collision no policy can avoid.
        let scenario = Scenario::new(scenario, clearance, task.turning_radius(robot.max_linear))?;
        let substeps = (task.control_period / task.physics_dt).round() as u32;
        let obs_dim = task.observation.len();
        Ok(Self {
            scenario,
            lidar: Lidar::new(robot.lidar.clone()),
            footprint,
            robot,
            task,
            levels: Vec::new(),
            substeps,
            obs_dim,
        })
    }

    /// Adds `n` (≥ 2) difficulty levels of the scenario, level `k` at difficulty `k / (n - 1)`
    /// (the last is the scenario as written), for environments whose level an automatic
    /// curriculum moves ([`NavEnv::set_level`]).
    pub fn with_difficulty_levels(mut self, n: usize) -> Result<Self, SimError> {
        let n = n.max(2);
        self.levels =
            (0..n).map(|k| self.scenario.at_difficulty(k as f32 / (n - 1) as f32)).collect::<Result<_, _>>()?;
        Ok(self)
    }

    /// The same scenes under another task (observation, action ranges, timing, rules): this
    /// setup's compiled scenario with `task`, so that an episode drawn with a given seed is
    /// the same scene under both. Compiled afresh, a task whose turning radius differs would
    /// admit other starts and draw other episodes. Refused as [`Self::on_scenes_of`] refuses.
    pub fn with_task(&self, task: TaskConfig) -> Result<Self, SimError> {
        Self::new(self.scenario.spec().clone(), self.robot.clone(), task)?.on_scenes_of(self)
    }

    /// This setup on `other`'s compiled scenario (and difficulty levels): the episodes
    /// `other` draws, under this setup's task. Refused unless both are the same scenario and
    /// robot, with the same clearance (collision range), and this task needs no more room at
    /// the start than `other`'s scenes keep (a turning radius no larger).
    pub fn on_scenes_of(mut self, other: &EnvSetup) -> Result<Self, SimError> {
        let (mine, theirs) = (&self.scenario, &other.scenario);
        let incompatible = |message: String| SimError::Incompatible { robot: self.robot.name.clone(), message };
        if mine.spec() != theirs.spec() || self.robot != other.robot {
            return Err(incompatible(format!(
                "scenes of `{}` with `{}` are not those of `{}` with `{}`",
                theirs.spec().name,
                other.robot.name,
                mine.spec().name,
                self.robot.name
            )));
        }
        if mine.clearance() != theirs.clearance() || mine.start_clearance() > theirs.start_clearance() + 1e-6 {
            return Err(incompatible(format!(
                "scenes compiled for a clearance of {} m ({} m at the start) cannot be run under a task that needs {} m ({} m at the start)",
                theirs.clearance(),
                theirs.start_clearance(),
                mine.clearance(),
                mine.start_clearance()
            )));
        }
        self.scenario = other.scenario.clone();
        self.levels = other.levels.clone();
        Ok(self)
    }

    /// Loads the scenario (preset or file) with its own robot and the default task.
    pub fn from_scenario_name(name: &str) -> Result<Self, SimError> {
        Self::load(name, None, None)
    }

    /// Loads a scenario (preset or file), a robot (preset or file; default: the scenario's)
    /// and a task file (default: [`TaskConfig::default`]), and checks that they fit together:
    /// what the CLI's `--scenario/--robot/--task` and the Python API take.
    pub fn load(scenario: &str, robot: Option<&str>, task: Option<&Path>) -> Result<Self, SimError> {
        let spec = ScenarioSpec::load(scenario)?;
        let robot = RobotSpec::load(robot.unwrap_or(&spec.robot))?;
        let task = match task {
            Some(p) => TaskConfig::from_file(p)?,
            None => TaskConfig::default(),
        };
        Self::new(spec, robot, task)
    }

    /// Length of the observation vector.
    pub fn obs_dim(&self) -> usize {
        self.obs_dim
    }

    /// Physics steps per control step.
    pub fn substeps(&self) -> u32 {
        self.substeps
    }
}

/// Values per mover in [`NavEnv::write_privileged`]: `x, y, vx, vy, r`.
pub const PRIVILEGED_PER_MOVER: usize = 5;
/// Where [`NavEnv::write_privileged`] puts a mover that is not there (m ahead).
pub const PRIVILEGED_FAR: f32 = 10.0;

/// Length of [`NavEnv::write_privileged`]'s state for `movers` movers (0 for none: no
/// privileged state is kept).
pub fn privileged_len(movers: usize) -> usize {
    if movers == 0 { 0 } else { PRIVILEGED_PER_MOVER * movers + 2 }
}

/// One robot navigating one episode after another.
#[derive(Debug)]
pub struct NavEnv {
    setup: Arc<EnvSetup>,
    rng: Pcg64Mcg,
    /// Difficulty level (index into `setup.levels`) of an automatic curriculum.
    level: Option<usize>,
    /// The `plan_ahead` observation term's points (robot frame), preallocated.
    ahead: Vec<Vec2>,
    world: Arc<World>,
    drive: DiffDrive,
    goal: Vec2,
    last_command: Twist,
    distance: f32,
    steps: u32,
    ranges: Vec<f32>,
    dirs: Vec<Vec2>,
    /// Writes the task's observation and keeps its history terms' past.
    observer: ObservationBuilder,
    /// An observation written only to record a step's history (see `step_twist`).
    scratch: Vec<f32>,
    min_range: f32,
    episode_return: f32,
    speed_sum: f32,
    path_length: f32,
    initial_distance: f32,
    last_episode: Option<EpisodeStats>,
    movers: Vec<Mover>,
    crowd: Crowd,
    min_person_gap: f32,
    mover_rays: RayGeometry,
    time: f32,
    /// Commands given but not yet applied (control latency), oldest first.
    pending: std::collections::VecDeque<Twist>,
    applied: Twist,
    speed_scale: f32,
    goal_velocity: Vec2,
    /// This episode's free space, start and goal (for its shortest path).
    reach: Option<Arc<ReachabilityGrid>>,
    start: Vec2,
    first_goal: Vec2,
    angular_acceleration_sum: f32,
    /// Movers in the privileged state kept at an episode's end (0: none).
    privileged_movers: usize,
    /// The privileged state when the last episode ended (see [`NavEnv::keep_final_privileged`]).
    final_privileged: Vec<f32>,
    /// The global plan being followed (empty: none) and the path length from each corner
    /// to its end.
    plan: Arc<[Vec2]>,
    plan_suffix: Vec<f32>,
    plan_progress: usize,
    /// Where the policy steers: the goal, or the plan's point a lookahead ahead.
    target: Vec2,
    /// The plan controllers are given in [`NavEnv::run_to_end`] when the scenario's static
    /// world is known in advance (a prior map, as DWA is given one); empty otherwise.
    prior_plan: Arc<[Vec2]>,
    /// The empty plan, shared.
    no_plan: Arc<[Vec2]>,
}

impl NavEnv {
    /// An environment with its own random stream, already reset.
    pub fn new(setup: Arc<EnvSetup>, seed: u64) -> Result<Self, SimError> {
        let n = setup.lidar.beams();
        let observer = ObservationBuilder::new(&setup.task.observation);
        let scratch = if observer.has_history() { vec![0.0; setup.obs_dim] } else { Vec::new() };
        let drive = DiffDrive::new(DriveParams::from(&setup.robot), Pose2::default());
        let mut env = Self {
            rng: Pcg64Mcg::seed_from_u64(seed),
            world: Arc::new(World::new(Vec::new())),
            drive,
            goal: Vec2::ZERO,
            last_command: Twist::default(),
            distance: 0.0,
            steps: 0,
            ranges: vec![f32::INFINITY; n],
            dirs: vec![Vec2::ZERO; n],
            observer,
            scratch,
            min_range: f32::INFINITY,
            episode_return: 0.0,
            speed_sum: 0.0,
            path_length: 0.0,
            initial_distance: 0.0,
            last_episode: None,
            movers: Vec::new(),
            crowd: Crowd::default(),
            min_person_gap: f32::INFINITY,
            mover_rays: RayGeometry::default(),
            time: 0.0,
            pending: std::collections::VecDeque::with_capacity(setup.task.randomization.latency_steps + 1),
            applied: Twist::default(),
            speed_scale: 1.0,
            goal_velocity: Vec2::ZERO,
            reach: None,
            start: Vec2::ZERO,
            first_goal: Vec2::ZERO,
            angular_acceleration_sum: 0.0,
            privileged_movers: 0,
            final_privileged: Vec::new(),
            plan: Arc::from(Vec::new()),
            plan_suffix: Vec::new(),
            plan_progress: 0,
            target: Vec2::ZERO,
            prior_plan: Arc::from(Vec::new()),
            no_plan: Arc::from(Vec::new()),
            level: None,
            ahead: vec![Vec2::ZERO; setup.task.observation.plan_ahead().map_or(0, |p| p.0)],
            setup,
        };
        env.reset()?;
        Ok(env)
    }

    /// Starts a new episode: draws a world, start and goal, and takes the first scan.
    pub fn reset(&mut self) -> Result<(), SimError> {
        let setup = self.setup.clone();
        let scenario = match self.level {
            Some(l) => &setup.levels[l],
            None => &setup.scenario,
        };
        // Movers timed to meet the robot are timed for its nominal top speed.
        let speed = Some(self.setup.robot.max_linear);
        // A moving obstacle may start on top of the robot; draw again (rarely needed).
        let mut ep = scenario.sample_for(&mut self.rng, speed)?;
        let room = self.setup.scenario.start_clearance();
        for _ in 0..20 {
            let p = ep.start.position();
            if ep.movers.iter().all(|m| m.signed_distance(p) >= room)
                && ep.people.iter().all(|q| q.signed_distance(p) >= room)
            {
                break;
            }
            ep = scenario.sample_for(&mut self.rng, speed)?;
        }
        self.movers = ep.movers;
        self.crowd = Crowd::new(ep.people, &ep.world);
        self.time = 0.0;
        self.world = ep.world;
        let dr = &self.setup.task.randomization;
        let mut params = DriveParams::from(&self.setup.robot);
        let jitter = |j: f32, rng: &mut Pcg64Mcg| if j > 0.0 { 1.0 + rng.random_range(-j..=j) } else { 1.0 };
        params.wheel_radius *= jitter(dr.wheel_radius_jitter, &mut self.rng);
        params.wheel_separation *= jitter(dr.wheel_separation_jitter, &mut self.rng);
        self.speed_scale = jitter(dr.speed_limit_jitter, &mut self.rng);
        params.linear = params.linear.map(|v| v * self.speed_scale);
        params.max_angular *= self.speed_scale;
        self.drive = DiffDrive::new(params, ep.start);
        self.pending.clear();
        self.pending.extend(std::iter::repeat_n(Twist::default(), dr.latency_steps));
        self.applied = Twist::default();
        self.goal = ep.goal;
        self.goal_velocity = ep.goal_velocity;
        self.start = ep.start.position();
        self.first_goal = ep.goal;
        self.angular_acceleration_sum = 0.0;
        // A goal that moves has no fixed plan; it is steered to directly.
        let plan = match &self.setup.task.plan {
            Some(_) if ep.goal_velocity == Vec2::ZERO => match &ep.map {
                Some(map) => scenario.global_plan_on_map(map, self.start, ep.goal),
                None => scenario.global_plan(&self.world, &ep.reach, self.start, ep.goal),
            },
            _ => None,
        };
        // Without a plan nothing is allocated (a fixed world's reset allocates nothing).
        self.plan_suffix = plan.as_deref().map(crate::plan::suffix_lengths).unwrap_or_default();
        self.plan = plan.map_or_else(|| self.no_plan.clone(), Arc::from);
        self.plan_progress = 0;
        // A world known in advance is a prior map: controllers get the plan too.
        self.prior_plan =
            if self.setup.scenario.fixed_world().is_some() { self.plan.clone() } else { self.no_plan.clone() };
        self.reach = Some(ep.reach);
        self.last_command = Twist::default();
        self.initial_distance = (self.goal - ep.start.position()).length();
        self.distance = self.update_target().0;
        self.steps = 0;
        self.episode_return = 0.0;
        self.speed_sum = 0.0;
        self.path_length = 0.0;
        let radius = self.setup.footprint.radius();
        self.min_person_gap = self.crowd.min_gap(self.drive.pose.position(), radius);
        self.observer.reset();
        self.scan();
        self.min_range = self.current_min_range();
        Ok(())
    }

    fn scan(&mut self) {
        let s = &self.setup;
        if self.movers.is_empty() && self.crowd.is_empty() {
            s.lidar.scan(&self.drive.pose, self.world.ray_geometry(), &mut self.dirs, &mut self.ranges);
        } else {
            self.mover_rays.clear();
            for m in &self.movers {
                m.push_to(&mut self.mover_rays);
            }
            for p in &self.crowd.people {
                p.push_to(&mut self.mover_rays);
            }
            let layers = [self.world.ray_geometry(), &self.mover_rays];
            s.lidar.scan_layers(&self.drive.pose, &layers, &mut self.dirs, &mut self.ranges);
        }
        s.lidar.apply_noise(&mut self.rng, &mut self.ranges);
        s.lidar.corrupt(&mut self.rng, 0.0, s.task.randomization.lidar_dropout, &mut self.ranges);
    }

    fn current_min_range(&self) -> f32 {
        self.ranges.iter().copied().fold(f32::INFINITY, f32::min)
    }

    /// The nearest the scan's returns come to the sensor if the robot drove straight on at its
    /// measured speed for `horizon` seconds, the returns held still (never more than the
    /// nearest return now).
    fn min_range_ahead(&self, horizon: f32) -> f32 {
        let yaw = self.drive.pose.yaw;
        let travel = Vec2::new(yaw.cos(), yaw.sin()) * (self.drive.velocity.linear * horizon);
        // Each return's distance to the segment the sensor sweeps.
        self.ranges
            .iter()
            .zip(&self.dirs)
            .filter(|(r, _)| r.is_finite())
            .map(|(&r, &dir)| point_segment_distance_squared(dir * r, Vec2::ZERO, travel))
            .fold(f32::INFINITY, f32::min)
            .sqrt()
    }

    /// Applies a normalised action in `[-1, 1]²` for one control period.
    pub fn step(&mut self, action: [f32; 2]) -> StepOutcome {
        let std = self.setup.task.randomization.action_std;
        let action =
            if std > 0.0 { action.map(|a| a + std * self.rng.sample::<f32, _>(StandardNormal)) } else { action };
        let cmd = self.setup.task.action.to_twist(action);
        self.step_twist(cmd)
    }

    /// Applies a velocity command (clipped to the task's action ranges) for one control period.
    pub fn step_twist(&mut self, cmd: Twist) -> StepOutcome {
        if self.observer.has_history() {
            // The history records the observation of the step being taken, as written for the
            // policy; one that was never written (a `Controller` driving) is written now. Only
            // layouts with a history draw observation noise here.
            if !self.observer.is_written() {
                let mut scratch = std::mem::take(&mut self.scratch);
                self.write_observation(&mut scratch);
                self.scratch = scratch;
            }
            self.observer.commit();
        }
        let setup = Arc::clone(&self.setup);
        let task = &setup.task;
        let a = &task.action;
        let cmd = Twist::new(
            if cmd.linear.is_finite() { cmd.linear.clamp(a.linear[0], a.linear[1]) } else { a.linear[0] },
            if cmd.angular.is_finite() { cmd.angular.clamp(a.angular[0], a.angular[1]) } else { 0.0 },
        );
        // Control latency: the command given now is applied `latency_steps` steps later.
        self.pending.push_back(cmd);
        let given = cmd;
        let cmd = self.pending.pop_front().unwrap_or(given);
        self.applied = cmd;
        let mut contact = false;
        let yaw_rate_before = self.drive.velocity.angular;
        let robot_radius = setup.footprint.radius();
        // People keep the robot's clearance (footprint or collision range, plus margin) away.
        let personal = setup.scenario.clearance();
        self.crowd.plan(self.drive.pose.position(), personal, task.control_period, &mut self.rng);
        for _ in 0..setup.substeps {
            let before = self.drive.pose.position();
            self.drive.step(cmd, task.physics_dt);
            self.time += task.physics_dt;
            if self.goal_velocity != Vec2::ZERO {
                (self.goal, self.goal_velocity) =
                    setup.scenario.move_goal(self.goal, self.goal_velocity, task.physics_dt);
            }
            for m in &mut self.movers {
                m.set_time(self.time);
            }
            self.crowd.advance(task.physics_dt);
            self.path_length += (self.drive.pose.position() - before).length();
            let fp = &setup.footprint;
            if self.world.footprint_collides(fp, &self.drive.pose)
                || self.movers.iter().any(|m| m.touches(fp, &self.drive.pose))
                || self.crowd.people.iter().any(|p| p.touches(fp, &self.drive.pose))
            {
                contact = true;
                break;
            }
        }
        self.last_command = given;
        self.angular_acceleration_sum += (self.drive.velocity.angular - yaw_rate_before).abs() / task.control_period;
        self.speed_sum += self.drive.velocity.linear.abs();
        self.steps += 1;
        self.scan();
        let r_min = self.current_min_range();
        self.min_range = self.min_range.min(r_min);

        let d = (self.goal - self.drive.pose.position()).length();
        // Progress towards the goal, along the plan when there is one.
        let (remaining, off_plan) = self.update_target();
        let rw = &task.reward;
        let progress_scale = if rw.progress_reference_speed > 0.0 {
            rw.progress_reference_speed / self.setup.robot.max_linear
        } else {
            1.0
        };
        let mut reward = rw.progress * progress_scale * (self.distance - remaining);
        let here = self.drive.pose.position();
        if !self.crowd.is_empty() {
            self.min_person_gap = self.min_person_gap.min(self.crowd.min_gap(here, robot_radius));
        }
        if rw.social > 0.0 {
            let pose = &self.drive.pose;
            let velocity = Vec2::new(pose.yaw.cos(), pose.yaw.sin()) * self.drive.velocity.linear;
            let (radius, horizon) = (rw.social_radius, rw.social_horizon);
            let mut intrusion = self.crowd.intrusion(here, velocity, robot_radius, radius, horizon);
            if rw.social_movers {
                intrusion +=
                    self.movers.iter().map(|m| m.intrusion(here, velocity, robot_radius, radius, horizon)).sum::<f32>();
            }
            reward -= rw.social * intrusion;
        }
        let r_charged = if rw.proximity_horizon > 0.0 { self.min_range_ahead(rw.proximity_horizon) } else { r_min };
        if r_charged < rw.proximity_range {
            reward -= rw.proximity * rw.proximity_shape.value(r_charged, rw.proximity_range, task.collision_range);
        }
        if rw.idle > 0.0 && self.drive.velocity.linear.abs() < rw.idle_speed {
            reward -= rw.idle;
        }
        reward -= rw.plan_deviation * (off_plan - rw.plan_deviation_band).max(0.0);
        self.distance = remaining;
        let outcome = if contact || r_min < task.collision_range {
            reward += rw.collision;
            Some(Outcome::Collision)
        } else if d < task.goal_tolerance {
            reward += rw.goal + rw.goal_time_bonus * (task.max_steps.saturating_sub(self.steps)) as f32;
            Some(Outcome::Success)
        } else if self.steps >= task.max_steps {
            reward += rw.timeout;
            Some(Outcome::Timeout)
        } else {
            None
        };
        self.episode_return += reward;
        if let Some(outcome) = outcome {
            self.last_episode = Some(EpisodeStats {
                outcome,
                episode_return: self.episode_return,
                length: self.steps,
                time: self.steps as f32 * task.control_period,
                min_range: self.min_range,
                mean_speed: self.speed_sum / self.steps as f32,
                path_length: self.path_length,
                initial_distance: self.initial_distance,
                final_distance: d,
                wheel_radius: self.drive.params.wheel_radius,
                wheel_separation: self.drive.params.wheel_separation,
                speed_scale: self.speed_scale,
                min_person_gap: self.min_person_gap,
                mean_angular_acceleration: self.angular_acceleration_sum / self.steps as f32,
                optimal_path_length: f32::NAN,
            });
        }
        StepOutcome {
            reward,
            terminated: matches!(outcome, Some(Outcome::Success | Outcome::Collision)),
            truncated: outcome == Some(Outcome::Timeout),
        }
    }

    /// Writes the observation vector (layout of the task) into `out`. A layout with history
    /// terms shows the values written at the previous steps of the episode (or, for a step
    /// taken without a write, the values it would have written).
    pub fn write_observation(&mut self, out: &mut [f32]) {
        let (mut dist, mut bearing) = self.drive.pose.polar_of(self.target);
        let dr = &self.setup.task.randomization;
        if dr.obs_goal_distance_std > 0.0 {
            dist = (dist + dr.obs_goal_distance_std * self.rng.sample::<f32, _>(StandardNormal)).max(0.0);
        }
        if dr.obs_goal_bearing_std > 0.0 {
            bearing = wrap_angle(bearing + dr.obs_goal_bearing_std * self.rng.sample::<f32, _>(StandardNormal));
        }
        let lidar_std = dr.obs_lidar_std;
        if let Some((_, spacing)) = self.setup.task.observation.plan_ahead() {
            let pose = &self.drive.pose;
            crate::plan::points_ahead(&self.plan, self.plan_progress, self.goal, pose, spacing, &mut self.ahead);
        }
        let inputs = ObservationInputs {
            ranges: &self.ranges,
            angle_increment: self.setup.lidar.spec().angle_increment(),
            angle_min: self.setup.lidar.spec().angle_min,
            // The scanner, where the ranges are measured from and in whose frame.
            pose: self.drive.pose.compose(&self.setup.lidar.spec().mount),
            goal_distance: dist,
            goal_bearing: bearing,
            last_command: self.last_command,
            velocity: self.drive.velocity,
            // A differential drive does not slide sideways.
            lateral_velocity: 0.0,
            plan_ahead: &self.ahead,
        };
        let rng = &mut self.rng;
        self.observer.write(&inputs, out, || {
            if lidar_std > 0.0 { lidar_std * rng.sample::<f32, _>(StandardNormal) } else { 0.0 }
        });
    }

    /// Goal distance and bearing in the robot frame.
    pub fn goal_polar(&self) -> (f32, f32) {
        self.drive.pose.polar_of(self.goal)
    }

    /// Moves the target to where the robot is now (the goal, or the point a lookahead ahead
    /// along the plan) and returns the distance left to the goal (straight, or via the target
    /// and the rest of the plan) and the robot's distance from the plan (0 without one).
    fn update_target(&mut self) -> (f32, f32) {
        let here = self.drive.pose.position();
        match &self.setup.task.plan {
            Some(p) if !self.plan.is_empty() => {
                let s = crate::plan::follow(&self.plan, &self.plan_suffix, &mut self.plan_progress, here, p.lookahead);
                self.target = s.point;
                ((s.point - here).length() + s.rest, s.offset)
            }
            _ => {
                self.target = self.goal;
                ((self.goal - here).length(), 0.0)
            }
        }
    }

    /// Where the policy steers now: the goal, or with a plan the point a lookahead ahead
    /// along it.
    pub fn target(&self) -> Vec2 {
        self.target
    }

    /// The global plan the task follows this episode (empty without one).
    pub fn plan(&self) -> &Arc<[Vec2]> {
        &self.plan
    }

    /// Fills what a robot's topics would carry (scan, odometry, goal) for a [`Controller`].
    pub fn robot_observation(&self, out: &mut RobotObservation) {
        let spec = self.setup.lidar.spec();
        if out.scan.ranges.len() != self.ranges.len() {
            out.scan = LaserScan::for_spec(spec);
        }
        out.scan.ranges.copy_from_slice(&self.ranges);
        out.scan_mount = spec.mount;
        out.pose = self.drive.pose;
        out.velocity = self.drive.velocity;
        out.lateral_velocity = 0.0;
        out.goal = self.goal;
        out.last_command = self.last_command;
        out.time = self.steps as f32 * self.setup.task.control_period;
        if !Arc::ptr_eq(&out.plan, &self.prior_plan) {
            out.plan = self.prior_plan.clone();
        }
    }

    /// The shortest path from this episode's start to its (first) goal past the static world,
    /// keeping the robot's clearance (m; `None` if they are not connected at that clearance).
    /// Theta* over the world's free cells (it allocates; stepping never calls it).
    pub fn shortest_path_length(&self) -> Option<f32> {
        self.reach.as_ref()?.shortest_path_length(self.start, self.first_goal)
    }

    /// Difficulty level of an automatic curriculum (`None` when off).
    pub fn level(&self) -> Option<usize> {
        self.level
    }

    /// Puts the environment on difficulty level `level` of its setup's
    /// [`EnvSetup::levels`] (clamped to the last), or off the levels (`None`); the next
    /// [`Self::reset`] draws from it.
    pub fn set_level(&mut self, level: Option<usize>) {
        let n = self.setup.levels.len();
        self.level = level.filter(|_| n > 0).map(|l| l.min(n - 1));
    }

    /// The automatic curriculum's move after an episode (as Isaac Lab moves terrain levels): a
    /// success goes one level up, a failure one down; a success on the top level sends the
    /// environment to a random level, so that easier rooms keep being seen.
    pub fn advance_level(&mut self, success: bool) {
        let n = self.setup.levels.len();
        if let Some(l) = self.level {
            self.level = Some(match (success, l + 1 >= n) {
                (true, true) => self.rng.random_range(0..n),
                (true, false) => l + 1,
                (false, _) => l.saturating_sub(1),
            });
        }
    }

    /// Writes the privileged state a training critic may read beside the observation (an
    /// asymmetric actor-critic: the deployed actor never sees it) into `out`, of
    /// [`privileged_len`]`(movers)` values: for the `movers` nearest moving obstacles and
    /// people (by gap to their bounding circle), their centre and their velocity relative to
    /// the robot's, both in the robot frame, and their bounding radius (`x, y, vx, vy, r`);
    /// then the robot's top speed this episode and its footprint radius. Missing movers read
    /// as [`PRIVILEGED_FAR`] m ahead, standing, of radius 0.
    ///
    /// Why: whether a crossing cart will be in the robot's way is hard to read from a few
    /// scans, so a critic that sees only the scans values such states poorly; the mover's
    /// velocity makes it plain.
    pub fn write_privileged(&self, movers: usize, out: &mut [f32]) {
        assert!(movers > 0, "a privileged state of at least one mover");
        assert_eq!(out.len(), privileged_len(movers), "privileged state of {movers} movers");
        let pose = &self.drive.pose;
        let here = pose.position();
        let own = Vec2::new(pose.yaw.cos(), pose.yaw.sin()) * self.drive.velocity.linear;
        // (gap, index, centre, velocity, radius) of every mover and person.
        let things = || {
            self.movers
                .iter()
                .map(|m| (m.pose.position(), m.velocity, m.shape.bound_radius()))
                .chain(self.crowd.people.iter().map(|p| (p.position, p.velocity, p.radius)))
                .enumerate()
                .map(move |(i, (p, v, r))| ((p - here).length() - r, i, p, v, r))
        };
        // Slot by slot, the nearest after the previous slot's (by gap, then index): no
        // allocation, and a handful of movers makes the repeated scan cheap.
        let mut after: Option<(f32, usize)> = None;
        for slot in out[..PRIVILEGED_PER_MOVER * movers].chunks_exact_mut(PRIVILEGED_PER_MOVER) {
            let next = things()
                .filter(|t| after.is_none_or(|a| (t.0, t.1) > a))
                .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            match next {
                Some((gap, i, p, v, r)) => {
                    let (p, v) = (pose.to_local(p), pose.vector_to_local(v - own));
                    slot.copy_from_slice(&[p.x, p.y, v.x, v.y, r]);
                    after = Some((gap, i));
                }
                None => slot.copy_from_slice(&[PRIVILEGED_FAR, 0.0, 0.0, 0.0, 0.0]),
            }
        }
        let n = out.len();
        out[n - 2] = self.drive.params.linear[1];
        out[n - 1] = self.setup.footprint.radius();
    }

    /// Keeps the privileged state of `movers` movers at every episode's end (0: none).
    pub fn set_privileged_movers(&mut self, movers: usize) {
        self.privileged_movers = movers;
        self.final_privileged = vec![0.0; privileged_len(movers)];
    }

    /// Stores the privileged state now, the episode's last (before [`NavEnv::reset`]).
    pub fn keep_final_privileged(&mut self) {
        if self.privileged_movers > 0 {
            let mut out = std::mem::take(&mut self.final_privileged);
            self.write_privileged(self.privileged_movers, &mut out);
            self.final_privileged = out;
        }
    }

    /// The privileged state stored by [`NavEnv::keep_final_privileged`].
    pub fn final_privileged(&self) -> &[f32] {
        &self.final_privileged
    }

    /// The statistics of the episode that ended last (`None` before the first ends).
    pub fn last_episode(&self) -> Option<EpisodeStats> {
        self.last_episode
    }

    /// The robot's pose.
    pub fn pose(&self) -> Pose2 {
        self.drive.pose
    }

    /// The measured body velocity (what odometry reports).
    pub fn velocity(&self) -> Twist {
        self.drive.velocity
    }

    /// The command given at the previous control step (before latency).
    pub fn last_command(&self) -> Twist {
        self.last_command
    }

    /// The command applied to the wheels in the last control step (after latency).
    pub fn applied_command(&self) -> Twist {
        self.applied
    }

    /// This episode's drive parameters (after randomisation).
    pub fn drive_params(&self) -> DriveParams {
        self.drive.params
    }

    /// The goal.
    pub fn goal(&self) -> Vec2 {
        self.goal
    }

    /// The people, where they are now.
    pub fn people(&self) -> &[Person] {
        &self.crowd.people
    }

    /// The moving obstacles, where they are now.
    pub fn movers(&self) -> &[Mover] {
        &self.movers
    }

    /// The current world.
    pub fn world(&self) -> &Arc<World> {
        &self.world
    }

    /// The latest scan (full beam count).
    pub fn ranges(&self) -> &[f32] {
        &self.ranges
    }

    /// The shared setup.
    pub fn setup(&self) -> &Arc<EnvSetup> {
        &self.setup
    }

    /// Runs one episode from the current state under `controller`, then resets.
    /// Returns the episode's statistics.
    pub fn run_episode(&mut self, controller: &mut dyn Controller) -> Result<EpisodeStats, SimError> {
        let stats = self.run_to_end(controller, |_| {});
        self.reset()?;
        Ok(stats)
    }

    /// Runs the current episode to its end under `controller` (reset first), calling
    /// `on_step(self)` at the start and after every control step; the environment is left at
    /// the end (not reset), so the episode's last state can still be read.
    /// Measures the episode's shortest path (for SPL) first; with a static world known in
    /// advance, controllers are given it as their plan ([`RobotObservation::plan`]).
    pub fn run_to_end(&mut self, controller: &mut dyn Controller, mut on_step: impl FnMut(&Self)) -> EpisodeStats {
        let optimal = self.shortest_path_length().unwrap_or(f32::NAN);
        // The task's own plan when it has one (reset gave it to controllers already).
        let known_room = self.setup.scenario.fixed_world().is_some() && self.goal_velocity == Vec2::ZERO;
        if known_room && self.plan.is_empty() {
            let scenario = &self.setup.scenario;
            let plan =
                self.reach.as_ref().and_then(|r| scenario.global_plan(&self.world, r, self.start, self.first_goal));
            self.prior_plan = plan.map_or_else(|| self.no_plan.clone(), Arc::from);
        }
        controller.reset();
        on_step(self);
        let mut obs = RobotObservation::default();
        loop {
            self.robot_observation(&mut obs);
            let out = self.step_twist(controller.act(&obs));
            on_step(self);
            if out.terminated || out.truncated {
                let stats = self.last_episode.as_mut().expect("set when an episode ends");
                stats.optimal_path_length = optimal;
                return *stats;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::controller::{GreedyGoal, StraightAhead};

    fn setup(name: &str) -> Arc<EnvSetup> {
        Arc::new(EnvSetup::from_scenario_name(name).unwrap())
    }

    #[test]
    fn privileged_state_shows_the_nearest_movers_in_the_robot_frame() {
        let mut env = NavEnv::new(setup("heldout-dynamic-fast-crossing"), 3).unwrap();
        for _ in 0..20 {
            env.step([1.0, 0.3]);
        }
        let k = 3;
        let mut out = vec![f32::NAN; privileged_len(k)];
        env.write_privileged(k, &mut out);
        let pose = env.pose();
        let own = Vec2::new(pose.yaw.cos(), pose.yaw.sin()) * env.drive.velocity.linear;
        assert!(own.length() > 0.05, "the robot moves: {own:?}");
        // The scene's two movers, nearest first; the third slot is empty.
        let mut movers: Vec<&Mover> = env.movers().iter().collect();
        assert_eq!(movers.len(), 2);
        let gap = |m: &Mover| (m.pose.position() - pose.position()).length() - m.shape.bound_radius();
        movers.sort_by(|a, b| gap(a).total_cmp(&gap(b)));
        for (slot, m) in out.chunks_exact(PRIVILEGED_PER_MOVER).zip(&movers) {
            let p = pose.to_local(m.pose.position());
            let v = pose.vector_to_local(m.velocity - own);
            let want = [p.x, p.y, v.x, v.y, m.shape.bound_radius()];
            for (got, want) in slot.iter().zip(want) {
                assert!((got - want).abs() < 1e-4, "{slot:?} against {want:?}");
            }
        }
        assert_eq!(&out[10..15], &[PRIVILEGED_FAR, 0.0, 0.0, 0.0, 0.0], "no third mover");
        let params = env.drive_params();
        assert_eq!(out[15], params.linear[1], "the robot's top speed this episode");
        assert_eq!(out[16], env.setup().footprint.radius());
    }

    #[test]
    fn default_layout_is_the_articles() {
        let t = TaskConfig::default();
        assert_eq!(t.observation.len(), 124);
        let yaml = include_str!("../../../configs/task.yaml");
        let parsed: TaskConfig = crate::config::from_yaml_str("configs/task.yaml", yaml).unwrap();
        assert_eq!(parsed, t, "configs/task.yaml documents the defaults");
    }

    #[test]
    fn action_scaling_round_trips() {
        let a = ActionConfig::default();
        assert_eq!(a.to_twist([-1.0, -1.0]), Twist::new(0.1, -0.5));
        assert_eq!(a.to_twist([1.0, 1.0]), Twist::new(0.5, 0.5));
        assert_eq!(a.to_twist([5.0, f32::NAN]), Twist::new(0.5, 0.0));
        let t = Twist::new(0.3, 0.25);
        let back = a.to_twist(a.to_action(t));
        assert!((back.linear - 0.3).abs() < 1e-6 && (back.angular - 0.25).abs() < 1e-6);
        // In m/s already: unchanged by a top speed. In shares of it: scaled, angular kept.
        assert_eq!(a.for_top_speed(0.22), a);
        let shares = ActionConfig { linear: [0.2, 1.0], linear_relative: true, ..Default::default() };
        let burger = shares.for_top_speed(0.22);
        assert_eq!((burger.linear, burger.angular, burger.linear_relative), ([0.2 * 0.22, 0.22], a.angular, false));
        assert_eq!(burger.to_twist([1.0, 0.0]).linear, 0.22);
        // A share above the top speed is refused, naming the key; the same range in m/s is not.
        let task = |linear_relative| TaskConfig {
            action: ActionConfig { linear: [0.2, 1.5], linear_relative, ..Default::default() },
            ..Default::default()
        };
        let e = task(true).validate().unwrap_err();
        assert!(e.key == "action.linear" && e.expected.contains("<= 1"), "{e:?}");
        task(false).validate().unwrap();
        // The turning room at the start follows the robot's slowest command.
        let relative = TaskConfig { action: shares, ..Default::default() };
        assert!((relative.turning_radius(0.22) - 0.2 * 0.22 / 0.5).abs() < 1e-6);
    }

    #[test]
    fn greedy_reaches_goals_in_an_empty_room() {
        let mut env = NavEnv::new(setup("empty-room"), 7).unwrap();
        let mut c = GreedyGoal::default();
        let mut successes = 0;
        for _ in 0..40 {
            let s = env.run_episode(&mut c).unwrap();
            if s.outcome == Outcome::Success {
                successes += 1;
                assert!(s.final_distance < 0.3);
                assert!(s.path_length >= s.initial_distance - 0.3 - 1e-3);
            }
        }
        // Blind to walls and unable to turn on the spot (v >= 0.1 m/s), it sometimes starts
        // facing a wall with the goal behind it; everything else it reaches.
        assert!(successes >= 34, "{successes}/40");
    }

    #[test]
    fn spl_and_smoothness_of_a_greedy_run() {
        let mut env = NavEnv::new(setup("empty-room"), 7).unwrap();
        let mut c = GreedyGoal::default();
        let eps: Vec<EpisodeStats> = (0..20)
            .map(|_| {
                let s = env.run_to_end(&mut c, |_| {});
                env.reset().unwrap();
                s
            })
            .collect();
        for e in &eps {
            // In an empty room the shortest path is the straight line, less the goal's radius
            // not counted: from start to goal centre.
            assert!((e.optimal_path_length - e.initial_distance).abs() < 0.02, "{e:?}");
            assert!(e.mean_angular_acceleration.is_finite() && e.mean_angular_acceleration >= 0.0);
        }
        let s = EvalSummary::of(&eps);
        // Greedy turns towards the goal and drives straight: SPL a little below its success
        // rate (the turn-in arc), never above it. Measured SPL / success 0.91-0.98 over
        // environment seeds 1-8.
        assert!(s.spl <= s.success_rate + 1e-6 && s.spl > 0.7 * s.success_rate, "{s:?}");
        assert!(s.success_ci95[0] <= s.success_rate && s.success_rate <= s.success_ci95[1]);
        // Episodes stepped without `run_to_end` have no shortest path: SPL is unknown.
        let mut unknown = eps.clone();
        unknown[0].optimal_path_length = f32::NAN;
        assert!(EvalSummary::of(&unknown).spl.is_nan());
    }

    #[test]
    fn wilson_intervals_match_published_values() {
        // Newcombe (1998), table I, and the closed form: 0/10, 5/10, 10/10, 81/263.
        let close = |a: [f32; 2], b: [f32; 2]| (a[0] - b[0]).abs() < 5e-4 && (a[1] - b[1]).abs() < 5e-4;
        assert!(close(wilson_interval(0, 10), [0.0, 0.2775]), "{:?}", wilson_interval(0, 10));
        assert!(close(wilson_interval(5, 10), [0.2366, 0.7634]), "{:?}", wilson_interval(5, 10));
        assert!(close(wilson_interval(10, 10), [0.7225, 1.0]), "{:?}", wilson_interval(10, 10));
        assert!(close(wilson_interval(81, 263), [0.2553, 0.3662]), "{:?}", wilson_interval(81, 263));
        assert_eq!(wilson_interval(0, 0), [0.0, 1.0]);
    }

    #[test]
    fn driving_into_a_wall_is_a_collision_with_the_penalty() {
        let mut env = NavEnv::new(setup("empty-room"), 1).unwrap();
        let mut c = StraightAhead { speed: 0.5 };
        let mut collisions = 0;
        for _ in 0..10 {
            let s = env.run_episode(&mut c).unwrap();
            if s.outcome == Outcome::Collision {
                collisions += 1;
                assert!(s.min_range < 0.25 + 1e-6);
                assert!(s.episode_return < -25.0);
            }
        }
        assert!(collisions >= 5, "straight ahead in a 6 m room mostly hits a wall: {collisions}");
    }

    /// Drives two environments of the same scene and seed straight on at full speed until the
    /// first ends (the same actions, so the same path) and returns each step's charges, minus
    /// the rewards: `(first, second)`.
    fn charges_straight_to_a_wall(first: &mut NavEnv, second: &mut NavEnv) -> Vec<(f32, f32)> {
        let mut charges = Vec::new();
        for _ in 0..200 {
            let (a, b) = (first.step([1.0, 0.0]), second.step([1.0, 0.0]));
            assert_eq!(a.terminated, b.terminated);
            if a.terminated || a.truncated {
                break;
            }
            charges.push((-a.reward, -b.reward));
        }
        charges
    }

    /// With a look-ahead the proximity penalty charges a wall the robot drives at before the
    /// wall is inside the range, never less than the plain penalty and never more than the
    /// shape's top.
    #[test]
    fn proximity_horizon_charges_a_wall_ahead_early() {
        let spec = ScenarioSpec::load("empty-room").unwrap();
        let robot = RobotSpec::load("jetbot").unwrap();
        let env = |proximity_horizon| {
            let reward = RewardConfig {
                progress: 0.0,
                proximity_shape: ProximityShape::Linear,
                proximity_horizon,
                ..Default::default()
            };
            let task = TaskConfig { reward, ..Default::default() };
            NavEnv::new(Arc::new(EnvSetup::new(spec.clone(), robot.clone(), task).unwrap()), 1).unwrap()
        };
        let charges = charges_straight_to_a_wall(&mut env(0.0), &mut env(1.0));
        let first = |pick: fn(&(f32, f32)) -> f32| charges.iter().position(|c| pick(c) > 0.0).unwrap();
        let (plain, early) = (first(|c| c.0), first(|c| c.1));
        assert!(plain >= early + 3, "charged from step {early} with the look-ahead, {plain} without: {charges:?}");
        assert!(charges.iter().all(|&(n, a)| a >= n - 1e-6), "{charges:?}");
        // Within the last steps the wall is close whatever the look-ahead: 1 is the shape's top.
        let (n, a) = charges[charges.len() - 1];
        assert!(a <= 1.0 + 1e-6 && a >= n, "{charges:?}");
        let bad =
            TaskConfig { reward: RewardConfig { proximity_horizon: -1.0, ..Default::default() }, ..Default::default() };
        assert_eq!(bad.validate().unwrap_err().key, "reward.proximity_horizon");
    }

    /// The cross-track penalty charges the robot's distance from its plan beyond the band,
    /// each step, and nothing while it keeps within the band; a negative weight is rejected.
    #[test]
    fn plan_deviation_charges_the_distance_from_the_plan() {
        let spec = ScenarioSpec::load("empty-room").unwrap();
        let robot = RobotSpec::load("jetbot").unwrap();
        let env = |plan_deviation| {
            let reward = RewardConfig { plan_deviation, plan_deviation_band: 0.1, ..Default::default() };
            let task = TaskConfig { reward, plan: Some(PlanConfig { lookahead: 0.6 }), ..Default::default() };
            let mut env = NavEnv::new(Arc::new(EnvSetup::new(spec.clone(), robot.clone(), task).unwrap()), 3).unwrap();
            env.reset().unwrap();
            env
        };
        let (mut plain, mut charged) = (env(0.0), env(2.0));
        assert!(plain.plan().len() >= 2 && plain.plan() == charged.plan());
        let (mut inside, mut outside) = (0, 0);
        // Full left turn: the robot leaves the plan and circles back towards it.
        for _ in 0..40 {
            let (a, b) = (plain.step([1.0, 1.0]), charged.step([1.0, 1.0]));
            if a.terminated || a.truncated {
                break;
            }
            let p = charged.pose().position();
            let off = charged.plan().windows(2).map(|w| point_segment_distance_squared(p, w[0], w[1]).sqrt());
            let off = off.fold(f32::INFINITY, f32::min);
            let want = 2.0 * (off - 0.1).max(0.0);
            assert!(
                (a.reward - b.reward - want).abs() < 1e-4,
                "off the plan by {off}: {} against {}",
                a.reward,
                b.reward
            );
            if want > 0.0 { outside += 1 } else { inside += 1 }
        }
        assert!(inside > 0 && outside > 5, "{inside} steps inside the band, {outside} outside");
        let bad =
            TaskConfig { reward: RewardConfig { plan_deviation: -1.0, ..Default::default() }, ..Default::default() };
        assert_eq!(bad.validate().unwrap_err().key, "reward.plan_deviation");
    }

    /// The look-ahead range: a return ahead comes as close as the robot will drive to it, a
    /// slower robot keeps it further, a return abeam stays where it is.
    #[test]
    fn range_ahead_is_the_closest_approach_of_a_straight_drive() {
        let spec = ScenarioSpec::load("empty-room").unwrap();
        let robot = RobotSpec::load("jetbot").unwrap();
        let setup = EnvSetup::new(spec, robot, TaskConfig::default()).unwrap();
        let mut env = NavEnv::new(Arc::new(setup), 1).unwrap();
        env.drive.pose.yaw = 0.0;
        env.ranges = vec![1.0, 0.6, f32::INFINITY];
        env.dirs = vec![Vec2::new(1.0, 0.0), Vec2::new(0.0, 1.0), Vec2::new(-1.0, 0.0)];
        let at = |env: &mut NavEnv, speed: f32, horizon: f32| {
            env.drive.velocity.linear = speed;
            env.min_range_ahead(horizon)
        };
        assert!((at(&mut env, 0.5, 1.0) - 0.5).abs() < 1e-6, "1 m ahead after 0.5 m");
        assert!(at(&mut env, 0.5, 3.0).abs() < 1e-6, "driving through the return ahead");
        assert!((at(&mut env, 0.25, 1.0) - 0.6).abs() < 1e-6, "slower: the one abeam is nearer");
        env.ranges[1] = 2.0;
        assert!((at(&mut env, 0.25, 1.0) - 0.75).abs() < 1e-6, "slower");
        assert!((at(&mut env, 0.0, 1.0) - 1.0).abs() < 1e-6, "standing: the range now");
        assert!((at(&mut env, -0.5, 1.0) - 1.0).abs() < 1e-6, "reversing away from it");
        env.ranges[0] = f32::INFINITY;
        assert!((at(&mut env, 0.5, 3.0) - 2.0).abs() < 1e-6, "a return abeam stays where it is");
    }

    #[test]
    fn progress_paid_at_a_reference_speed_scales_with_the_robots_top_speed() {
        let spec = ScenarioSpec::load("empty-room").unwrap();
        let burger = RobotSpec::load("turtlebot3-burger").unwrap();
        // Progress alone: the reward of a step is the progress term.
        let env = |reference| {
            let reward = RewardConfig { proximity: 0.0, progress_reference_speed: reference, ..Default::default() };
            let task = TaskConfig { reward, ..Default::default() };
            NavEnv::new(Arc::new(EnvSetup::new(spec.clone(), burger.clone(), task).unwrap()), 4).unwrap()
        };
        let (mut metres, mut paid) = (env(0.0), env(0.5));
        let mut compared = 0;
        for _ in 0..20 {
            let (a, b) = (metres.step([1.0, 0.0]), paid.step([1.0, 0.0]));
            if a.terminated || a.truncated {
                break;
            }
            if a.reward.abs() > 1e-4 {
                assert!((b.reward / a.reward - 0.5 / burger.max_linear).abs() < 1e-3, "{} {}", a.reward, b.reward);
                compared += 1;
            }
        }
        assert!(compared >= 5, "{compared} steps of progress compared");
        let bad = TaskConfig {
            reward: RewardConfig { progress_reference_speed: -1.0, ..Default::default() },
            ..Default::default()
        };
        assert_eq!(bad.validate().unwrap_err().key, "reward.progress_reference_speed");
    }

    #[test]
    fn linear_proximity_penalty_grows_to_the_collision_range() {
        let spec = ScenarioSpec::load("empty-room").unwrap();
        let robot = RobotSpec::load("jetbot").unwrap();
        let task = |proximity_shape| {
            // Only the proximity term: the reward is minus the shape's value.
            let reward = RewardConfig { progress: 0.0, proximity_shape, ..Default::default() };
            TaskConfig { reward, ..Default::default() }
        };
        let env = |shape| NavEnv::new(Arc::new(EnvSetup::new(spec.clone(), robot.clone(), task(shape)).unwrap()), 1);
        let (mut exp, mut lin) = (env(ProximityShape::Exp).unwrap(), env(ProximityShape::Linear).unwrap());
        let mut pairs = charges_straight_to_a_wall(&mut exp, &mut lin);
        pairs.retain(|&(e, _)| e != 0.0);
        assert!(pairs.len() >= 3, "the robot must cross the 0.5 m band before the wall: {pairs:?}");
        for &(e, l) in &pairs {
            // exp(-r) gives r back; the linear value at r is (0.5 - r) / (0.5 - 0.25).
            let r = -e.ln();
            assert!((0.25..0.5).contains(&r), "{r}");
            assert!((l - (0.5 - r) / 0.25).abs() < 1e-4, "r {r}: linear {l}");
        }
        // The linear charge grows with every step in; the exponential one hardly changes.
        assert!(pairs.windows(2).all(|w| w[1].1 > w[0].1), "{pairs:?}");
        let (first, last) = (pairs[0], pairs[pairs.len() - 1]);
        assert!(last.1 - first.1 > 0.5 && last.0 - first.0 < 0.2, "{pairs:?}");
        let bad = TaskConfig {
            reward: RewardConfig { proximity_range: 0.2, ..task(ProximityShape::Linear).reward },
            ..Default::default()
        };
        assert_eq!(bad.validate().unwrap_err().key, "reward.proximity_range");
        assert!(
            TaskConfig { reward: RewardConfig { proximity_range: 0.2, ..Default::default() }, ..Default::default() }
                .validate()
                .is_ok()
        );
    }

    #[test]
    fn timeout_is_truncation_not_termination() {
        let spec = ScenarioSpec::load("empty-room").unwrap();
        let robot = RobotSpec::load("jetbot").unwrap();
        let task = TaskConfig { max_steps: 5, ..Default::default() };
        let mut env = NavEnv::new(Arc::new(EnvSetup::new(spec, robot, task).unwrap()), 3).unwrap();
        // Slowest forward speed: 5 steps cover 0.05 m, while start and goal are >= 1 m apart
        // and the start has >= 0.35 m of clearance, so neither goal nor collision can happen.
        for i in 0..5 {
            let out = env.step([-1.0, 0.0]);
            assert_eq!(out.truncated, i == 4);
            assert!(!out.terminated);
            if i == 4 {
                assert!(out.reward < -25.0);
            }
        }
        assert_eq!(env.last_episode().unwrap().outcome, Outcome::Timeout);
    }

    #[test]
    fn standing_still_costs_the_idle_penalty_and_driving_does_not() {
        let spec = ScenarioSpec::load("empty-room").unwrap();
        let robot = RobotSpec::load("jetbot").unwrap();
        let stop = ActionConfig { linear: [0.0, 0.5], ..Default::default() };
        let task = |idle: f32| {
            let reward = RewardConfig { idle, ..Default::default() };
            TaskConfig { action: stop.clone(), reward, ..Default::default() }
        };
        let env = |idle| NavEnv::new(Arc::new(EnvSetup::new(spec.clone(), robot.clone(), task(idle)).unwrap()), 3);
        let (mut off, mut on) = (env(0.0).unwrap(), env(0.5).unwrap());
        // Standing (speed 0 from the start): every step costs exactly the penalty more.
        for _ in 0..5 {
            let (a, b) = (off.step([-1.0, 0.0]), on.step([-1.0, 0.0]));
            assert!(!a.terminated && !a.truncated);
            assert!((a.reward - b.reward - 0.5).abs() < 1e-5, "{} vs {}", a.reward, b.reward);
        }
        // Driving at 0.25 m/s (once the robot is up to speed): no penalty at all.
        let mut gaps = Vec::new();
        for _ in 0..10 {
            let (a, b) = (off.step([0.0, 0.0]), on.step([0.0, 0.0]));
            gaps.push(a.reward - b.reward);
        }
        assert!(gaps[3..].iter().all(|g| g.abs() < 1e-6), "{gaps:?}");
        let bad = TaskConfig { reward: RewardConfig { idle: -1.0, ..Default::default() }, ..Default::default() };
        assert_eq!(bad.validate().unwrap_err().key, "reward.idle");
    }

    #[test]
    fn with_task_keeps_the_scenes_and_refuses_a_task_that_needs_more_room() {
        let spec = ScenarioSpec::load("heldout-static-corridor").unwrap();
        let robot = RobotSpec::load("jetbot").unwrap();
        let stop =
            TaskConfig { action: ActionConfig { linear: [0.0, 0.5], ..Default::default() }, ..Default::default() };
        let article = EnvSetup::new(spec.clone(), robot.clone(), TaskConfig::default()).unwrap();
        let moved = article.with_task(stop.clone()).unwrap();
        assert_eq!(moved.task, stop);
        assert_eq!(moved.scenario.start_clearance(), article.scenario.start_clearance());
        let own = EnvSetup::new(spec, robot, stop.clone()).unwrap();
        assert!(own.scenario.start_clearance() < article.scenario.start_clearance());
        let starts = |s: EnvSetup| {
            let mut env = NavEnv::new(Arc::new(s), 5).unwrap();
            (0..6)
                .map(|_| {
                    let p = env.drive.pose.position();
                    env.reset().unwrap();
                    p
                })
                .collect::<Vec<_>>()
        };
        let article_starts = starts(article.with_task(TaskConfig::default()).unwrap());
        assert_eq!(starts(moved), article_starts);
        // Scenes drawn for a robot that may stop are too tight for one that cannot...
        let e = own.with_task(TaskConfig::default()).unwrap_err().to_string();
        assert!(e.contains("at the start"), "{e}");
        // ...and scenes compiled for one collision range do not serve another.
        let wide = TaskConfig { collision_range: 0.4, ..Default::default() };
        assert!(article.with_task(wide).is_err());
        // ...nor are one room's scenes another room's.
        let other = EnvSetup::load("heldout-static-legs", Some("jetbot"), None).unwrap();
        let e = other.on_scenes_of(&article).unwrap_err().to_string();
        assert!(e.contains("heldout-static-legs") && e.contains("heldout-static-corridor"), "{e}");
    }

    #[test]
    fn observation_matches_its_layout() {
        let mut env = NavEnv::new(setup("static-room"), 11).unwrap();
        let mut obs = vec![0.0; 124];
        env.write_observation(&mut obs);
        assert!(obs[..120].iter().all(|r| (0.15..=3.0).contains(r)));
        let (d, b) = env.goal_polar();
        assert_eq!((obs[120], obs[121]), (d, b));
        // The pooled value is the minimum of its three beams.
        let ranges = env.ranges().to_vec();
        for (i, o) in obs[..120].iter().enumerate() {
            let m = ranges[3 * i..3 * i + 3].iter().copied().fold(f32::INFINITY, f32::min);
            assert_eq!(*o, m.clamp(0.15, 3.0));
        }
        env.step([1.0, 1.0]);
        env.write_observation(&mut obs);
        assert_eq!((obs[122], obs[123]), (0.5, 0.5));
    }

    #[test]
    fn history_terms_show_the_steps_taken() {
        let layout = ObservationLayout(vec![
            ObsTerm::History {
                term: Box::new(ObsTerm::GoalDistance),
                steps: 3,
                stride: 1,
                order: HistoryOrder::OldestFirst,
                fill: HistoryFill::First,
                ego_motion: false,
                predict: 0.0,
            },
            ObsTerm::History {
                term: Box::new(ObsTerm::Linear),
                steps: 2,
                stride: 1,
                order: HistoryOrder::NewestFirst,
                fill: HistoryFill::Zero,
                ego_motion: false,
                predict: 0.0,
            },
            ObsTerm::Lateral,
        ]);
        let spec = ScenarioSpec::load("static-room").unwrap();
        let robot = RobotSpec::load(&spec.robot).unwrap();
        let task = TaskConfig { observation: layout, ..Default::default() };
        let mut env = NavEnv::new(Arc::new(EnvSetup::new(spec, robot, task).unwrap()), 11).unwrap();
        let mut obs = vec![0.0; 6];
        let mut seen = vec![(env.goal_polar().0, env.velocity().linear)];
        env.write_observation(&mut obs);
        assert_eq!(obs, vec![seen[0].0, seen[0].0, seen[0].0, 0.0, 0.0, 0.0]);
        // A step taken without a write (a controller driving) is recorded all the same.
        for _ in 0..2 {
            env.step_twist(Twist::new(0.3, 0.2));
            seen.push((env.goal_polar().0, env.velocity().linear));
        }
        env.write_observation(&mut obs);
        assert!(seen[2].1 > 0.0);
        assert_eq!(obs, vec![seen[0].0, seen[1].0, seen[2].0, seen[2].1, seen[1].1, 0.0]);
        env.reset().unwrap();
        env.write_observation(&mut obs);
        let d = env.goal_polar().0;
        assert_eq!(obs, vec![d, d, d, 0.0, 0.0, 0.0]);
    }
}
