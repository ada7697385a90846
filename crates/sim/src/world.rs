//! A static world: obstacles and walls, with the queries the simulator needs
//! (footprint collision, clearance, ray geometry for the lidar).

use crate::geometry::{Obstacle, Pose2, Rect, Vec2};
use crate::lidar::RayGeometry;
use crate::map::OccupancyGrid;
use crate::robot::Footprint;
use parry2d::query::intersection_test;
use std::sync::Arc;

/// Obstacles and walls, compiled for queries.
#[derive(Clone, Debug)]
pub struct World {
    obstacles: Vec<Obstacle>,
    rays: RayGeometry,
    bounds: Rect,
    grid: Option<Arc<OccupancyGrid>>,
}

impl World {
    /// Builds a world from compiled obstacles.
    pub fn new(obstacles: Vec<Obstacle>) -> Self {
        let rays = RayGeometry::new(obstacles.iter().map(|o| &o.primitive));
        let mut min = Vec2::splat(f32::INFINITY);
        let mut max = Vec2::splat(f32::NEG_INFINITY);
        for o in &obstacles {
            min = min.min(o.bound_center - Vec2::splat(o.bound_radius));
            max = max.max(o.bound_center + Vec2::splat(o.bound_radius));
        }
        if obstacles.is_empty() {
            (min, max) = (Vec2::ZERO, Vec2::ZERO);
        }
        Self { obstacles, rays, bounds: Rect { min, max }, grid: None }
    }

    /// Builds a world from an occupancy-grid map plus obstacles placed on it.
    pub fn with_grid(obstacles: Vec<Obstacle>, grid: Arc<OccupancyGrid>) -> Self {
        let mut w = Self::new(obstacles);
        let b = grid.bounds();
        w.bounds = if w.obstacles.is_empty() {
            b
        } else {
            Rect { min: w.bounds.min.min(b.min), max: w.bounds.max.max(b.max) }
        };
        w.rays.set_grid(grid.clone());
        w.grid = Some(grid);
        w
    }

    /// The occupancy-grid map, if the world has one.
    pub fn grid(&self) -> Option<&Arc<OccupancyGrid>> {
        self.grid.as_ref()
    }

    /// The obstacles.
    pub fn obstacles(&self) -> &[Obstacle] {
        &self.obstacles
    }

    /// What the lidar casts against.
    pub fn ray_geometry(&self) -> &RayGeometry {
        &self.rays
    }

    /// A rectangle containing every obstacle (from their bounding circles: quick, loose).
    pub fn bounds(&self) -> Rect {
        self.bounds
    }

    /// The smallest axis-aligned rectangle containing every obstacle and the grid's known
    /// cells (zero-size at the origin for an empty world).
    pub fn tight_bounds(&self) -> Rect {
        let mut min = Vec2::splat(f32::INFINITY);
        let mut max = Vec2::splat(f32::NEG_INFINITY);
        for o in &self.obstacles {
            let b = o.shape.compute_aabb(&o.pose);
            min = min.min(Vec2::new(b.mins.x, b.mins.y));
            max = max.max(Vec2::new(b.maxs.x, b.maxs.y));
        }
        if let Some(g) = &self.grid {
            let k = g.known_bounds();
            (min, max) = (min.min(k.min), max.max(k.max));
        }
        if min.x > max.x { Rect { min: Vec2::ZERO, max: Vec2::ZERO } } else { Rect { min, max } }
    }

    /// Whether the footprint at `pose` touches or overlaps any obstacle. Bounding circles
    /// cull first, then the exact distance from `base_link` to the obstacle: a disc footprint
    /// is decided by it, a polygon footprint within reach goes to parry2d.
    pub fn footprint_collides(&self, footprint: &Footprint, pose: &Pose2) -> bool {
        if self.grid.as_ref().is_some_and(|g| g.footprint_collides(footprint, pose)) {
            return true;
        }
        let p = pose.position();
        let r = footprint.radius();
        let robot = pose.to_parry();
        self.obstacles.iter().any(|o| {
            let reach = r + o.bound_radius;
            if (o.bound_center - p).length_squared() > reach * reach {
                return false;
            }
            let d = o.primitive.signed_distance(p);
            if d > r {
                return false;
            }
            if footprint.is_disc() {
                return true;
            }
            // parry2d supports every pair of shapes used here; treat "unsupported" as contact
            // so that a surprise can only stop a robot, never let it pass through.
            match intersection_test(&robot, footprint.shape(), &o.pose, o.shape.as_ref()) {
                Ok(hit) => hit.intersecting,
                Err(_) => true,
            }
        })
    }

    /// Distance from `p` to the nearest obstacle surface (negative inside one; +inf if none).
    pub fn clearance(&self, p: Vec2) -> f32 {
        let grid = self.grid.as_ref().map_or(f32::INFINITY, |g| g.clearance(p));
        self.obstacles.iter().map(|o| o.primitive.signed_distance(p)).fold(grid, f32::min)
    }

    /// Like [`World::clearance`] but stops early: whether the clearance at `p` is at least `min`.
    pub fn is_clear(&self, p: Vec2, min: f32) -> bool {
        if self.grid.as_ref().is_some_and(|g| !g.is_clear(p, min)) {
            return false;
        }
        self.obstacles
            .iter()
            .all(|o| (o.bound_center - p).length() - o.bound_radius >= min || o.primitive.signed_distance(p) >= min)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::ObstacleSpec;
    use crate::robot::FootprintSpec;

    #[test]
    fn footprint_contact() {
        let w = World::new(vec![
            Obstacle::new(ObstacleSpec::Box { center: [1.0, 0.0], size: [0.2, 2.0], yaw: 0.0 }).unwrap(),
            Obstacle::new(ObstacleSpec::Wall { from: [-1.0, -1.0], to: [-1.0, 1.0] }).unwrap(),
        ]);
        let circle = Footprint::new(&FootprintSpec::Circle { radius: 0.1 }).unwrap();
        assert!(!w.footprint_collides(&circle, &Pose2::new(0.75, 0.0, 0.0)));
        assert!(w.footprint_collides(&circle, &Pose2::new(0.85, 0.0, 0.0)));
        assert!(w.footprint_collides(&circle, &Pose2::new(-0.95, 0.5, 0.0)));
        let rect =
            Footprint::new(&FootprintSpec::Polygon(vec![[-0.3, -0.1], [0.3, -0.1], [0.3, 0.1], [-0.3, 0.1]])).unwrap();
        // A long robot: touching when facing the box, clear when turned sideways.
        assert!(w.footprint_collides(&rect, &Pose2::new(0.65, 0.0, 0.0)));
        assert!(!w.footprint_collides(&rect, &Pose2::new(0.65, 0.0, std::f32::consts::FRAC_PI_2)));
        assert!((w.clearance(Vec2::new(0.0, 0.0)) - 0.9).abs() < 1e-6);
        assert!(w.is_clear(Vec2::new(0.0, 0.0), 0.85) && !w.is_clear(Vec2::new(0.0, 0.0), 0.95));
    }
}
