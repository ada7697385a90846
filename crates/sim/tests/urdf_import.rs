//! `rlnav robot import`: URDFs written for the tests (a TurtleBot3 Burger-like robot, a round
//! robot with unusual but valid conventions) and the errors unusable files give; published
//! descriptions that use xacro (TurtleBot3, TurtleBot 4 on the iRobot Create 3), a xacro file
//! that exercises the language, and, when `RLNAV_XACRO_PYTHON` names a Python with the `xacro`
//! package, the same files expanded by ROS's `xacro` for comparison.

use rlnav_sim::robot::FootprintSpec;
use rlnav_sim::urdf::{UrdfImport, import_description_file, import_urdf, import_urdf_file};
use rlnav_sim::xacro::{PackagePath, XacroOptions, expand_file};
use rlnav_sim::{Footprint, RobotSpec};
use std::f32::consts::{FRAC_PI_2, PI};
use std::path::{Path, PathBuf};

fn path(name: &str) -> PathBuf {
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
    // xacro is expanded first; an empty robot is then refused as any empty URDF is.
    let e = import_urdf("robot.urdf.xacro", "<robot xmlns:xacro=\"http://ros.org/wiki/xacro\"/>").unwrap_err();
    assert!(e.to_string().contains("robot.urdf.xacro: no <link> elements"), "{e}");
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

/// The TurtleBot 4 / Create 3 packages, as `--package-path` gives them.
fn tb4_packages() -> PackagePath {
    PackagePath::new([path("turtlebot4")])
}

fn options(packages: PackagePath, args: &[(&str, &str)]) -> XacroOptions {
    XacroOptions { args: args.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect(), packages }
}

fn import(file: &str, options: &XacroOptions) -> UrdfImport {
    import_description_file(&path(file), options).unwrap_or_else(|e| panic!("{file}: {e}"))
}

/// The extent of a polygon footprint: (min x, max x, min y, max y).
fn extent(r: &RobotSpec) -> (f32, f32, f32, f32) {
    let FootprintSpec::Polygon(pts) = &r.footprint else { panic!("{:?}", r.footprint) };
    pts.iter().fold((f32::MAX, f32::MIN, f32::MAX, f32::MIN), |(a, b, c, d), p| {
        (a.min(p[0]), b.max(p[0]), c.min(p[1]), d.max(p[1]))
    })
}

fn close(a: f32, b: f32) -> bool {
    (a - b).abs() < 1e-5
}

#[test]
fn published_turtlebot3_descriptions_import_with_their_drive_geometry() {
    // ROBOTIS's files as published: `.urdf` files that use xacro:arg and ${namespace}.
    let no_packages = XacroOptions::default();
    let burger = import("turtlebot3/turtlebot3_burger.urdf", &no_packages);
    let r = &burger.robot;
    assert_eq!(r.name, "turtlebot3_burger");
    assert!(close(r.wheel_radius, 0.033) && close(r.wheel_separation, 0.160), "{r:?}");
    // base_link's collision box: 0.140 m square centred 0.032 m behind base_link.
    let (x0, x1, y0, y1) = extent(r);
    assert!(close(x0, -0.102) && close(x1, 0.038) && close(y0, -0.07) && close(y1, 0.07), "{:?}", extent(r));
    assert!(close(r.lidar.mount.x, -0.032) && close(r.lidar.mount.y, 0.0) && close(r.lidar.mount.yaw, 0.0));
    assert!(
        burger.found.iter().any(|f| f.starts_with("xacro expanded (1 file, args namespace:=)")),
        "{:?}",
        burger.found
    );

    for model in ["waffle", "waffle_pi"] {
        let imp = import(&format!("turtlebot3/turtlebot3_{model}.urdf"), &no_packages);
        let r = &imp.robot;
        assert!(close(r.wheel_radius, 0.033) && close(r.wheel_separation, 0.288), "{model}: {r:?}");
        // A 0.266 m square box centred 0.064 m behind base_link; the lidar above that centre.
        let (x0, x1, y0, y1) = extent(r);
        assert!(
            close(x0, -0.197) && close(x1, 0.069) && close(y0, -0.133) && close(y1, 0.133),
            "{model}: {:?}",
            extent(r)
        );
        assert!(close(r.lidar.mount.x, -0.064) && close(r.lidar.mount.y, 0.0), "{model}: {:?}", r.lidar.mount);
    }

    // The namespace argument renames every frame, as `xacro ... namespace:=tb3_` does.
    let named = import("turtlebot3/turtlebot3_burger.urdf", &options(PackagePath::default(), &[("namespace", "tb3_")]));
    assert!(named.found.iter().any(|f| f.contains("robot frame `tb3_base_footprint`")), "{:?}", named.found);
    assert!(named.found.iter().any(|f| f.contains("`tb3_wheel_left_joint` and `tb3_wheel_right_joint`")));
    assert!(close(named.robot.wheel_separation, 0.160));
}

/// `key: value` from the Create 3's diff-drive controller configuration.
fn control_yaml(key: &str) -> f32 {
    let text = std::fs::read_to_string(path("turtlebot4/irobot_create_control/config/control.yaml")).unwrap();
    let line = text.lines().find(|l| l.trim_start().starts_with(&format!("{key}:"))).unwrap();
    line.split_once(':').unwrap().1.trim().parse().unwrap()
}

#[test]
fn turtlebot4_xacro_gives_the_create3_drive_and_the_rplidar_mount() {
    let imp =
        import("turtlebot4/turtlebot4_description/urdf/standard/turtlebot4.urdf.xacro", &options(tb4_packages(), &[]));
    let r = &imp.robot;
    assert_eq!(r.name, "turtlebot4");
    // create3.urdf.xacro: wheels 3.575 cm in radius (wheel.urdf.xacro), 23.3 cm apart
    // (distance_between_wheels); the controller configuration states the same numbers.
    assert!(close(r.wheel_radius, 0.03575) && close(r.wheel_separation, 0.233), "{r:?}");
    assert!(
        close(r.wheel_radius, control_yaml("wheel_radius"))
            && close(r.wheel_separation, control_yaml("wheel_separation"))
    );
    // base_link's collision cylinder: body_radius 16.4 cm, centred.
    assert_eq!(r.footprint, FootprintSpec::Circle { radius: 0.164 });
    // turtlebot4.urdf.xacro: the RPLIDAR on the shell (centred), 4 cm behind, turned by pi/2.
    assert!(
        close(r.lidar.mount.x, -0.04) && close(r.lidar.mount.y, 0.0) && close(r.lidar.mount.yaw, FRAC_PI_2),
        "{:?}",
        r.lidar.mount
    );
    // rplidar.urdf.xacro's ray sensor (not the Create 3's cliff and IR ray sensors).
    assert_eq!(r.lidar.beams, 640);
    assert!(close(r.lidar.angle_min, -PI) && close(r.lidar.angle_max, PI));
    assert_eq!((r.lidar.range_min, r.lidar.range_max), (0.164, 12.0));
    assert!(imp.found.iter().any(|f| f.contains("ray sensor on `rplidar_link`")), "{:?}", imp.found);
    assert!(
        imp.found.iter().any(|f| f.contains("args gazebo:=classic namespace:= visualize_rays:=false")),
        "{:?}",
        imp.found
    );

    // The Lite: the lidar on the base, 0.393584 cm ahead. Gazebo Ignition's sensor reads the same.
    let lite = import(
        "turtlebot4/turtlebot4_description/urdf/lite/turtlebot4.urdf.xacro",
        &options(tb4_packages(), &[("gazebo", "ignition")]),
    );
    let l = &lite.robot;
    assert!(close(l.wheel_radius, 0.03575) && close(l.wheel_separation, 0.233));
    assert!(close(l.lidar.mount.x, 0.00393584) && close(l.lidar.mount.yaw, FRAC_PI_2), "{:?}", l.lidar.mount);
    assert_eq!((l.lidar.beams, l.lidar.range_max), (640, 12.0));

    // Without the package path the first $(find) says what is missing, where.
    let e = import_description_file(
        &path("turtlebot4/turtlebot4_description/urdf/standard/turtlebot4.urdf.xacro"),
        &XacroOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("standard/turtlebot4.urdf.xacro:4: package `irobot_create_description` not found"), "{e}");
}

#[test]
fn xacro_language_features_expand_to_the_intended_robot() {
    let imp = import("xacro/features.urdf.xacro", &XacroOptions::default());
    let r = &imp.robot;
    // wheel_diameter 0.1 / 2; track = base_width 0.30 + wheel_width 0.04.
    assert!(close(r.wheel_radius, 0.05) && close(r.wheel_separation, 0.34), "{r:?}");
    assert!(close(r.max_wheel_speed, 10.0), "limit velocity 0.5 / wheel_radius");
    let (x0, x1, y0, y1) = extent(r);
    assert!(close(x0, -0.25) && close(x1, 0.15) && close(y0, -0.15) && close(y1, 0.15), "{:?}", extent(r));
    assert!(close(r.lidar.mount.x, 0.15) && close(r.lidar.mount.yaw.abs(), PI), "{:?}", r.lidar.mount);
    assert_eq!(r.lidar.beams, 720);
    assert!(close(r.lidar.angle_min, -0.75 * PI) && close(r.lidar.angle_max, 0.75 * PI));
    assert_eq!((r.lidar.range_min, r.lidar.range_max), (0.1, 12.0));
    let x = expand_file(&path("xacro/features.urdf.xacro"), &XacroOptions::default()).unwrap();
    assert!(x.xml.contains("<gazebo reference=\"base_link\">") && x.xml.contains("<casters>1</casters>"), "{}", x.xml);
    assert!(x.xml.contains("<wheels>big 0.05 m</wheels>") && x.xml.contains("${not_evaluated}"), "{}", x.xml);
    assert_eq!(x.files.len(), 2, "the file and its relative include");

    // Arguments: a prefix on every frame, no lidar, bigger wheels.
    let args = options(PackagePath::default(), &[("prefix", "r1_"), ("lidar", "false"), ("wheel_diameter", "0.2")]);
    let imp = import("xacro/features.urdf.xacro", &args);
    assert!(close(imp.robot.wheel_radius, 0.1) && close(imp.robot.wheel_separation, 0.34));
    assert!(imp.found.iter().any(|f| f.contains("`r1_wheel_left_joint`")), "{:?}", imp.found);
    assert!(imp.defaults.iter().any(|d| d.contains("lidar mount [0, 0, 0]")), "{:?}", imp.defaults);
}

#[test]
fn xacro_errors_name_file_line_and_construct() {
    let dir = std::env::temp_dir().join(format!("rlnav-xacro-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let write = |name: &str, text: &str| {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    let head = "<?xml version=\"1.0\"?>\n<robot name=\"r\" xmlns:xacro=\"http://ros.org/wiki/xacro\">\n";
    // An unsupported construct in an included file: that file and line, and where it was included.
    write(
        "inner.xacro",
        &format!("{head}  <link name=\"a\"/>\n  <xacro:include filename=\"x.xacro\" ns=\"x\"/>\n</robot>\n"),
    );
    let outer = write("outer.urdf.xacro", &format!("{head}\n  <xacro:include filename=\"inner.xacro\"/>\n</robot>\n"));
    let e = import_description_file(&outer, &XacroOptions::default()).unwrap_err().to_string();
    let inner = dir.join("inner.xacro").display().to_string();
    assert!(e.starts_with(&format!("{inner}:4: <xacro:include ns=")) && e.contains("not supported"), "{e}");
    assert!(e.contains(&format!("included at {}:4", outer.display())), "{e}");
    // A bad expression inside a macro: the line in the macro, and the call.
    let m = write(
        "macro.urdf.xacro",
        &format!(
            "{head}  <xacro:macro name=\"m\" params=\"r\">\n    <link name=\"${{r % }}\"/>\n  </xacro:macro>\n  <xacro:m r=\"1\"/>\n</robot>\n"
        ),
    );
    let e = import_description_file(&m, &XacroOptions::default()).unwrap_err().to_string();
    assert!(e.starts_with(&format!("{}:4: cannot evaluate `${{r % }}`", m.display())), "{e}");
    assert!(e.contains(&format!("in macro `m` called at {}:6", m.display())), "{e}");
    // Malformed XML.
    let bad = write("bad.xacro", &format!("{head}  <link name=\"a\">\n</robot>\n"));
    let e = import_description_file(&bad, &XacroOptions::default()).unwrap_err().to_string();
    assert!(e.starts_with(&format!("{}:4: not well-formed XML", bad.display())), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A description compared with ROS's xacro: file, `NAME:=VALUE` arguments, and whether it
/// needs the TurtleBot 4 packages.
type ReferenceCase = (&'static str, &'static [(&'static str, &'static str)], bool);

const REFERENCE_CASES: &[ReferenceCase] = &[
    ("turtlebot3/turtlebot3_burger.urdf", &[], false),
    ("turtlebot3/turtlebot3_waffle.urdf", &[("namespace", "tb3_")], false),
    ("turtlebot3/turtlebot3_waffle_pi.urdf", &[], false),
    ("turtlebot4/turtlebot4_description/urdf/standard/turtlebot4.urdf.xacro", &[], true),
    (
        "turtlebot4/turtlebot4_description/urdf/standard/turtlebot4.urdf.xacro",
        &[("gazebo", "ignition"), ("namespace", "/tb4")],
        true,
    ),
    ("turtlebot4/turtlebot4_description/urdf/lite/turtlebot4.urdf.xacro", &[], true),
    ("turtlebot4/irobot_create_description/urdf/create3.urdf.xacro", &[], true),
    ("xacro/features.urdf.xacro", &[], false),
    ("xacro/features.urdf.xacro", &[("prefix", "r1_"), ("lidar", "false"), ("wheel_diameter", "0.2")], false),
];

/// Expands with ROS's xacro (PyPI `xacro`), resolving `$(find)` through ROS_PACKAGE_PATH
/// (the PyPI package resolves it through ament_index, which a plain venv does not have).
const PY_XACRO: &str = r#"
import os, sys, xacro
from xacro import substitution_args

def find(pkg):
    for root in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep):
        for d, dirs, files in os.walk(root):
            if "package.xml" in files:
                text = open(os.path.join(d, "package.xml")).read()
                if "<name>%s</name>" % pkg in text:
                    return d
    raise Exception("package %s not found" % pkg)

substitution_args._eval_find = find
args = dict(a.split(":=", 1) for a in sys.argv[2:])
print(xacro.process_file(sys.argv[1], mappings=args).toxml())
"#;

/// Everything of a URDF model that `robot import` or a simulator reads, as (what, numbers),
/// sorted: links' geometry and inertia, joints' frames, axes and limits.
fn model_summary(xml: &str) -> Vec<(String, Vec<f64>)> {
    let m = urdf_rs::read_from_string(xml).unwrap();
    let geom = |g: &urdf_rs::Geometry| -> (String, Vec<f64>) {
        match g {
            urdf_rs::Geometry::Box { size } => ("box".into(), size.0.to_vec()),
            urdf_rs::Geometry::Cylinder { radius, length } => ("cylinder".into(), vec![*radius, *length]),
            urdf_rs::Geometry::Capsule { radius, length } => ("capsule".into(), vec![*radius, *length]),
            urdf_rs::Geometry::Sphere { radius } => ("sphere".into(), vec![*radius]),
            urdf_rs::Geometry::Mesh { filename, scale } => {
                (format!("mesh {filename}"), scale.as_ref().map(|s| s.0.to_vec()).unwrap_or_default())
            }
        }
    };
    let pose = |p: &urdf_rs::Pose| [p.xyz.0, p.rpy.0].concat();
    let mut out = Vec::new();
    for l in &m.links {
        for (k, c) in l.collision.iter().enumerate() {
            let (kind, n) = geom(&c.geometry);
            out.push((format!("link {} collision {k} {kind}", l.name), [pose(&c.origin), n].concat()));
        }
        for (k, v) in l.visual.iter().enumerate() {
            let (kind, n) = geom(&v.geometry);
            out.push((format!("link {} visual {k} {kind}", l.name), [pose(&v.origin), n].concat()));
        }
        let i = &l.inertial;
        let inertia = [i.inertia.ixx, i.inertia.ixy, i.inertia.ixz, i.inertia.iyy, i.inertia.iyz, i.inertia.izz];
        out.push((
            format!("link {} inertial", l.name),
            [pose(&i.origin), vec![i.mass.value], inertia.to_vec()].concat(),
        ));
    }
    for j in &m.joints {
        let limit = [j.limit.lower, j.limit.upper, j.limit.effort, j.limit.velocity];
        out.push((
            format!("joint {} {:?} {} -> {}", j.name, j.joint_type, j.parent.link, j.child.link),
            [pose(&j.origin), j.axis.xyz.0.to_vec(), limit.to_vec()].concat(),
        ));
    }
    out.sort_by(|a, b| a.0.cmp(&b.0));
    out
}

#[test]
fn expansions_match_ros_xacro() {
    let Ok(python) = std::env::var("RLNAV_XACRO_PYTHON") else {
        eprintln!("RLNAV_XACRO_PYTHON is not set (a python with PyPI `xacro`): comparison with ROS's xacro skipped");
        return;
    };
    for (file, args, with_packages) in REFERENCE_CASES {
        let packages = if *with_packages { tb4_packages() } else { PackagePath::default() };
        let ours = expand_file(&path(file), &options(packages, args)).unwrap_or_else(|e| panic!("{file}: {e}"));
        let mut cmd = std::process::Command::new(&python);
        cmd.arg("-c").arg(PY_XACRO).arg(path(file)).args(args.iter().map(|(k, v)| format!("{k}:={v}")));
        cmd.env("ROS_PACKAGE_PATH", path("turtlebot4"));
        let out = cmd.output().unwrap();
        assert!(out.status.success(), "{file}: ROS xacro failed: {}", String::from_utf8_lossy(&out.stderr));
        let reference = String::from_utf8(out.stdout).unwrap();

        let (a, b) = (model_summary(&ours.xml), model_summary(&reference));
        let keys = |s: &[(String, Vec<f64>)]| s.iter().map(|(k, _)| k.clone()).collect::<Vec<_>>();
        assert_eq!(keys(&a), keys(&b), "{file} {args:?}: links and joints differ");
        for ((k, x), (_, y)) in a.iter().zip(&b) {
            assert_eq!(x.len(), y.len(), "{file}: {k}");
            for (p, q) in x.iter().zip(y) {
                assert!((p - q).abs() <= 1e-12 * p.abs().max(1.0), "{file} {args:?}: {k}: {x:?} vs {y:?}");
            }
        }
        // And the robot imported from each is the same (lidar sensor included).
        let ours_robot = import_urdf("x.urdf", &ours.xml).map(|i| i.robot);
        let ref_robot = import_urdf("x.urdf", &reference).map(|i| i.robot);
        match (ours_robot, ref_robot) {
            (Ok(p), Ok(q)) => assert_eq!(p, q, "{file} {args:?}"),
            (Err(p), Err(q)) => assert_eq!(p.to_string(), q.to_string(), "{file} {args:?}"),
            (p, q) => panic!("{file} {args:?}: {p:?} vs {q:?}"),
        }
        eprintln!("{file} {args:?}: {} links and joints match ROS xacro", a.len());
    }
}
