//! Poses, angles and the obstacle shapes worlds are made of.
//!
//! Shapes are stored twice: as parry2d shapes (collision queries, the reference ray caster)
//! and as flat primitives (circles and segments) that the lidar's hot loop reads.

use crate::config::{Invalid, check_positive};
use parry2d::math::Pose;
use parry2d::shape::{Ball, ConvexPolygon, Cuboid, Segment, SharedShape};
use serde::{Deserialize, Serialize};
use std::f32::consts::{PI, TAU};

/// 2D vector (glam's, as parry2d uses it).
pub type Vec2 = parry2d::math::Vector;

/// Wraps an angle to (-π, π].
#[inline]
pub fn wrap_angle(a: f32) -> f32 {
    let r = a.rem_euclid(TAU);
    if r > PI { r - TAU } else { r }
}

/// A planar pose: position (m) and yaw (rad, counter-clockwise from +x).
/// In YAML it is written `[x, y, yaw]`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(from = "[f32; 3]", into = "[f32; 3]")]
pub struct Pose2 {
    /// x (m).
    pub x: f32,
    /// y (m).
    pub y: f32,
    /// Yaw (rad).
    pub yaw: f32,
}

impl From<[f32; 3]> for Pose2 {
    fn from(v: [f32; 3]) -> Self {
        Self { x: v[0], y: v[1], yaw: v[2] }
    }
}

impl From<Pose2> for [f32; 3] {
    fn from(p: Pose2) -> Self {
        [p.x, p.y, p.yaw]
    }
}

impl Pose2 {
    /// A pose from its parts.
    pub const fn new(x: f32, y: f32, yaw: f32) -> Self {
        Self { x, y, yaw }
    }

    /// The position.
    #[inline]
    pub fn position(&self) -> Vec2 {
        Vec2::new(self.x, self.y)
    }

    /// The inverse transform: the parent frame's pose in this pose's frame.
    pub fn inverse(&self) -> Pose2 {
        let (s, c) = self.yaw.sin_cos();
        Pose2::new(-(c * self.x + s * self.y), s * self.x - c * self.y, wrap_angle(-self.yaw))
    }

    /// `self ∘ local`: a pose given in this pose's frame, expressed in the parent frame.
    #[inline]
    pub fn compose(&self, local: &Pose2) -> Pose2 {
        let (s, c) = self.yaw.sin_cos();
        Pose2 {
            x: self.x + c * local.x - s * local.y,
            y: self.y + s * local.x + c * local.y,
            yaw: wrap_angle(self.yaw + local.yaw),
        }
    }

    /// A point in the parent frame expressed in this pose's frame.
    #[inline]
    pub fn to_local(&self, p: Vec2) -> Vec2 {
        self.vector_to_local(p - self.position())
    }

    /// A free vector (a velocity, an offset) of the parent frame in this pose's frame: rotated,
    /// not moved.
    #[inline]
    pub fn vector_to_local(&self, v: Vec2) -> Vec2 {
        let (s, c) = self.yaw.sin_cos();
        Vec2::new(c * v.x + s * v.y, -s * v.x + c * v.y)
    }

    /// Distance and bearing (in this pose's frame, wrapped to (-π, π]) of a parent-frame point.
    #[inline]
    pub fn polar_of(&self, p: Vec2) -> (f32, f32) {
        let l = self.to_local(p);
        (l.length(), wrap_angle(l.y.atan2(l.x)))
    }

    /// A point in this pose's frame expressed in the parent frame.
    #[inline]
    pub fn to_parent(&self, p: Vec2) -> Vec2 {
        let (s, c) = self.yaw.sin_cos();
        Vec2::new(self.x + c * p.x - s * p.y, self.y + s * p.x + c * p.y)
    }

    /// The same pose as parry2d's type.
    pub fn to_parry(&self) -> Pose {
        Pose::new(self.position(), self.yaw)
    }
}

/// One obstacle as written in a scenario file, in world coordinates.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum ObstacleSpec {
    /// A cylinder seen from above.
    Circle {
        /// Centre `[x, y]` (m).
        center: [f32; 2],
        /// Radius (m).
        radius: f32,
    },
    /// An oriented box.
    Box {
        /// Centre `[x, y]` (m).
        center: [f32; 2],
        /// Side lengths `[length_x, length_y]` (m) before rotation.
        size: [f32; 2],
        /// Rotation (rad), default 0.
        #[serde(default)]
        yaw: f32,
    },
    /// A convex polygon (vertices in either winding).
    Polygon {
        /// Vertices `[[x, y], ...]`, at least 3.
        points: Vec<[f32; 2]>,
    },
    /// A line-segment wall of zero thickness.
    Wall {
        /// One end `[x, y]`.
        from: [f32; 2],
        /// The other end `[x, y]`.
        to: [f32; 2],
    },
}

impl ObstacleSpec {
    /// Checks sizes, convexity and finiteness.
    pub fn validate(&self) -> Result<(), Invalid> {
        let finite = |v: &[f32]| v.iter().all(|x| x.is_finite());
        match self {
            ObstacleSpec::Circle { center, radius } => {
                if !finite(center) {
                    return Err(Invalid::new("circle.center", "finite [x, y]"));
                }
                check_positive("circle.radius", *radius)
            }
            ObstacleSpec::Box { center, size, yaw } => {
                if !finite(center) || !yaw.is_finite() {
                    return Err(Invalid::new("box", "finite center and yaw"));
                }
                check_positive("box.size[0]", size[0])?;
                check_positive("box.size[1]", size[1])
            }
            ObstacleSpec::Polygon { points } => {
                let pts: Vec<Vec2> = points.iter().map(|p| Vec2::new(p[0], p[1])).collect();
                if pts.len() < 3 || !points.iter().all(|p| finite(p)) {
                    return Err(Invalid::new("polygon.points", "at least 3 finite vertices"));
                }
                if convex_ccw(&pts).is_none() {
                    return Err(Invalid::new(
                        "polygon.points",
                        "a convex polygon with non-zero area (split concave shapes into convex ones)",
                    ));
                }
                Ok(())
            }
            ObstacleSpec::Wall { from, to } => {
                if !finite(from) || !finite(to) || from == to {
                    return Err(Invalid::new("wall", "two distinct finite end points"));
                }
                Ok(())
            }
        }
    }
}

/// Returns the vertices in counter-clockwise order if they form a strictly convex polygon
/// with non-zero area (collinear vertices are tolerated), else `None`.
pub fn convex_ccw(points: &[Vec2]) -> Option<Vec<Vec2>> {
    let n = points.len();
    if n < 3 {
        return None;
    }
    let area2: f32 = (0..n).map(|i| points[i].perp_dot(points[(i + 1) % n])).sum();
    if area2.abs() < 1e-8 {
        return None;
    }
    let mut pts = points.to_vec();
    if area2 < 0.0 {
        pts.reverse();
    }
    for i in 0..n {
        let a = pts[i];
        let b = pts[(i + 1) % n];
        let c = pts[(i + 2) % n];
        if (b - a).perp_dot(c - b) < -1e-6 {
            return None;
        }
    }
    Some(pts)
}

/// A world-frame primitive the lidar and distance queries work on.
#[derive(Clone, Debug, PartialEq)]
pub enum Primitive {
    /// Circle (centre, radius).
    Circle {
        /// Centre.
        center: Vec2,
        /// Radius.
        radius: f32,
    },
    /// Convex polygon, counter-clockwise vertices.
    Polygon {
        /// Vertices, CCW.
        vertices: Vec<Vec2>,
    },
    /// Zero-thickness segment.
    Segment {
        /// One end.
        a: Vec2,
        /// Other end.
        b: Vec2,
    },
}

/// A compiled obstacle: its primitive, its parry2d shape and pose, and a bounding circle.
#[derive(Clone)]
pub struct Obstacle {
    /// What the scenario said.
    pub spec: ObstacleSpec,
    /// World-frame primitive.
    pub primitive: Primitive,
    /// parry2d shape (for collision and the reference ray caster).
    pub shape: SharedShape,
    /// Pose of `shape` in the world.
    pub pose: Pose,
    /// Bounding circle centre.
    pub bound_center: Vec2,
    /// Bounding circle radius.
    pub bound_radius: f32,
}

impl std::fmt::Debug for Obstacle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Obstacle").field("spec", &self.spec).finish()
    }
}

impl Obstacle {
    /// Compiles a (validated) spec. Returns `Err` for specs that fail [`ObstacleSpec::validate`].
    pub fn new(spec: ObstacleSpec) -> Result<Self, Invalid> {
        spec.validate()?;
        let v = |p: [f32; 2]| Vec2::new(p[0], p[1]);
        let (primitive, shape, pose) = match &spec {
            ObstacleSpec::Circle { center, radius } => (
                Primitive::Circle { center: v(*center), radius: *radius },
                SharedShape::new(Ball::new(*radius)),
                Pose::new(v(*center), 0.0),
            ),
            ObstacleSpec::Box { center, size, yaw } => {
                let pose = Pose2::new(center[0], center[1], *yaw);
                let (hx, hy) = (size[0] / 2.0, size[1] / 2.0);
                let vertices =
                    [[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]].iter().map(|c| pose.to_parent(v(*c))).collect();
                (Primitive::Polygon { vertices }, SharedShape::new(Cuboid::new(Vec2::new(hx, hy))), pose.to_parry())
            }
            ObstacleSpec::Polygon { points } => {
                let pts: Vec<Vec2> = points.iter().map(|p| v(*p)).collect();
                let ccw = convex_ccw(&pts).ok_or_else(|| Invalid::new("polygon.points", "convex polygon"))?;
                let shape = ConvexPolygon::from_convex_polyline(ccw.clone())
                    .ok_or_else(|| Invalid::new("polygon.points", "a non-degenerate convex polygon"))?;
                (Primitive::Polygon { vertices: ccw }, SharedShape::new(shape), Pose::IDENTITY)
            }
            ObstacleSpec::Wall { from, to } => (
                Primitive::Segment { a: v(*from), b: v(*to) },
                SharedShape::new(Segment::new(v(*from), v(*to))),
                Pose::IDENTITY,
            ),
        };
        let (bound_center, bound_radius) = primitive.bounding_circle();
        Ok(Self { spec, primitive, shape, pose, bound_center, bound_radius })
    }
}

impl Primitive {
    /// A circle containing the primitive.
    pub fn bounding_circle(&self) -> (Vec2, f32) {
        match self {
            Primitive::Circle { center, radius } => (*center, *radius),
            Primitive::Polygon { vertices } => {
                let c = vertices.iter().copied().fold(Vec2::ZERO, |a, b| a + b) / vertices.len() as f32;
                let r = vertices.iter().map(|p| (*p - c).length()).fold(0.0, f32::max);
                (c, r)
            }
            Primitive::Segment { a, b } => ((*a + *b) * 0.5, (*b - *a).length() * 0.5),
        }
    }

    /// Euclidean distance from `p` to the primitive's surface; negative inside (solid shapes).
    pub fn signed_distance(&self, p: Vec2) -> f32 {
        match self {
            Primitive::Circle { center, radius } => (p - *center).length() - radius,
            Primitive::Segment { a, b } => point_segment_distance(p, *a, *b),
            Primitive::Polygon { vertices } => {
                // The nearest edge by squared distance, one square root at the end (the same
                // value: the root is monotonic and correctly rounded).
                let mut d2 = f32::INFINITY;
                let mut inside = true;
                let mut a = vertices[vertices.len() - 1];
                for &b in vertices.iter() {
                    d2 = d2.min(point_segment_distance_squared(p, a, b));
                    if (b - a).perp_dot(p - a) < 0.0 {
                        inside = false;
                    }
                    a = b;
                }
                let d = d2.sqrt();
                if inside { -d } else { d }
            }
        }
    }
}

/// The time in `[0, horizon]` at which two points moving at constant velocities come nearest:
/// `offset` is the other's position minus this one's, `relative_velocity` the other's velocity
/// minus this one's. 0 when they do not close in (or `horizon` is 0).
#[inline]
pub fn closest_approach_time(offset: Vec2, relative_velocity: Vec2, horizon: f32) -> f32 {
    let vv = relative_velocity.length_squared();
    if vv < 1e-12 || horizon <= 0.0 {
        return 0.0;
    }
    (-offset.dot(relative_velocity) / vv).clamp(0.0, horizon)
}

/// Distance from `p` to segment `[a, b]`.
#[inline]
pub fn point_segment_distance(p: Vec2, a: Vec2, b: Vec2) -> f32 {
    point_segment_distance_squared(p, a, b).sqrt()
}

/// Squared distance from `p` to segment `[a, b]`.
#[inline]
pub fn point_segment_distance_squared(p: Vec2, a: Vec2, b: Vec2) -> f32 {
    let e = b - a;
    let len2 = e.length_squared();
    let t = if len2 > 0.0 { ((p - a).dot(e) / len2).clamp(0.0, 1.0) } else { 0.0 };
    (a + e * t - p).length_squared()
}

/// An axis-aligned rectangle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rect {
    /// Lower-left corner.
    pub min: Vec2,
    /// Upper-right corner.
    pub max: Vec2,
}

impl Rect {
    /// The rectangle's size.
    pub fn size(&self) -> Vec2 {
        self.max - self.min
    }

    /// Whether `p` lies inside (inclusive).
    pub fn contains(&self, p: Vec2) -> bool {
        p.x >= self.min.x && p.x <= self.max.x && p.y >= self.min.y && p.y <= self.max.y
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn closest_approach_is_when_the_gap_stops_closing() {
        // 4 m apart closing at 2 m/s with a 1 m offset: nearest at 2 s.
        let (p, v) = (Vec2::new(4.0, 1.0), Vec2::new(-2.0, 0.0));
        assert!((closest_approach_time(p, v, 5.0) - 2.0).abs() < 1e-6);
        assert_eq!(closest_approach_time(p, v, 1.5), 1.5, "no further than the horizon");
        assert_eq!(closest_approach_time(p, -v, 5.0), 0.0, "moving apart: now");
        assert_eq!(closest_approach_time(p, Vec2::ZERO, 5.0), 0.0);
        assert_eq!(closest_approach_time(p, v, 0.0), 0.0);
    }

    #[test]
    fn wrap_angle_range() {
        for a in [-10.0f32, -PI, -3.0, 0.0, 3.0, PI, 7.0, 100.0] {
            let w = wrap_angle(a);
            assert!(w > -PI && w <= PI, "{a} -> {w}");
            assert!(((w - a) / TAU - ((w - a) / TAU).round()).abs() < 1e-4);
        }
        assert_eq!(wrap_angle(-PI), PI);
    }

    #[test]
    fn inverse_undoes_compose() {
        let a = Pose2::new(1.5, -2.0, 2.5);
        let b = Pose2::new(-0.3, 0.7, -1.0);
        let back = a.inverse().compose(&a.compose(&b));
        assert!((back.x - b.x).abs() < 1e-5 && (back.y - b.y).abs() < 1e-5 && (back.yaw - b.yaw).abs() < 1e-5);
        let p = Vec2::new(0.4, 3.0);
        let q = a.inverse().to_parent(a.to_parent(p));
        assert!((q - p).length() < 1e-5);
    }

    #[test]
    fn pose_round_trip() {
        let p = Pose2::new(1.0, -2.0, 0.7);
        let q = Vec2::new(0.3, 0.4);
        let back = p.to_local(p.to_parent(q));
        assert!((back - q).length() < 1e-5);
        let c = p.compose(&Pose2::new(1.0, 0.0, 0.1));
        assert!((c.x - (1.0 + 0.7f32.cos())).abs() < 1e-5);
        assert!((c.yaw - 0.8).abs() < 1e-6);
    }

    #[test]
    fn polygon_validation() {
        let square = ObstacleSpec::Polygon { points: vec![[0., 0.], [0., 1.], [1., 1.], [1., 0.]] };
        assert!(square.validate().is_ok(), "clockwise is accepted");
        let dart = ObstacleSpec::Polygon { points: vec![[0., 0.], [2., 0.], [0.5, 0.5], [0., 2.]] };
        assert_eq!(dart.validate().unwrap_err().key, "polygon.points");
        let line = ObstacleSpec::Polygon { points: vec![[0., 0.], [1., 1.], [2., 2.]] };
        assert!(line.validate().is_err());
    }

    #[test]
    fn signed_distance_box() {
        let o = Obstacle::new(ObstacleSpec::Box { center: [1.0, 0.0], size: [1.0, 2.0], yaw: 0.0 }).unwrap();
        assert!((o.primitive.signed_distance(Vec2::new(-1.0, 0.0)) - 1.5).abs() < 1e-6);
        assert!((o.primitive.signed_distance(Vec2::new(1.0, 0.0)) + 0.5).abs() < 1e-6);
        assert!((o.bound_radius - (0.25f32 + 1.0).sqrt()).abs() < 1e-6);
    }
}
