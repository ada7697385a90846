//! People: pedestrians that walk from goal to goal at their own pace, avoiding each other,
//! the static obstacles and the robot's current position with ORCA (optimal reciprocal
//! collision avoidance, through the `dodgy_2d` crate). The lidar sees them as cylinders and
//! touching one is a collision.
//!
//! They see where the robot is, not where it is going: a robot that drives at a person
//! still meets one who steps aside too late, as people do.

use crate::config::{Invalid, check_interval, check_range};
use crate::geometry::{Primitive, Vec2, closest_approach_time};
use crate::lidar::RayGeometry;
use crate::robot::Footprint;
use crate::world::World;
use dodgy_2d::{Agent, AvoidanceOptions, Obstacle as OrcaObstacle};
use parry2d::query::intersection_test;
use parry2d::shape::Ball;
use rand::RngExt;
use serde::{Deserialize, Serialize};
use std::borrow::Cow;

/// In which order a person visits their goals.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GoalOrder {
    /// In the listed order, starting over after the last.
    #[default]
    Sequence,
    /// A random other goal each time.
    Random,
}

/// A person in a scenario file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PersonSpec {
    /// Body radius seen from above (m, default 0.25).
    #[serde(default = "default_radius")]
    pub radius: f32,
    /// Places to walk between `[[x, y], ...]`, at least two.
    pub goals: Vec<[f32; 2]>,
    /// Preferred walking speed `[min, max]` (m/s, default [0.5, 1.2]), drawn per episode.
    #[serde(default = "default_speed")]
    pub speed: [f32; 2],
    /// Goal order (default `sequence`).
    #[serde(default)]
    pub order: GoalOrder,
    /// Start at a random point between the first two goals (default true); otherwise at the
    /// first goal.
    #[serde(default = "yes")]
    pub random_start: bool,
}

fn default_radius() -> f32 {
    0.25
}
fn default_speed() -> [f32; 2] {
    [0.5, 1.2]
}
fn yes() -> bool {
    true
}

impl PersonSpec {
    /// Checks the values.
    pub fn validate(&self) -> Result<(), Invalid> {
        check_range("radius", self.radius, 0.05, 2.0)?;
        if self.goals.len() < 2 || !self.goals.iter().flatten().all(|v| v.is_finite()) {
            return Err(Invalid::new("goals", "at least two finite [x, y] points"));
        }
        check_interval("speed", self.speed, 0.0, 5.0)
    }

    /// This episode's person.
    pub fn instantiate<R: rand::Rng>(&self, rng: &mut R) -> Person {
        let goals: Vec<Vec2> = self.goals.iter().map(|g| Vec2::new(g[0], g[1])).collect();
        let speed =
            if self.speed[1] > self.speed[0] { rng.random_range(self.speed[0]..=self.speed[1]) } else { self.speed[0] };
        let position = if self.random_start { goals[0].lerp(goals[1], rng.random_range(0.0..1.0)) } else { goals[0] };
        let bias = side_bias(rng);
        Person { radius: self.radius, goals, order: self.order, speed, position, velocity: Vec2::ZERO, next: 1, bias }
    }
}

/// People the generator draws for every episode, each walking back and forth across the
/// straight line from start to goal.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PeopleGenSpec {
    /// Number `[min, max]` (default [1, 3]).
    pub count: [u32; 2],
    /// Walking speed range (m/s, default [0.5, 1.2]).
    pub speed: [f32; 2],
    /// Body radius range (m, default [0.2, 0.3]).
    pub radius: [f32; 2],
    /// Length of the crossing walk (m, default [2, 5]; the other patterns walk along the
    /// start–goal line, from beyond the goal to near the start).
    pub travel: [f32; 2],
    /// How each person walks relative to the robot's straight start–goal line, drawn uniformly
    /// per person (default `[cross]`).
    pub patterns: Vec<crate::scenario::MotionPattern>,
}

impl Default for PeopleGenSpec {
    fn default() -> Self {
        Self {
            count: [1, 3],
            speed: [0.5, 1.2],
            radius: [0.2, 0.3],
            travel: [2.0, 5.0],
            patterns: vec![crate::scenario::MotionPattern::Cross],
        }
    }
}

impl PeopleGenSpec {
    /// Checks the values.
    pub fn validate(&self) -> Result<(), Invalid> {
        crate::config::check_count("count", self.count, 100)?;
        check_interval("speed", self.speed, 0.0, 5.0)?;
        check_interval("radius", self.radius, 0.05, 2.0)?;
        check_interval("travel", self.travel, 0.0, 1000.0)?;
        crate::scenario::check_patterns("patterns", &self.patterns)
    }
}

/// One episode's person.
#[derive(Clone, Debug, PartialEq)]
pub struct Person {
    /// Body radius (m).
    pub radius: f32,
    goals: Vec<Vec2>,
    order: GoalOrder,
    /// Preferred speed this episode (m/s).
    pub speed: f32,
    /// Where the person is.
    pub position: Vec2,
    /// How the person moves now (m/s).
    pub velocity: Vec2,
    next: usize,
    /// Heading offset kept for one leg of the walk (rad): the side this person passes on.
    bias: f32,
}

/// A leg's heading offset: 0.25 rad to one side or the other.
fn side_bias(rng: &mut impl rand::Rng) -> f32 {
    if rng.random_bool(0.5) { 0.25 } else { -0.25 }
}

impl Person {
    /// The goal the person walks to now.
    pub fn goal(&self) -> Vec2 {
        self.goals[self.next]
    }

    /// Distance from `p` to the person's surface (negative inside).
    pub fn signed_distance(&self, p: Vec2) -> f32 {
        (p - self.position).length() - self.radius
    }

    /// Whether the robot's footprint at `pose` touches the person.
    pub fn touches(&self, footprint: &Footprint, pose: &crate::geometry::Pose2) -> bool {
        let d = self.signed_distance(pose.position());
        if d > footprint.radius() {
            return false;
        }
        if footprint.is_disc() {
            return true;
        }
        let me = crate::geometry::Pose2::new(self.position.x, self.position.y, 0.0);
        intersection_test(&pose.to_parry(), footprint.shape(), &me.to_parry(), &Ball::new(self.radius))
            .map_or(true, |hit| hit.intersecting)
    }

    /// Adds the person to a ray geometry.
    pub fn push_to(&self, g: &mut RayGeometry) {
        g.push_circle(self.position, self.radius);
    }
}

/// Distance at which a person counts a goal as reached (m).
const GOAL_REACHED: f32 = 0.2;
/// ORCA look-ahead for other agents and for obstacles (s).
const TIME_HORIZON: f32 = 2.0;
const OBSTACLE_HORIZON: f32 = 1.0;

fn to_orca(v: Vec2) -> dodgy_2d::Vec2 {
    dodgy_2d::Vec2::new(v.x, v.y)
}

/// The people of one episode and the static obstacles as ORCA sees them.
#[derive(Clone, Debug, Default)]
pub struct Crowd {
    /// The people.
    pub people: Vec<Person>,
    obstacles: Vec<OrcaObstacle>,
}

impl Crowd {
    /// A crowd walking in `world` (its obstacles become ORCA polygons; cylinders as
    /// 12-gons around them, walls as thin boxes; an occupancy grid is not given to ORCA, so
    /// goals on a map should be in sight of one another).
    pub fn new(people: Vec<Person>, world: &World) -> Self {
        let obstacles = if people.is_empty() {
            Vec::new()
        } else {
            world.obstacles().iter().map(|o| OrcaObstacle::Closed { vertices: outline(&o.primitive) }).collect()
        };
        Self { people, obstacles }
    }

    /// Whether there is no one.
    pub fn is_empty(&self) -> bool {
        self.people.is_empty()
    }

    /// Chooses every person's velocity for the next `dt` seconds (ORCA among the people, the
    /// obstacles and the robot, which stands at `robot` with radius `robot_radius`).
    pub fn plan(&mut self, robot: Vec2, robot_radius: f32, dt: f32, rng: &mut impl rand::Rng) {
        if self.people.is_empty() {
            return;
        }
        let agents: Vec<Agent> = self
            .people
            .iter()
            .map(|p| Agent {
                position: to_orca(p.position),
                velocity: to_orca(p.velocity),
                radius: p.radius,
                avoidance_responsibility: 1.0,
            })
            .chain(std::iter::once(Agent {
                position: to_orca(robot),
                velocity: dodgy_2d::Vec2::ZERO,
                radius: robot_radius,
                // The robot is not expected to give way: people take all of the avoidance.
                avoidance_responsibility: 1e-3,
            }))
            .collect();
        let obstacles: Vec<Cow<'_, OrcaObstacle>> = self.obstacles.iter().map(Cow::Borrowed).collect();
        let mut neighbours: Vec<Cow<'_, Agent>> = agents.iter().map(Cow::Borrowed).collect();
        let mut velocities = Vec::with_capacity(self.people.len());
        for (i, p) in self.people.iter_mut().enumerate() {
            if (p.goal() - p.position).length() < GOAL_REACHED {
                p.bias = side_bias(rng);
                p.next = match p.order {
                    GoalOrder::Sequence => (p.next + 1) % p.goals.len(),
                    GoalOrder::Random => {
                        let k = rng.random_range(0..p.goals.len() - 1);
                        if k >= p.next { k + 1 } else { k }
                    }
                };
            }
            let to_goal = p.goal() - p.position;
            // Heading a little to one side for the whole leg (plus some wander), so that
            // symmetric standoffs (a face square across the route, head-on meetings) resolve
            // by sliding one way instead of freezing. ORCA alone has no way around.
            let (s, c) = (p.bias * (to_goal.length() > 0.5) as u8 as f32 + rng.random_range(-0.05f32..=0.05)).sin_cos();
            let dir = to_goal.normalize_or_zero();
            let dir = Vec2::new(c * dir.x - s * dir.y, s * dir.x + c * dir.y);
            let preferred = dir * p.speed.min(to_goal.length() / dt);
            // Everyone but this person: swap them to the end and pass the rest (one list for
            // all, rather than one per person).
            let last = neighbours.len() - 1;
            neighbours.swap(i, last);
            let options = AvoidanceOptions {
                // dodgy_2d keeps this distance from obstacles (it does not add the radius).
                obstacle_margin: p.radius + 0.05,
                time_horizon: TIME_HORIZON,
                obstacle_time_horizon: OBSTACLE_HORIZON,
            };
            // dodgy_2d 0.5 panics (`f32::clamp` on NaN in its linear program) on some
            // degenerate configurations; one crashed a training run after 8 M steps and could
            // not be reproduced in 7 M person-steps of the same rooms. A person whose solve
            // fails stands still for this step rather than the simulator aborting.
            let solve = || {
                agents[i].compute_avoiding_velocity(
                    &neighbours[..last],
                    &obstacles,
                    to_orca(preferred),
                    p.speed,
                    dt,
                    &options,
                )
            };
            let v = std::panic::catch_unwind(std::panic::AssertUnwindSafe(solve))
                .ok()
                .map(|v| Vec2::new(v.x, v.y))
                .filter(|v| v.is_finite())
                .unwrap_or(Vec2::ZERO);
            neighbours.swap(i, last);
            velocities.push(v);
        }
        for (p, v) in self.people.iter_mut().zip(velocities) {
            p.velocity = v;
        }
    }

    /// Moves everyone along their velocity for `dt` seconds.
    pub fn advance(&mut self, dt: f32) {
        for p in &mut self.people {
            p.position += p.velocity * dt;
        }
    }

    /// Smallest gap between the robot's circumscribed circle at `robot` and a person's body
    /// (+inf when there is no one).
    pub fn min_gap(&self, robot: Vec2, robot_radius: f32) -> f32 {
        self.people.iter().map(|p| p.signed_distance(robot) - robot_radius).fold(f32::INFINITY, f32::min)
    }

    /// The social penalty's sum over the people (see [`social_charge`]): `robot` and
    /// `robot_velocity` are the robot's position and velocity, and each gap is the one at the
    /// nearest approach within `horizon` seconds if both keep their velocities (0: the gap now).
    pub fn intrusion(&self, robot: Vec2, robot_velocity: Vec2, robot_radius: f32, radius: f32, horizon: f32) -> f32 {
        self.people
            .iter()
            .map(|p| {
                let t = closest_approach_time(p.position - robot, p.velocity - robot_velocity, horizon);
                social_charge(p.signed_distance(robot + (robot_velocity - p.velocity) * t) - robot_radius, radius)
            })
            .sum()
    }
}

/// One body's share of the social penalty: for a gap (from the robot's circumscribed circle)
/// below `radius`, `(radius - gap) / radius`, growing from 0 at the edge to 1 at contact.
#[inline]
pub fn social_charge(gap: f32, radius: f32) -> f32 {
    ((radius - gap.max(0.0)) / radius).max(0.0)
}

/// A primitive's outline as a counter-clockwise polygon for ORCA.
fn outline(p: &Primitive) -> Vec<dodgy_2d::Vec2> {
    match p {
        Primitive::Circle { center, radius } => {
            // Circumscribed 12-gon, so that the polygon contains the cylinder.
            let r = radius / (std::f32::consts::PI / 12.0).cos();
            (0..12)
                .map(|k| {
                    let a = k as f32 * std::f32::consts::TAU / 12.0;
                    to_orca(*center + Vec2::new(a.cos(), a.sin()) * r)
                })
                .collect()
        }
        Primitive::Segment { a, b } => {
            let n = (*b - *a).perp().normalize_or_zero() * 0.01;
            vec![to_orca(*a - n), to_orca(*b - n), to_orca(*b + n), to_orca(*a + n)]
        }
        Primitive::Polygon { vertices } => vertices.iter().map(|v| to_orca(*v)).collect(),
    }
}
