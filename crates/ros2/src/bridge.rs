//! `rlnav ros2 sim`: the simulator as a ROS 2 robot, the part Gazebo plays in the reference
//! article. It runs a scenario in real time (or faster, with `/clock`), publishes `/scan`,
//! `/odom`, `/tf` (odom -> base_link), `/tf_static` (map -> odom, base_link -> laser), `/clock`,
//! the world on `/map` (transient local, as `map_server` serves it), the scene as markers on
//! `/rlnav/sim/markers` (obstacles, movers, people and the goal, for RViz2 and Foxglove) and
//! the scenario's goal on `/goal_pose`, and drives the robot with what arrives on `/cmd_vel`.
//! [`SimBridge`] is the logic without DDS; [`run_bridge`] puts it on the wire.

use crate::bus::{Bus, BusError, Qos, Reach, drain};
use crate::msg::{
    self, Clock, LaserScan, MarkerArray, OccupancyGrid, Odometry, PoseStamped, StringMsg, TFMessage, TransformStamped,
    TwistStamped,
};
use crate::sim_topics::{Frames, SimMessages, map_message, scene_markers, tf_message};
use rlnav_sim::task::{ActionConfig, EnvSetup, SimError, TaskConfig};
use rlnav_sim::{EpisodeStats, NavEnv, RobotSpec, ScenarioSpec, Twist};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// The frame of `/map`, which the bridge puts at the odometry origin (a perfectly localised
/// robot: `map -> odom` is the identity).
pub const MAP_FRAME: &str = "map";

/// Where the scene's markers go.
pub const MARKERS_TOPIC: &str = "/rlnav/sim/markers";

/// How the bridge runs.
#[derive(Clone, Debug)]
pub struct BridgeOptions {
    /// Seed of the episodes.
    pub seed: u64,
    /// Episodes to run before returning (0: until stopped).
    pub episodes: usize,
    /// Simulated seconds per wall-clock second (1: real time).
    pub rate: f64,
    /// Frame names.
    pub frames: Frames,
    /// `/cmd_vel` carries `TwistStamped` instead of `Twist`.
    pub cmd_vel_stamped: bool,
    /// A command older than this (simulated seconds) is replaced by zero, as robot bases do.
    pub cmd_timeout: f64,
}

impl Default for BridgeOptions {
    fn default() -> Self {
        Self { seed: 0, episodes: 1, rate: 1.0, frames: Frames::default(), cmd_vel_stamped: false, cmd_timeout: 0.5 }
    }
}

/// The simulated robot and its latest command.
pub struct SimBridge {
    env: NavEnv,
    frames: Frames,
    cmd: Twist,
    cmd_at: f64,
    cmd_timeout: f64,
    time: f64,
}

/// The task for a robot driven from outside: any command the robot can execute is applied
/// (down to a stop and reversing, which training's action range excludes).
pub fn bridge_setup(scenario: &str, robot: Option<&str>) -> Result<Arc<EnvSetup>, SimError> {
    let spec = ScenarioSpec::load(scenario)?;
    let robot = RobotSpec::load(robot.unwrap_or(&spec.robot))?;
    let task = TaskConfig {
        action: ActionConfig {
            linear: [robot.min_linear.min(0.0), robot.max_linear],
            angular: [-robot.max_angular, robot.max_angular],
            linear_relative: false,
        },
        ..Default::default()
    };
    Ok(Arc::new(EnvSetup::new(spec, robot, task)?))
}

impl SimBridge {
    /// A bridge over a fresh environment of `setup`.
    pub fn new(setup: Arc<EnvSetup>, opts: &BridgeOptions) -> Result<Self, SimError> {
        Ok(Self {
            env: NavEnv::new(setup, opts.seed)?,
            frames: opts.frames.clone(),
            cmd: Twist::default(),
            cmd_at: f64::NEG_INFINITY,
            cmd_timeout: opts.cmd_timeout,
            time: 0.0,
        })
    }

    /// Simulated time (s).
    pub fn time(&self) -> f64 {
        self.time
    }

    /// The control period (s).
    pub fn period(&self) -> f64 {
        self.env.setup().task.control_period as f64
    }

    /// The environment.
    pub fn env(&self) -> &NavEnv {
        &self.env
    }

    /// A velocity command arrived; non-finite parts count as zero.
    pub fn on_cmd(&mut self, t: &msg::Twist) {
        let f = |v: f64| if v.is_finite() { v as f32 } else { 0.0 };
        self.cmd = Twist::new(f(t.linear.x), f(t.angular.z));
        self.cmd_at = self.time;
    }

    /// The messages for the current state.
    pub fn messages(&self) -> SimMessages {
        SimMessages::of(&self.env, self.time, &self.frames)
    }

    /// Advances one control period under the latest command. Returns the episode's figures
    /// when it ended; the robot then stays where the episode left it (its messages show the
    /// last pose, at the goal or the collision) until [`SimBridge::next_episode`].
    pub fn step(&mut self) -> Result<Option<EpisodeStats>, SimError> {
        let cmd = if self.time - self.cmd_at <= self.cmd_timeout { self.cmd } else { Twist::default() };
        let out = self.env.step_twist(cmd);
        self.time += self.period();
        if out.terminated || out.truncated {
            return Ok(self.env.last_episode());
        }
        Ok(None)
    }

    /// Starts the next episode (after [`SimBridge::step`] reported the end of one).
    pub fn next_episode(&mut self) -> Result<(), SimError> {
        self.env.reset()
    }
}

/// Runs the bridge until its episodes are done or `stop` is set; `on_episode` gets each
/// finished episode's figures.
pub fn run_bridge(
    mut bridge: SimBridge,
    opts: &BridgeOptions,
    domain: u16,
    reach: Reach,
    stop: Arc<AtomicBool>,
    mut on_episode: impl FnMut(&EpisodeStats),
) -> Result<(), BusError> {
    let mut bus = Bus::new("rlnav_sim", domain, reach)?;
    let scan_pub = bus.publisher::<LaserScan>("/scan", Qos::SensorData)?;
    let odom_pub = bus.publisher::<Odometry>("/odom", Qos::Default)?;
    let tf_pub = bus.publisher::<TFMessage>("/tf", Qos::Default)?;
    let tf_static_pub = bus.publisher::<TFMessage>("/tf_static", Qos::Latched)?;
    let clock_pub = bus.publisher::<Clock>("/clock", Qos::Default)?;
    let goal_pub = bus.publisher::<PoseStamped>("/goal_pose", Qos::Default)?;
    let episode_pub = bus.publisher::<StringMsg>("/rlnav/sim/episode", Qos::Default)?;
    let map_pub = bus.publisher::<OccupancyGrid>("/map", Qos::Latched)?;
    let markers_pub = bus.publisher::<MarkerArray>(MARKERS_TOPIC, Qos::Default)?;
    // The world as a map, at the start and whenever an episode brings a new one.
    let publish_map = |b: &SimBridge| {
        let _ = map_pub.publish(map_message(b.env().world(), b.messages().stamp, MAP_FRAME));
    };
    let twist_sub =
        if opts.cmd_vel_stamped { None } else { Some(bus.subscription::<msg::Twist>("/cmd_vel", Qos::Default)?) };
    let stamped_sub =
        if opts.cmd_vel_stamped { Some(bus.subscription::<TwistStamped>("/cmd_vel", Qos::Default)?) } else { None };
    let wall_period = Duration::from_secs_f64(bridge.period() / opts.rate.max(1e-3));
    let mut next = Instant::now();
    let mut done = 0;
    let mut last_goal = f64::NEG_INFINITY;
    let mut dropped = 0;
    let mount = bridge.env().setup().lidar.spec().mount;
    // The whole scene every step (a late joiner sees it at once; a few kB), cleared first at
    // each new episode.
    let publish = |b: &SimBridge, goal_due: bool, new_episode: bool| {
        let _ = markers_pub.publish(scene_markers(b.env(), b.messages().stamp, &opts.frames.odom, new_episode));
        let m = b.messages();
        let _ = clock_pub.publish(Clock { clock: m.stamp });
        let _ = odom_pub.publish(m.odom.clone());
        let tf = m.tf.transforms[0].clone();
        let _ = tf_pub.publish(TFMessage { transforms: vec![tf] });
        let _ = scan_pub.publish(m.scan);
        if goal_due {
            let _ = goal_pub.publish(m.goal);
        }
    };
    let statics = tf_message(Default::default(), mount, msg::Time::default(), &opts.frames);
    // One message with both: a late joiner of a keep-last-1 topic gets only the last one.
    let map_to_odom = TransformStamped::planar(msg::Time::default(), MAP_FRAME, &opts.frames.odom, 0.0, 0.0, 0.0);
    let _ = tf_static_pub.publish(TFMessage { transforms: vec![map_to_odom, statics.transforms[1].clone()] });
    publish_map(&bridge);
    publish(&bridge, true, true);
    while !stop.load(Ordering::Relaxed) && (opts.episodes == 0 || done < opts.episodes) {
        next += wall_period;
        if let Some(s) = &twist_sub {
            if let Some(m) = drain(s, &mut dropped).last() {
                bridge.on_cmd(m);
            }
        }
        if let Some(s) = &stamped_sub {
            if let Some(m) = drain(s, &mut dropped).last() {
                bridge.on_cmd(&m.twist);
            }
        }
        let episode_error = |e: SimError| BusError::Create { what: "episode".into(), message: e.to_string() };
        let ended = bridge.step().map_err(episode_error)?;
        // The goal is re-sent every second (and at each new episode), so that a node started
        // late, or one that subscribes with volatile durability as RViz's goal does, gets it.
        let goal_due = ended.is_some() || bridge.time() - last_goal >= 1.0;
        if goal_due {
            last_goal = bridge.time();
        }
        if let Some(stats) = ended {
            // The episode's last state first (the robot at the goal, or where it collided), so
            // that a peer watching /odom sees where the episode ended, not only the next start.
            publish(&bridge, false, false);
            done += 1;
            let json = serde_json::to_string(&stats).unwrap_or_default();
            let _ = episode_pub.publish(StringMsg { data: json });
            on_episode(&stats);
            if opts.episodes != 0 && done >= opts.episodes {
                break;
            }
            bridge.next_episode().map_err(episode_error)?;
            publish_map(&bridge);
        }
        publish(&bridge, goal_due, ended.is_some());
        let now = Instant::now();
        if next > now {
            std::thread::sleep(next - now);
        } else {
            // Running behind (a slow machine): do not try to catch up in a burst.
            next = now;
        }
    }
    // RustDDS sends from its own thread: a moment for the last samples (the episode's end) to
    // leave before the process may exit.
    std::thread::sleep(Duration::from_millis(200));
    Ok(())
}
