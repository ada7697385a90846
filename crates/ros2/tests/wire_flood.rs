//! The policy node on the wire under a 1 kHz flood of garbage and good scans from another
//! DDS participant (loopback, its own domain): it keeps ticking, every command it publishes is
//! finite and within the policy's limits, it stops on garbage and drives on good data, and its
//! memory stays flat.

use rlnav_policy::PolicyRunner;
use rlnav_ros2::bus::{Bus, Qos, Reach};
use rlnav_ros2::msg::*;
use rlnav_ros2::node::{NodeParams, NodeState, PolicyNode, run_node};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

const POLICY: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../policies/jetbot-static-mlp.onnx");

fn rss_kib() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    s.lines().find(|l| l.starts_with("VmRSS:"))?.split_whitespace().nth(1)?.parse().ok()
}

fn scan(k: usize) -> LaserScan {
    let inc = std::f32::consts::TAU / 360.0;
    let (len, v) = [(360, 2.5), (0, 1.0), (7, -3.0), (360, f32::NAN), (1000, f32::INFINITY), (360, 2.5)][k % 6];
    LaserScan {
        header: Header::new(Time { sec: (k / 1000) as i32, nanosec: ((k % 1000) * 1_000_000) as u32 }, "laser"),
        angle_min: -std::f32::consts::PI,
        angle_max: -std::f32::consts::PI + inc * 359.0,
        angle_increment: if k % 11 == 0 { 0.0 } else { inc },
        scan_time: 0.1,
        range_min: 0.05,
        range_max: 8.0,
        ranges: vec![v; len],
        ..Default::default()
    }
}

#[test]
fn a_1khz_flood_over_dds_leaves_the_node_running_safely_with_flat_memory() {
    let domain = 71;
    let runner = PolicyRunner::load(std::path::Path::new(POLICY), None).unwrap();
    let params = NodeParams { goal: Some([30.0, 0.0]), ..Default::default() };
    let stop = Arc::new(AtomicBool::new(false));
    let seen: Arc<Mutex<Vec<(f32, f32, bool)>>> = Arc::default();
    let (s2, seen2) = (stop.clone(), seen.clone());
    let node = std::thread::spawn(move || {
        run_node(PolicyNode::new(runner, params), domain, Reach::Localhost, s2, |c, state| {
            seen2.lock().unwrap().push((c.linear, c.angular, *state == NodeState::Driving));
        })
    });
    let mut bus = Bus::new("flood", domain, Reach::Localhost).unwrap();
    let scan_pub = bus.publisher::<LaserScan>("/scan", Qos::SensorData).unwrap();
    let odom_pub = bus.publisher::<Odometry>("/odom", Qos::Default).unwrap();
    let odom = |k: usize| Odometry {
        header: Header::new(Time::default(), "odom"),
        child_frame_id: "base_link".into(),
        // Jumps of up to 16 m between messages.
        pose: PoseWithCovariance { pose: Pose::planar((k % 17) as f64, 0.0, 0.0), ..Default::default() },
        ..Default::default()
    };
    std::thread::sleep(Duration::from_millis(1500));
    let mut rss_after_warmup = None;
    let start = Instant::now();
    let mut k = 0;
    while start.elapsed() < Duration::from_secs(6) {
        let _ = scan_pub.publish(scan(k));
        if k % 10 == 0 {
            let _ = odom_pub.publish(odom(k));
        }
        k += 1;
        if k == 2000 {
            rss_after_warmup = rss_kib();
        }
        let next = start + Duration::from_micros(1000 * k as u64);
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
    // Then good data only: the node drives.
    for j in 0..20 {
        let _ = scan_pub.publish(scan(6 * (k + j)));
        let _ = odom_pub.publish(odom(0));
        std::thread::sleep(Duration::from_millis(50));
    }
    let rss_end = rss_kib();
    stop.store(true, Ordering::Relaxed);
    node.join().unwrap().unwrap();
    let seen = seen.lock().unwrap();
    let driving = seen.iter().filter(|s| s.2).count();
    eprintln!(
        "{k} scans in the flood; {} commands, {driving} while driving; RSS {rss_after_warmup:?} -> {rss_end:?} KiB",
        seen.len()
    );
    assert!(seen.len() >= 60, "the node kept ticking at 10 Hz through the flood: {} commands", seen.len());
    for (v, w, _) in seen.iter() {
        assert!(v.is_finite() && w.is_finite() && v.abs() <= 0.5 && w.abs() <= 0.5, "unsafe command ({v}, {w})");
    }
    assert!(seen.iter().rev().take(5).any(|s| s.2), "drives again once the data is good");
    if let (Some(a), Some(b)) = (rss_after_warmup, rss_end) {
        assert!(b < a + 16 * 1024, "RSS grew from {a} KiB to {b} KiB during the flood ({k} scans)");
    }
}
