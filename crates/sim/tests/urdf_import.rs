//! `rlnav robot import`: URDFs written for the tests (a TurtleBot3 Burger-like robot, a round
//! robot with unusual but valid conventions) and the errors unusable files give.

use rlnav_sim::robot::FootprintSpec;
use rlnav_sim::urdf::{import_urdf, import_urdf_file};
use rlnav_sim::{Footprint, RobotSpec};
use std::path::Path;

fn path(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/urdf").join(name)
}

#[test]
fn burger_like_urdf_gives_the_burger() {
    let imp = import_urdf_file(&path("burger_like.urdf")).unwrap();
    let r = &imp.robot;
    assert_eq!(r.name, "burger_like");
    assert!((r.wheel_radius - 0.033).abs() < 1e-6);
    assert!((r.wheel_separation - 0.160).abs() < 1e-5, "{}", r.wheel_separation);
    assert!((r.max_wheel_speed - 6.67).abs() < 1e-5);
    assert!((r.max_linear - 0.22).abs() < 0.001, "6.67 rad/s x 0.033 m = 0.22 m/s (the Burger's top speed)");
    // The footprint is the base box, 0.14 m square centred 0.032 m behind base_link.
    let FootprintSpec::Polygon(pts) = &r.footprint else { panic!("{:?}", r.footprint) };
    let (xs, ys): (Vec<f32>, Vec<f32>) = pts.iter().map(|p| (p[0], p[1])).unzip();
    let fold = |v: &[f32], f: fn(f32, f32) -> f32, init| v.iter().copied().fold(init, f);
    assert!((fold(&xs, f32::min, 9.0) + 0.102).abs() < 1e-4 && (fold(&xs, f32::max, -9.0) - 0.038).abs() < 1e-4);
    assert!((fold(&ys, f32::min, 9.0) + 0.07).abs() < 1e-4 && (fold(&ys, f32::max, -9.0) - 0.07).abs() < 1e-4);
    assert_eq!(pts.len(), 4);
    // The lidar: base_scan's pose, and the Gazebo sensor's geometry.
    assert!((r.lidar.mount.x + 0.032).abs() < 1e-6 && r.lidar.mount.y.abs() < 1e-6);
    assert_eq!(r.lidar.beams, 360);
    assert_eq!((r.lidar.range_min, r.lidar.range_max), (0.12, 3.5));
    assert!(r.lidar.is_full_circle() && r.lidar.angle_min == 0.0);
    assert!(imp.found.iter().any(|f| f.contains("wheel_left_joint") && f.contains("wheel_right_joint")));
    assert!(imp.defaults.iter().any(|d| d.contains("acceleration")));
    // The YAML it writes loads back as the same robot.
    let dir = std::env::temp_dir().join(format!("rlnav-urdf-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("burger_like.yaml");
    std::fs::write(&file, imp.to_yaml("burger_like.urdf")).unwrap();
    assert_eq!(&RobotSpec::load(file.to_str().unwrap()).unwrap(), r);
}

#[test]
fn round_robot_with_axis_along_y_and_a_backwards_lidar() {
    let imp = import_urdf_file(&path("round_rotated_lidar.urdf")).unwrap();
    let r = &imp.robot;
    assert!((r.wheel_radius - 0.036).abs() < 1e-6 && (r.wheel_separation - 0.233).abs() < 1e-5);
    assert_eq!(r.footprint, FootprintSpec::Circle { radius: 0.171 });
    assert!(Footprint::new(&r.footprint).unwrap().is_disc());
    assert!((r.lidar.mount.x + 0.04).abs() < 1e-6 && (r.lidar.mount.yaw.abs() - std::f32::consts::PI).abs() < 1e-5);
    // What it did not find, it says.
    let said = imp.defaults.join("\n");
    assert!(said.contains("<limit velocity>") && said.contains("sensor"), "{said}");
    let yaml = imp.to_yaml("round_rotated_lidar.urdf");
    assert!(yaml.contains("# DEFAULT (check it): wheel speed limit"), "{yaml}");
}

#[test]
fn unusable_urdfs_say_why() {
    let e = import_urdf_file(&path("no_wheels.urdf")).unwrap_err().to_string();
    assert!(e.contains("no_wheels.urdf") && e.contains("no pair of drive wheels") && e.contains("shoulder"), "{e}");
    let e = import_urdf("robot.urdf.xacro", "<robot xmlns:xacro=\"http://ros.org/wiki/xacro\"/>").unwrap_err();
    assert!(e.to_string().contains("xacro is out of scope"), "{e}");
    let e = import_urdf("broken.urdf", "<robot name=\"x\"><link name=\"a\">").unwrap_err().to_string();
    assert!(e.contains("broken.urdf") && e.contains("not a valid URDF"), "{e}");
    let e = import_urdf_file(Path::new("missing.urdf")).unwrap_err().to_string();
    assert!(e.contains("missing.urdf") && e.contains("cannot read"), "{e}");
    // One wheel only.
    let one = std::fs::read_to_string(path("burger_like.urdf")).unwrap().replace(
        "type=\"continuous\">\n    <parent link=\"base_link\"/>\n    <child link=\"wheel_right_link\"/>",
        "type=\"fixed\">\n    <parent link=\"base_link\"/>\n    <child link=\"wheel_right_link\"/>",
    );
    let e = import_urdf("one.urdf", &one).unwrap_err().to_string();
    assert!(e.contains("no pair of drive wheels") && e.contains("wheel_left_joint at y = 0.080"), "{e}");
}
