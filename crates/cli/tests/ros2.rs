//! ROS 2 end to end, as separate processes talking DDS: rlnav's policy node drives rlnav's sim
//! bridge to the goal (static scene; a box moving across the path), and peers rlnav did not
//! write (rclpy for ROS 2 Jazzy over Fast DDS, Eclipse Cyclone DDS) talk to both.
//!
//! Traffic stays on loopback: every process is told so (`--localhost`,
//! `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`, a loopback-only Cyclone config), each test has its
//! own ROS_DOMAIN_ID, and where the kernel allows, each test runs in a private network
//! namespace (`unshare -rn`) that has nothing but its own loopback. The peers need a Python
//! with `ros-jazzy-rclpy` and `cyclonedds` (`.ci/run` builds it) named by RLNAV_ROS_PYTHON;
//! without it those tests say so and pass.

use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_rlnav");
const ROOT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../..");

fn private_net_available() -> bool {
    Command::new("unshare").args(["-rn", "true"]).status().is_ok_and(|s| s.success())
}

/// Runs `script` under sh, in a private network namespace when possible, on `domain`.
fn run_script(script: &str, domain: u16) -> (bool, String, String) {
    let script = format!("ip link set lo up 2>/dev/null\n{script}");
    let mut cmd = if private_net_available() {
        let mut c = Command::new("unshare");
        c.args(["-rn", "sh", "-c", &script]);
        c
    } else {
        let mut c = Command::new("sh");
        c.args(["-c", &script]);
        c
    };
    let out = cmd
        .current_dir(ROOT)
        .env("ROS_DOMAIN_ID", domain.to_string())
        .env("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        .output()
        .unwrap();
    (out.status.success(), String::from_utf8_lossy(&out.stdout).into(), String::from_utf8_lossy(&out.stderr).into())
}

const POLICY: &str = "policies/jetbot-static-mlp.onnx";

/// One episode of `scenario` in the sim bridge, driven by the policy node; the episode's
/// figures as the bridge printed them.
fn closed_loop(scenario: &str, seed: u64, domain: u16) -> serde_json::Value {
    let script = format!(
        "timeout 120 '{BIN}' ros2 node --policy {POLICY} --localhost & N=$!\n\
         timeout 100 '{BIN}' ros2 sim --scenario {scenario} --seed {seed} --episodes 1 --localhost; R=$?\n\
         kill -INT $N; wait $N; exit $R"
    );
    let (ok, stdout, stderr) = run_script(&script, domain);
    assert!(ok, "closed loop on {scenario} failed:\n{stdout}\n{stderr}");
    let line =
        stdout.lines().find(|l| l.starts_with('{')).unwrap_or_else(|| panic!("no episode line:\n{stdout}\n{stderr}"));
    let stats: serde_json::Value = serde_json::from_str(line).unwrap();
    assert!(stderr.contains("[rlnav_policy] driving"), "the node logs its state:\n{stderr}");
    stats
}

#[test]
fn node_drives_the_sim_bridge_to_the_goal_of_a_static_scene() {
    let stats = closed_loop("paper-static-1", 0, 61);
    assert_eq!(stats["outcome"], "success", "{stats}");
    assert!(stats["final_distance"].as_f64().unwrap() < 0.3);
}

// The closed loop runs in real time, so its timing (and so the box's position when the robot
// arrives) varies from run to run and machine to machine: the scene is one where the shipped
// policy's outcome does not hinge on that timing. In simulation the policy passed the 0.1 m/s
// box in 200 of 200 seeded episodes, but the 0.2 m/s box in only 89 of 100 (`rlnav eval
// --policy policies/jetbot-static-mlp.onnx --scenario paper-dynamic-box0N --episodes N`), which
// would make a one-episode test fail about one run in ten.
#[test]
fn node_passes_a_box_moving_across_the_path_without_touching_it() {
    let stats = closed_loop("paper-dynamic-box01", 0, 62);
    assert_ne!(stats["outcome"], "collision", "{stats}");
    assert_eq!(stats["outcome"], "success", "{stats}");
}

/// Runs a peer mode of `tools/ros2_interop.py` against rlnav's node or sim bridge.
fn interop(mode: &str, rlnav_args: &str, domain: u16) -> Option<(serde_json::Value, String)> {
    interop_with(mode, &[rlnav_args], domain, 60)
}

/// Runs a peer mode of `tools/ros2_interop.py` for `seconds` against rlnav processes (`ros2
/// ARGS` each: a node, a sim bridge, or both), their output after the peer's.
fn interop_with(mode: &str, rlnav: &[&str], domain: u16, seconds: u32) -> Option<(serde_json::Value, String)> {
    let Ok(python) = std::env::var("RLNAV_ROS_PYTHON") else {
        eprintln!("RLNAV_ROS_PYTHON not set: skipping the {mode} interoperability test (.ci/run sets it)");
        return None;
    };
    let mut start = String::new();
    let mut stop = String::new();
    for (k, rlnav_args) in rlnav.iter().enumerate() {
        // Loopback only; ROS arguments, which take everything after them, come last.
        let rlnav_args = match rlnav_args.split_once(" --ros-args") {
            Some((ours, ros)) => format!("{ours} --localhost --ros-args{ros}"),
            None => format!("{rlnav_args} --localhost"),
        };
        start += &format!("timeout {} '{BIN}' ros2 {rlnav_args} > rlnav{k}.out & N{k}=$!\n", seconds + 30);
        stop += &format!("kill -INT $N{k} 2>/dev/null; wait $N{k}; echo; cat rlnav{k}.out\n");
    }
    let script = format!(
        "{start}timeout {} '{python}' tools/ros2_interop.py {mode} --seconds {seconds}; R=$?\n{stop}exit $R",
        seconds + 20
    );
    // The domain too: two tests may run one peer mode at once (and would share the files).
    let dir = std::env::temp_dir().join(format!(
        "rlnav-interop-{}-{}-{domain}",
        mode.replace([' ', '/'], "_"),
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    let script = format!("cd '{}'\n{}", dir.display(), script.replace("tools/", &format!("{ROOT}/tools/")));
    let (ok, stdout, stderr) = run_script(&script, domain);
    let peer = stdout
        .lines()
        .find(|l| l.contains("\"peer\""))
        .unwrap_or_else(|| panic!("{mode}: no result:\n{stdout}\n{stderr}"));
    let v: serde_json::Value = serde_json::from_str(peer).unwrap();
    assert!(ok && v["ok"] == true, "{mode}: {v}\n{stdout}\n{stderr}");
    std::fs::remove_dir_all(&dir).ok();
    Some((v, stdout))
}

/// The U-shaped dead end over DDS, every part a separate process: rlnav's sim bridge runs
/// `fixtures/u-dead-end.yaml` (a U opening towards the robot, the goal behind it), rlnav's node
/// drives it with the shipped policy and no goal of its own, and rclpy, in the global
/// planner's place, publishes a `nav_msgs/Path` round the U on `/plan` and watches the
/// bridge's `/odom` until the robot is within the goal tolerance of the path's end. The bridge
/// must also count the episode a success (its goal is the path's end), so the robot really
/// arrived in the simulated world.
///
/// The bridge re-sends its scenario goal on `/goal_pose` every second, and a goal replaces a
/// plan in the node; in a Nav2 stack `/goal_pose` is bt_navigator's, not the controller's, so
/// the node's goal topic is moved aside, as it would be there.
#[test]
fn rclpy_plan_round_a_u_shaped_dead_end_brings_the_robot_to_the_goal() {
    let sim = format!("sim --scenario {ROOT}/crates/cli/tests/fixtures/u-dead-end.yaml --episodes 1");
    let node = format!("node --policy {ROOT}/{POLICY} --ros-args -r goal_pose:=/rlnav/unused_goal_pose");
    if let Some((v, stdout)) = interop_with("rclpy-u-plan", &[sim.as_str(), node.as_str()], 70, 90) {
        eprintln!("{v}");
        assert_eq!(v["arrived"], true, "{v}");
        assert!(v["final_distance"].as_f64().unwrap() < 0.3, "{v}");
        // Round the U, never into it.
        assert_eq!(v["inside_u"], 0, "{v}");
        assert!(stdout.contains("\"outcome\":\"success\""), "the bridge's episode: {stdout}");
    }
}

/// The counterfactual: the same scene with only the bridge's goal (on `/goal_pose`, which the
/// node takes), no plan, and the node's own planning on the bridge's `/map` turned off
/// (`map_topic` empty). Steering at the goal, the shipped policy drives into the U and does
/// not arrive (measured 2026-12-03: it hits the U's back wall after 9.1 s, 1.9 m from the goal;
/// `rlnav render --episode` shows the same in-process, a collision after 8.0 s).
#[test]
fn without_a_plan_the_u_shaped_dead_end_traps_the_policy() {
    let sim = format!("sim --scenario {ROOT}/crates/cli/tests/fixtures/u-dead-end.yaml --episodes 1");
    let node = format!("node --policy {ROOT}/{POLICY} --ros-args -p \"map_topic:=''\"");
    if let Some((v, _)) = interop_with("rclpy-u-plan --no-plan", &[sim.as_str(), node.as_str()], 71, 60) {
        eprintln!("{v}");
        assert_eq!(v["arrived"], false, "{v}");
        assert!(v["inside_u"].as_u64().unwrap() > 0, "drove into the U: {v}");
    }
}

/// With no planner but a map: the node takes the bridge's `/map` (transient local, as
/// map_server serves it) and its `map -> odom` on `/tf_static`, plans round the U itself with
/// A* on the inflated map, and follows that plan to the bridge's goal. rclpy only watches.
/// The counterfactual above is the same run with `map_topic` empty: the policy enters the U.
/// Measured 2026-12-03: arrived after 13.0 s, 0.50 m from the U at the closest.
#[test]
fn with_the_bridges_map_the_node_plans_round_the_u_shaped_dead_end() {
    let sim = format!("sim --scenario {ROOT}/crates/cli/tests/fixtures/u-dead-end.yaml --episodes 1");
    let node = format!("node --policy {ROOT}/{POLICY}");
    if let Some((v, stdout)) = interop_with("rclpy-u-plan --no-plan", &[sim.as_str(), node.as_str()], 72, 90) {
        eprintln!("{v}");
        assert_eq!(v["arrived"], true, "{v}\n{stdout}");
        assert_eq!(v["inside_u"], 0, "{v}");
        assert!(stdout.contains("\"outcome\":\"success\""), "the bridge's episode: {stdout}");
    }
}

#[test]
fn rclpy_drives_with_the_node_and_sees_it_in_the_graph() {
    let node = format!("node --policy {ROOT}/{POLICY} --goal 3 0");
    if let Some((v, _)) = interop("rclpy-node", &node, 63) {
        assert_eq!(v["graph"]["cmd_vel_type"][0], "geometry_msgs/msg/Twist");
        assert_eq!(v["graph"]["node"], true);
    }
}

/// A node started without a goal drives once rclpy publishes a `nav_msgs/Path` on `/plan`
/// (Nav2's planner output): the plan crossed the wire and became the goal.
#[test]
fn rclpy_plan_drives_a_node_that_has_no_goal() {
    let node = format!("node --policy {ROOT}/{POLICY}");
    if let Some((v, _)) = interop("rclpy-plan", &node, 67) {
        assert!(v["moving"].as_u64().unwrap() >= 5, "{v}");
        assert_eq!(v["graph"]["plan_type"][0], "nav_msgs/msg/Path");
    }
}

/// `--ros-args -r __ns:=/robot1`, as a launch file starts one of several robots' nodes: the
/// node is on the graph in the namespace, reads `/robot1/scan` and `/robot1/odom` and
/// commands `/robot1/cmd_vel`.
#[test]
fn rclpy_drives_a_namespaced_node() {
    let node = format!("node --policy {ROOT}/{POLICY} --goal 3 0 --ros-args -r __ns:=/robot1");
    if let Some((v, _)) = interop("rclpy-node --ns /robot1", &node, 69) {
        assert_eq!(v["graph"]["cmd_vel_type"][0], "geometry_msgs/msg/Twist");
        assert_eq!(v["graph"]["node"], true);
    }
}

#[test]
fn rclpy_reads_the_sim_bridge_and_drives_it_to_the_goal() {
    if let Some((v, stdout)) = interop("rclpy-sim", "sim --scenario empty-room --seed 3 --episodes 1", 64) {
        assert_eq!(v["beams"], 360);
        assert!(stdout.contains("\"outcome\":\"success\""), "{stdout}");
    }
}

#[test]
fn cyclone_dds_gets_commands_from_the_node() {
    let node = format!("node --policy {ROOT}/{POLICY} --goal 3 0");
    interop("cyclone-node", &node, 65);
}

#[test]
fn cyclone_dds_reads_the_sim_bridge() {
    interop("cyclone-sim", "sim --scenario empty-room --episodes 0", 66);
}

/// What systemd, `docker stop` and a launch file's shutdown send: the node must leave the robot
/// commanded to stop (a zero /cmd_vel) before it exits, as it does on Ctrl-C.
#[test]
fn sigterm_leaves_the_robot_commanded_to_stop() {
    drive_then_sigterm(&["--policy", &format!("{ROOT}/{POLICY}")], 68);
}

/// Without `--policy` the node runs the policy built into the binary (policies/default.onnx):
/// a robot needs no checkout beside the binary.
#[test]
fn the_node_runs_its_built_in_policy_without_a_policy_file() {
    let stderr = drive_then_sigterm(&[], 73);
    assert!(stderr.contains("policies/default.onnx (built in)"), "{stderr}");
}

/// Runs `rlnav ros2 node ARGS --goal 30 0` against an open scan until it drives, sends it
/// SIGTERM and checks that it exits cleanly with a zero /cmd_vel last; returns its stderr.
fn drive_then_sigterm(args: &[&str], domain: u16) -> String {
    use rlnav_ros2::bus::{Bus, Qos, Reach, drain};
    use rlnav_ros2::msg::*;
    use std::time::{Duration, Instant};
    let mut node = Command::new(BIN)
        .args(["ros2", "node"])
        .args(args)
        .args(["--goal", "30", "0", "--localhost"])
        .env("ROS_DOMAIN_ID", domain.to_string())
        .env("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut bus = Bus::new("sigterm_peer", domain, Reach::Localhost).unwrap();
    let scan_pub = bus.publisher::<LaserScan>("/scan", Qos::SensorData).unwrap();
    let odom_pub = bus.publisher::<Odometry>("/odom", Qos::Default).unwrap();
    let cmd_sub = bus.subscription::<Twist>("/cmd_vel", Qos::Default).unwrap();
    let inc = std::f32::consts::TAU / 360.0;
    // An open space all around: the policy drives towards the goal 30 m ahead.
    let scan = LaserScan {
        header: Header::new(Time::default(), "laser"),
        angle_min: -std::f32::consts::PI,
        angle_max: -std::f32::consts::PI + inc * 359.0,
        angle_increment: inc,
        scan_time: 0.1,
        range_min: 0.05,
        range_max: 8.0,
        ranges: vec![2.5; 360],
        ..Default::default()
    };
    let odom = Odometry {
        header: Header::new(Time::default(), "odom"),
        child_frame_id: "base_link".into(),
        pose: PoseWithCovariance { pose: Pose::planar(0.0, 0.0, 0.0), ..Default::default() },
        ..Default::default()
    };
    let (mut dropped, mut moving, mut last, mut signalled) = (0u64, 0, None::<Twist>, None::<Instant>);
    let start = Instant::now();
    loop {
        if start.elapsed() > Duration::from_secs(60) {
            let _ = node.kill();
            let _ = node.wait();
            panic!("the node did not drive or did not exit");
        }
        let _ = scan_pub.publish(scan.clone());
        let _ = odom_pub.publish(odom.clone());
        for c in drain(&cmd_sub, &mut dropped) {
            moving += (c.linear.x != 0.0) as usize;
            last = Some(c);
        }
        if signalled.is_none() && moving >= 5 {
            let pid = node.id().to_string();
            assert!(Command::new("kill").args(["-TERM", &pid]).status().unwrap().success());
            signalled = Some(Instant::now());
        }
        if let Some(t) = signalled {
            // Keep reading for a moment after the exit: the last command may still be in flight.
            if node.try_wait().unwrap().is_some() && t.elapsed() > Duration::from_millis(500) {
                std::thread::sleep(Duration::from_millis(300));
                for c in drain(&cmd_sub, &mut dropped) {
                    last = Some(c);
                }
                break;
            }
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let status = node.wait().unwrap();
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut node.stderr.take().unwrap(), &mut stderr).unwrap();
    assert!(status.success(), "the node exits cleanly on SIGTERM: {status:?}\n{stderr}");
    let last = last.expect("commands received");
    assert_eq!((last.linear.x, last.angular.z), (0.0, 0.0), "last command after SIGTERM: {last:?}\n{stderr}");
    stderr
}
