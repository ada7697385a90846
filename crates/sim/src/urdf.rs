//! Robots from URDF: the two drive wheels (radius and separation), the footprint from the
//! base link's collision geometry, the lidar's mount pose (and its beams and ranges when the
//! file carries a Gazebo ray sensor), and the speed limits the wheel joints state.
//!
//! Parsing is `urdf-rs`'s; this module reads the kinematic tree. It reports what it found and
//! every default it had to use, so that a user knows which numbers to check. A description
//! written in xacro (most robots' are, and TurtleBot3's `.urdf` files use it too) is expanded
//! first by [`crate::xacro`].

use crate::config::Validate;
use crate::geometry::{Pose2, convex_ccw};
use crate::lidar::LidarSpec;
use crate::robot::{FootprintSpec, RobotSpec};
use crate::xacro::{PackagePath, XacroError, XacroOptions};
use glam::{DAffine3, DQuat, DVec3, EulerRot};
use std::collections::HashMap;
use std::f64::consts::PI;
use std::path::Path;
use urdf_rs::{Geometry, JointType};

/// Why a URDF could not become a robot.
#[derive(Debug, thiserror::Error)]
pub enum UrdfError {
    /// The file could not be read.
    #[error("{file}: cannot read: {error}")]
    Io {
        /// The file.
        file: String,
        /// What the OS said (in the message, not chained, so that it is said once).
        error: std::io::Error,
    },
    /// A xacro description that could not be expanded (the message names file and line).
    #[error(transparent)]
    Xacro(#[from] XacroError),
    /// Not valid URDF XML.
    #[error("{file}: not a valid URDF: {message}")]
    Parse {
        /// The file.
        file: String,
        /// The parser's message.
        message: String,
    },
    /// A URDF that does not describe a differential-drive robot rlnav can use.
    #[error("{file}: {message}")]
    Unusable {
        /// The file.
        file: String,
        /// What is missing and what was seen.
        message: String,
    },
}

/// What came out of an import.
#[derive(Clone, Debug)]
pub struct UrdfImport {
    /// The robot, ready to save as YAML.
    pub robot: RobotSpec,
    /// What was read from the file (one line each).
    pub found: Vec<String>,
    /// What the file did not say and which default was used (one line each).
    pub defaults: Vec<String>,
}

impl UrdfImport {
    /// The robot as a YAML file, with what was found and defaulted as comments on top.
    pub fn to_yaml(&self, source: &str) -> String {
        let mut s = format!("# Imported from {source} by `rlnav robot import`.\n");
        for f in &self.found {
            s += &format!("# found: {f}\n");
        }
        for d in &self.defaults {
            s += &format!("# DEFAULT (check it): {d}\n");
        }
        s + &crate::config::to_yaml_string(&self.robot)
    }
}

/// A URDF origin as a rigid transform: translation `xyz`, then fixed-axis roll, pitch, yaw
/// (R = Rz(yaw) Ry(pitch) Rx(roll)).
fn origin_tf(p: &urdf_rs::Pose) -> DAffine3 {
    let [roll, pitch, yaw] = p.rpy.0;
    DAffine3::from_rotation_translation(DQuat::from_euler(EulerRot::ZYX, yaw, pitch, roll), DVec3::from(p.xyz.0))
}

/// Planar yaw of a frame's x axis.
fn yaw_of(t: &DAffine3) -> f64 {
    let x = t.matrix3.x_axis;
    x.y.atan2(x.x)
}

/// Link names that mark a lidar, most specific first.
const LIDAR_NAMES: &[&str] = &["lidar", "laser", "scan", "hokuyo", "rplidar", "lds", "velodyne", "sick"];

/// Reads a URDF or xacro file. xacro is expanded without arguments, finding packages
/// through `ROS_PACKAGE_PATH` and `AMENT_PREFIX_PATH`; [`import_description_file`] takes
/// arguments and search folders.
pub fn import_urdf_file(path: &Path) -> Result<UrdfImport, UrdfError> {
    let options = XacroOptions { packages: PackagePath::default().with_environment(), ..XacroOptions::default() };
    import_description_file(path, &options)
}

/// Reads a URDF or xacro file, expanding xacro with `options` (arguments, package search path).
pub fn import_description_file(path: &Path, options: &XacroOptions) -> Result<UrdfImport, UrdfError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|error| UrdfError::Io { file: file.clone(), error })?;
    import_description(&file, &text, options)
}

/// Reads URDF or xacro text (`file` names it in messages; relative xacro includes start from
/// its folder). xacro is expanded without arguments and without a package search path.
pub fn import_urdf(file: &str, text: &str) -> Result<UrdfImport, UrdfError> {
    import_description(file, text, &XacroOptions::default())
}

/// Reads URDF or xacro text, expanding xacro with `options`.
pub fn import_description(file: &str, text: &str, options: &XacroOptions) -> Result<UrdfImport, UrdfError> {
    if !crate::xacro::is_xacro(file, text) {
        return import_plain(file, text, Vec::new(), Vec::new());
    }
    let x = crate::xacro::expand_str(file, text, options)?;
    let found = vec![format!(
        "xacro expanded ({} file{}{})",
        x.files.len(),
        if x.files.len() == 1 { "" } else { "s" },
        if x.args.is_empty() {
            String::new()
        } else {
            format!(", args {}", x.args.iter().map(|(k, v)| format!("{k}:={v}")).collect::<Vec<_>>().join(" "))
        }
    )];
    let mut defaults = Vec::new();
    if !x.unused_args.is_empty() {
        defaults.push(format!(
            "argument(s) {} given but not used: the description declares no such <xacro:arg>",
            x.unused_args.join(", ")
        ));
    }
    import_plain(file, &x.xml, found, defaults)
}

/// Reads plain URDF text; `found` and `defaults` start with what came before (the expansion).
fn import_plain(
    file: &str,
    text: &str,
    mut found: Vec<String>,
    mut defaults: Vec<String>,
) -> Result<UrdfImport, UrdfError> {
    let model =
        urdf_rs::read_from_string(text).map_err(|e| UrdfError::Parse { file: file.into(), message: e.to_string() })?;
    let unusable = |message: String| UrdfError::Unusable { file: file.to_string(), message };
    if model.links.is_empty() {
        return Err(unusable("no <link> elements".into()));
    }

    // The tree: each link's pose in the root link's frame.
    let parent_of: HashMap<&str, &urdf_rs::Joint> = model.joints.iter().map(|j| (j.child.link.as_str(), j)).collect();
    let root = model
        .links
        .iter()
        .find(|l| !parent_of.contains_key(l.name.as_str()))
        .ok_or_else(|| unusable("no root link (every link is some joint's child)".into()))?;
    let mut in_root: HashMap<&str, DAffine3> = HashMap::new();
    in_root.insert(root.name.as_str(), DAffine3::IDENTITY);
    // Joints may come in any order; resolve until nothing changes.
    for _ in 0..model.joints.len() + 1 {
        let mut changed = false;
        for j in &model.joints {
            if in_root.contains_key(j.child.link.as_str()) {
                continue;
            }
            if let Some(p) = in_root.get(j.parent.link.as_str()).copied() {
                in_root.insert(j.child.link.as_str(), p * origin_tf(&j.origin));
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    // base_link is the robot frame by ROS convention (REP-105); otherwise the root.
    let base_name = if in_root.contains_key("base_link") { "base_link" } else { root.name.as_str() };
    let base_inv = in_root[base_name].inverse();
    let pose_in_base = |link: &str| in_root.get(link).map(|t| base_inv * *t);
    found.push(format!("robot frame `{base_name}` (root link `{}`)", root.name));

    // Drive wheels: continuous joints (or revolute without limits) turning about the lateral
    // axis, whose child link is a cylinder.
    let link = |name: &str| model.links.iter().find(|l| l.name == name);
    let mut continuous = Vec::new();
    let mut wheels = Vec::new();
    for j in &model.joints {
        let spins = j.joint_type == JointType::Continuous
            || (j.joint_type == JointType::Revolute && !(j.limit.upper - j.limit.lower).is_finite());
        if !spins {
            continue;
        }
        continuous.push(j.name.clone());
        let Some(tf) = pose_in_base(&j.child.link) else { continue };
        let axis = tf.transform_vector3(DVec3::from(j.axis.xyz.0)).normalize_or(DVec3::X);
        let geometry = link(&j.child.link).and_then(|l| {
            l.collision
                .iter()
                .map(|c| &c.geometry)
                .chain(l.visual.iter().map(|v| &v.geometry))
                .find_map(|g| if let Geometry::Cylinder { radius, .. } = g { Some(*radius) } else { None })
        });
        match geometry {
            Some(radius) if axis.y.abs() > 0.9 => wheels.push((j, tf.translation, radius)),
            _ => {}
        }
    }
    let left: Vec<_> = wheels.iter().filter(|w| w.1[1] > 1e-3).collect();
    let right: Vec<_> = wheels.iter().filter(|w| w.1[1] < -1e-3).collect();
    if left.is_empty() || right.is_empty() {
        return Err(unusable(format!(
            "no pair of drive wheels: expected two continuous joints turning about the robot's \
             lateral (y) axis, with cylinder geometry, one left and one right of `{base_name}`; \
             continuous joints seen: [{}], of which wheels: [{}]",
            continuous.join(", "),
            wheels.iter().map(|w| format!("{} at y = {:.3}", w.0.name, w.1[1])).collect::<Vec<_>>().join(", ")
        )));
    }
    // The pair on the most common axle: for each left wheel, the right wheel closest in x.
    let (l, r) = left
        .iter()
        .flat_map(|l| right.iter().map(move |r| (*l, *r)))
        .min_by(|a, b| (a.0.1[0] - a.1.1[0]).abs().total_cmp(&(b.0.1[0] - b.1.1[0]).abs()))
        .expect("both sides are non-empty");
    let wheel_radius = 0.5 * (l.2 + r.2);
    let wheel_separation = l.1[1] - r.1[1];
    found.push(format!(
        "drive wheels `{}` and `{}`: radius {wheel_radius:.4} m, separation {wheel_separation:.4} m",
        l.0.name, r.0.name
    ));
    if left.len() + right.len() > 2 {
        found.push(format!(
            "{} wheels in all: treated as skid steer with the track of the nearest left/right pair",
            left.len() + right.len()
        ));
    }

    // Speed limits from the wheel joints' <limit velocity>.
    let velocity = [l.0.limit.velocity, r.0.limit.velocity];
    let max_wheel_speed = if velocity.iter().all(|v| v.is_finite() && *v > 0.0) {
        let v = velocity[0].min(velocity[1]);
        found.push(format!("wheel speed limit {v:.3} rad/s (joint <limit velocity>)"));
        v
    } else {
        let v = 0.5 / wheel_radius;
        defaults.push(format!(
            "wheel speed limit {v:.3} rad/s (0.5 m/s at the wheel): the wheel joints give no <limit velocity>"
        ));
        v
    };
    let max_linear = max_wheel_speed * wheel_radius;
    let max_angular = 2.0 * max_linear / wheel_separation;
    defaults.push("accelerations 1.0 m/s² and 3.0 rad/s² (URDF has no acceleration limits)".into());

    // Footprint: the base link's collision shapes, or, failing that, those of links fixed to it.
    let mut outline: Vec<[f64; 2]> = Vec::new();
    let mut used = Vec::new();
    let fixed_to_base: Vec<&str> = model
        .joints
        .iter()
        .filter(|j| j.joint_type == JointType::Fixed && j.parent.link == base_name)
        .map(|j| j.child.link.as_str())
        .filter(|c| !LIDAR_NAMES.iter().any(|n| c.to_lowercase().contains(n)))
        .collect();
    for candidates in [vec![base_name], fixed_to_base, vec![root.name.as_str()]] {
        for name in candidates {
            let (Some(l), Some(tf)) = (link(name), pose_in_base(name)) else { continue };
            for c in &l.collision {
                let t = tf * origin_tf(&c.origin);
                let pts = shape_outline(&c.geometry, &t);
                if !pts.is_empty() {
                    outline.extend(pts);
                    used.push(name.to_string());
                }
            }
        }
        if !outline.is_empty() {
            break;
        }
    }
    used.dedup();
    let footprint = if outline.is_empty() {
        // The wheels' extent: a rectangle around both wheels.
        let half_w = 0.5 * wheel_separation + 0.02;
        let half_l = wheel_radius.max(0.05);
        defaults.push(format!(
            "footprint {:.3} x {:.3} m around the wheels: `{base_name}` has no box, cylinder or \
             sphere collision geometry (meshes are not read)",
            2.0 * half_l,
            2.0 * half_w
        ));
        rect(half_l, half_w)
    } else {
        let fp = footprint_from(&outline);
        found.push(format!("footprint from the collision geometry of {}", used.join(", ")));
        fp
    };

    // Lidar: a link named like one; beams and ranges from a Gazebo ray sensor if present.
    let lidar_link = LIDAR_NAMES.iter().find_map(|n| {
        model.links.iter().find(|l| l.name.to_lowercase().contains(n) && pose_in_base(&l.name).is_some())
    });
    let mut lidar = LidarSpec::default();
    match lidar_link {
        Some(l) => {
            let t = pose_in_base(&l.name).expect("checked above");
            lidar.mount = Pose2::new(t.translation.x as f32, t.translation.y as f32, yaw_of(&t) as f32);
            found.push(format!(
                "lidar link `{}` at [{:.3}, {:.3}, {:.3}] in `{base_name}`",
                l.name, lidar.mount.x, lidar.mount.y, lidar.mount.yaw
            ));
        }
        None => {
            defaults.push(format!("lidar mount [0, 0, 0]: no link named like a lidar ({})", LIDAR_NAMES.join(", ")))
        }
    }
    let sensors = gazebo_ray_sensors(text);
    // The lidar link's sensor; a single ray sensor anywhere is taken as the lidar's too.
    let sensor = match lidar_link {
        Some(l) => sensors.iter().find(|s| s.reference.as_deref() == Some(l.name.as_str())),
        None => None,
    }
    .or(if sensors.len() == 1 { sensors.first() } else { None });
    match sensor {
        Some(s) => {
            found.push(format!(
                "Gazebo ray sensor{}: {} beams over [{:.4}, {:.4}] rad, {}-{} m",
                s.reference.as_ref().map(|r| format!(" on `{r}`")).unwrap_or_default(),
                s.beams,
                s.angle_min,
                s.angle_max,
                s.range_min,
                s.range_max
            ));
            lidar.beams = s.beams;
            lidar.angle_min = s.angle_min;
            lidar.angle_max = s.angle_max;
            lidar.range_min = s.range_min;
            lidar.range_max = s.range_max;
        }
        None => defaults.push(format!(
            "lidar of {} beams over 360°, {}-{} m: {}",
            lidar.beams,
            lidar.range_min,
            lidar.range_max,
            if sensors.is_empty() {
                "no Gazebo <sensor type=\"ray\"> in the file".to_string()
            } else {
                format!(
                    "none of the {} Gazebo ray sensors is on the lidar link (they are on {})",
                    sensors.len(),
                    sensors.iter().map(|s| s.reference.as_deref().unwrap_or("no link")).collect::<Vec<_>>().join(", ")
                )
            }
        )),
    }

    let name = if model.name.trim().is_empty() { "imported".to_string() } else { model.name.clone() };
    let robot = RobotSpec {
        description: format!(
            "imported from {}",
            Path::new(file).file_name().map_or(file.into(), |f| f.to_string_lossy())
        ),
        name,
        wheel_radius: wheel_radius as f32,
        wheel_separation: wheel_separation as f32,
        max_wheel_speed: max_wheel_speed as f32,
        max_linear: max_linear as f32,
        min_linear: -(max_linear as f32),
        max_angular: max_angular as f32,
        max_linear_accel: 1.0,
        max_angular_accel: 3.0,
        footprint,
        lidar,
    };
    robot
        .validate()
        .map_err(|e| unusable(format!("the robot read from it is invalid: `{}`: {}", e.key, e.expected)))?;
    Ok(UrdfImport { robot, found, defaults })
}

/// The outline of a collision shape seen from above (points in the base frame).
fn shape_outline(g: &Geometry, t: &DAffine3) -> Vec<[f64; 2]> {
    let corners = |hx: f64, hy: f64, hz: f64| {
        let mut v = Vec::new();
        for sx in [-1.0, 1.0] {
            for sy in [-1.0, 1.0] {
                for sz in [-1.0, 1.0] {
                    let p = t.transform_point3(DVec3::new(sx * hx, sy * hy, sz * hz));
                    v.push([p[0], p[1]]);
                }
            }
        }
        v
    };
    match g {
        Geometry::Box { size } => corners(size[0] / 2.0, size[1] / 2.0, size[2] / 2.0),
        Geometry::Cylinder { radius, length } | Geometry::Capsule { radius, length } => {
            // A cylinder's axis is its frame's z: sample both end circles.
            let mut v = Vec::new();
            for k in 0..32 {
                let a = k as f64 * 2.0 * PI / 32.0;
                for z in [-length / 2.0, length / 2.0] {
                    let p = t.transform_point3(DVec3::new(radius * a.cos(), radius * a.sin(), z));
                    v.push([p[0], p[1]]);
                }
            }
            v
        }
        Geometry::Sphere { radius } => (0..32)
            .map(|k| k as f64 * 2.0 * PI / 32.0)
            .map(|a| [t.translation.x + radius * a.cos(), t.translation.y + radius * a.sin()])
            .collect(),
        Geometry::Mesh { .. } => Vec::new(),
    }
}

fn rect(hx: f64, hy: f64) -> FootprintSpec {
    FootprintSpec::Polygon(vec![
        [-hx as f32, -hy as f32],
        [hx as f32, -hy as f32],
        [hx as f32, hy as f32],
        [-hx as f32, hy as f32],
    ])
}

/// A circle when the outline is round and centred on the robot frame, else its convex hull.
fn footprint_from(points: &[[f64; 2]]) -> FootprintSpec {
    let radii: Vec<f64> = points.iter().map(|p| p[0].hypot(p[1])).collect();
    let (lo, hi) = radii.iter().fold((f64::INFINITY, 0.0f64), |(a, b), r| (a.min(*r), b.max(*r)));
    if hi > 0.0 && (hi - lo) / hi < 0.02 {
        return FootprintSpec::Circle { radius: hi as f32 };
    }
    let pts: Vec<crate::geometry::Vec2> =
        points.iter().map(|p| crate::geometry::Vec2::new(p[0] as f32, p[1] as f32)).collect();
    match convex_ccw(&parry2d::transformation::convex_hull(&pts)) {
        Some(ccw) => FootprintSpec::Polygon(ccw.iter().map(|v| [v.x, v.y]).collect()),
        None => FootprintSpec::Circle { radius: hi as f32 },
    }
}

/// A Gazebo ray sensor's scan geometry, and the link its `<gazebo reference>` names.
#[derive(Debug, PartialEq)]
struct RaySensor {
    reference: Option<String>,
    beams: usize,
    angle_min: f32,
    angle_max: f32,
    range_min: f32,
    range_max: f32,
}

/// Every complete `<sensor type="ray|gpu_ray|lidar|gpu_lidar">` in `<gazebo>` blocks (which
/// urdf-rs skips), reading `scan/horizontal/{samples,min_angle,max_angle}` and `range/{min,max}`.
fn gazebo_ray_sensors(text: &str) -> Vec<RaySensor> {
    use quick_xml::events::Event;
    let mut reader = quick_xml::Reader::from_str(text);
    let mut path: Vec<String> = Vec::new();
    // The `reference` of each open `<gazebo>`, innermost last.
    let mut references: Vec<Option<String>> = Vec::new();
    let mut values: Option<HashMap<String, f32>> = None;
    let mut out = Vec::new();
    let attr = |e: &quick_xml::events::BytesStart, name: &[u8]| {
        e.attributes()
            .flatten()
            .find(|a| a.key.local_name().as_ref() == name)
            .map(|a| String::from_utf8_lossy(&a.value).into_owned())
    };
    // A malformed file simply ends the search (urdf-rs has already read it).
    while let Ok(event) = reader.read_event() {
        match event {
            Event::Start(e) => {
                let name = String::from_utf8_lossy(e.local_name().as_ref()).into_owned();
                if name == "gazebo" {
                    references.push(attr(&e, b"reference"));
                } else if name == "sensor"
                    && matches!(attr(&e, b"type").as_deref(), Some("ray" | "gpu_ray" | "lidar" | "gpu_lidar"))
                {
                    values = Some(HashMap::new());
                }
                path.push(name);
            }
            Event::End(_) => match path.pop().as_deref() {
                Some("gazebo") => {
                    references.pop();
                }
                Some("sensor") => {
                    if let Some(v) = values.take() {
                        let get = |k: &str| v.get(k).copied();
                        let sensor = (|| {
                            Some(RaySensor {
                                reference: references.last().cloned().flatten(),
                                beams: get("horizontal/samples")? as usize,
                                angle_min: get("horizontal/min_angle")?,
                                angle_max: get("horizontal/max_angle")?,
                                range_min: get("range/min")?,
                                range_max: get("range/max")?,
                            })
                        })();
                        out.extend(sensor);
                    }
                }
                _ => {}
            },
            Event::Text(t) => {
                let n = path.len();
                if let (Some(v), true) = (values.as_mut(), n >= 2) {
                    let key = format!("{}/{}", path[n - 2], path[n - 1]);
                    if let Ok(x) = String::from_utf8_lossy(t.as_ref()).trim().parse::<f32>() {
                        v.entry(key).or_insert(x);
                    }
                }
            }
            Event::Eof => break,
            _ => {}
        }
    }
    out
}
