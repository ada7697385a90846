//! `rlnav ros2 node`: a policy driving a robot over ROS 2. [`PolicyNode`] is the logic, with
//! no DDS in it (fed messages and the time, it answers the command and the state), so every
//! safety rule is tested directly; [`run_node`] wires it to the robot's topics.
//!
//! Safe by construction: without a goal, with a stale or unusable scan or pose, with NaN
//! anywhere, or at the goal, the command is zero and the state says why; when good data
//! returns, it drives again.

use crate::bus::{Bus, BusError, Qos, Reach, drain};
use crate::follow_path::{FollowPathServer, GoalLimits};
use crate::msg::{
    self, LaserScan, OccupancyGrid, Odometry, Path as PlanMsg, PoseStamped, StringMsg, TFMessage, Time, TwistStamped,
};
use crate::ros_args::RosArgs;
use rlnav_planners::astar;
use rlnav_planners::costmap::{Costmap, CostmapConfig};
use rlnav_policy::{PolicyContract, PolicyRunner};
use rlnav_sim::config::{ConfigError, Invalid, Validate, check_positive};
use rlnav_sim::{Controller, Pose2, RobotObservation, Twist, Vec2, wrap_angle};
use rustdds::mio1::{Events, Interest, Poll, Token};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// The node's parameters (a ROS-style YAML; every field has a default).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NodeParams {
    /// `sensor_msgs/LaserScan` input.
    pub scan_topic: String,
    /// `nav_msgs/Odometry` input (pose and velocity).
    pub odom_topic: String,
    /// `geometry_msgs/PoseStamped` input for the pose instead of odometry (motion capture);
    /// empty: use odometry. The velocity is then differentiated from the poses.
    pub pose_topic: String,
    /// `geometry_msgs/PoseStamped` goals (RViz2's "2D Goal Pose").
    pub goal_topic: String,
    /// `nav_msgs/Path` plans to follow (Nav2's planner server publishes `/plan`): the policy
    /// steers to a point `lookahead` ahead along the plan, and the plan's last pose is the goal.
    pub plan_topic: String,
    /// How far ahead along a plan the policy's goal is put (m, path length from the robot's
    /// projection on the plan); default: half the policy's lidar range, within 0.5-2 m.
    pub lookahead: Option<f32>,
    /// `/tf` input, to bring goals given in another frame into the pose frame.
    pub tf_topic: String,
    /// `/tf_static` input (transient local): fixed transforms, such as `map -> odom` where a
    /// robot is localised once.
    pub tf_static_topic: String,
    /// `nav_msgs/OccupancyGrid` input (transient local, as `map_server` serves it). With a map
    /// and a goal but no plan from a planner, the node plans itself: A* on the map inflated for
    /// the robot, replanned every `replan_period`, followed as a plan. Empty: never plan.
    pub map_topic: String,
    /// How often the node replans on the map (s; Nav2's navigator replans once a second).
    pub replan_period: f64,
    /// The robot's radius for inflating the map (m): a path keeps its centre this far from
    /// obstacles. Default: the footprint radius of the policy's robot (0.2 m if unknown).
    pub robot_radius: Option<f32>,
    /// Inflation of the planning costmap (m, Nav2's `inflation_radius`): paths keep away from
    /// obstacles out to here, at a cost decaying with `cost_scaling_factor` (1/m).
    pub inflation_radius: f32,
    /// See `inflation_radius`.
    pub cost_scaling_factor: f32,
    /// Velocity command output.
    pub cmd_vel_topic: String,
    /// Publish `geometry_msgs/TwistStamped` instead of `Twist` (ROS 2 Jazzy's Nav2 default).
    pub cmd_vel_stamped: bool,
    /// Frame of stamped commands.
    pub base_frame: String,
    /// `std_msgs/String` state output.
    pub status_topic: String,
    /// A goal `[x, y]` in the pose frame, used until one arrives on the goal topic.
    pub goal: Option<[f64; 2]>,
    /// Distance at which the goal counts as reached (m); default: the policy's contract.
    pub goal_tolerance: Option<f32>,
    /// Cap on |linear| (m/s) below the policy's limits. For a policy whose linear action is a
    /// fraction of the robot's top speed, this is that top speed, and it is required.
    pub max_linear: Option<f32>,
    /// Cap on |angular| (rad/s) below the policy's limits.
    pub max_angular: Option<f32>,
    /// Stop when no scan arrived for this long (s).
    pub scan_timeout: f64,
    /// Stop when no pose arrived for this long (s).
    pub pose_timeout: f64,
    /// Yaw of the lidar in the base frame (rad), for a lidar mounted rotated.
    pub lidar_yaw_offset: f32,
    /// Compute a command as each scan arrives (`scan`) or every control period (`timer`).
    pub trigger: Trigger,
    /// QoS of the scan reader: `sensor_data` (best effort, the default: it matches reliable
    /// and best-effort drivers), `reliable` or `transient_local`.
    pub scan_qos: Qos,
    /// QoS of the odometry (or pose) reader; default `sensor_data`, which matches a TurtleBot 4's
    /// best-effort `/odom` as well as reliable ones.
    pub odom_qos: Qos,
    /// QoS of the command writer; default `reliable` (a best-effort reader, such as a
    /// `sensor_data` subscriber, matches it too).
    pub cmd_vel_qos: Qos,
    /// Stamp stamped commands with the simulator's time from `/clock` (ROS's `use_sim_time`).
    /// Timeouts are judged on the node's own clock by arrival either way.
    pub use_sim_time: bool,
    /// Serve Nav2's `nav2_msgs/action/FollowPath` as controller_server does, so that
    /// bt_navigator drives through the node (see [`crate::follow_path`]).
    pub follow_path: bool,
    /// The action's name (controller_server's: `follow_path`, in the node's namespace).
    pub follow_path_action: String,
    /// How long the node may stay stopped (no usable scan, pose or transform) before a
    /// FollowPath goal is aborted (s).
    pub failure_tolerance: f64,
    /// Progress checker: a FollowPath goal is aborted (`FAILED_TO_MAKE_PROGRESS`) when the
    /// robot moves less than this (m) ...
    pub required_movement_radius: f32,
    /// ... in this long (s), as Nav2's SimpleProgressChecker.
    pub movement_time_allowance: f64,
    /// The node's namespace (`-r __ns:=/robot1`; empty: the root): relative topic names
    /// resolve under it. Not a parameter.
    #[serde(skip)]
    pub namespace: String,
    /// The node's name (`-r __node:=NAME`; empty: `rlnav_policy`). Not a parameter.
    #[serde(skip)]
    pub node_name: String,
}

/// When the node computes a command.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Trigger {
    /// Every control period of the policy's contract.
    Timer,
    /// On each new scan (at most once per half control period).
    Scan,
}

impl Default for NodeParams {
    fn default() -> Self {
        Self {
            scan_topic: "scan".into(),
            odom_topic: "odom".into(),
            pose_topic: String::new(),
            goal_topic: "goal_pose".into(),
            plan_topic: "plan".into(),
            lookahead: None,
            tf_topic: "/tf".into(),
            tf_static_topic: "/tf_static".into(),
            map_topic: "map".into(),
            replan_period: 1.0,
            robot_radius: None,
            inflation_radius: 0.55,
            cost_scaling_factor: 3.0,
            cmd_vel_topic: "cmd_vel".into(),
            cmd_vel_stamped: false,
            base_frame: "base_link".into(),
            status_topic: "rlnav/status".into(),
            goal: None,
            goal_tolerance: None,
            max_linear: None,
            max_angular: None,
            scan_timeout: 0.5,
            pose_timeout: 0.5,
            lidar_yaw_offset: 0.0,
            trigger: Trigger::Timer,
            scan_qos: Qos::SensorData,
            odom_qos: Qos::SensorData,
            cmd_vel_qos: Qos::Default,
            use_sim_time: false,
            follow_path: true,
            follow_path_action: "follow_path".into(),
            failure_tolerance: 1.0,
            required_movement_radius: 0.5,
            movement_time_allowance: 10.0,
            namespace: String::new(),
            node_name: String::new(),
        }
    }
}

impl NodeParams {
    /// Reads a parameter file. Besides the flat form, ROS 2's `NODE: {ros__parameters: ...}`
    /// nesting is accepted, so a launch file's parameters work unchanged.
    pub fn from_file(path: &Path) -> Result<Self, ConfigError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|error| ConfigError::Io { file: file.clone(), error })?;
        Self::from_yaml(&file, &text)
    }

    /// Parses parameters from YAML text (`source` names it in errors): flat, or a ROS 2
    /// parameters file (`NODE: {ros__parameters: ...}` sections). In the latter, the sections
    /// for every node (`/**`) and for this node (`rlnav_policy`, `/rlnav_policy`) apply, in
    /// that order, so a stack's shared file (Nav2's `nav2_params.yaml`) works unchanged; other
    /// nodes' sections are skipped. A file of one section for another name is taken as this
    /// node's (a launch file may rename it).
    pub fn from_yaml(source: &str, text: &str) -> Result<Self, ConfigError> {
        let flat = node_section(source, text, DEFAULT_NODE_NAME)?;
        let flat = serde_norway::to_string(&flat)
            .map_err(|e| ConfigError::Parse { file: source.to_string(), message: e.to_string() })?;
        rlnav_sim::config::from_yaml_str(source, &flat)
    }

    /// These parameters under ROS 2 command-line arguments: parameters files (their `/**` and
    /// this node's sections) then `-p NAME:=VALUE`, checked as a parameters file is; then
    /// `__node`, `__ns` and topic remappings. Returns the remappings that matched none of the
    /// node's topics (ROS passes launch-wide remappings to every node, so they are not errors).
    pub fn with_ros_args(self, a: &RosArgs) -> Result<(Self, Vec<String>), ConfigError> {
        use serde_norway::Value;
        let source = "--ros-args";
        let node_name = a.node_name.clone().unwrap_or_else(|| self.node().to_string());
        let namespace = a.namespace.clone().unwrap_or_else(|| self.namespace.clone());
        let parse =
            |file: &str, e: serde_norway::Error| ConfigError::Parse { file: file.to_string(), message: e.to_string() };
        let mut merged = match serde_norway::to_value(&self).map_err(|e| parse(source, e))? {
            Value::Mapping(m) => m,
            _ => unreachable!("parameters serialize to a mapping"),
        };
        for f in &a.params_files {
            let file = f.display().to_string();
            let text = std::fs::read_to_string(f).map_err(|error| ConfigError::Io { file: file.clone(), error })?;
            if let Value::Mapping(m) = node_section(&file, &text, &node_name)? {
                merged.extend(m);
            }
        }
        for (name, value) in &a.params {
            let v: Value = serde_norway::from_str(value).map_err(|e| parse(&format!("{source} -p {name}"), e))?;
            merged.insert(Value::String(name.clone()), v);
        }
        let text = serde_norway::to_string(&Value::Mapping(merged)).map_err(|e| parse(source, e))?;
        let mut p: Self = rlnav_sim::config::from_yaml_str(source, &text)?;
        p.node_name = node_name;
        p.namespace = namespace;
        let mut unmatched = Vec::new();
        for (from, to) in &a.remaps {
            let target = p.topic(from);
            let mut hit = false;
            for t in p.topics_mut_by_resolved(&target) {
                *t = to.clone();
                hit = true;
            }
            if !hit {
                unmatched.push(format!("{from}:={to}"));
            }
        }
        Ok((p, unmatched))
    }

    /// The node's name (`rlnav_policy` unless renamed).
    pub fn node(&self) -> &str {
        if self.node_name.is_empty() { DEFAULT_NODE_NAME } else { &self.node_name }
    }

    /// The absolute name of one of the node's topics, resolved in its namespace.
    pub fn topic(&self, name: &str) -> String {
        crate::ros_args::resolve(&self.namespace, self.node(), name)
    }

    /// Every topic parameter (`pose_topic` empty when unused).
    fn topics_mut(&mut self) -> [&mut String; 10] {
        [
            &mut self.scan_topic,
            &mut self.odom_topic,
            &mut self.pose_topic,
            &mut self.goal_topic,
            &mut self.plan_topic,
            &mut self.tf_topic,
            &mut self.tf_static_topic,
            &mut self.map_topic,
            &mut self.cmd_vel_topic,
            &mut self.status_topic,
        ]
    }

    /// The topic parameters whose resolved name is `resolved`.
    fn topics_mut_by_resolved(&mut self, resolved: &str) -> Vec<&mut String> {
        let (ns, node) = (self.namespace.clone(), self.node().to_string());
        self.topics_mut()
            .into_iter()
            .filter(|t| !t.is_empty() && crate::ros_args::resolve(&ns, &node, t) == resolved)
            .collect()
    }

    /// Replaces every topic parameter by its absolute name in the node's namespace.
    pub fn resolve_topics(&mut self) {
        let (ns, node) = (self.namespace.clone(), self.node().to_string());
        for t in self.topics_mut().into_iter().filter(|t| !t.is_empty()) {
            *t = crate::ros_args::resolve(&ns, &node, t);
        }
    }
}

/// The node's name on the ROS graph unless `__node` renames it.
pub const DEFAULT_NODE_NAME: &str = "rlnav_policy";

/// The parameters for `node` in YAML text, as one flat mapping: the whole text when it is
/// flat, else its `/**` and `node` sections of a ROS 2 parameters file (see
/// [`NodeParams::from_yaml`]).
fn node_section(source: &str, text: &str, node: &str) -> Result<serde_norway::Value, ConfigError> {
    use serde_norway::{Mapping, Value};
    let parse = |e: serde_norway::Error| ConfigError::Parse { file: source.to_string(), message: e.to_string() };
    let value: Value = serde_norway::from_str(text).map_err(parse)?;
    let sections: Vec<(String, &Mapping)> = value
        .as_mapping()
        .map(|m| {
            m.iter()
                .filter_map(|(k, v)| Some((k.as_str()?.to_string(), v.get("ros__parameters")?.as_mapping()?)))
                .collect()
        })
        .unwrap_or_default();
    if sections.is_empty() {
        return Ok(value);
    }
    let ours = |k: &str| matches!(k, "/**" | "**") || k.trim_start_matches('/') == node;
    let mut picked: Vec<&(String, &Mapping)> = sections.iter().filter(|(k, _)| ours(k)).collect();
    // Wildcards first, so that this node's own section overrides them.
    picked.sort_by_key(|(k, _)| !k.ends_with("**"));
    if picked.is_empty() && sections.len() == 1 {
        picked.push(&sections[0]);
    }
    if picked.is_empty() {
        let names: Vec<&str> = sections.iter().map(|(k, _)| k.as_str()).collect();
        return Err(ConfigError::Parse {
            file: source.to_string(),
            message: format!(
                "no parameters for {node}: expected a `{node}:` or `/**:` section, found {}",
                names.join(", ")
            ),
        });
    }
    let mut merged = Mapping::new();
    for (_, m) in picked {
        for (k, v) in m.iter() {
            merged.insert(k.clone(), v.clone());
        }
    }
    Ok(Value::Mapping(merged))
}

impl Validate for NodeParams {
    fn validate(&self) -> Result<(), Invalid> {
        for (k, v) in [
            ("scan_timeout", self.scan_timeout),
            ("pose_timeout", self.pose_timeout),
            ("failure_tolerance", self.failure_tolerance),
            ("movement_time_allowance", self.movement_time_allowance),
            ("replan_period", self.replan_period),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(Invalid::new(k, "a positive number of seconds"));
            }
        }
        for (k, v) in [
            ("goal_tolerance", self.goal_tolerance),
            ("max_linear", self.max_linear),
            ("max_angular", self.max_angular),
            ("lookahead", self.lookahead),
            ("required_movement_radius", Some(self.required_movement_radius)),
            ("robot_radius", self.robot_radius),
            ("inflation_radius", Some(self.inflation_radius)),
            ("cost_scaling_factor", Some(self.cost_scaling_factor)),
        ] {
            if let Some(v) = v {
                check_positive(k, v)?;
            }
        }
        if self.goal.is_some_and(|g| !g.iter().all(|x| x.is_finite())) {
            return Err(Invalid::new("goal", "two finite numbers [x, y]"));
        }
        for (k, t) in [
            ("scan_topic", &self.scan_topic),
            ("odom_topic", &self.odom_topic),
            ("goal_topic", &self.goal_topic),
            ("plan_topic", &self.plan_topic),
            ("tf_topic", &self.tf_topic),
            ("tf_static_topic", &self.tf_static_topic),
            ("cmd_vel_topic", &self.cmd_vel_topic),
            ("status_topic", &self.status_topic),
            ("follow_path_action", &self.follow_path_action),
        ] {
            if !crate::ros_args::valid_name(t) {
                return Err(Invalid::new(
                    k,
                    format!("a topic name (absolute `/scan`, relative `scan` or private `~/scan`), got `{t}`"),
                ));
            }
        }
        for (k, t) in [("pose_topic", &self.pose_topic), ("map_topic", &self.map_topic)] {
            if !t.is_empty() && !crate::ros_args::valid_name(t) {
                return Err(Invalid::new(k, format!("a topic name or empty, got `{t}`")));
            }
        }
        Ok(())
    }
}

/// What the node is doing.
#[derive(Clone, Debug, PartialEq)]
pub enum NodeState {
    /// No goal yet.
    Idle,
    /// Following the policy.
    Driving,
    /// Within the goal tolerance; waiting for a new goal.
    GoalReached,
    /// Commanding zero velocity because of the reason given.
    Stopped(String),
}

impl std::fmt::Display for NodeState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            NodeState::Idle => f.write_str("idle"),
            NodeState::Driving => f.write_str("driving"),
            NodeState::GoalReached => f.write_str("goal reached"),
            NodeState::Stopped(why) => write!(f, "stopped: {why}"),
        }
    }
}

/// A pose sample with the time it arrived.
#[derive(Clone, Copy, Debug)]
struct PoseSample {
    pose: Pose2,
    velocity: Twist,
    /// Lateral velocity (m/s, `base_link` y).
    lateral: f32,
    received: f64,
}

/// A plan being followed: its points in its own frame and how far along the robot is.
#[derive(Clone, Debug)]
struct Plan {
    frame: String,
    points: Vec<Vec2>,
    /// The segment the robot's projection lay on last (it only moves forward).
    progress: usize,
    /// Planned by the node on its map (replanned as it goes), not received.
    own: bool,
}

/// A map to plan on: its frame, where its grid lies in it, and the grid as an inflated
/// costmap in the grid's own frame.
struct MapPlanner {
    frame: String,
    origin: Pose2,
    /// Metres per costmap cell (the map's, or coarser for a very large map).
    resolution: f32,
    costmap: Costmap,
}

/// Map cells of this value or more are obstacles (`map_server`'s `occupied_thresh` 0.65).
pub const MAP_OCCUPIED: i8 = 65;

/// Larger maps are planned on coarser cells, so that a replan, which runs in the control
/// loop, stays within a few tens of milliseconds (measured with `astar_speed`: A* across 2^18
/// cells 27 ms, across 2^20 120 ms, on a 2-core VM).
pub const MAP_MAX_CELLS: usize = 1 << 18;

/// How much A* prefers paths away from obstacles (the DWA baseline's `cost_weight`).
const PLAN_COST_WEIGHT: f32 = 3.0;

/// The footprint radius of the contract's robot when rlnav knows it (a shipped robot), else the
/// largest of the robots it was trained across, else 0.2 m.
fn default_robot_radius(contract: &PolicyContract) -> f32 {
    rlnav_sim::RobotSpec::load(&contract.robot)
        .map(|r| r.footprint().radius())
        .ok()
        .or(contract.envelope.as_ref().map(|e| e.footprint_radius[1]))
        .unwrap_or(0.2)
}

pub use rlnav_sim::plan::plan_subgoal;

/// The policy node's logic.
pub struct PolicyNode {
    params: NodeParams,
    runner: PolicyRunner,
    tolerance: f32,
    scan: Option<(rlnav_sim::LaserScan, f64, Time)>,
    pose: Option<PoseSample>,
    pose_frame: Option<String>,
    goal: Option<Vec2>,
    /// The plan being followed, if the goal came as one.
    plan: Option<Plan>,
    /// The point the policy steered to at the last tick (the goal, or a point on the plan).
    target: Option<Vec2>,
    /// Path length left to the goal at the last tick (m): along the plan, else straight.
    remaining: Option<f32>,
    lookahead: f32,
    pending_goal: Option<PoseStamped>,
    /// Why the last goal could not be used (it stops the robot until a usable goal arrives).
    goal_error: Option<String>,
    tf: BTreeMap<(String, String), Pose2>,
    map: Option<MapPlanner>,
    /// When the node last planned on its map (s, the node's clock).
    planned_at: Option<f64>,
    /// Why planning on the map failed last (said once until it changes).
    plan_failure: Option<String>,
    /// Lines to log (see [`PolicyNode::take_notes`]).
    notes: Vec<String>,
    reached: bool,
    last_command: Twist,
    started: Option<f64>,
    state: NodeState,
    /// Messages that did not decode or made no sense.
    pub rejected: u64,
}

fn finite_pose(p: &msg::Pose) -> Option<Pose2> {
    let (x, y) = (p.position.x, p.position.y);
    if !(x.is_finite() && y.is_finite() && p.orientation.is_unit(1e-2)) {
        return None;
    }
    Some(Pose2::new(x as f32, y as f32, p.orientation.yaw() as f32))
}

impl PolicyNode {
    /// [`Self::new`], refusing a policy that needs the robot's top speed when `params` do not
    /// give it (`max_linear`): what `rlnav ros2 node` starts.
    pub fn try_new(runner: PolicyRunner, params: NodeParams) -> Result<Self, rlnav_policy::runner::PolicyError> {
        let node = Self::new(runner, params);
        node.runner.check_top_speed()?;
        Ok(node)
    }

    /// The node for `runner` with `params`.
    pub fn new(mut runner: PolicyRunner, params: NodeParams) -> Self {
        // Without it such a policy stops the robot at every tick, saying why.
        if let Some(v) = params.max_linear {
            runner.set_top_speed(v);
        }
        let tolerance = params.goal_tolerance.unwrap_or(runner.contract().goal_tolerance);
        // The lookahead the policy was trained with, else half the lidar's range.
        let trained = runner.contract().plan.as_ref().map(|p| p.lookahead);
        let lookahead =
            params.lookahead.or(trained).unwrap_or((0.5 * runner.contract().scan.range_max).clamp(0.5, 2.0));
        let goal = params.goal.map(|g| Vec2::new(g[0] as f32, g[1] as f32));
        Self {
            params,
            runner,
            tolerance,
            scan: None,
            pose: None,
            pose_frame: None,
            goal,
            plan: None,
            target: None,
            remaining: None,
            lookahead,
            pending_goal: None,
            goal_error: None,
            tf: BTreeMap::new(),
            map: None,
            planned_at: None,
            plan_failure: None,
            notes: Vec::new(),
            reached: false,
            last_command: Twist::default(),
            started: None,
            state: NodeState::Idle,
            rejected: 0,
        }
    }

    /// The policy's control period (s).
    pub fn control_period(&self) -> f64 {
        self.runner.contract().control_period as f64
    }

    /// The current state.
    pub fn state(&self) -> &NodeState {
        &self.state
    }

    /// The goal in the pose frame, if any (a plan's last point, as of the last tick).
    pub fn goal(&self) -> Option<Vec2> {
        self.goal
    }

    /// Where the policy steered at the last tick, in the pose frame: the goal, or with a plan
    /// the point `lookahead` ahead along it.
    pub fn target(&self) -> Option<Vec2> {
        self.target
    }

    /// The lookahead along plans (m).
    pub fn lookahead(&self) -> f32 {
        self.lookahead
    }

    /// Path length left to the goal as of the last tick (m): along the plan from the robot's
    /// projection on it, or the straight distance to a goal given alone.
    pub fn distance_to_goal(&self) -> Option<f32> {
        self.remaining
    }

    /// The robot's position (pose frame) and speed (m/s, forward and lateral together) from
    /// the latest pose, if any.
    pub fn motion(&self) -> Option<(Vec2, f32)> {
        self.pose.map(|p| {
            let lateral = if p.lateral.is_finite() { p.lateral } else { 0.0 };
            (p.pose.position(), p.velocity.linear.hypot(lateral))
        })
    }

    /// Drops the goal and any plan: the robot stops, idle (a canceled or aborted FollowPath
    /// goal).
    pub fn clear_goal(&mut self) {
        self.plan = None;
        self.goal = None;
        self.target = None;
        self.remaining = None;
        self.pending_goal = None;
        self.goal_error = None;
        self.planned_at = None;
    }

    /// Lines for the log since the last call (a map taken or refused, planning that failed).
    pub fn take_notes(&mut self) -> Vec<String> {
        std::mem::take(&mut self.notes)
    }

    /// Whether the node holds a map to plan on.
    pub fn has_map(&self) -> bool {
        self.map.is_some()
    }

    /// A map arrived (`map_topic`): it replaces the one held, and plans made on the old one are
    /// made again. A map that does not describe itself consistently is refused with a note.
    pub fn on_map(&mut self, m: &OccupancyGrid) {
        match self.map_planner(m) {
            Ok(map) => {
                let (w, h) = map.costmap.size();
                self.notes.push(format!(
                    "map in `{}`: {} x {} cells of {} m{}",
                    map.frame,
                    m.info.width,
                    m.info.height,
                    m.info.resolution,
                    if map.resolution > m.info.resolution {
                        format!(", planned on {w} x {h} cells of {} m", map.resolution)
                    } else {
                        String::new()
                    }
                ));
                self.map = Some(map);
                self.planned_at = None;
            }
            Err(why) => {
                self.rejected += 1;
                self.notes.push(format!("map refused: {why}"));
            }
        }
    }

    fn map_planner(&self, m: &OccupancyGrid) -> Result<MapPlanner, String> {
        let info = &m.info;
        let (width, height) = (info.width as usize, info.height as usize);
        if !(info.resolution.is_finite() && info.resolution > 0.0) {
            return Err(format!("info.resolution is {}, expected a positive number of metres", info.resolution));
        }
        if width == 0 || height == 0 || width.checked_mul(height) != Some(m.data.len()) {
            return Err(format!(
                "info.width x info.height is {width} x {height}, but data holds {} cells",
                m.data.len()
            ));
        }
        let origin =
            finite_pose(&info.origin).ok_or("info.origin is not a finite pose with a unit quaternion".to_string())?;
        if m.header.frame_id.is_empty() {
            return Err("header.frame_id is empty, expected the map's frame (`map`)".into());
        }
        // Coarser cells for a very large map: a coarse cell is an obstacle when any of its fine
        // cells is.
        let mut factor = 1;
        while width.div_ceil(factor) * height.div_ceil(factor) > MAP_MAX_CELLS {
            factor += 1;
        }
        let (cw, ch) = (width.div_ceil(factor), height.div_ceil(factor));
        let mut lethal = vec![false; cw * ch];
        for (k, v) in m.data.iter().enumerate() {
            // Unknown cells (-1) are passable, as Nav2's planner has them by default.
            if *v >= MAP_OCCUPIED {
                lethal[(k / width / factor) * cw + (k % width) / factor] = true;
            }
        }
        let resolution = info.resolution * factor as f32;
        let radius = self.params.robot_radius.unwrap_or_else(|| default_robot_radius(self.runner.contract()));
        let config = CostmapConfig {
            resolution,
            inflation_radius: self.params.inflation_radius,
            cost_scaling_factor: self.params.cost_scaling_factor,
            ..CostmapConfig::default()
        };
        let costmap = Costmap::from_cells(cw, ch, config, radius, lethal).ok_or("the grid is empty")?;
        Ok(MapPlanner { frame: m.header.frame_id.clone(), origin, resolution, costmap })
    }

    /// With a map, a goal and no plan from a planner: plans (again, once `replan_period` has
    /// passed) from the robot at `robot` (pose frame) to the goal. Where no path is found, or
    /// the map's frame has no transform, the plan is dropped and the policy steers at the goal
    /// itself (a note says why).
    fn plan_on_map(&mut self, robot: Pose2, now: f64) {
        let (Some(map), Some(goal)) = (&self.map, self.goal) else { return };
        if self.reached || self.plan.as_ref().is_some_and(|p| !p.own) {
            return;
        }
        if self.planned_at.is_some_and(|t| now - t < self.params.replan_period) {
            return;
        }
        self.planned_at = Some(now);
        let pose_frame = self.pose_frame.as_deref().unwrap_or_default();
        let planned = match self.lookup(pose_frame, &map.frame) {
            None => Err(format!("no transform from the map's frame `{}` to `{pose_frame}`", map.frame)),
            Some(t) => {
                // Map frame, then the grid's frame.
                let (from, to) = (t.to_local(robot.position()), t.to_local(goal));
                let (a, b) = (map.origin.to_local(from), map.origin.to_local(to));
                match astar::plan(&map.costmap, a, b, PLAN_COST_WEIGHT) {
                    Some(cells) => {
                        let mut points: Vec<Vec2> = cells.into_iter().map(|c| map.origin.to_parent(c)).collect();
                        // The goal itself, not the centre of its cell.
                        if let Some(last) = points.last_mut() {
                            *last = to;
                        }
                        Ok(Plan { frame: map.frame.clone(), points, progress: 0, own: true })
                    }
                    None => Err(format!(
                        "no path on the map from ({:.2}, {:.2}) to ({:.2}, {:.2}) in `{}`",
                        from.x, from.y, to.x, to.y, map.frame
                    )),
                }
            }
        };
        match planned {
            Ok(plan) => {
                self.plan = Some(plan);
                if self.plan_failure.take().is_some() {
                    self.notes.push("planning on the map again".into());
                }
            }
            Err(why) => {
                self.plan = None;
                if self.plan_failure.as_ref() != Some(&why) {
                    self.notes.push(format!("{why}: steering at the goal"));
                    self.plan_failure = Some(why);
                }
            }
        }
    }

    /// A scan arrived at `now` (s, the node's clock).
    pub fn on_scan(&mut self, m: &LaserScan, now: f64) {
        // A scan stamped a little before the one held arrived out of order and is dropped.
        // One stamped far before it means the sender's clock jumped (or the held stamp was
        // bogus, far in the future), so it is taken: a single bad stamp must not lock the node
        // out of every later scan. Staleness is judged by arrival time, never by stamps.
        if let Some((_, _, stamp)) = &self.scan {
            let behind = stamp.as_secs() - m.header.stamp.as_secs();
            if behind > 0.0 && behind < 1.0 {
                self.rejected += 1;
                return;
            }
        }
        let scan = rlnav_sim::LaserScan {
            angle_min: m.angle_min,
            angle_increment: m.angle_increment,
            range_min: m.range_min,
            range_max: m.range_max,
            ranges: m.ranges.clone(),
        };
        self.scan = Some((scan, now, m.header.stamp));
    }

    /// Odometry arrived (ignored when the pose comes from a pose topic).
    pub fn on_odom(&mut self, m: &Odometry, now: f64) {
        if !self.params.pose_topic.is_empty() {
            return;
        }
        let t = &m.twist.twist;
        match finite_pose(&m.pose.pose) {
            Some(pose) if t.linear.x.is_finite() && t.angular.z.is_finite() => {
                let velocity = Twist::new(t.linear.x as f32, t.angular.z as f32);
                // A non-finite lateral velocity only matters to a policy that reads it; its
                // observation check stops the robot then.
                let lateral = t.linear.y as f32;
                self.set_pose(PoseSample { pose, velocity, lateral, received: now }, &m.header.frame_id);
            }
            _ => {
                self.rejected += 1;
                self.pose = None;
            }
        }
    }

    /// A pose (motion capture) arrived; the velocity is its difference from the last one.
    pub fn on_pose(&mut self, m: &PoseStamped, now: f64) {
        let Some(pose) = finite_pose(&m.pose) else {
            self.rejected += 1;
            self.pose = None;
            return;
        };
        let (velocity, lateral) = match self.pose {
            Some(prev) if now - prev.received > 1e-3 => {
                let dt = (now - prev.received) as f32;
                let d = pose.position() - prev.pose.position();
                let (sin, cos) = prev.pose.yaw.sin_cos();
                let forward = d.x * cos + d.y * sin;
                let left = -d.x * sin + d.y * cos;
                (Twist::new(forward / dt, wrap_angle(pose.yaw - prev.pose.yaw) / dt), left / dt)
            }
            Some(prev) => (prev.velocity, prev.lateral),
            None => (Twist::default(), 0.0),
        };
        self.set_pose(PoseSample { pose, velocity, lateral, received: now }, &m.header.frame_id);
    }

    fn set_pose(&mut self, sample: PoseSample, frame: &str) {
        self.pose = Some(sample);
        if self.pose_frame.as_deref() != Some(frame) {
            self.pose_frame = Some(frame.to_string());
        }
        if let Some(g) = self.pending_goal.take() {
            self.on_goal(&g);
        }
    }

    /// Transforms arrived; they are kept to bring goals into the pose frame.
    pub fn on_tf(&mut self, m: &TFMessage) {
        for t in &m.transforms {
            let tr = &t.transform;
            let ok = tr.translation.x.is_finite() && tr.translation.y.is_finite() && tr.rotation.is_unit(1e-2);
            if !ok {
                self.rejected += 1;
                continue;
            }
            let p = Pose2::new(tr.translation.x as f32, tr.translation.y as f32, tr.rotation.yaw() as f32);
            self.tf.insert((t.header.frame_id.clone(), t.child_frame_id.clone()), p);
        }
    }

    /// The pose of frame `child` in frame `parent`, through the transforms known (either
    /// direction, any chain).
    fn lookup(&self, parent: &str, child: &str) -> Option<Pose2> {
        if parent == child {
            return Some(Pose2::default());
        }
        // Breadth-first over the frame graph; each step composes one transform.
        let mut seen = vec![parent.to_string()];
        let mut frontier = vec![(parent.to_string(), Pose2::default())];
        while let Some((frame, pose)) = frontier.pop() {
            for ((a, b), t) in &self.tf {
                let next = if *a == frame {
                    Some((b, pose.compose(t)))
                } else if *b == frame {
                    Some((a, pose.compose(&t.inverse())))
                } else {
                    None
                };
                if let Some((f, p)) = next {
                    if f == child {
                        return Some(p);
                    }
                    if !seen.contains(f) {
                        seen.push(f.clone());
                        frontier.insert(0, (f.clone(), p));
                    }
                }
            }
        }
        None
    }

    /// A goal arrived. A goal in another frame than the pose's is transformed when the
    /// transform is known, and refused (the node stops) when it is not.
    pub fn on_goal(&mut self, m: &PoseStamped) {
        let (x, y) = (m.pose.position.x, m.pose.position.y);
        if !(x.is_finite() && y.is_finite()) {
            self.rejected += 1;
            return;
        }
        let Some(pose_frame) = self.pose_frame.clone() else {
            // No pose yet: keep it until the pose frame is known.
            self.pending_goal = Some(m.clone());
            return;
        };
        let frame = &m.header.frame_id;
        let goal = if frame.is_empty() || *frame == pose_frame {
            Some(Vec2::new(x as f32, y as f32))
        } else {
            self.lookup(&pose_frame, frame).map(|t| t.to_parent(Vec2::new(x as f32, y as f32)))
        };
        // A goal pose replaces any plan, except the node's own plan to the same goal (a goal
        // re-sent, as the sim bridge does every second).
        let same = goal.zip(self.goal).is_some_and(|(a, b)| (a - b).length() < 1e-3);
        if !(same && self.plan.as_ref().is_some_and(|p| p.own)) {
            self.plan = None;
            self.planned_at = None;
        }
        match goal {
            Some(g) => {
                self.goal_error = None;
                if !same {
                    self.goal = Some(g);
                    self.reached = false;
                    self.runner.reset();
                }
            }
            None => {
                self.goal = None;
                self.goal_error = Some(format!("goal in frame `{frame}`, which has no transform to `{pose_frame}`"));
            }
        }
    }

    /// A plan arrived: it replaces the goal and any earlier plan. Its last pose is the goal;
    /// an empty plan cancels the goal (the robot stops, idle). Its frame is resolved at every
    /// tick, through `/tf` when it is not the pose frame (a `map` plan follows the robot's
    /// localisation as `map -> odom` moves). A plan with a non-finite point is refused.
    pub fn on_plan(&mut self, m: &PlanMsg) {
        let mut points: Vec<Vec2> = Vec::with_capacity(m.poses.len());
        for ps in &m.poses {
            let (x, y) = (ps.pose.position.x, ps.pose.position.y);
            if !(x.is_finite() && y.is_finite()) {
                self.rejected += 1;
                return;
            }
            let q = Vec2::new(x as f32, y as f32);
            if points.last() != Some(&q) {
                points.push(q);
            }
        }
        self.goal_error = None;
        self.pending_goal = None;
        let Some(&end) = points.last() else {
            self.plan = None;
            self.goal = None;
            self.target = None;
            return;
        };
        // A new plan to the same goal (Nav2 replans about once a second) keeps the episode: the
        // policy's memory and a goal already reached.
        let same_goal = self.plan.as_ref().is_some_and(|p| {
            p.frame == m.header.frame_id && p.points.last().is_some_and(|e| (*e - end).length() < self.tolerance)
        });
        if !same_goal {
            self.reached = false;
            self.runner.reset();
        }
        self.plan = Some(Plan { frame: m.header.frame_id.clone(), points, progress: 0, own: false });
    }

    /// The goal and the point to steer to for a robot at `pose` (pose frame): the goal alone,
    /// or with a plan its last point and the point `lookahead` ahead along it.
    fn targets(&mut self, pose: Pose2) -> Result<Option<(Vec2, Vec2)>, String> {
        let Some(plan) = &self.plan else {
            self.remaining = self.goal.map(|g| (g - pose.position()).length());
            return Ok(self.goal.map(|g| (g, g)));
        };
        let pose_frame = self.pose_frame.as_deref().unwrap_or_default();
        let t = if plan.frame.is_empty() || plan.frame == pose_frame {
            Pose2::default()
        } else {
            self.lookup(pose_frame, &plan.frame)
                .ok_or_else(|| format!("plan in frame `{}`, which has no transform to `{pose_frame}`", plan.frame))?
        };
        let lookahead = self.lookahead;
        let plan = self.plan.as_mut().expect("checked above");
        let here = t.to_local(pose.position());
        let sub = plan_subgoal(&plan.points, &mut plan.progress, here, lookahead);
        let end = *plan.points.last().expect("plans are not empty");
        // From the robot to the end of the segment it is on, then the rest of the plan.
        let next = (plan.progress + 1).min(plan.points.len() - 1);
        let rest: f32 = plan.points[next..].windows(2).map(|w| (w[1] - w[0]).length()).sum();
        self.remaining = Some((plan.points[next] - here).length() + rest);
        Ok(Some((t.to_parent(end), t.to_parent(sub))))
    }

    fn cap(&self, c: Twist) -> Twist {
        let l = self.params.max_linear.unwrap_or(f32::INFINITY);
        let a = self.params.max_angular.unwrap_or(f32::INFINITY);
        Twist::new(c.linear.clamp(-l, l), c.angular.clamp(-a, a))
    }

    /// The command for time `now`, and the state it leaves the node in.
    pub fn tick(&mut self, now: f64) -> Twist {
        let (cmd, state) = self.decide(now);
        let cmd = if cmd.linear.is_finite() && cmd.angular.is_finite() { cmd } else { Twist::default() };
        self.last_command = cmd;
        self.state = state;
        cmd
    }

    fn decide(&mut self, now: f64) -> (Twist, NodeState) {
        let stop = |why: String| (Twist::default(), NodeState::Stopped(why));
        if let Some(why) = &self.goal_error {
            return stop(why.clone());
        }
        if self.goal.is_none() && self.plan.is_none() {
            return (Twist::default(), NodeState::Idle);
        }
        let Some((_, scan_at, _)) = &self.scan else { return stop("no scan yet".into()) };
        if now - scan_at > self.params.scan_timeout {
            return stop(format!("no scan for {:.2} s", now - scan_at));
        }
        let Some(pose) = self.pose else { return stop("no pose yet (or the last one was not finite)".into()) };
        if now - pose.received > self.params.pose_timeout {
            return stop(format!("no pose for {:.2} s", now - pose.received));
        }
        self.plan_on_map(pose.pose, now);
        let (goal, target) = match self.targets(pose.pose) {
            Ok(Some(g)) => g,
            Ok(None) => return (Twist::default(), NodeState::Idle),
            Err(why) => return stop(why),
        };
        self.goal = Some(goal);
        self.target = Some(target);
        let scan = &self.scan.as_ref().expect("checked above").0;
        let d = (goal - pose.pose.position()).length();
        if self.reached || d < self.tolerance {
            self.reached = true;
            return (Twist::default(), NodeState::GoalReached);
        }
        let started = *self.started.get_or_insert(now);
        let obs = RobotObservation {
            scan: scan.clone(),
            scan_mount: Pose2::new(0.0, 0.0, self.params.lidar_yaw_offset),
            pose: pose.pose,
            velocity: pose.velocity,
            lateral_velocity: pose.lateral,
            goal: target,
            last_command: self.last_command,
            time: (now - started) as f32,
            // The node follows plans itself (`target`): the policy sees the target as its goal.
            plan: Default::default(),
        };
        match self.runner.try_act(&obs) {
            Ok(c) => (self.cap(c), NodeState::Driving),
            Err(e) => stop(format!("policy input: {e}")),
        }
    }
}

/// Notices an input topic that stays silent: a wrong name, a QoS the publisher does not offer
/// (RustDDS reports incompatible QoS to the reader, not to the log) or a driver that is not
/// running all look alike to the node, which only stops with "no scan yet". After `after`
/// seconds without a message it says so once, with what to check; when messages come, it says
/// that too.
#[derive(Clone, Debug)]
pub struct SilenceWatch {
    topic: String,
    after: f64,
    last: f64,
    reported: bool,
}

impl SilenceWatch {
    /// Watches `topic` from time `now` (s).
    pub fn new(topic: &str, after: f64, now: f64) -> Self {
        Self { topic: topic.to_string(), after, last: now, reported: false }
    }

    /// `arrived`: whether messages came since the last call. Returns a line to log, if any.
    pub fn check(&mut self, arrived: bool, now: f64) -> Option<String> {
        if arrived {
            self.last = now;
            if std::mem::take(&mut self.reported) {
                return Some(format!("{}: messages arriving", self.topic));
            }
            return None;
        }
        if !self.reported && now - self.last >= self.after {
            self.reported = true;
            return Some(format!(
                "nothing on {} for {:.0} s: check that it is published under this name \
                 (`ros2 topic list`) and that its publisher's QoS matches (`ros2 topic info -v {}`)",
                self.topic, self.after, self.topic
            ));
        }
        None
    }
}

/// How long an input topic may stay silent before the node says so (s).
pub const SILENCE_REPORT_S: f64 = 3.0;

/// The node's clock: wall time since it started (it does not follow `/clock`).
fn now_since(start: Instant) -> f64 {
    start.elapsed().as_secs_f64()
}

/// Runs the node until `stop` is set: subscribes, computes, publishes, and logs each change of
/// state on stderr and on the status topic.
pub fn run_node(
    mut node: PolicyNode,
    domain: u16,
    reach: Reach,
    stop: Arc<AtomicBool>,
    mut on_command: impl FnMut(Twist, &NodeState),
) -> Result<(), BusError> {
    let mut p = node.params.clone();
    let mut bus = Bus::in_namespace(&p.namespace, p.node(), domain, reach)?;
    // Every topic by its absolute name in the node's namespace.
    p.resolve_topics();
    let scan_sub = bus.subscription::<LaserScan>(&p.scan_topic, p.scan_qos)?;
    // Odometry and poses are read best effort, which matches reliable and best-effort writers
    // alike (a TurtleBot 4 publishes /odom best effort; a reliable reader would never match it).
    let odom_sub =
        if p.pose_topic.is_empty() { Some(bus.subscription::<Odometry>(&p.odom_topic, p.odom_qos)?) } else { None };
    let pose_sub =
        if p.pose_topic.is_empty() { None } else { Some(bus.subscription::<PoseStamped>(&p.pose_topic, p.odom_qos)?) };
    let clock_sub = if p.use_sim_time { Some(bus.subscription::<msg::Clock>("/clock", Qos::Default)?) } else { None };
    let mut sim_time: Option<Time> = None;
    let goal_sub = bus.subscription::<PoseStamped>(&p.goal_topic, Qos::Default)?;
    let plan_sub = bus.subscription::<PlanMsg>(&p.plan_topic, Qos::Default)?;
    let tf_sub = bus.subscription::<TFMessage>(&p.tf_topic, Qos::Default)?;
    // Transient local, as tf2's static broadcaster and map_server publish: a late joiner still
    // gets them.
    let mut tf_static_sub = bus.subscription::<TFMessage>(&p.tf_static_topic, Qos::Latched)?;
    let mut map_sub = if p.map_topic.is_empty() {
        None
    } else {
        Some(bus.subscription::<OccupancyGrid>(&p.map_topic, Qos::Latched)?)
    };
    let twist_pub =
        if p.cmd_vel_stamped { None } else { Some(bus.publisher::<msg::Twist>(&p.cmd_vel_topic, p.cmd_vel_qos)?) };
    let stamped_pub =
        if p.cmd_vel_stamped { Some(bus.publisher::<TwistStamped>(&p.cmd_vel_topic, p.cmd_vel_qos)?) } else { None };
    let status_pub = bus.publisher::<StringMsg>(&p.status_topic, Qos::Default)?;
    let mut follow_path = if p.follow_path {
        let limits = GoalLimits {
            failure_tolerance: p.failure_tolerance,
            required_movement_radius: p.required_movement_radius,
            movement_time_allowance: p.movement_time_allowance,
        };
        Some(FollowPathServer::new(&mut bus, &p.topic(&p.follow_path_action), limits)?)
    } else {
        None
    };
    // Wake on arriving data rather than polling on a timer: the scan-to-command latency is
    // then DDS's, not a sleep's.
    let mut poll = Poll::new().map_err(|e| BusError::Create { what: "poll".into(), message: e.to_string() })?;
    let mut events = Events::with_capacity(16);
    let reg = poll.registry();
    let watch = |r: &mut dyn rustdds::mio1::event::Source, k: usize| {
        reg.register(r, Token(k), Interest::READABLE)
            .map_err(|e| BusError::Create { what: "poll registration".into(), message: e.to_string() })
    };
    let mut scan_sub = scan_sub;
    let mut goal_sub = goal_sub;
    let mut tf_sub = tf_sub;
    let mut plan_sub = plan_sub;
    watch(&mut plan_sub, 5)?;
    watch(&mut scan_sub, 0)?;
    watch(&mut goal_sub, 1)?;
    watch(&mut tf_sub, 2)?;
    let mut odom_sub = odom_sub;
    if let Some(s) = odom_sub.as_mut() {
        watch(s, 3)?;
    }
    let mut pose_sub = pose_sub;
    if let Some(s) = pose_sub.as_mut() {
        watch(s, 4)?;
    }
    watch(&mut tf_static_sub, 9)?;
    if let Some(s) = map_sub.as_mut() {
        watch(s, 10)?;
    }
    if let Some(f) = follow_path.as_mut() {
        f.register(reg, 6)
            .map_err(|e| BusError::Create { what: "poll registration".into(), message: e.to_string() })?;
    }
    let period = node.control_period();
    let start = Instant::now();
    let mut scan_watch = SilenceWatch::new(&p.scan_topic, SILENCE_REPORT_S, 0.0);
    let pose_topic = if p.pose_topic.is_empty() { &p.odom_topic } else { &p.pose_topic };
    let mut pose_watch = SilenceWatch::new(pose_topic, SILENCE_REPORT_S, 0.0);
    let mut next_tick = 0.0;
    let mut last_state = String::new();
    let mut dropped = 0;
    let mut pending_scan = false;
    while !stop.load(Ordering::Relaxed) {
        let now = now_since(start);
        for m in drain(&tf_sub, &mut dropped).iter().chain(&drain(&tf_static_sub, &mut dropped)) {
            node.on_tf(m);
        }
        if let Some(s) = &map_sub {
            // Only the newest map counts.
            if let Some(m) = drain(s, &mut dropped).last() {
                node.on_map(m);
            }
        }
        if let Some(s) = &clock_sub {
            if let Some(c) = drain(s, &mut dropped).last() {
                sim_time = Some(c.clock);
            }
        }
        let mut pose_arrived = false;
        if let Some(s) = &odom_sub {
            for m in drain(s, &mut dropped) {
                node.on_odom(&m, now);
                pose_arrived = true;
            }
        }
        if let Some(s) = &pose_sub {
            for m in drain(s, &mut dropped) {
                node.on_pose(&m, now);
                pose_arrived = true;
            }
        }
        if let Some(f) = follow_path.as_mut() {
            for line in f.handle_requests(&mut node) {
                eprintln!("[{}] {line}", p.node());
            }
        }
        // While a FollowPath goal runs, the action owns the robot: goals and plans on the
        // topics (RViz's goal, the planner's /plan, which bt_navigator also sends as the goal's
        // path) are read and dropped.
        let action_owns = follow_path.as_ref().is_some_and(|f| f.is_active());
        for m in drain(&goal_sub, &mut dropped) {
            if !action_owns {
                node.on_goal(&m);
            }
        }
        for m in drain(&plan_sub, &mut dropped) {
            if !action_owns {
                node.on_plan(&m);
            }
        }
        let scans = drain(&scan_sub, &mut dropped);
        for line in
            [scan_watch.check(!scans.is_empty(), now), pose_watch.check(pose_arrived, now)].into_iter().flatten()
        {
            eprintln!("[{}] {line}", p.node());
        }
        pending_scan |= !scans.is_empty();
        for m in &scans {
            node.on_scan(m, now);
        }
        let due = match p.trigger {
            Trigger::Timer => now >= next_tick,
            Trigger::Scan => (pending_scan && now >= next_tick) || now >= next_tick + period,
        };
        if due {
            pending_scan = false;
            next_tick = match p.trigger {
                Trigger::Timer => (next_tick + period).max(now),
                Trigger::Scan => now + 0.5 * period,
            };
            let mut cmd = node.tick(now);
            if let Some(f) = follow_path.as_mut() {
                if let Some(line) = f.after_tick(&mut node, now) {
                    eprintln!("[{}] {line}", p.node());
                    // An aborted goal stops the robot at once, not a tick later.
                    if node.goal().is_none() {
                        cmd = Twist::default();
                    }
                }
            }
            let twist = msg::Twist::planar(cmd.linear as f64, cmd.angular as f64);
            // A failed publish (no reader yet, a full queue) is not a reason to stop ticking.
            if let Some(pb) = &twist_pub {
                let _ = pb.publish(twist);
            }
            if let Some(pb) = &stamped_pub {
                let wall =
                    || Time::from_secs(std::time::SystemTime::UNIX_EPOCH.elapsed().map_or(0.0, |d| d.as_secs_f64()));
                // With use_sim_time and no /clock yet, zero, as rclcpp stamps before the first.
                let stamp = if p.use_sim_time { sim_time.unwrap_or_default() } else { wall() };
                let _ = pb.publish(TwistStamped { header: msg::Header::new(stamp, &p.base_frame), twist });
            }
            for line in node.take_notes() {
                eprintln!("[{}] {line}", p.node());
            }
            let state = node.state().to_string();
            if state != last_state {
                eprintln!("[rlnav_policy] {state}");
                let _ = status_pub.publish(StringMsg { data: state.clone() });
                last_state = state;
            }
            on_command(cmd, node.state());
        }
        node.rejected += std::mem::take(&mut dropped);
        if let Some(f) = follow_path.as_mut() {
            node.rejected += std::mem::take(&mut f.rejected);
        }
        // Sleep until data arrives or the next tick is due (at most 50 ms, to see `stop`).
        let wait = (next_tick - now_since(start)).clamp(0.0, 0.05);
        let wait = if p.trigger == Trigger::Scan && !pending_scan {
            (next_tick + period - now_since(start)).clamp(0.0, 0.05)
        } else {
            wait
        };
        // An interrupted wait only means an early look at the readers.
        let _ = poll.poll(&mut events, Some(Duration::from_secs_f64(wait)));
    }
    // Leave the robot stopped. RustDDS sends from its own thread, and ros2-client does not
    // expose the writer's wait for acknowledgements: returning at once can end the process
    // before the sample leaves (measured: SIGTERM left the robot driving). So the zero goes out
    // a few times over 150 ms, which also covers a reader that missed the first one.
    let zero = msg::Twist::default();
    for k in 0..4 {
        if k > 0 {
            std::thread::sleep(Duration::from_millis(50));
        }
        if let Some(pb) = &twist_pub {
            let _ = pb.publish(zero);
        }
        if let Some(pb) = &stamped_pub {
            let stamped = TwistStamped { header: msg::Header::new(Time::default(), &p.base_frame), twist: zero };
            let _ = pb.publish(stamped);
        }
    }
    Ok(())
}
