//! rlnav's message structs against bytes a real ROS 2 produced (rclpy for Jazzy, Fast CDR;
//! `tools/ros2_golden.py`): the golden bytes decode to the expected message, and rlnav's
//! encoding has the same length and the same bytes everywhere but alignment padding (which
//! Fast CDR leaves uninitialised and rlnav writes as zeros).

use rlnav_ros2::msg::*;
use std::collections::BTreeMap;

const QZ: f64 = 0.24740395925452294;
const QW: f64 = 0.9689124217106447;

fn golden() -> BTreeMap<String, Vec<u8>> {
    let text = include_str!("fixtures/cdr_golden.json");
    let hex: BTreeMap<String, String> = serde_json::from_str(text).unwrap();
    hex.into_iter()
        .map(|(k, v)| (k, (0..v.len()).step_by(2).map(|i| u8::from_str_radix(&v[i..i + 2], 16).unwrap()).collect()))
        .collect()
}

fn check<M: RosMessage + PartialEq + std::fmt::Debug>(expected: M) {
    let golden = golden();
    let bytes = golden.get(&M::type_name()).unwrap_or_else(|| panic!("no golden bytes for {}", M::type_name()));
    let decoded: M = from_cdr(bytes).unwrap();
    assert_eq!(decoded, expected, "{}: golden bytes decode to the expected message", M::type_name());
    let ours = to_cdr(&expected);
    // Fast CDR rounds a message shorter than one 4-byte word up to it (rclpy's `std_msgs/Empty`
    // is its one byte and three of padding); longer ones end where their data ends.
    let padded = if ours.len() < 8 { ours.len().next_multiple_of(4) } else { ours.len() };
    assert_eq!(padded, bytes.len(), "{}: encoded length", M::type_name());
    for (i, (a, b)) in ours.iter().zip(bytes).enumerate() {
        assert!(a == b || *a == 0, "{}: byte {i} is {a:#04x}, ROS 2 wrote {b:#04x}", M::type_name());
    }
}

fn rotated() -> Quaternion {
    Quaternion { z: QZ, w: QW, ..Default::default() }
}

#[test]
fn laser_scan_matches_ros2() {
    check(LaserScan {
        header: Header::new(Time { sec: 12, nanosec: 345 }, "laser"),
        angle_min: -std::f32::consts::PI,
        angle_max: 3.1241393,
        angle_increment: 0.017453292,
        time_increment: 0.0,
        scan_time: 0.1,
        range_min: 0.12,
        range_max: 3.5,
        ranges: vec![1.0, f32::INFINITY, 0.5],
        intensities: vec![],
    });
}

#[test]
fn odometry_matches_ros2() {
    let mut pc = [0.0; 36];
    pc[0] = 0.01;
    pc[35] = 0.05;
    let mut tc = [0.0; 36];
    tc[7] = 0.02;
    check(Odometry {
        header: Header::new(Time { sec: 3, nanosec: 500_000_000 }, "odom"),
        child_frame_id: "base_link".into(),
        pose: PoseWithCovariance {
            pose: Pose { position: Point { x: 1.5, y: -2.25, z: 0.0 }, orientation: rotated() },
            covariance: Covariance(pc),
        },
        twist: TwistWithCovariance { twist: Twist::planar(0.3, -0.4), covariance: Covariance(tc) },
    });
}

#[test]
fn twists_poses_clock_and_string_match_ros2() {
    check(Twist::planar(0.3, -0.4));
    check(TwistStamped {
        header: Header::new(Time { sec: 7, nanosec: 1 }, "base_link"),
        twist: Twist::planar(0.3, -0.4),
    });
    check(PoseStamped {
        header: Header::new(Time::default(), "map"),
        pose: Pose { position: Point { x: 4.0, y: 0.5, z: 0.0 }, orientation: rotated() },
    });
    check(Clock { clock: Time { sec: 42, nanosec: 999_999_999 } });
    check(StringMsg { data: "driving".into() });
}

#[test]
fn marker_array_matches_ros2() {
    let clear = Marker { action: Marker::DELETEALL, ..Default::default() };
    let mut pose = Pose::planar(1.5, -2.0, 0.0);
    pose.position.z = 0.25;
    pose.orientation = rotated();
    let moving_box = Marker {
        header: Header::new(Time { sec: 7, nanosec: 250 }, "odom"),
        ns: "movers".into(),
        id: 3,
        kind: Marker::CUBE,
        action: Marker::ADD,
        pose,
        scale: Vector3 { x: 0.6, y: 0.4, z: 0.5 },
        color: ColorRGBA { r: 0.95, g: 0.5, b: 0.1, a: 1.0 },
        ..Default::default()
    };
    let mut identity = Pose::default();
    identity.orientation.w = 1.0;
    let point = |x: f64, y: f64| Point { x, y, z: 0.0 };
    let wedge = Marker {
        header: Header::new(Time::default(), "odom"),
        ns: "obstacles".into(),
        id: 12,
        kind: Marker::TRIANGLE_LIST,
        pose: identity,
        scale: Vector3 { x: 1.0, y: 1.0, z: 1.0 },
        lifetime: Duration { sec: 2, nanosec: 500 },
        frame_locked: true,
        points: vec![point(0.0, 0.0), point(1.0, 0.0), point(0.0, 2.0)],
        text: "wedge".into(),
        ..Default::default()
    };
    check(MarkerArray { markers: vec![clear, moving_box, wedge] });
}

/// The plan's type, and the one-byte empty structure inside FollowPath's result (which ROS 2
/// pads to 4 bytes).
#[test]
fn path_and_empty_match_ros2() {
    let stamp = Time { sec: 5, nanosec: 25 };
    let pose = |x, y| PoseStamped {
        header: Header::new(stamp, "map"),
        pose: Pose { position: Point { x, y, z: 0.0 }, orientation: rotated() },
    };
    check(Path { header: Header::new(stamp, "map"), poses: vec![pose(0.0, 0.0), pose(1.0, 0.5)] });
    check(Empty::default());
}
