//! Whether a robot that cannot stop can leave its start pose.
//!
//! A differential-drive robot whose action ranges keep it moving forward (`v_min > 0`) turns
//! no tighter than `r = v_min / w_max`. Started facing a wall at the end of a dead-end
//! corridor narrower than `2 r` plus its clearance on both sides, every path collides: no
//! controller can pass such an episode, and it measures nothing. A start pose is kept when a
//! forward search over the robot's tightest arcs and straight segments reaches, without
//! coming closer than the clearance to an obstacle, either a pose from which it can circle in
//! place (one of its two turning circles clear, so it can then face any way) or a place
//! `ESCAPE_DISTANCE` from the start.

use crate::geometry::{Pose2, Vec2};
use crate::world::World;
use std::f32::consts::TAU;

/// Distance from the start that counts as having left it (m).
const ESCAPE_DISTANCE: f32 = 1.0;
/// Length of one motion primitive (m), checked at its middle and end.
const STEP: f32 = 0.1;
/// Lattice of visited poses, relative to the start: position cells (m) and heading bins. The
/// search never keeps a pose `ESCAPE_DISTANCE` away, so the lattice is a fixed square.
const CELL: f32 = 0.05;
const HALF: i32 = (ESCAPE_DISTANCE / CELL) as i32;
const SIDE: usize = 2 * HALF as usize + 1;
const HEADINGS: usize = 32;
const LATTICE_WORDS: usize = (SIDE * SIDE * HEADINGS).div_ceil(64);
/// Poses waiting to be expanded, at most. The search runs at every reset, so it keeps its
/// state on the stack (resets allocate nothing); a search that fills it has found room to
/// move, and the start is called leavable.
const QUEUE: usize = 4096;

/// Whether a robot at `start` that turns no tighter than `turning_radius` (0: turns on the
/// spot) and keeps `clearance` from every obstacle can leave it: see the module docs.
pub fn can_leave(world: &World, start: Pose2, turning_radius: f32, clearance: f32) -> bool {
    if turning_radius <= 0.0 {
        return true;
    }
    let r = turning_radius;
    let circles_clear = |p: Pose2| {
        let left = Vec2::new(-p.yaw.sin(), p.yaw.cos()) * r;
        let c = p.position();
        world.is_clear(c + left, r + clearance) || world.is_clear(c - left, r + clearance)
    };
    if circles_clear(start) {
        return true;
    }
    let origin = start.position();
    // Index of a pose in the lattice (`None` beyond it).
    let index = |p: Pose2| {
        let (x, y) = (((p.x - origin.x) / CELL).round() as i32, ((p.y - origin.y) / CELL).round() as i32);
        if x.abs() > HALF || y.abs() > HALF {
            return None;
        }
        let h = (p.yaw.rem_euclid(TAU) / TAU * HEADINGS as f32).round() as usize % HEADINGS;
        Some((((x + HALF) as usize * SIDE) + (y + HALF) as usize) * HEADINGS + h)
    };
    let mut seen = [0u64; LATTICE_WORDS];
    let mut mark = |i: usize| {
        let fresh = seen[i / 64] & (1 << (i % 64)) == 0;
        seen[i / 64] |= 1 << (i % 64);
        fresh
    };
    // A ring buffer: breadth first.
    let mut queue = [start; QUEUE];
    let (mut head, mut len) = (0usize, 1usize);
    if let Some(i) = index(start) {
        mark(i);
    }
    while len > 0 {
        let p = queue[head];
        (head, len) = ((head + 1) % QUEUE, len - 1);
        if circles_clear(p) || (p.position() - origin).length() >= ESCAPE_DISTANCE {
            return true;
        }
        for curvature in [0.0, 1.0 / r, -1.0 / r] {
            let (mid, end) = (arc(p, curvature, 0.5 * STEP), arc(p, curvature, STEP));
            if !(world.is_clear(mid.position(), clearance) && world.is_clear(end.position(), clearance)) {
                continue;
            }
            if index(end).is_some_and(|i| !mark(i)) {
                continue;
            }
            if len == QUEUE {
                return true;
            }
            queue[(head + len) % QUEUE] = end;
            len += 1;
        }
    }
    false
}

/// The pose `length` metres along a forward arc of `curvature` (1/m, left positive) from `p`.
fn arc(p: Pose2, curvature: f32, length: f32) -> Pose2 {
    if curvature == 0.0 {
        return Pose2::new(p.x + length * p.yaw.cos(), p.y + length * p.yaw.sin(), p.yaw);
    }
    let yaw = p.yaw + curvature * length;
    Pose2::new(p.x + (yaw.sin() - p.yaw.sin()) / curvature, p.y - (yaw.cos() - p.yaw.cos()) / curvature, yaw)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Obstacle, ObstacleSpec};
    use std::f32::consts::{FRAC_PI_2, PI};

    /// A dead-end corridor along +x, `width` wide, closed at x = 0, open for 6 m.
    fn dead_end(width: f32) -> World {
        let wall = |from: [f32; 2], to: [f32; 2]| Obstacle::new(ObstacleSpec::Wall { from, to }).expect("a valid wall");
        World::new(vec![wall([0.0, 0.0], [6.0, 0.0]), wall([0.0, width], [6.0, width]), wall([0.0, 0.0], [0.0, width])])
    }

    #[test]
    fn a_start_facing_the_end_of_a_narrow_dead_end_cannot_be_left() {
        let (r, clearance) = (0.2, 0.25);
        let world = dead_end(1.2);
        // 0.5 m from the end, in the middle: facing the end there is no way out (a U-turn
        // needs 0.4 m sideways and 0.2 m ahead, and every one reaches a wall); facing a side
        // wall, a quarter turn then the corridor; facing out, straight on; turning on the
        // spot, any way.
        let at = |yaw: f32| Pose2::new(0.5, 0.6, yaw);
        assert!(!can_leave(&world, at(PI), r, clearance));
        assert!(can_leave(&world, at(FRAC_PI_2), r, clearance));
        assert!(can_leave(&world, at(0.0), r, clearance));
        assert!(can_leave(&world, at(PI), 0.0, clearance));
        // Further from the end the robot has room to turn round (a circle of 0.45 m radius
        // clear of the walls fits in a 1.4 m corridor).
        let wide = dead_end(1.4);
        assert!(can_leave(&wide, Pose2::new(1.5, 0.7, PI), r, clearance));
    }

    #[test]
    fn arcs_keep_their_radius() {
        let p = Pose2::new(1.0, 2.0, 0.3);
        let q = arc(p, 1.0 / 0.2, 0.2 * PI);
        // Half a circle of radius 0.2: 0.4 m to the left, facing back.
        let left = Vec2::new(-0.3f32.sin(), 0.3f32.cos()) * 0.4;
        assert!((q.position() - (p.position() + left)).length() < 1e-4, "{q:?}");
        assert!(((q.yaw - p.yaw) - PI).abs() < 1e-5);
        let s = arc(p, 0.0, 0.5);
        assert!((s.position() - p.position()).length() - 0.5 < 1e-6 && s.yaw == p.yaw);
    }
}
