//! What a simulated robot publishes each control step, as ROS 2 messages: the scan, the
//! odometry, the transforms and the goal. The sim bridge sends these over DDS and the
//! benchmark writes them to MCAP, so a recording and a live run carry the same bytes.

use crate::msg::{
    self, Covariance, Header, LaserScan, MapMetaData, OccupancyGrid, Odometry, Pose, PoseStamped, PoseWithCovariance,
    TFMessage, Time, TransformStamped, TwistWithCovariance,
};
use rlnav_sim::map::Cell;
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
