//! Differential-drive robots: [`RobotSpec`] (YAML presets in `robots/`, embedded) and the
//! [`DiffDrive`] kinematics that move them.

use crate::config::{ConfigError, Invalid, Validate, check_positive, check_range, preset_or_file};
use crate::controller::Twist;
use crate::geometry::{Pose2, Vec2, convex_ccw, wrap_angle};
use crate::lidar::LidarSpec;
use parry2d::shape::{Ball, ConvexPolygon, Shape, SharedShape};
use serde::{Deserialize, Serialize};

/// The robots shipped in `robots/`, embedded in the binary: `(name, yaml)`.
pub const ROBOT_PRESETS: &[(&str, &str)] = &[
    ("jetbot", include_str!("../../../robots/jetbot.yaml")),
    ("turtlebot3-burger", include_str!("../../../robots/turtlebot3-burger.yaml")),
    ("turtlebot3-waffle", include_str!("../../../robots/turtlebot3-waffle.yaml")),
    ("turtlebot4-lite", include_str!("../../../robots/turtlebot4-lite.yaml")),
    ("jackal", include_str!("../../../robots/jackal.yaml")),
];

/// The robot's outline seen from above, in `base_link`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum FootprintSpec {
    /// A disc centred on `base_link`.
    Circle {
        /// Radius (m).
        radius: f32,
    },
    /// A convex polygon `[[x, y], ...]` (m), as Nav2's `footprint` parameter.
    Polygon(Vec<[f32; 2]>),
}

/// A compiled footprint: parry2d shape and circumscribed radius about `base_link`.
#[derive(Clone)]
pub struct Footprint {
    shape: SharedShape,
    radius: f32,
    disc: bool,
}

impl std::fmt::Debug for Footprint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Footprint").field("radius", &self.radius).finish()
    }
}

impl Footprint {
    /// Compiles a spec.
    pub fn new(spec: &FootprintSpec) -> Result<Self, Invalid> {
        match spec {
            FootprintSpec::Circle { radius } => {
                check_positive("circle.radius", *radius)?;
                Ok(Self { shape: SharedShape::new(Ball::new(*radius)), radius: *radius, disc: true })
            }
            FootprintSpec::Polygon(points) => {
                let pts: Vec<Vec2> = points.iter().map(|p| Vec2::new(p[0], p[1])).collect();
                let ccw = convex_ccw(&pts)
                    .filter(|_| pts.iter().all(|p| p.is_finite()))
                    .ok_or_else(|| Invalid::new("polygon", "a convex polygon of at least 3 finite vertices"))?;
                let radius = ccw.iter().map(|p| p.length()).fold(0.0, f32::max);
                let shape = ConvexPolygon::from_convex_polyline(ccw)
                    .ok_or_else(|| Invalid::new("polygon", "a non-degenerate convex polygon"))?;
                Ok(Self { shape: SharedShape::new(shape), radius, disc: false })
            }
        }
    }

    /// The parry2d shape in `base_link`.
    pub fn shape(&self) -> &dyn Shape {
        self.shape.as_ref()
    }

    /// Whether the footprint is a disc centred on `base_link`.
    pub fn is_disc(&self) -> bool {
        self.disc
    }

    /// Circumscribed radius about `base_link` (the robot's reach when it turns in place).
    pub fn radius(&self) -> f32 {
        self.radius
    }
}

/// A differential-drive robot: drive geometry, limits, footprint and lidar.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotSpec {
    /// Preset name.
    pub name: String,
    /// One line on what the robot is and where its numbers come from.
    #[serde(default)]
    pub description: String,
    /// Drive wheel radius (m).
    pub wheel_radius: f32,
    /// Distance between the two drive wheels' contact points (m).
    pub wheel_separation: f32,
    /// Highest wheel angular speed (rad/s); commands are scaled down to respect it,
    /// keeping the path's curvature.
    pub max_wheel_speed: f32,
    /// Forward speed limit (m/s).
    pub max_linear: f32,
    /// Lowest linear speed (m/s); negative allows reversing.
    #[serde(default)]
    pub min_linear: f32,
    /// Angular speed limit, both directions (rad/s).
    pub max_angular: f32,
    /// Linear acceleration limit (m/s²).
    pub max_linear_accel: f32,
    /// Angular acceleration limit (rad/s²).
    pub max_angular_accel: f32,
    /// Outline for collision.
    pub footprint: FootprintSpec,
    /// The 2D lidar.
    pub lidar: LidarSpec,
}

impl Validate for RobotSpec {
    fn validate(&self) -> Result<(), Invalid> {
        if self.name.trim().is_empty() {
            return Err(Invalid::new("name", "a non-empty name"));
        }
        check_range("wheel_radius", self.wheel_radius, 0.005, 2.0)?;
        check_range("wheel_separation", self.wheel_separation, 0.01, 10.0)?;
        check_positive("max_wheel_speed", self.max_wheel_speed)?;
        check_range("max_linear", self.max_linear, 0.01, 20.0)?;
        check_range("min_linear", self.min_linear, -self.max_linear, self.max_linear)?;
        check_range("max_angular", self.max_angular, 0.01, 50.0)?;
        check_positive("max_linear_accel", self.max_linear_accel)?;
        check_positive("max_angular_accel", self.max_angular_accel)?;
        Footprint::new(&self.footprint).map_err(|e| e.under("footprint"))?;
        self.lidar.validate().map_err(|e| e.under("lidar"))
    }
}

impl RobotSpec {
    /// A shipped preset by name, or a YAML file by path.
    pub fn load(name_or_path: &str) -> Result<Self, ConfigError> {
        preset_or_file("robot", ROBOT_PRESETS, name_or_path)
    }

    /// The compiled footprint (the spec is validated on load).
    pub fn footprint(&self) -> Footprint {
        Footprint::new(&self.footprint).expect("validated footprint")
    }
}

/// Drive parameters a [`DiffDrive`] integrates with (a copy, so that per-episode
/// randomisation can perturb them without touching the spec).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DriveParams {
    /// Wheel radius (m).
    pub wheel_radius: f32,
    /// Wheel separation (m).
    pub wheel_separation: f32,
    /// Wheel speed limit (rad/s).
    pub max_wheel_speed: f32,
    /// Linear speed range (m/s).
    pub linear: [f32; 2],
    /// Angular speed limit (rad/s).
    pub max_angular: f32,
    /// Linear acceleration limit (m/s²).
    pub max_linear_accel: f32,
    /// Angular acceleration limit (rad/s²).
    pub max_angular_accel: f32,
}

impl From<&RobotSpec> for DriveParams {
    fn from(s: &RobotSpec) -> Self {
        Self {
            wheel_radius: s.wheel_radius,
            wheel_separation: s.wheel_separation,
            max_wheel_speed: s.max_wheel_speed,
            linear: [s.min_linear, s.max_linear],
            max_angular: s.max_angular,
            max_linear_accel: s.max_linear_accel,
            max_angular_accel: s.max_angular_accel,
        }
    }
}

/// Unicycle kinematics of a differential-drive base: pose and the velocity it is moving at.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DiffDrive {
    /// Drive parameters.
    pub params: DriveParams,
    /// Pose of `base_link` in the world.
    pub pose: Pose2,
    /// Current velocity (what odometry would report).
    pub velocity: Twist,
}

impl DiffDrive {
    /// A robot at rest at `pose`.
    pub fn new(params: DriveParams, pose: Pose2) -> Self {
        Self { params, pose, velocity: Twist::default() }
    }

    /// Wheel angular speeds `(left, right)` (rad/s) for a body twist.
    pub fn wheel_speeds(&self, t: Twist) -> (f32, f32) {
        let p = &self.params;
        let half = 0.5 * p.wheel_separation;
        ((t.linear - t.angular * half) / p.wheel_radius, (t.linear + t.angular * half) / p.wheel_radius)
    }

    /// The velocity the base reaches after one physics step `dt` toward command `cmd`:
    /// clamped to the velocity limits, then to the acceleration limits, then scaled down so
    /// that neither wheel exceeds its speed limit (the curvature `ω / v` is kept).
    pub fn limited_velocity(&self, cmd: Twist, dt: f32) -> Twist {
        let p = &self.params;
        let v_goal = if cmd.linear.is_finite() { cmd.linear.clamp(p.linear[0], p.linear[1]) } else { 0.0 };
        let w_goal = if cmd.angular.is_finite() { cmd.angular.clamp(-p.max_angular, p.max_angular) } else { 0.0 };
        let dv = p.max_linear_accel * dt;
        let dw = p.max_angular_accel * dt;
        let mut v = self.velocity.linear + (v_goal - self.velocity.linear).clamp(-dv, dv);
        let mut w = self.velocity.angular + (w_goal - self.velocity.angular).clamp(-dw, dw);
        let (l, r) = self.wheel_speeds(Twist { linear: v, angular: w });
        let fastest = l.abs().max(r.abs());
        if fastest > p.max_wheel_speed {
            let k = p.max_wheel_speed / fastest;
            v *= k;
            w *= k;
        }
        Twist { linear: v, angular: w }
    }

    /// Advances one physics step of `dt` seconds under command `cmd`, integrating the
    /// unicycle exactly along the circular arc the constant velocity describes.
    pub fn step(&mut self, cmd: Twist, dt: f32) {
        let t = self.limited_velocity(cmd, dt);
        self.pose = integrate_arc(&self.pose, t, dt);
        self.velocity = t;
    }
}

/// Exact pose after moving at constant twist `t` for `dt` seconds from `pose`.
#[inline]
pub fn integrate_arc(pose: &Pose2, t: Twist, dt: f32) -> Pose2 {
    let dth = t.angular * dt;
    // The arc's chord: length v·dt·sin(h)/h (h = dθ/2) along the mid-arc heading. The same
    // displacement as (v/ω)(sin θ1 − sin θ0, cos θ0 − cos θ1), without its cancellation: with
    // a small ω that form multiplies the rounding of a sine difference by a large radius
    // (v = 0.3, ω = 0.0017: the chord came out 2e-5 m longer than the arc).
    let h = 0.5 * dth;
    let sinc = if h.abs() < 1e-4 { 1.0 - h * h / 6.0 } else { h.sin() / h };
    let chord = t.linear * dt * sinc;
    let (sm, cm) = (pose.yaw + h).sin_cos();
    Pose2 { x: pose.x + chord * cm, y: pose.y + chord * sm, yaw: wrap_angle(pose.yaw + dth) }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn presets_load() {
        for (name, _) in ROBOT_PRESETS {
            let r = RobotSpec::load(name).unwrap();
            assert_eq!(&r.name, name);
        }
        let jet = RobotSpec::load("jetbot").unwrap();
        assert_eq!((jet.wheel_radius, jet.wheel_separation), (0.0325, 0.1125));
        let tb4 = RobotSpec::load("turtlebot4-lite").unwrap();
        assert_eq!((tb4.max_linear, tb4.lidar.range_min, tb4.lidar.beams), (0.31, 0.15, 360));
        assert!(matches!(RobotSpec::load("nope"), Err(ConfigError::UnknownPreset { .. })));
    }

    fn jetbot() -> DiffDrive {
        DiffDrive::new(DriveParams::from(&RobotSpec::load("jetbot").unwrap()), Pose2::default())
    }

    #[test]
    fn accelerates_within_limits_and_reaches_command() {
        let mut d = jetbot();
        let a = d.params.max_linear_accel;
        d.step(Twist::new(0.4, 0.0), 0.02);
        assert!((d.velocity.linear - a * 0.02).abs() < 1e-6);
        for _ in 0..100 {
            d.step(Twist::new(0.4, 0.0), 0.02);
        }
        assert!((d.velocity.linear - 0.4).abs() < 1e-6);
        assert!(d.pose.y.abs() < 1e-6 && d.pose.yaw == 0.0);
    }

    #[test]
    fn garbage_commands_stop_the_robot() {
        let mut d = jetbot();
        d.velocity = Twist::new(0.3, 0.2);
        for _ in 0..100 {
            d.step(Twist::new(f32::NAN, f32::INFINITY), 0.02);
        }
        assert_eq!(d.velocity, Twist::new(0.0, 0.0));
    }

    proptest! {
        #[test]
        fn wheel_limits_keep_curvature(v in -1.0f32..1.0, w in -20.0f32..20.0) {
            let mut d = jetbot();
            d.params.max_linear_accel = 1e6;
            d.params.max_angular_accel = 1e6;
            d.params.linear = [-1.0, 1.0];
            d.params.max_angular = 20.0;
            let t = d.limited_velocity(Twist::new(v, w), 0.02);
            let (l, r) = d.wheel_speeds(t);
            prop_assert!(l.abs() <= d.params.max_wheel_speed * 1.0001 && r.abs() <= d.params.max_wheel_speed * 1.0001);
            // Same curvature: v * t.ω == ω * t.v.
            prop_assert!((v * t.angular - w * t.linear).abs() <= 1e-4 * (1.0 + v.abs() * w.abs()));
        }

        #[test]
        fn arc_integration_is_exact(x in -5.0f32..5.0, y in -5.0f32..5.0, yaw in -3.1f32..3.1,
                                    v in -0.5f32..0.5, w in -2.0f32..2.0) {
            let start = Pose2::new(x, y, yaw);
            let t = Twist::new(v, w);
            // Ten small steps land where one big step does (constant twist = one arc).
            let mut p = start;
            for _ in 0..10 { p = integrate_arc(&p, t, 0.01); }
            let q = integrate_arc(&start, t, 0.1);
            prop_assert!((p.x - q.x).abs() < 1e-4 && (p.y - q.y).abs() < 1e-4);
            prop_assert!(wrap_angle(p.yaw - q.yaw).abs() < 1e-4);
            // Distance travelled along the arc is |v| dt; the chord can only be shorter.
            let chord = (q.position() - start.position()).length();
            prop_assert!(chord <= v.abs() * 0.1 + 1e-5);
            // Pure rotation does not move the robot.
            let r = integrate_arc(&start, Twist::new(0.0, w), 0.1);
            prop_assert!((r.position() - start.position()).length() < 1e-6);
        }
    }
}
