//! A DWA local planner modelled on Nav2's DWB controller, with an A* global path.
//!
//! Every control period: the costmap takes the scan; the global path is replanned once a second
//! or when a cell on it becomes impassable; velocity pairs are sampled in the dynamic window
//! (what the accelerations allow within one control period, inside the limits); each pair is
//! simulated forward at constant velocity for `sim_time`; trajectories through inscribed or
//! lethal cells are discarded; the rest are scored by DWB's critics with Nav2's default weights
//! and the cheapest is driven:
//!
//! - `BaseObstacle` (0.02): the highest cost along the trajectory;
//! - `PathDist` (32) and `GoalDist` (24): grid distance (cells) from the trajectory's end to the
//!   global path and to the local goal (the farthest path point within `local_goal_distance`);
//! - `PathAlign` (32) and `GoalAlign` (24): the same, at a point `forward_point_distance` ahead
//!   of the end pose (so that the robot lines up with the path), off near the goal;
//! - `Oscillation` (1): a cost for reversing the turn direction.
//!
//! Where it differs from Nav2: no `RotateToGoal` (rlnav's task has no goal orientation), no
//! recovery behaviours (when every sample collides it turns towards the path at the slowest
//! speed), constant-velocity forward simulation instead of DWB's acceleration ramp, and the
//! footprint is the circle of `robot_radius` (Nav2's circular-robot check).

use crate::astar;
use crate::costmap::{Costmap, CostmapConfig, INSCRIBED};
use rlnav_sim::geometry::Rect;
use rlnav_sim::task::EnvSetup;
use rlnav_sim::{Controller, Pose2, RobotObservation, Twist, Vec2, World};
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;
use std::sync::Arc;

/// Critic weights (Nav2's defaults for DWB).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CriticScales {
    /// BaseObstacle.scale (0.02).
    pub obstacle: f32,
    /// PathAlign.scale (32).
    pub path_align: f32,
    /// GoalAlign.scale (24).
    pub goal_align: f32,
    /// PathDist.scale (32).
    pub path_dist: f32,
    /// GoalDist.scale (24).
    pub goal_dist: f32,
    /// Oscillation.scale (1).
    pub oscillation: f32,
    /// forward_point_distance of the align critics (m, 0.325).
    pub forward_point_distance: f32,
}

impl Default for CriticScales {
    fn default() -> Self {
        Self {
            obstacle: 0.02,
            path_align: 32.0,
            goal_align: 24.0,
            path_dist: 32.0,
            goal_dist: 24.0,
            oscillation: 1.0,
            forward_point_distance: 0.325,
        }
    }
}

/// DWA parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DwaConfig {
    /// The costmap.
    pub costmap: CostmapConfig,
    /// Distance the robot's centre keeps from obstacles: its footprint radius, or more (m).
    pub robot_radius: f32,
    /// Linear speed range (m/s).
    pub linear: [f32; 2],
    /// Angular speed limit (rad/s).
    pub max_angular: f32,
    /// Linear acceleration limit (m/s²).
    pub linear_accel: f32,
    /// Angular acceleration limit (rad/s²).
    pub angular_accel: f32,
    /// Control period (s).
    pub control_period: f32,
    /// Forward simulation horizon (s, Nav2: 1.7).
    pub sim_time: f32,
    /// Forward simulation step (s).
    pub sim_dt: f32,
    /// Linear velocity samples (Nav2: 20).
    pub vx_samples: usize,
    /// Angular velocity samples (Nav2: 20).
    pub vtheta_samples: usize,
    /// Critic weights.
    pub scales: CriticScales,
    /// Global replanning period (s).
    pub replan_period: f32,
    /// A* cost weight: a step through cost 252 costs `1 + weight` times its length.
    pub cost_weight: f32,
    /// How far along the path the local goal is (m).
    pub local_goal_distance: f32,
}

impl Default for DwaConfig {
    fn default() -> Self {
        Self {
            costmap: CostmapConfig::default(),
            robot_radius: 0.25,
            linear: [0.1, 0.5],
            max_angular: 0.5,
            linear_accel: 2.0,
            angular_accel: 3.2,
            control_period: 0.1,
            sim_time: 1.7,
            sim_dt: 0.1,
            vx_samples: 20,
            vtheta_samples: 20,
            scales: CriticScales::default(),
            replan_period: 1.0,
            cost_weight: 3.0,
            local_goal_distance: 1.5,
        }
    }
}

impl DwaConfig {
    /// The configuration for episodes of `setup`: the task's speed limits and control period,
    /// the robot's accelerations, and a centre that keeps the footprint radius or the task's
    /// collision range (whichever is larger) plus 3 cm from obstacles.
    pub fn for_setup(setup: &EnvSetup) -> Self {
        let a = &setup.task.action;
        Self {
            robot_radius: setup.footprint.radius().max(setup.task.collision_range) + 0.03,
            linear: a.linear,
            max_angular: a.angular[0].abs().min(a.angular[1].abs()),
            linear_accel: setup.robot.max_linear_accel,
            angular_accel: setup.robot.max_angular_accel,
            control_period: setup.task.control_period,
            ..Default::default()
        }
    }
}

/// The DWA controller.
pub struct Dwa {
    config: DwaConfig,
    bounds: Rect,
    /// The prior map the static layer was built from (kept for pictures and reports).
    world: Option<Arc<World>>,
    map: Costmap,
    path: Vec<Vec2>,
    since_replan: f32,
    last: Twist,
    planned_goal: Option<Vec2>,
}

impl Dwa {
    /// A planner for a robot moving inside `bounds`, with the static layer from `world` when
    /// given (Nav2 with a prior map) or from the lidar alone.
    pub fn new(config: DwaConfig, bounds: Rect, world: Option<Arc<World>>) -> Self {
        let map = Costmap::new(bounds, config.costmap.clone(), config.robot_radius, world.as_deref());
        Self {
            config,
            bounds,
            world,
            map,
            path: Vec::new(),
            since_replan: f32::INFINITY,
            last: Twist::default(),
            planned_goal: None,
        }
    }

    /// A planner for episodes of `setup` ([`DwaConfig::for_setup`]) over the scenario's area,
    /// with the scenario's static world as its prior map when every episode shares it.
    pub fn for_setup(setup: &EnvSetup) -> Self {
        let a = setup.scenario.area();
        let bounds = Rect { min: a.min - Vec2::splat(0.5), max: a.max + Vec2::splat(0.5) };
        Self::new(DwaConfig::for_setup(setup), bounds, setup.scenario.fixed_world().cloned())
    }

    /// The costmap as it is now.
    pub fn costmap(&self) -> &Costmap {
        &self.map
    }

    /// The global path (world points, from near the robot to the goal).
    pub fn path(&self) -> &[Vec2] {
        &self.path
    }

    /// The region the planner covers.
    pub fn bounds(&self) -> Rect {
        self.bounds
    }

    /// The prior map, if it was given one.
    pub fn prior_map(&self) -> Option<&Arc<World>> {
        self.world.as_ref()
    }

    fn path_blocked(&self, here: Vec2) -> bool {
        self.path.iter().take_while(|p| (**p - here).length() < 2.5).any(|p| self.map.cost_at(*p) >= INSCRIBED)
    }

    fn replan(&mut self, from: Vec2, goal: Vec2) {
        self.since_replan = 0.0;
        self.planned_goal = Some(goal);
        self.path = astar::plan(&self.map, from, goal, self.config.cost_weight).unwrap_or_else(|| {
            // No path on the costmap: head for the goal and let the critics and the lidar sort
            // it out (Nav2 would fail the goal here and start its recoveries).
            vec![from, goal]
        });
    }

    /// Grid distances (cells, 8-connected unit steps) from `sources` over passable cells,
    /// inside a square window of `half` cells around `center`.
    fn distance_field(&self, center: (usize, usize), half: usize, sources: &[Vec2]) -> Field {
        let (w, h) = self.map.size();
        let x0 = center.0.saturating_sub(half);
        let y0 = center.1.saturating_sub(half);
        let x1 = (center.0 + half + 1).min(w);
        let y1 = (center.1 + half + 1).min(h);
        let (fw, fh) = (x1 - x0, y1 - y0);
        let mut d = vec![u16::MAX; fw * fh];
        let mut q = VecDeque::new();
        for s in sources {
            if let Some((x, y)) = self.map.cell_of(*s) {
                if x >= x0 && x < x1 && y >= y0 && y < y1 {
                    let k = (y - y0) * fw + (x - x0);
                    if d[k] != 0 {
                        d[k] = 0;
                        q.push_back(k);
                    }
                }
            }
        }
        while let Some(k) = q.pop_front() {
            let (x, y) = (k % fw, k / fw);
            for (dx, dy) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
                let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                if nx < 0 || ny < 0 || nx >= fw as i64 || ny >= fh as i64 {
                    continue;
                }
                let nk = ny as usize * fw + nx as usize;
                if d[nk] == u16::MAX && self.map.cost(nx as usize + x0, ny as usize + y0) < INSCRIBED {
                    d[nk] = d[k] + 1;
                    q.push_back(nk);
                }
            }
        }
        Field { x0, y0, w: fw, h: fh, d, unreachable: (2 * half) as f32 }
    }
}

/// A distance field over a window of the costmap.
struct Field {
    x0: usize,
    y0: usize,
    w: usize,
    h: usize,
    d: Vec<u16>,
    unreachable: f32,
}

impl Field {
    fn at(&self, map: &Costmap, p: Vec2) -> f32 {
        match map.cell_of(p) {
            Some((x, y)) if x >= self.x0 && y >= self.y0 && x - self.x0 < self.w && y - self.y0 < self.h => {
                let v = self.d[(y - self.y0) * self.w + (x - self.x0)];
                if v == u16::MAX { self.unreachable } else { v as f32 }
            }
            _ => self.unreachable,
        }
    }
}

impl Controller for Dwa {
    fn act(&mut self, obs: &RobotObservation) -> Twist {
        let c = self.config.clone();
        let pose = obs.pose;
        let here = pose.position();
        if !(here.is_finite() && obs.goal.is_finite() && pose.yaw.is_finite()) {
            return Twist::default();
        }
        self.map.update(&pose, &obs.scan_mount, &obs.scan);
        self.since_replan += c.control_period;
        let goal_moved = self.planned_goal.is_none_or(|g| (g - obs.goal).length() > 0.2);
        if self.path.is_empty() || goal_moved || self.since_replan >= c.replan_period || self.path_blocked(here) {
            self.replan(here, obs.goal);
        }
        // Drop the part of the path already passed.
        if let Some((i, _)) =
            self.path.iter().enumerate().min_by(|a, b| (*a.1 - here).length().total_cmp(&(*b.1 - here).length()))
        {
            self.path.drain(..i);
        }
        let mut local_goal = *self.path.last().unwrap_or(&obs.goal);
        let mut along = 0.0;
        for w in self.path.windows(2) {
            along += (w[1] - w[0]).length();
            if along > c.local_goal_distance {
                local_goal = w[0];
                break;
            }
        }
        let res = self.map.resolution();
        let reach = c.linear[1].abs() * c.sim_time + c.scales.forward_point_distance + 0.5;
        let half = (reach / res).ceil() as usize;
        let Some(center) = self.map.cell_of(here) else { return Twist::new(c.linear[0], 0.0) };
        let local_path: Vec<Vec2> =
            self.path.iter().copied().take_while(|p| (*p - here).length() <= reach + 0.5).collect();
        let path_field = self.distance_field(center, half, &local_path);
        let goal_field = self.distance_field(center, half, &[local_goal]);
        let near_goal = (obs.goal - here).length() < c.scales.forward_point_distance * 2.0;

        // The dynamic window around the measured velocity.
        let v0 = obs.velocity;
        let (vlo, vhi) = (
            (v0.linear - c.linear_accel * c.control_period).max(c.linear[0]),
            (v0.linear + c.linear_accel * c.control_period).min(c.linear[1]),
        );
        let (vlo, vhi) = if vlo <= vhi { (vlo, vhi) } else { (c.linear[0], c.linear[0]) };
        let (wlo, whi) = (
            (v0.angular - c.angular_accel * c.control_period).max(-c.max_angular),
            (v0.angular + c.angular_accel * c.control_period).min(c.max_angular),
        );
        let (wlo, whi) = if wlo <= whi { (wlo, whi) } else { (-c.max_angular, c.max_angular) };
        let steps = (c.sim_time / c.sim_dt).round().max(1.0) as usize;
        let mut best: Option<(f32, Twist)> = None;
        for i in 0..c.vx_samples.max(1) {
            let v = if c.vx_samples > 1 { vlo + (vhi - vlo) * i as f32 / (c.vx_samples - 1) as f32 } else { vhi };
            for j in 0..c.vtheta_samples.max(1) {
                let w = if c.vtheta_samples > 1 {
                    wlo + (whi - wlo) * j as f32 / (c.vtheta_samples - 1) as f32
                } else {
                    0.0
                };
                let mut p = pose;
                let mut worst = 0u8;
                let mut valid = true;
                for _ in 0..steps {
                    p = integrate(p, v, w, c.sim_dt);
                    let cost = self.map.cost_at(p.position());
                    if cost >= INSCRIBED {
                        valid = false;
                        break;
                    }
                    worst = worst.max(cost);
                }
                if !valid {
                    continue;
                }
                let end = p.position();
                let fwd = end + Vec2::new(p.yaw.cos(), p.yaw.sin()) * c.scales.forward_point_distance;
                let s = &c.scales;
                let mut score = s.obstacle * worst as f32
                    + s.path_dist * path_field.at(&self.map, end)
                    + s.goal_dist * goal_field.at(&self.map, end);
                if !near_goal {
                    score +=
                        s.path_align * path_field.at(&self.map, fwd) + s.goal_align * goal_field.at(&self.map, fwd);
                }
                if self.last.angular * w < 0.0 && self.last.angular.abs() > 0.05 {
                    score += s.oscillation;
                }
                if best.is_none_or(|b| score < b.0) {
                    best = Some((score, Twist::new(v, w)));
                }
            }
        }
        let cmd = match best {
            Some((_, t)) => t,
            None => {
                // Everything collides: creep and turn towards the path.
                let target = self.path.get(1).copied().unwrap_or(obs.goal);
                let (_, bearing) = pose.polar_of(target);
                Twist::new(c.linear[0], c.max_angular.copysign(bearing))
            }
        };
        self.last = cmd;
        cmd
    }

    fn reset(&mut self) {
        self.map.clear_obstacles();
        self.path.clear();
        self.since_replan = f32::INFINITY;
        self.last = Twist::default();
        self.planned_goal = None;
    }

    fn name(&self) -> &str {
        "dwa"
    }
}

/// Unicycle motion at constant `(v, w)` for `dt` (exact arcs).
fn integrate(p: Pose2, v: f32, w: f32, dt: f32) -> Pose2 {
    if w.abs() < 1e-6 {
        Pose2::new(p.x + v * dt * p.yaw.cos(), p.y + v * dt * p.yaw.sin(), p.yaw)
    } else {
        let yaw = p.yaw + w * dt;
        let r = v / w;
        Pose2::new(p.x + r * (yaw.sin() - p.yaw.sin()), p.y - r * (yaw.cos() - p.yaw.cos()), yaw)
    }
}
