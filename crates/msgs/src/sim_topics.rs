//! What a simulated robot publishes each control step, as ROS 2 messages: the scan, the
//! odometry, the transforms and the goal. The sim bridge sends these over DDS and the
//! benchmark writes them to MCAP, so a recording and a live run carry the same bytes.

use crate::msg::{
    self, ColorRGBA, Covariance, Header, LaserScan, MapMetaData, Marker, MarkerArray, OccupancyGrid, Odometry, Pose,
    PoseStamped, PoseWithCovariance, TFMessage, Time, TransformStamped, TwistWithCovariance,
};
use rlnav_sim::geometry::{ObstacleSpec, Primitive};
use rlnav_sim::map::Cell;
use rlnav_sim::movers::MoverShape;
use rlnav_sim::{LidarSpec, NavEnv, Pose2, Twist, Vec2, World};

/// The frame names of REP-105, as a robot's URDF and driver name them.
#[derive(Clone, Debug, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct Frames {
    /// The odometry (world) frame.
    pub odom: String,
    /// The robot body frame.
    pub base: String,
    /// The lidar frame.
    pub laser: String,
}

impl Default for Frames {
    fn default() -> Self {
        Self { odom: "odom".into(), base: "base_link".into(), laser: "laser".into() }
    }
}

/// One control step of a simulated robot, as messages.
#[derive(Clone, Debug, PartialEq)]
pub struct SimMessages {
    /// The stamp every message carries.
    pub stamp: Time,
    /// `/scan`.
    pub scan: LaserScan,
    /// `/odom`.
    pub odom: Odometry,
    /// `/tf`: odom -> base_link and base_link -> laser.
    pub tf: TFMessage,
    /// `/cmd_vel` as applied in the step that led here.
    pub cmd_vel: msg::Twist,
    /// `/goal_pose`.
    pub goal: PoseStamped,
}

/// A `LaserScan` for `ranges` taken by a lidar of `spec` (`+inf` where nothing returned).
pub fn scan_message(spec: &LidarSpec, ranges: &[f32], stamp: Time, frame: &str, scan_time: f32) -> LaserScan {
    let inc = spec.angle_increment();
    LaserScan {
        header: Header::new(stamp, frame),
        angle_min: spec.angle_min,
        angle_max: spec.angle_min + inc * (ranges.len().max(1) - 1) as f32,
        angle_increment: inc,
        time_increment: 0.0,
        scan_time,
        range_min: spec.range_min,
        range_max: spec.range_max,
        ranges: ranges.to_vec(),
        intensities: Vec::new(),
    }
}

/// `nav_msgs/Odometry` for a planar pose and body velocity.
pub fn odometry_message(pose: Pose2, velocity: Twist, stamp: Time, frames: &Frames) -> Odometry {
    // Small, nonzero variances for the planar terms and large ones for the unobserved, as
    // planar robot drivers report them.
    let mut pc = [0.0; 36];
    let mut tc = [0.0; 36];
    for (i, v) in [1e-4, 1e-4, 1e6, 1e6, 1e6, 1e-3].into_iter().enumerate() {
        pc[i * 7] = v;
        tc[i * 7] = v;
    }
    Odometry {
        header: Header::new(stamp, &frames.odom),
        child_frame_id: frames.base.clone(),
        pose: PoseWithCovariance {
            pose: Pose::planar(pose.x as f64, pose.y as f64, pose.yaw as f64),
            covariance: Covariance(pc),
        },
        twist: TwistWithCovariance {
            twist: msg::Twist::planar(velocity.linear as f64, velocity.angular as f64),
            covariance: Covariance(tc),
        },
    }
}

/// The transforms a planar robot broadcasts: odom -> base and base -> laser (its mount).
pub fn tf_message(pose: Pose2, mount: Pose2, stamp: Time, frames: &Frames) -> TFMessage {
    TFMessage {
        transforms: vec![
            TransformStamped::planar(stamp, &frames.odom, &frames.base, pose.x as f64, pose.y as f64, pose.yaw as f64),
            TransformStamped::planar(
                stamp,
                &frames.base,
                &frames.laser,
                mount.x as f64,
                mount.y as f64,
                mount.yaw as f64,
            ),
        ],
    }
}

/// A goal position as `geometry_msgs/PoseStamped` (what RViz2's "2D Goal Pose" sends).
pub fn goal_message(goal: Vec2, stamp: Time, frame: &str) -> PoseStamped {
    PoseStamped { header: Header::new(stamp, frame), pose: Pose::planar(goal.x as f64, goal.y as f64, 0.0) }
}

/// The static world as `nav_msgs/OccupancyGrid` in `frame` (`map`, which the bridge puts at
/// the odometry origin), as `map_server` would serve it. A map scenario's grid is sent as it is
/// (free 0, occupied 100, unknown -1), with any shape obstacles on it drawn in; a world of
/// shapes is drawn at 5 cm over its bounds plus 0.25 m (coarser for worlds over 200 m), a cell
/// occupied when an obstacle comes within its circumscribed circle (so no obstacle is missed).
pub fn map_message(world: &World, stamp: Time, frame: &str) -> OccupancyGrid {
    let (width, height, resolution, origin) = match world.grid() {
        Some(g) => {
            let (w, h) = g.size();
            (w, h, g.resolution(), g.origin())
        }
        None => {
            let b = world.tight_bounds();
            let (min, size) = (b.min - Vec2::splat(0.25), b.size() + Vec2::splat(0.5));
            let resolution = (size.x.max(size.y) / 4000.0).max(0.05);
            let cells = |v: f32| ((v / resolution).ceil() as usize).max(1);
            (cells(size.x), cells(size.y), resolution, Pose2::new(min.x, min.y, 0.0))
        }
    };
    let has_shapes = !world.obstacles().is_empty();
    // Anything within the circumscribed circle may touch the cell.
    let reach = 0.5 * resolution * std::f32::consts::SQRT_2;
    let mut data = Vec::with_capacity(width * height);
    for iy in 0..height {
        for ix in 0..width {
            let centre = origin.to_parent(Vec2::new((ix as f32 + 0.5) * resolution, (iy as f32 + 0.5) * resolution));
            let from_grid = world.grid().map(|g| match g.cell(ix, iy) {
                Cell::Free => 0,
                Cell::Occupied => 100,
                Cell::Unknown => -1,
            });
            let shape_near =
                has_shapes && world.obstacles().iter().any(|o| o.primitive.signed_distance(centre) <= reach);
            data.push(if shape_near { 100 } else { from_grid.unwrap_or(0) });
        }
    }
    OccupancyGrid {
        header: Header::new(stamp, frame),
        info: MapMetaData {
            map_load_time: stamp,
            resolution,
            width: width as u32,
            height: height as u32,
            origin: Pose::planar(origin.x as f64, origin.y as f64, origin.yaw as f64),
        },
        data,
    }
}

/// Marker colours: static obstacles grey, movers orange, people blue, the goal green.
const GREY: ColorRGBA = ColorRGBA { r: 0.55, g: 0.55, b: 0.6, a: 1.0 };
const ORANGE: ColorRGBA = ColorRGBA { r: 0.95, g: 0.5, b: 0.1, a: 1.0 };
const BLUE: ColorRGBA = ColorRGBA { r: 0.2, g: 0.4, b: 0.9, a: 1.0 };
const GREEN: ColorRGBA = ColorRGBA { r: 0.1, g: 0.8, b: 0.3, a: 0.6 };

/// Height drawn for obstacles and movers, and for people (m).
const OBSTACLE_HEIGHT: f64 = 0.5;
const PERSON_HEIGHT: f64 = 1.7;

/// An upright shape standing on the floor at `(x, y)`, turned by `yaw`.
#[allow(clippy::too_many_arguments)]
fn solid(
    header: &Header,
    ns: &str,
    id: usize,
    kind: i32,
    x: f32,
    y: f32,
    yaw: f32,
    size: [f64; 3],
    color: ColorRGBA,
) -> Marker {
    let mut pose = Pose::planar(x as f64, y as f64, yaw as f64);
    pose.position.z = 0.5 * size[2];
    Marker {
        header: header.clone(),
        ns: ns.into(),
        id: id as i32,
        kind,
        action: Marker::ADD,
        pose,
        scale: msg::Vector3 { x: size[0], y: size[1], z: size[2] },
        color,
        ..Default::default()
    }
}

/// The scene as `visualization_msgs/MarkerArray` in `frame` (the odometry frame, in which the
/// world is laid out), for RViz2 and Foxglove: namespace `obstacles` (cylinders, boxes,
/// walls as thin boxes, other polygons as floor triangles), `movers`, `people` (cylinders of
/// their radius) and `goal` (a disc of the goal tolerance). With `clear`, a `DELETEALL`
/// comes first, so that a new episode's world replaces the last one's whole.
pub fn scene_markers(env: &NavEnv, stamp: Time, frame: &str, clear: bool) -> MarkerArray {
    let header = Header::new(stamp, frame);
    let mut markers = Vec::new();
    if clear {
        markers.push(Marker { header: header.clone(), action: Marker::DELETEALL, ..Default::default() });
    }
    let h = OBSTACLE_HEIGHT;
    for (i, o) in env.world().obstacles().iter().enumerate() {
        let m = match &o.primitive {
            Primitive::Circle { center, radius } => {
                let d = 2.0 * *radius as f64;
                solid(&header, "obstacles", i, Marker::CYLINDER, center.x, center.y, 0.0, [d, d, h], GREY)
            }
            Primitive::Segment { a, b } => {
                let (c, e) = ((*a + *b) * 0.5, *b - *a);
                let size = [e.length() as f64, 0.05, h];
                solid(&header, "obstacles", i, Marker::CUBE, c.x, c.y, e.y.atan2(e.x), size, GREY)
            }
            Primitive::Polygon { vertices } if matches!(o.spec, ObstacleSpec::Box { .. }) && vertices.len() == 4 => {
                let c = vertices.iter().fold(Vec2::ZERO, |s, v| s + *v) * 0.25;
                let (e0, e1) = (vertices[1] - vertices[0], vertices[2] - vertices[1]);
                let size = [e0.length() as f64, e1.length() as f64, h];
                solid(&header, "obstacles", i, Marker::CUBE, c.x, c.y, e0.y.atan2(e0.x), size, GREY)
            }
            Primitive::Polygon { vertices } => {
                let mut m = solid(&header, "obstacles", i, Marker::TRIANGLE_LIST, 0.0, 0.0, 0.0, [1.0; 3], GREY);
                m.pose.position.z = 0.0;
                let point = |v: Vec2| msg::Point { x: v.x as f64, y: v.y as f64, z: 0.0 };
                for k in 1..vertices.len().saturating_sub(1) {
                    m.points.extend([point(vertices[0]), point(vertices[k]), point(vertices[k + 1])]);
                }
                m
            }
        };
        markers.push(m);
    }
    for (i, mv) in env.movers().iter().enumerate() {
        let p = mv.pose;
        markers.push(match mv.shape {
            MoverShape::Circle { radius } => {
                let d = 2.0 * radius as f64;
                solid(&header, "movers", i, Marker::CYLINDER, p.x, p.y, 0.0, [d, d, h], ORANGE)
            }
            MoverShape::Box { size } => {
                let s = [size[0] as f64, size[1] as f64, h];
                solid(&header, "movers", i, Marker::CUBE, p.x, p.y, p.yaw, s, ORANGE)
            }
        });
    }
    for (i, person) in env.people().iter().enumerate() {
        let (q, d) = (person.position, 2.0 * person.radius as f64);
        markers.push(solid(&header, "people", i, Marker::CYLINDER, q.x, q.y, 0.0, [d, d, PERSON_HEIGHT], BLUE));
    }
    let (g, d) = (env.goal(), 2.0 * env.setup().task.goal_tolerance as f64);
    markers.push(solid(&header, "goal", 0, Marker::CYLINDER, g.x, g.y, 0.0, [d, d, 0.02], GREEN));
    MarkerArray { markers }
}

impl SimMessages {
    /// The messages for the environment's current state at time `t` (s).
    pub fn of(env: &NavEnv, t: f64, frames: &Frames) -> Self {
        let stamp = Time::from_secs(t);
        let setup = env.setup();
        let spec = setup.lidar.spec();
        let (pose, cmd) = (env.pose(), env.last_command());
        Self {
            stamp,
            scan: scan_message(spec, env.ranges(), stamp, &frames.laser, setup.task.control_period),
            odom: odometry_message(pose, env.velocity(), stamp, frames),
            tf: tf_message(pose, spec.mount, stamp, frames),
            cmd_vel: msg::Twist::planar(cmd.linear as f64, cmd.angular as f64),
            goal: goal_message(env.goal(), stamp, &frames.odom),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    #[test]
    fn the_scene_as_markers() {
        // Walls, boxes and cylinders, a crossing box mover and people: each one marker where
        // the simulator has it.
        let mut seen = [0; 3];
        for name in ["static-room", "random-rooms", "random-dynamic", "paper-dynamic-box01", "people-room"] {
            let setup = rlnav_sim::task::EnvSetup::from_scenario_name(name).unwrap();
            let env = NavEnv::new(Arc::new(setup), 5).unwrap();
            let m = scene_markers(&env, Time::from_secs(1.5), "odom", true);
            assert_eq!(m.markers[0].action, Marker::DELETEALL);
            let count = |ns: &str| m.markers.iter().filter(|k| k.ns == ns).count();
            assert_eq!(count("obstacles"), env.world().obstacles().len(), "{name}");
            assert_eq!(count("movers"), env.movers().len(), "{name}");
            assert_eq!(count("people"), env.people().len(), "{name}");
            assert_eq!(count("goal"), 1);
            for k in &m.markers[1..] {
                assert_eq!((k.header.frame_id.as_str(), k.action), ("odom", Marker::ADD));
                assert!(k.scale.x > 0.0 && k.scale.y > 0.0 && k.scale.z > 0.0, "{name}: {k:?}");
            }
            // Each obstacle's drawn centre is inside or on it.
            for (k, o) in m.markers[1..].iter().zip(env.world().obstacles()) {
                if k.kind != Marker::TRIANGLE_LIST {
                    let c = Vec2::new(k.pose.position.x as f32, k.pose.position.y as f32);
                    assert!(o.primitive.signed_distance(c) <= 1e-3, "{name}: {k:?}");
                }
            }
            for (k, p) in m.markers.iter().filter(|k| k.ns == "people").zip(env.people()) {
                assert!((k.pose.position.x as f32 - p.position.x).abs() < 1e-5);
                assert!((k.scale.x as f32 - 2.0 * p.radius).abs() < 1e-5);
            }
            let g = m.markers.last().unwrap();
            assert!((g.pose.position.x as f32 - env.goal().x).abs() < 1e-5);
            // A step later, without the clear: the same markers less the DELETEALL.
            assert_eq!(scene_markers(&env, Time::from_secs(1.6), "odom", false).markers.len(), m.markers.len() - 1);
            seen[0] += m.markers.iter().filter(|k| k.kind == Marker::CUBE && k.ns == "movers").count();
            seen[1] += count("people");
            seen[2] += m.markers.iter().filter(|k| k.kind == Marker::CUBE && k.ns == "obstacles").count();
        }
        assert!(seen.iter().all(|n| *n > 0), "box movers, people and boxes or walls were all drawn: {seen:?}");
    }

    #[test]
    fn the_world_as_a_map() {
        // Shapes: drawn at 5 cm; the room's walls and a cylinder are there, the start is free.
        let setup = Arc::new(rlnav_sim::task::EnvSetup::from_scenario_name("static-room").unwrap());
        let env = NavEnv::new(setup.clone(), 3).unwrap();
        let m = map_message(env.world(), Time::default(), "map");
        assert_eq!(m.header.frame_id, "map");
        assert_eq!(m.info.resolution, 0.05);
        let (w, h) = (m.info.width as usize, m.info.height as usize);
        assert_eq!(m.data.len(), w * h);
        let at = |p: Vec2| {
            let (ox, oy) = (m.info.origin.position.x as f32, m.info.origin.position.y as f32);
            let (ix, iy) = (((p.x - ox) / 0.05) as usize, ((p.y - oy) / 0.05) as usize);
            m.data[iy * w + ix]
        };
        assert_eq!(at(env.pose().position()), 0, "the robot starts in free space");
        let occupied = m.data.iter().filter(|v| **v == 100).count();
        assert!(occupied > 0 && occupied < w * h / 2, "{occupied} of {}", w * h);
        let wall = env.world().tight_bounds().min + Vec2::splat(0.01);
        assert_eq!(at(wall), 100, "the arena's corner");
        // A map scenario: the grid as it is, unknown cells included.
        let setup = Arc::new(rlnav_sim::task::EnvSetup::from_scenario_name("warehouse").unwrap());
        let env = NavEnv::new(setup, 3).unwrap();
        let g = env.world().grid().unwrap();
        let m = map_message(env.world(), Time::default(), "map");
        assert_eq!((m.info.width as usize, m.info.height as usize), g.size());
        assert_eq!(m.data[0], -1, "outside the building is unknown");
        let expect = |c: Cell| match c {
            Cell::Free => 0,
            Cell::Occupied => 100,
            Cell::Unknown => -1,
        };
        for (i, v) in m.data.iter().enumerate() {
            assert_eq!(*v, expect(g.cell(i % g.size().0, i / g.size().0)), "cell {i}");
        }
    }

    #[test]
    fn messages_describe_the_simulated_robot() {
        let setup = Arc::new(rlnav_sim::task::EnvSetup::from_scenario_name("static-room").unwrap());
        let env = NavEnv::new(setup.clone(), 3).unwrap();
        let m = SimMessages::of(&env, 2.5, &Frames::default());
        let spec = setup.lidar.spec();
        assert_eq!(m.scan.ranges.len(), spec.beams);
        let last = spec.angle_min + spec.angle_increment() * (spec.beams - 1) as f32;
        assert!((m.scan.angle_max - last).abs() < 1e-5, "angle_max is the last beam's angle");
        assert_eq!(m.stamp, Time { sec: 2, nanosec: 500_000_000 });
        let p = env.pose();
        assert!((m.odom.pose.pose.position.x - p.x as f64).abs() < 1e-6);
        assert!((m.odom.pose.pose.orientation.yaw() - p.yaw as f64).abs() < 1e-6);
        assert_eq!(m.tf.transforms[0].child_frame_id, "base_link");
        assert_eq!(m.tf.transforms[1].header.frame_id, "base_link");
        assert_eq!(m.goal.pose.position.x, env.goal().x as f64);
    }
}
