//! `rlnav ros2`: the policy node and the simulator bridge (pure Rust ROS 2).

use super::stop_flag;
use anyhow::Result;
use clap::Subcommand;
use rlnav_ros2::bridge::{BridgeOptions, SimBridge, bridge_setup, run_bridge};
use rlnav_ros2::bus::{Reach, domain_from_env};
use rlnav_ros2::node::{NodeParams, PolicyNode, run_node};
use rlnav_ros2::ros_args::RosArgs;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct DdsArgs {
    /// DDS domain (default: ROS_DOMAIN_ID, else 0).
    #[arg(long)]
    domain: Option<u16>,
    /// Talk over loopback only (also set by ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST).
    #[arg(long)]
    localhost: bool,
}

impl DdsArgs {
    fn resolve(&self) -> Result<(u16, Reach)> {
        let domain = match self.domain {
            Some(d) => d,
            None => domain_from_env()?,
        };
        let reach = if self.localhost { Reach::Localhost } else { Reach::from_env() };
        Ok((domain, reach))
    }
}

/// The policy `rlnav ros2 node` runs without `--policy`, built into the binary so that a
/// robot needs no checkout beside it.
const DEFAULT_POLICY: &[u8] = include_bytes!("../../../../policies/default.onnx");
/// Where [`DEFAULT_POLICY`] comes from, for messages.
const DEFAULT_POLICY_NAME: &str = "policies/default.onnx";

#[derive(Subcommand)]
pub enum Command {
    /// Drive a robot with a policy: /scan and /odom (or a pose topic) in, /cmd_vel out, the
    /// goal from --goal, the parameters or /goal_pose; state on /rlnav/status.
    Node {
        /// The policy (ONNX with its contract, e.g. policies/jetbot-static-mlp.onnx); default:
        /// the built-in policies/default.onnx, one policy for the Jetbot, TurtleBot3 Burger and
        /// Waffle and TurtleBot 4 Lite that follows Nav2's plans.
        #[arg(long)]
        policy: Option<PathBuf>,
        /// A side contract for a policy file without one.
        #[arg(long, requires = "policy")]
        contract: Option<PathBuf>,
        /// Parameter YAML (topics, frames, limits, timeouts; flat or ROS 2's
        /// `node: {ros__parameters: ...}`).
        #[arg(long)]
        params: Option<PathBuf>,
        /// Goal X Y in the pose frame (overrides the parameters' goal).
        #[arg(long, num_args = 2, value_names = ["X", "Y"], allow_negative_numbers = true)]
        goal: Option<Vec<f64>>,
        /// Do not serve Nav2's FollowPath action (`follow_path`), which is served by default so
        /// that bt_navigator can drive through the node in controller_server's place (the
        /// parameter `follow_path: false` does the same).
        #[arg(long)]
        no_follow_path: bool,
        #[command(flatten)]
        dds: DdsArgs,
        /// ROS 2 arguments, last, as `ros2 run` and launch files pass them: `-r scan:=/front/scan`,
        /// `-r __ns:=/robot1`, `-r __node:=NAME`, `-p max_linear:=0.2`, `--params-file FILE`,
        /// `--log-level LEVEL`.
        #[arg(long = "ros-args", num_args = 0.., allow_hyphen_values = true, value_name = "ARG")]
        ros_args: Option<Vec<String>>,
    },
    /// Run a scenario as a ROS 2 robot: /scan, /odom, /tf, /tf_static, /clock and /goal_pose
    /// out, /cmd_vel in. Prints each episode's figures as a JSON line.
    Sim {
        /// Scenario: a shipped name or a YAML file.
        #[arg(long, default_value = "static-room")]
        scenario: String,
        /// Robot (default: the scenario's).
        #[arg(long)]
        robot: Option<String>,
        /// Seed of the episodes.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Episodes to run, then exit (0: until Ctrl-C).
        #[arg(long, default_value_t = 0)]
        episodes: usize,
        /// Simulated seconds per second (1: real time).
        #[arg(long, default_value_t = 1.0)]
        rate: f64,
        /// /cmd_vel carries geometry_msgs/TwistStamped.
        #[arg(long)]
        cmd_vel_stamped: bool,
        #[command(flatten)]
        dds: DdsArgs,
    },
}

/// RustDDS and ros2-client report what goes wrong on the wire (a QoS mismatch, a topic whose
/// type differs, discovery trouble) through `log`; without a logger the user sees nothing. Two
/// RustDDS modules are quietened: its writer warns several times a second about normal
/// loopback discovery (errors only), its UDP listener reports leaving multicast groups that
/// loopback never joined at every exit (off).
fn init_logger(level: Option<String>) {
    let default = level.unwrap_or_else(|| "warn".into());
    let filter = format!("{default},rustdds::rtps::writer=error,rustdds::network::udp_listener=off");
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or(filter)).init();
}

pub fn run(command: Command) -> Result<()> {
    match command {
        Command::Node { policy, contract, params, goal, no_follow_path, dds, ros_args } => {
            let ros = RosArgs::parse(&ros_args.unwrap_or_default())?;
            init_logger(ros.log_filter());
            let (domain, reach) = dds.resolve()?;
            let mut p = match &params {
                Some(f) => NodeParams::from_file(f)?,
                None => NodeParams::default(),
            };
            if let Some(g) = goal {
                p.goal = Some([g[0], g[1]]);
            }
            let (mut p, unmatched) = p.with_ros_args(&ros)?;
            if no_follow_path {
                p.follow_path = false;
            }
            for r in unmatched {
                eprintln!("[{}] remapping {r} matches none of the node's topics", p.node());
            }
            let (runner, policy) = match &policy {
                Some(f) => (rlnav_policy::PolicyRunner::load(f, contract.as_deref())?, f.display().to_string()),
                None => (
                    rlnav_policy::PolicyRunner::from_bytes(DEFAULT_POLICY_NAME, DEFAULT_POLICY)?,
                    format!("{DEFAULT_POLICY_NAME} (built in)"),
                ),
            };
            let c = runner.contract();
            let started = format!(
                "rlnav_policy: {} ({} beams over [{:.2}, {:.2}] rad, every {:.3} s) on domain {domain}; {} -> {}",
                policy,
                c.scan.beams,
                c.scan.angle_min,
                c.scan.angle_max,
                c.control_period,
                p.topic(&p.scan_topic),
                p.topic(&p.cmd_vel_topic)
            );
            let serving = p.follow_path.then(|| p.topic(&p.follow_path_action));
            // Refused before anything is said to be running (a policy that needs max_linear).
            let node = PolicyNode::try_new(runner, p)?;
            eprintln!("{started}");
            if let Some(action) = serving {
                eprintln!("rlnav_policy: serving nav2_msgs/action/FollowPath as {action}");
            }
            run_node(node, domain, reach, stop_flag()?, |_, _| {})?;
            Ok(())
        }
        Command::Sim { scenario, robot, seed, episodes, rate, cmd_vel_stamped, dds } => {
            init_logger(None);
            let (domain, reach) = dds.resolve()?;
            anyhow::ensure!(rate.is_finite() && rate > 0.0, "--rate must be positive");
            let setup = bridge_setup(&scenario, robot.as_deref())?;
            let opts = BridgeOptions { seed, episodes, rate, cmd_vel_stamped, ..Default::default() };
            eprintln!(
                "rlnav_sim: {} with {} on domain {domain}, {rate}x real time",
                setup.scenario.spec().name,
                setup.robot.name
            );
            let bridge = SimBridge::new(setup, &opts)?;
            run_bridge(bridge, &opts, domain, reach, stop_flag()?, |stats| {
                println!("{}", serde_json::to_string(stats).unwrap_or_default());
            })?;
            Ok(())
        }
    }
}
