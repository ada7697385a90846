//! The policy contract: everything a deployment needs to feed a policy the observation it was
//! trained on and to read its action, carried in the ONNX file's `metadata_props` (key
//! [`CONTRACT_KEY`], YAML) or, for models rlnav did not write, in a side YAML file.

use rlnav_sim::config::{ConfigError, Invalid, Validate, check_interval, check_positive, check_range};
use rlnav_sim::task::ObservationLayout;
use rlnav_sim::{LidarSpec, Twist};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// `metadata_props` key holding the whole contract as YAML.
pub const CONTRACT_KEY: &str = "rlnav.contract";
/// Version of the contract format this build writes and reads.
pub const CONTRACT_FORMAT: u32 = 1;

/// The scan the observation's lidar term is built from, before pooling: `beams` rays across
/// `[angle_min, angle_max]`, counter-clockwise from `angle_min` (ROS's order) or clockwise
/// from `angle_max`, in a frame aligned with `base_link` (an incoming scan is rotated by its
/// mount yaw and re-sampled to this geometry).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScanContract {
    /// Number of beams.
    pub beams: usize,
    /// Angle of beam 0 (rad).
    pub angle_min: f32,
    /// Angle of the last beam (rad); a full turn spreads beams `2π / beams` apart.
    pub angle_max: f32,
    /// Readings below this are invalid (read as no return) (m).
    pub range_min: f32,
    /// Readings above this are no return (m).
    pub range_max: f32,
    /// Beam order (default counter-clockwise).
    #[serde(default)]
    pub direction: BeamOrder,
}

/// Order of the beams in a scan.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BeamOrder {
    /// From `angle_min`, counter-clockwise (`sensor_msgs/LaserScan`).
    #[default]
    CounterClockwise,
    /// From `angle_max`, clockwise.
    Clockwise,
}

impl ScanContract {
    /// Angle (base frame) of contract beam `j`.
    pub fn beam_angle(&self, j: usize) -> f32 {
        let spec = self.lidar_spec();
        match self.direction {
            BeamOrder::CounterClockwise => spec.beam_angle(j),
            BeamOrder::Clockwise if spec.is_full_circle() => spec.angle_max - j as f32 * spec.angle_increment(),
            BeamOrder::Clockwise => spec.beam_angle(self.beams - 1 - j),
        }
    }

    /// The contract beam of counter-clockwise index `k`.
    pub fn from_ccw(&self, k: usize) -> usize {
        match self.direction {
            BeamOrder::CounterClockwise => k,
            BeamOrder::Clockwise if self.lidar_spec().is_full_circle() => (self.beams - k) % self.beams,
            BeamOrder::Clockwise => self.beams - 1 - k,
        }
    }
    /// The scan geometry of a simulated lidar.
    pub fn of(spec: &LidarSpec) -> Self {
        Self {
            beams: spec.beams,
            angle_min: spec.angle_min,
            angle_max: spec.angle_max,
            range_min: spec.range_min,
            range_max: spec.range_max,
            direction: BeamOrder::CounterClockwise,
        }
    }

    /// As a lidar spec (mounted at `base_link`), for its beam geometry.
    pub fn lidar_spec(&self) -> LidarSpec {
        LidarSpec {
            beams: self.beams,
            angle_min: self.angle_min,
            angle_max: self.angle_max,
            range_min: self.range_min,
            range_max: self.range_max,
            ..Default::default()
        }
    }
}

/// How the network's `mu` becomes a velocity command.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ActionScaling {
    /// `mu` is clipped to `[-1, 1]` and mapped linearly onto the ranges (rlnav's policies).
    Normalized,
    /// `mu` is the command in m/s and rad/s, clipped to the ranges (rl_games exports as the
    /// article's nodes use them).
    Direct,
}

/// The action: `mu[0]` linear, `mu[1]` angular.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ActionContract {
    /// Scaling of `mu`.
    pub scaling: ActionScaling,
    /// Linear velocity range `[min, max]` (m/s).
    pub linear: [f32; 2],
    /// Angular velocity range `[min, max]` (rad/s).
    pub angular: [f32; 2],
    /// `linear` is in fractions of the robot's top speed, not m/s
    /// ([`rlnav_sim::task::ActionConfig::linear_relative`]): whoever runs the policy must
    /// know the robot's top speed ([`Self::for_top_speed`]).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub linear_relative: bool,
}

impl ActionContract {
    /// The ranges in m/s on a robot whose top speed is `top_speed`: itself when they are in
    /// m/s already.
    pub fn for_top_speed(&self, top_speed: f32) -> Self {
        let ranges = self.ranges().for_top_speed(top_speed);
        Self { linear: ranges.linear, linear_relative: false, ..self.clone() }
    }

    /// The ranges as the simulator's task takes them (it clips every command to them).
    pub fn ranges(&self) -> rlnav_sim::task::ActionConfig {
        rlnav_sim::task::ActionConfig {
            linear: self.linear,
            angular: self.angular,
            linear_relative: self.linear_relative,
        }
    }

    /// The velocity command for network output `mu` (a non-finite value stops the robot).
    /// The ranges must be in m/s ([`Self::for_top_speed`]): a relative range stops the robot.
    pub fn to_twist(&self, mu: [f32; 2]) -> Twist {
        if self.linear_relative || !(mu[0].is_finite() && mu[1].is_finite()) {
            return Twist::default();
        }
        let map = |x: f32, r: [f32; 2]| match self.scaling {
            ActionScaling::Normalized => r[0] + (x.clamp(-1.0, 1.0) + 1.0) * 0.5 * (r[1] - r[0]),
            ActionScaling::Direct => x.clamp(r[0], r[1]),
        };
        Twist::new(map(mu[0], self.linear), map(mu[1], self.angular))
    }
}

/// A recurrent state tensor carried from one step to the next.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecurrentState {
    /// Graph input that takes the state (zeros at the start of an episode).
    pub input: String,
    /// Graph output that gives the next state.
    pub output: String,
    /// Shape, e.g. `[1, 1, 64]` (layers, batch, units).
    pub shape: Vec<usize>,
}

/// Names of the graph's inputs and outputs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GraphIo {
    /// The observation input (`[batch, n]`).
    pub obs: String,
    /// The action mean output (`[batch, 2]`).
    pub mu: String,
    /// Recurrent states (empty for a feed-forward policy).
    #[serde(default)]
    pub recurrent: Vec<RecurrentState>,
}

impl Default for GraphIo {
    fn default() -> Self {
        Self { obs: "obs".into(), mu: "mu".into(), recurrent: Vec::new() }
    }
}

/// What a policy expects and produces.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PolicyContract {
    /// Contract format version.
    pub format: u32,
    /// What wrote it (`rlnav 0.1.0`, or who wrote a side contract).
    pub producer: String,
    /// Task or run name.
    pub task: String,
    /// Robot the policy was trained on.
    pub robot: String,
    /// Observation vector, term by term.
    pub observation: ObservationLayout,
    /// The scan the lidar term is built from.
    pub scan: ScanContract,
    /// The action.
    pub action: ActionContract,
    /// Seconds between commands.
    pub control_period: f32,
    /// Distance at which the goal counts as reached (m).
    pub goal_tolerance: f32,
    /// Graph input and output names.
    #[serde(default)]
    pub io: GraphIo,
    /// Trained to follow a global plan (absent: to steer to the goal): the observation's goal
    /// terms describe the point `plan.lookahead` ahead along the plan, as in training.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plan: Option<rlnav_sim::task::PlanConfig>,
    /// The robots it was trained to drive and the envelope of their geometry and limits
    /// (absent in contracts written before it, or by hand).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub envelope: Option<RobotEnvelope>,
}

/// The robots a policy was trained on, and the span of what differs between them: `[min, max]`
/// over the robots, widened by the per-episode jitter training applied.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotEnvelope {
    /// Robot names.
    pub robots: Vec<String>,
    /// Circumscribed footprint radius (m).
    pub footprint_radius: [f32; 2],
    /// Wheel separation (m).
    pub wheel_separation: [f32; 2],
    /// Top forward speed (m/s).
    pub max_linear: [f32; 2],
    /// Lidar maximum range (m).
    pub lidar_range_max: [f32; 2],
}

impl RobotEnvelope {
    /// The envelope of `robots`, each figure widened by the relative `jitter` of
    /// `[wheel_separation, speed]` training drew per episode.
    pub fn of(robots: &[rlnav_sim::RobotSpec], jitter: [f32; 2]) -> Self {
        let span = |f: &dyn Fn(&rlnav_sim::RobotSpec) -> f32, j: f32| {
            let lo = robots.iter().map(f).fold(f32::INFINITY, f32::min);
            let hi = robots.iter().map(f).fold(f32::NEG_INFINITY, f32::max);
            [lo * (1.0 - j), hi * (1.0 + j)]
        };
        let radius = |r: &rlnav_sim::RobotSpec| rlnav_sim::Footprint::new(&r.footprint).map_or(0.0, |f| f.radius());
        Self {
            robots: robots.iter().map(|r| r.name.clone()).collect(),
            footprint_radius: span(&radius, 0.0),
            wheel_separation: span(&|r| r.wheel_separation, jitter[0]),
            max_linear: span(&|r| r.max_linear, jitter[1]),
            lidar_range_max: span(&|r| r.lidar.range_max, 0.0),
        }
    }

    /// How `robot` lies outside the envelope, one line per figure (more than 10% beyond it),
    /// empty when it is inside.
    pub fn outside(&self, robot: &rlnav_sim::RobotSpec) -> Vec<String> {
        let radius = rlnav_sim::Footprint::new(&robot.footprint).map_or(0.0, |f| f.radius());
        let mut out = Vec::new();
        for (what, v, [lo, hi]) in [
            ("footprint radius", radius, self.footprint_radius),
            ("wheel separation", robot.wheel_separation, self.wheel_separation),
            ("top speed", robot.max_linear, self.max_linear),
            ("lidar range", robot.lidar.range_max, self.lidar_range_max),
        ] {
            if v < 0.9 * lo || v > 1.1 * hi {
                out.push(format!("{what} {v:.3} is outside the trained {lo:.3}–{hi:.3}"));
            }
        }
        out
    }
}

impl Validate for PolicyContract {
    fn validate(&self) -> Result<(), Invalid> {
        if self.format != CONTRACT_FORMAT {
            return Err(Invalid::new("format", format!("{CONTRACT_FORMAT} (this rlnav's), got {}", self.format)));
        }
        self.observation.check()?;
        self.scan.lidar_spec().validate().map_err(|e| e.under("scan"))?;
        for (key, beams) in self.observation.lidar_terms() {
            if self.scan.beams % beams != 0 {
                return Err(Invalid::new(key, format!("a divisor of scan.beams ({}), got {beams}", self.scan.beams)));
            }
        }
        // Past scans are moved by bearings counter-clockwise from `angle_min`.
        let moved =
            self.observation.0.iter().any(|t| matches!(t, rlnav_sim::task::ObsTerm::History { ego_motion: true, .. }));
        if moved && self.scan.direction != BeamOrder::CounterClockwise {
            return Err(Invalid::new(
                "scan.direction",
                "counter_clockwise for an observation with a history of moved scans (ego_motion)",
            ));
        }
        let linear_max = if self.action.linear_relative { 1.0 } else { 100.0 };
        check_interval("action.linear", self.action.linear, -linear_max, linear_max)?;
        check_interval("action.angular", self.action.angular, -100.0, 100.0)?;
        check_range("control_period", self.control_period, 1e-3, 10.0)?;
        check_positive("goal_tolerance", self.goal_tolerance)?;
        if let Some(p) = &self.plan {
            p.validate().map_err(|e| e.under("plan"))?;
        }
        if self.io.obs.is_empty() || self.io.mu.is_empty() {
            return Err(Invalid::new("io", "non-empty `obs` and `mu` names"));
        }
        for (i, s) in self.io.recurrent.iter().enumerate() {
            if s.input.is_empty() || s.output.is_empty() || s.shape.is_empty() || s.shape.contains(&0) {
                return Err(Invalid::new(format!("io.recurrent[{i}]"), "input and output names and a non-empty shape"));
            }
        }
        Ok(())
    }
}

impl PolicyContract {
    /// The contract of a policy trained on `task` with `robot`, named `name`: the task's
    /// observation, action and plan, the robot's scan in `base_link` orientation, feed-forward
    /// graph names (`obs` → `mu`) or rlnav's LSTM names when `io` says so.
    pub fn for_task(
        name: &str,
        task: &rlnav_sim::TaskConfig,
        robot: &rlnav_sim::RobotSpec,
        io: GraphIo,
        envelope: Option<RobotEnvelope>,
    ) -> Self {
        let mut scan = ScanContract::of(&robot.lidar);
        // The contract's beams are in base_link orientation; the simulated lidar's own start
        // angle is relative to its mount.
        scan.angle_min += robot.lidar.mount.yaw;
        scan.angle_max += robot.lidar.mount.yaw;
        Self {
            format: CONTRACT_FORMAT,
            producer: format!("rlnav {}", env!("CARGO_PKG_VERSION")),
            task: name.to_string(),
            robot: robot.name.clone(),
            observation: task.observation.clone(),
            scan,
            action: ActionContract {
                scaling: ActionScaling::Normalized,
                linear: task.action.linear,
                angular: task.action.angular,
                linear_relative: task.action.linear_relative,
            },
            control_period: task.control_period,
            goal_tolerance: task.goal_tolerance,
            io,
            plan: task.plan.clone(),
            envelope,
        }
    }

    /// Length of the observation vector.
    pub fn obs_dim(&self) -> usize {
        self.observation.len()
    }

    /// Reads a side contract (YAML).
    pub fn from_file(path: &Path) -> Result<Self, ConfigError> {
        rlnav_sim::config::from_yaml_file(path)
    }

    /// Parses contract YAML (`source` names it in errors).
    pub fn from_yaml(source: &str, text: &str) -> Result<Self, ConfigError> {
        rlnav_sim::config::from_yaml_str(source, text)
    }

    /// The contract as YAML.
    pub fn to_yaml(&self) -> String {
        rlnav_sim::config::to_yaml_string(self)
    }
}
