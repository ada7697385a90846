//! Following a global plan the way a Nav2 controller does: the policy steers to a point a
//! lookahead ahead along the path rather than to the goal itself. The ROS 2 node follows the
//! plans Nav2 sends; training and the benchmark follow the cheapest path past the static world
//! under [`PlanCost`] (what a Nav2 planner with the room's map would give).

use crate::geometry::Vec2;

/// How a global plan trades length for room: the price of a metre at a distance from the
/// nearest obstacle, Nav2's inflation cost as the planners read it. Within `band` of the
/// robot's clearance a metre costs `1 + weight * exp(-scaling * left)`, `left` being the
/// distance beyond the clearance; further out it costs 1.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanCost {
    /// The robot's clearance (m): the closest a path may come to an obstacle.
    pub clearance: f32,
    /// Extra price of a metre at the clearance (Nav2's lethal-adjacent cost, scaled).
    pub weight: f32,
    /// Decay of the extra price per metre beyond the clearance (Nav2's `cost_scaling_factor`).
    pub scaling: f32,
    /// How far beyond the clearance obstacles cost anything (Nav2's inflation radius less the
    /// inscribed radius).
    pub band: f32,
}

impl PlanCost {
    /// The costs the simulator's plans use, for a robot of `clearance`: the DWA baseline's A*
    /// (`cost_weight` 3, `cost_scaling_factor` 3, `docs/planners.md`), with the inflation
    /// reaching 0.5 m past the clearance so that a plan keeps to the middle of corridors up
    /// to 1.5 m wide for the Jetbot's 0.25 m.
    pub fn nav2_like(clearance: f32) -> Self {
        Self { clearance, weight: 3.0, scaling: 3.0, band: 0.5 }
    }

    /// Price of a metre through a point `distance` from the nearest obstacle.
    pub fn per_metre(&self, distance: f32) -> f32 {
        let left = (distance - self.clearance).max(0.0);
        if left >= self.band { 1.0 } else { 1.0 + self.weight * (-self.scaling * left).exp() }
    }

    /// The distance beyond which a metre costs 1 (how far a clearance field must measure).
    pub fn reach(&self) -> f32 {
        self.clearance + self.band
    }
}

/// Where [`follow`] put the target: the point and the path length still to go from it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Subgoal {
    /// The point `lookahead` ahead along the path (or its end).
    pub point: Vec2,
    /// Path length from `point` to the path's end (m).
    pub rest: f32,
    /// Distance from the robot to the path (m): to the nearest segment within reach, the one
    /// the robot is projected on (the cross-track error).
    pub offset: f32,
}

/// As [`plan_subgoal`], with the path length left after the point; `suffix[k]` is the path
/// length from point `k` to the end (see [`suffix_lengths`]).
pub fn follow(path: &[Vec2], suffix: &[f32], progress: &mut usize, p: Vec2, lookahead: f32) -> Subgoal {
    if path.len() < 2 {
        return Subgoal { point: path[0], rest: 0.0, offset: (p - path[0]).length() };
    }
    let last = path.len() - 2;
    let start = (*progress).min(last);
    // Nearest segment within reach: up to 2 lookaheads plus the robot's distance from the
    // current segment, along the path from the robot's projection on that segment (as Nav2's
    // controllers search from the last closest pose). Counted from the segment's start
    // instead, a segment longer than the reach (any-angle plans cross an open hall in one)
    // would hide the next one for good, and the target would stay at its end.
    let reach = 2.0 * lookahead + crate::geometry::point_segment_distance(p, path[start], path[start + 1]);
    let (mut best, mut best_d, mut best_t) = (start, f32::INFINITY, 0.0);
    let mut walked = 0.0;
    for k in start..=last {
        let (a, b) = (path[k], path[k + 1]);
        let e = b - a;
        let len2 = e.length_squared();
        let t = if len2 > 0.0 { ((p - a).dot(e) / len2).clamp(0.0, 1.0) } else { 0.0 };
        let d = (a + e * t - p).length();
        if d < best_d {
            (best, best_d, best_t) = (k, d, t);
        }
        walked += len2.sqrt() * if k == start { 1.0 - t } else { 1.0 };
        if walked > reach {
            break;
        }
    }
    *progress = best;
    // Walk `lookahead` along the path from the projection.
    let mut left = lookahead;
    let mut from = path[best] + (path[best + 1] - path[best]) * best_t;
    for k in best..=last {
        let to = path[k + 1];
        let step = (to - from).length();
        // (A zero-length segment, a repeated point as Nav2 plans have, is stepped over.)
        if step >= left && step > 0.0 {
            let point = from + (to - from) * (left / step);
            let rest = suffix.get(k + 1).map_or(0.0, |r| r + (to - point).length());
            return Subgoal { point, rest, offset: best_d };
        }
        left -= step;
        from = to;
    }
    Subgoal { point: path[last + 1], rest: 0.0, offset: best_d }
}

/// The point `lookahead` ahead along `path` (path length) of the robot at `p`: the robot is
/// projected on the nearest segment among those from `*progress` up to a few lookaheads
/// further (so a path that loops back past the robot is not cut short), `*progress` moves to
/// that segment, and the point is the path's end when less than `lookahead` remains. Points
/// are in one frame; `path` has at least one point.
pub fn plan_subgoal(path: &[Vec2], progress: &mut usize, p: Vec2, lookahead: f32) -> Vec2 {
    follow(path, &[], progress, p, lookahead).point
}

/// Fills `out` with the points `spacing`, 2·`spacing`, ... ahead of the robot at `pose` along
/// the path it follows: `plan` (projected as [`follow`] does, from segment `progress` on), or
/// the straight line to `goal` when `plan` is empty; the path's end where it is shorter. In the
/// robot's frame (x forward, y left): what the `plan_ahead` observation term shows of the
/// path's shape. The simulator and the policy runner both call it, so they cannot differ.
pub fn points_ahead(
    plan: &[Vec2],
    progress: usize,
    goal: Vec2,
    pose: &crate::geometry::Pose2,
    spacing: f32,
    out: &mut [Vec2],
) {
    let here = pose.position();
    let line = [here, goal];
    let (path, progress) = if plan.is_empty() { (&line[..], 0) } else { (plan, progress) };
    for (k, o) in out.iter_mut().enumerate() {
        let mut at = progress;
        *o = pose.to_local(follow(path, &[], &mut at, here, spacing * (k + 1) as f32).point);
    }
}

/// A path's length.
pub fn path_length(path: &[Vec2]) -> f32 {
    path.windows(2).map(|w| (w[1] - w[0]).length()).sum()
}

/// Path length from each point to the end.
pub fn suffix_lengths(path: &[Vec2]) -> Vec<f32> {
    let mut out = vec![0.0; path.len()];
    for k in (0..path.len().saturating_sub(1)).rev() {
        out[k] = out[k + 1] + (path[k + 1] - path[k]).length();
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rest_is_the_path_left_after_the_subgoal() {
        let l = [Vec2::new(0.0, 0.0), Vec2::new(2.0, 0.0), Vec2::new(2.0, 2.0)];
        let suffix = suffix_lengths(&l);
        assert_eq!(suffix, vec![4.0, 2.0, 0.0]);
        let mut k = 0;
        let s = follow(&l, &suffix, &mut k, Vec2::new(0.5, 0.1), 1.0);
        assert!((s.point - Vec2::new(1.5, 0.0)).length() < 1e-5 && (s.rest - 2.5).abs() < 1e-5, "{s:?}");
        // The robot is 0.1 m beside the first segment.
        assert!((s.offset - 0.1).abs() < 1e-5, "{s:?}");
        let s = follow(&l, &suffix, &mut k, Vec2::new(1.8, 0.0), 1.0);
        assert!((s.point - Vec2::new(2.0, 0.8)).length() < 1e-5 && (s.rest - 1.2).abs() < 1e-5, "{s:?}");
        let s = follow(&l, &suffix, &mut k, Vec2::new(2.0, 1.5), 1.0);
        assert_eq!(s, Subgoal { point: Vec2::new(2.0, 2.0), rest: 0.0, offset: 0.0 });
        // Off the corner's outside: the distance to the corner, not to either line.
        let s = follow(&l, &suffix, &mut 0, Vec2::new(2.3, -0.4), 1.0);
        assert!((s.offset - 0.5).abs() < 1e-5, "{s:?}");
        // Repeated points (Nav2 plans have them) and a lookahead ending on one: no NaN.
        let d = [Vec2::new(0.0, 0.0), Vec2::new(1.0, 0.0), Vec2::new(1.0, 0.0), Vec2::new(2.0, 0.0)];
        let p = plan_subgoal(&d, &mut 0, Vec2::new(0.0, 0.0), 1.0);
        assert_eq!(p, Vec2::new(1.0, 0.0));
        assert_eq!(path_length(&d), 2.0);
    }

    /// The plan that a TurtleBot3 Waffle got in the held-out hall: Theta* crosses the open
    /// floor in one 7 m segment. A robot driving along it must see the target move on to the
    /// later segments; the window used to be counted from the long segment's start, so the
    /// target stayed 0.6 m past its end and the robot circled there until the time-out.
    #[test]
    fn the_target_moves_past_a_segment_longer_than_the_search_window() {
        let plan =
            [Vec2::new(-5.41, 0.03), Vec2::new(1.525, -1.075), Vec2::new(2.375, -0.575), Vec2::new(5.377, 0.173)];
        let suffix = suffix_lengths(&plan);
        let mut k = 0;
        // Walk the plan in 5 cm steps: the target is always the point 0.6 m further along (the
        // end in the last 0.6 m), and `rest` counts down.
        let total = path_length(&plan);
        let mut last_rest = f32::INFINITY;
        for i in 0..=(total / 0.05) as usize {
            let along = (i as f32 * 0.05).min(total);
            let robot = follow(&plan, &[], &mut 0, plan[0], along).point;
            let s = follow(&plan, &suffix, &mut k, robot, 0.6);
            let want = follow(&plan, &[], &mut 0, plan[0], (along + 0.6).min(total)).point;
            assert!((s.point - want).length() < 1e-3, "at {along:.2} m: target {:?}, want {want:?}", s.point);
            assert!(s.rest <= last_rest + 1e-4, "at {along:.2} m: rest {} after {last_rest}", s.rest);
            last_rest = s.rest;
        }
        assert_eq!(k, plan.len() - 2);
    }

    #[test]
    fn points_ahead_follow_the_path_in_the_robot_frame() {
        use crate::geometry::Pose2;
        // An L: 1 m along +x, then up. The robot at the start faces +y (left of the path).
        let l = [Vec2::new(0.0, 0.0), Vec2::new(1.0, 0.0), Vec2::new(1.0, 2.0)];
        let pose = Pose2::new(0.0, 0.0, std::f32::consts::FRAC_PI_2);
        let mut out = [Vec2::ZERO; 4];
        points_ahead(&l, 0, Vec2::new(9.0, 9.0), &pose, 0.5, &mut out);
        // World (0.5, 0), (1, 0), (1, 0.5), (1, 1) seen facing +y: x' = y, y' = -x.
        let want = [(0.0, -0.5), (0.0, -1.0), (0.5, -1.0), (1.0, -1.0)];
        for (o, w) in out.iter().zip(want) {
            assert!((o.x - w.0).abs() < 1e-5 && (o.y - w.1).abs() < 1e-5, "{out:?}");
        }
        // Past the end: the end.
        let mut far = [Vec2::ZERO; 2];
        points_ahead(&l, 0, Vec2::new(9.0, 9.0), &Pose2::new(1.0, 1.5, 0.0), 1.0, &mut far);
        assert!(far.iter().all(|p| (*p - Vec2::new(0.0, 0.5)).length() < 1e-5), "{far:?}");
        // Without a plan: the line to the goal, 2 m straight ahead here.
        points_ahead(&[], 0, Vec2::new(2.0, 0.0), &Pose2::new(0.0, 0.0, 0.0), 1.5, &mut far);
        assert_eq!(far, [Vec2::new(1.5, 0.0), Vec2::new(2.0, 0.0)]);
    }
}
