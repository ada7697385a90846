//! Benchmark: the time from a scan being published to the policy node's command for it
//! arriving, over DDS on loopback (both directions of RustDDS, the node's loop and the
//! policy). The node runs with `trigger: scan`; a robot stand-in publishes a 10 Hz scan and
//! odometry and timestamps each `/cmd_vel` it receives against the last scan it sent.
//!
//! With `plan`, the goal comes as a 200-pose plan on `/plan` (plan following on) instead of
//! a fixed goal.
//!
//! cargo run --release -p rlnav-ros2 --example scan_to_cmd_latency -- [POLICY] [SCANS] [plan]

use rlnav_policy::PolicyRunner;
use rlnav_ros2::bus::{Bus, Qos, Reach, drain};
use rlnav_ros2::msg::*;
use rlnav_ros2::node::{NodeParams, PolicyNode, Trigger, run_node};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let policy = args.get(1).map_or("policies/jetbot-static-mlp.onnx", String::as_str);
    let scans: usize = args.get(2).map_or(Ok(200), |s| s.parse())?;
    let with_plan = args.get(3).is_some_and(|a| a == "plan");
    let domain = 77;
    let runner = PolicyRunner::load(std::path::Path::new(policy), None)?;
    let goal = if with_plan { None } else { Some([30.0, 0.0]) };
    // A policy whose speed is a share of the robot's top speed needs one; the contract's robot's
    // stands in (rlnav ros2 node asks for it instead).
    let max_linear = runner
        .needs_top_speed()
        .then(|| rlnav_sim::RobotSpec::load(&runner.contract().robot).map(|r| r.max_linear))
        .transpose()?;
    let params = NodeParams { goal, trigger: Trigger::Scan, max_linear, ..Default::default() };
    let stop = Arc::new(AtomicBool::new(false));
    let node_stop = stop.clone();
    let node = std::thread::spawn(move || {
        run_node(PolicyNode::new(runner, params), domain, Reach::Localhost, node_stop, |_, _| {})
    });

    let mut bus = Bus::new("latency_robot", domain, Reach::Localhost)?;
    let scan_pub = bus.publisher::<LaserScan>("/scan", Qos::SensorData)?;
    let odom_pub = bus.publisher::<Odometry>("/odom", Qos::Default)?;
    let cmd_sub = bus.subscription::<Twist>("/cmd_vel", Qos::Default)?;
    let plan_pub = bus.publisher::<Path>("/plan", Qos::Default)?;
    // A winding 30 m plan of 200 poses, as a planner server sends one.
    let plan = Path {
        header: Header::new(Time::default(), "odom"),
        poses: (0..200)
            .map(|i| {
                let x = i as f64 * 0.15;
                let pose = Pose::planar(x, 0.5 * (x * 0.4).sin(), 0.0);
                PoseStamped { header: Header::new(Time::default(), "odom"), pose }
            })
            .collect(),
    };
    let inc = std::f32::consts::TAU / 360.0;
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
    // Let discovery settle before timing.
    std::thread::sleep(Duration::from_secs(2));
    let mut latencies = Vec::new();
    let mut dropped = 0;
    for k in 0..scans + 20 {
        if with_plan && k % 10 == 0 {
            // Replanned once a second, as Nav2's default behaviour tree does.
            let _ = plan_pub.publish(plan.clone());
        }
        let _ = odom_pub.publish(odom.clone());
        std::thread::sleep(Duration::from_millis(5));
        drain(&cmd_sub, &mut dropped);
        let mut s = scan.clone();
        s.header.stamp = Time { sec: k as i32, nanosec: 0 };
        let sent = Instant::now();
        let _ = scan_pub.publish(s);
        // The answer to this scan: the first command after it, within the period.
        let deadline = sent + Duration::from_millis(90);
        while Instant::now() < deadline {
            if !drain(&cmd_sub, &mut dropped).is_empty() {
                if k >= 20 {
                    latencies.push(sent.elapsed().as_secs_f64() * 1e6);
                }
                break;
            }
            std::hint::spin_loop();
        }
        let next = sent + Duration::from_millis(100);
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
    stop.store(true, Ordering::Relaxed);
    node.join().expect("node thread")?;
    latencies.sort_by(f64::total_cmp);
    let pct = |p: f64| latencies[((latencies.len() - 1) as f64 * p).round() as usize];
    println!(
        "scan -> cmd_vel over DDS loopback, {} of {scans} scans answered: p50 {:.0} µs, p99 {:.0} µs, max {:.0} µs",
        latencies.len(),
        pct(0.5),
        pct(0.99),
        latencies.last().copied().unwrap_or(0.0)
    );
    Ok(())
}
