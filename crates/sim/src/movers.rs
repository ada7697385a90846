//! Moving obstacles: boxes and cylinders that travel along waypoints at a set speed, back and
//! forth or in a loop (the article's dynamic scene: boxes moving across the room at
//! 0.1–0.3 m/s). The lidar sees them and touching one is a collision.

use crate::config::{Invalid, check_interval, check_positive};
use crate::geometry::{Pose2, Vec2, closest_approach_time, point_segment_distance};
use crate::lidar::RayGeometry;
use crate::people::social_charge;
use crate::robot::Footprint;
use parry2d::query::intersection_test;
use parry2d::shape::{Ball, Cuboid, SharedShape};
use rand::RngExt;
use serde::{Deserialize, Serialize};

/// A moving obstacle's outline.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum MoverShape {
    /// A cylinder.
    Circle {
        /// Radius (m).
        radius: f32,
    },
    /// A box that keeps its heading along the path's current segment.
    Box {
        /// `[length, width]` (m); length along the direction of travel.
        size: [f32; 2],
    },
}

impl MoverShape {
    /// Radius of the smallest circle around the shape.
    pub fn bound_radius(&self) -> f32 {
        match self {
            MoverShape::Circle { radius } => *radius,
            MoverShape::Box { size } => 0.5 * size[0].hypot(size[1]),
        }
    }

    fn validate(&self) -> Result<(), Invalid> {
        match self {
            MoverShape::Circle { radius } => check_positive("shape.circle.radius", *radius),
            MoverShape::Box { size } => {
                check_positive("shape.box.size[0]", size[0])?;
                check_positive("shape.box.size[1]", size[1])
            }
        }
    }
}

/// How a mover runs along its waypoints.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PathMode {
    /// First to last waypoint and back again.
    #[default]
    BackAndForth,
    /// Around the closed polygon of waypoints.
    Loop,
    /// First to last waypoint once at constant velocity, then standing there (a crossing).
    Once,
    /// First to last waypoint, then from the first again: a stream of constant-velocity
    /// crossings (put the ends outside the room for traffic that comes and goes).
    Repeat,
}

/// A moving obstacle in a scenario file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MoverSpec {
    /// Outline.
    pub shape: MoverShape,
    /// Waypoints `[[x, y], ...]`, at least two.
    pub waypoints: Vec<[f32; 2]>,
    /// Speed range `[min, max]` (m/s), drawn per episode (equal bounds for a fixed speed).
    pub speed: [f32; 2],
    /// Back and forth (default) or loop.
    #[serde(default)]
    pub mode: PathMode,
    /// Start each episode at a random point of the path (default true); otherwise at the first
    /// waypoint.
    #[serde(default = "yes")]
    pub random_phase: bool,
}

fn yes() -> bool {
    true
}

impl MoverSpec {
    /// Checks the values.
    pub fn validate(&self) -> Result<(), Invalid> {
        self.shape.validate()?;
        if self.waypoints.len() < 2 || !self.waypoints.iter().flatten().all(|v| v.is_finite()) {
            return Err(Invalid::new("waypoints", "at least two finite [x, y] points"));
        }
        if self.waypoints.windows(2).all(|w| w[0] == w[1]) {
            return Err(Invalid::new("waypoints", "points that are not all the same"));
        }
        check_interval("speed", self.speed, 0.0, 20.0)
    }

    /// Draws this episode's mover.
    pub fn instantiate<R: rand::Rng>(&self, rng: &mut R) -> Mover {
        let speed =
            if self.speed[1] > self.speed[0] { rng.random_range(self.speed[0]..=self.speed[1]) } else { self.speed[0] };
        let mut points: Vec<Vec2> = self.waypoints.iter().map(|p| Vec2::new(p[0], p[1])).collect();
        if self.mode == PathMode::Loop {
            points.push(points[0]);
        }
        let length: f32 = points.windows(2).map(|w| (w[1] - w[0]).length()).sum();
        let cycle = match self.mode {
            PathMode::Loop | PathMode::Repeat => length,
            PathMode::BackAndForth => 2.0 * length,
            // A crossing starts somewhere along its way, not past its end.
            PathMode::Once => 0.5 * length,
        };
        let phase = if self.random_phase { rng.random_range(0.0..cycle.max(1e-6)) } else { 0.0 };
        Mover {
            shape: self.shape.clone(),
            points,
            length,
            mode: self.mode,
            speed,
            phase,
            pose: Pose2::default(),
            velocity: Vec2::ZERO,
        }
        .at_time(0.0)
    }
}

/// One episode's moving obstacle.
#[derive(Clone, Debug, PartialEq)]
pub struct Mover {
    /// Outline.
    pub shape: MoverShape,
    points: Vec<Vec2>,
    length: f32,
    mode: PathMode,
    /// Speed this episode (m/s).
    pub speed: f32,
    phase: f32,
    /// Current pose (yaw along the direction of travel).
    pub pose: Pose2,
    /// Current velocity (m/s; zero where a `once` path has ended).
    pub velocity: Vec2,
}

impl Mover {
    /// The mover placed where it is `t` seconds into the episode.
    pub fn at_time(mut self, t: f32) -> Self {
        self.set_time(t);
        self
    }

    /// The mover with its phase set so that `t` seconds into the episode it is `along` metres
    /// along its path from the first waypoint, on its way out (`outward`) or, for a
    /// back-and-forth path, on its way back; a `once` path that cannot be there at `t` (it would
    /// have to start before its first waypoint) starts at its first waypoint instead.
    pub fn timed(mut self, along: f32, t: f32, outward: bool) -> Self {
        let along = along.clamp(0.0, self.length);
        self.phase = match self.mode {
            PathMode::BackAndForth => {
                let target = if outward { along } else { 2.0 * self.length - along };
                (target - self.speed * t).rem_euclid((2.0 * self.length).max(1e-6))
            }
            PathMode::Loop | PathMode::Repeat => (along - self.speed * t).rem_euclid(self.length.max(1e-6)),
            PathMode::Once => (along - self.speed * t).max(0.0),
        };
        self.at_time(0.0)
    }

    /// Moves the mover to where it is `t` seconds into the episode.
    pub fn set_time(&mut self, t: f32) {
        let mut s = self.phase + self.speed * t;
        let mut backwards = false;
        let mut moving = true;
        if self.length <= 0.0 {
            s = 0.0;
            moving = false;
        } else if matches!(self.mode, PathMode::Loop | PathMode::Repeat) {
            s = s.rem_euclid(self.length);
        } else if self.mode == PathMode::Once {
            moving = s < self.length;
            s = s.clamp(0.0, self.length);
        } else {
            s = s.rem_euclid(2.0 * self.length);
            if s > self.length {
                s = 2.0 * self.length - s;
                backwards = true;
            }
        }
        let last = self.points.len() - 2;
        for (i, w) in self.points.windows(2).enumerate() {
            let seg = w[1] - w[0];
            let l = seg.length();
            if s <= l || i == last {
                let p = w[0] + seg * (s / l.max(1e-9)).min(1.0);
                let dir = if backwards { -seg } else { seg };
                self.pose = Pose2::new(p.x, p.y, dir.y.atan2(dir.x));
                self.velocity = if moving { dir * (self.speed / l.max(1e-9)) } else { Vec2::ZERO };
                return;
            }
            s -= l;
        }
    }

    /// Box corners (counter-clockwise) or `None` for a circle.
    pub fn corners(&self) -> Option<[Vec2; 4]> {
        match self.shape {
            MoverShape::Circle { .. } => None,
            MoverShape::Box { size } => {
                let (hx, hy) = (size[0] / 2.0, size[1] / 2.0);
                Some([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]].map(|c| self.pose.to_parent(Vec2::new(c[0], c[1]))))
            }
        }
    }

    /// Adds the mover's current outline to a ray geometry.
    pub fn push_to(&self, g: &mut RayGeometry) {
        match (&self.shape, self.corners()) {
            (MoverShape::Circle { radius }, _) => g.push_circle(self.pose.position(), *radius),
            (_, Some(c)) => g.push_polygon(&c),
            _ => {}
        }
    }

    /// Distance from `p` to the mover's surface (negative inside).
    pub fn signed_distance(&self, p: Vec2) -> f32 {
        match (&self.shape, self.corners()) {
            (MoverShape::Circle { radius }, _) => (p - self.pose.position()).length() - radius,
            (_, Some(c)) => {
                let d = (0..4).map(|i| point_segment_distance(p, c[i], c[(i + 1) % 4])).fold(f32::INFINITY, f32::min);
                let inside = (0..4).all(|i| (c[(i + 1) % 4] - c[i]).perp_dot(p - c[i]) >= 0.0);
                if inside { -d } else { d }
            }
            _ => f32::INFINITY,
        }
    }

    /// The mover's share of the social penalty ([`crate::people::social_charge`]) for a robot at
    /// `robot` moving at `robot_velocity`: the gap at the nearest approach of the two centres
    /// within `horizon` seconds if both keep their velocities (0: the gap now).
    pub fn intrusion(&self, robot: Vec2, robot_velocity: Vec2, robot_radius: f32, radius: f32, horizon: f32) -> f32 {
        let t = closest_approach_time(self.pose.position() - robot, self.velocity - robot_velocity, horizon);
        let gap = self.signed_distance(robot + (robot_velocity - self.velocity) * t) - robot_radius;
        social_charge(gap, radius)
    }

    /// Whether the robot's footprint at `pose` touches the mover.
    pub fn touches(&self, footprint: &Footprint, pose: &Pose2) -> bool {
        let reach = footprint.radius() + self.shape.bound_radius();
        if (self.pose.position() - pose.position()).length_squared() > reach * reach {
            return false;
        }
        let d = self.signed_distance(pose.position());
        if d > footprint.radius() {
            return false;
        }
        if footprint.is_disc() {
            return true;
        }
        let shape = match &self.shape {
            MoverShape::Circle { radius } => SharedShape::new(Ball::new(*radius)),
            MoverShape::Box { size } => SharedShape::new(Cuboid::new(Vec2::new(size[0] / 2.0, size[1] / 2.0))),
        };
        intersection_test(&pose.to_parry(), footprint.shape(), &self.pose.to_parry(), shape.as_ref())
            .map_or(true, |hit| hit.intersecting)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn back_and_forth_at_speed() {
        let spec = MoverSpec {
            shape: MoverShape::Box { size: [0.4, 0.2] },
            waypoints: vec![[0.0, 0.0], [2.0, 0.0]],
            speed: [0.5, 0.5],
            mode: PathMode::BackAndForth,
            random_phase: false,
        };
        let mut m = spec.instantiate(&mut rand_pcg::Pcg64Mcg::seed_from_u64(0));
        m.set_time(2.0);
        assert!((m.pose.x - 1.0).abs() < 1e-6 && m.pose.yaw == 0.0);
        m.set_time(6.0); // 3 m travelled: 1 m back from the far end, heading -x
        assert!((m.pose.x - 1.0).abs() < 1e-5 && (m.pose.yaw.abs() - std::f32::consts::PI).abs() < 1e-5);
        assert!((m.velocity - Vec2::new(-0.5, 0.0)).length() < 1e-5, "{:?}", m.velocity);
        m.set_time(8.0);
        assert!(m.pose.x.abs() < 1e-5);
        // The box is seen and touched where it is.
        assert!((m.signed_distance(Vec2::new(0.0, 0.5)) - 0.4).abs() < 1e-5);
        let fp = Footprint::new(&crate::robot::FootprintSpec::Circle { radius: 0.1 }).unwrap();
        assert!(m.touches(&fp, &Pose2::new(0.0, 0.19, 0.0)) && !m.touches(&fp, &Pose2::new(0.0, 0.21, 0.0)));
    }

    /// A timed mover is where it was asked to be at that time, going the way asked, on every
    /// kind of path; a `once` crossing that would have to start before its first waypoint
    /// starts at it.
    #[test]
    fn timed_movers_are_there_on_time() {
        let spec = |mode| MoverSpec {
            shape: MoverShape::Circle { radius: 0.2 },
            waypoints: vec![[0.0, 0.0], [4.0, 0.0]],
            speed: [0.5, 0.5],
            mode,
            random_phase: true,
        };
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(1);
        for mode in [PathMode::BackAndForth, PathMode::Loop, PathMode::Repeat] {
            for (along, t, outward) in [(1.5, 7.3, true), (3.0, 0.0, true), (0.5, 21.0, false), (2.2, 4.0, false)] {
                let mut m = spec(mode).instantiate(&mut rng).timed(along, t, outward);
                m.set_time(t);
                assert!((m.pose.x - along).abs() < 1e-3, "{mode:?} {along} at {t}: {}", m.pose.x);
                // Only a back-and-forth path has a way back (a loop's start is its end).
                let out = outward || mode != PathMode::BackAndForth;
                assert_eq!(m.velocity.x > 0.0, out, "{mode:?} {along} at {t}");
            }
        }
        let mut late = spec(PathMode::Once).instantiate(&mut rng).timed(1.0, 10.0, true);
        assert_eq!(late.pose.x, 0.0, "5 m of travel before 1 m along: it starts at the start");
        late.set_time(10.0);
        assert!((late.pose.x - 4.0).abs() < 1e-5);
        let mut on_time = spec(PathMode::Once).instantiate(&mut rng).timed(3.0, 4.0, true);
        on_time.set_time(4.0);
        assert!((on_time.pose.x - 3.0).abs() < 1e-5);
    }

    #[test]
    fn crossings_at_constant_velocity() {
        let spec = |mode| MoverSpec {
            shape: MoverShape::Circle { radius: 0.2 },
            waypoints: vec![[-5.0, 1.0], [5.0, 1.0]],
            speed: [0.5, 0.5],
            mode,
            random_phase: false,
        };
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(0);
        let mut once = spec(PathMode::Once).instantiate(&mut rng);
        let mut repeat = spec(PathMode::Repeat).instantiate(&mut rng);
        for (t, x_once, x_repeat) in [(4.0, -3.0, -3.0), (19.0, 4.5, 4.5), (25.0, 5.0, -2.5), (100.0, 5.0, -5.0)] {
            once.set_time(t);
            repeat.set_time(t);
            assert!((once.pose.x - x_once).abs() < 1e-4, "once at {t}: {}", once.pose.x);
            assert!((repeat.pose.x - x_repeat).abs() < 1e-4, "repeat at {t}: {}", repeat.pose.x);
            assert_eq!((once.pose.y, once.pose.yaw, repeat.pose.yaw), (1.0, 0.0, 0.0), "always heading +x");
            // A crossing that has ended stands still.
            let v_once = if t < 20.0 { 0.5 } else { 0.0 };
            assert_eq!((once.velocity, repeat.velocity), (Vec2::new(v_once, 0.0), Vec2::new(0.5, 0.0)), "at {t}");
        }
        // A random phase puts a crossing somewhere in its first half.
        let mut r = MoverSpec { random_phase: true, ..spec(PathMode::Once) };
        r.speed = [0.5, 0.5];
        for _ in 0..50 {
            let m = r.instantiate(&mut rng);
            assert!(m.pose.x >= -5.0 && m.pose.x <= 0.0);
        }
    }

    #[test]
    fn loop_and_random_speed() {
        let spec = MoverSpec {
            shape: MoverShape::Circle { radius: 0.2 },
            waypoints: vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]],
            speed: [0.1, 0.3],
            mode: PathMode::Loop,
            random_phase: false,
        };
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(1);
        let speeds: Vec<f32> = (0..200).map(|_| spec.instantiate(&mut rng).speed).collect();
        assert!(speeds.iter().all(|s| (0.1..=0.3).contains(s)));
        let mean = speeds.iter().sum::<f32>() / 200.0;
        assert!((mean - 0.2).abs() < 0.02);
        let mut m = spec.instantiate(&mut rng);
        m.set_time(3.5 / m.speed); // 3.5 m around a 4 m loop: on the last side, heading -y
        assert!((m.pose.x).abs() < 1e-4 && (m.pose.y - 0.5).abs() < 1e-4, "{:?}", m.pose);
    }
}
