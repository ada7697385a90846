//! The [`Controller`] trait that joins evaluation, benchmarking and deployment, the data a
//! controller sees ([`RobotObservation`]), and two simple controllers for tests and demos.

use crate::geometry::{Pose2, Vec2};
use crate::lidar::LidarSpec;

/// A body velocity command or measurement, as `geometry_msgs/Twist` restricted to the plane.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Twist {
    /// Forward speed (m/s).
    pub linear: f32,
    /// Yaw rate (rad/s), counter-clockwise positive.
    pub angular: f32,
}

impl Twist {
    /// A twist from its parts.
    pub const fn new(linear: f32, angular: f32) -> Self {
        Self { linear, angular }
    }
}

/// A scan as `sensor_msgs/LaserScan` carries it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LaserScan {
    /// Angle of beam 0 in the sensor frame (rad).
    pub angle_min: f32,
    /// Angle between beams (rad), counter-clockwise.
    pub angle_increment: f32,
    /// Closest valid range (m).
    pub range_min: f32,
    /// Farthest valid range (m).
    pub range_max: f32,
    /// Ranges (m); `+inf` is no return.
    pub ranges: Vec<f32>,
}

impl LaserScan {
    /// An empty scan with the geometry of `spec`.
    pub fn for_spec(spec: &LidarSpec) -> Self {
        Self {
            angle_min: spec.angle_min,
            angle_increment: spec.angle_increment(),
            range_min: spec.range_min,
            range_max: spec.range_max,
            ranges: vec![f32::INFINITY; spec.beams],
        }
    }

    /// The smallest valid range (+inf if none).
    pub fn min_range(&self) -> f32 {
        self.ranges.iter().copied().filter(|r| *r >= self.range_min).fold(f32::INFINITY, f32::min)
    }
}

/// Everything a local planner gets each control period: what a robot's `/scan` and `/odom`
/// topics and the navigation goal provide.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RobotObservation {
    /// The latest scan, in the sensor frame.
    pub scan: LaserScan,
    /// Sensor pose in `base_link`.
    pub scan_mount: Pose2,
    /// Robot pose in the odometry frame.
    pub pose: Pose2,
    /// Measured body velocity: forward (`base_link` x) and angular.
    pub velocity: Twist,
    /// Measured lateral body velocity (m/s, `base_link` y, left positive): odometry's
    /// `twist.linear.y`; 0 for a differential drive.
    pub lateral_velocity: f32,
    /// Goal position in the odometry frame.
    pub goal: Vec2,
    /// The command sent at the previous control step.
    pub last_command: Twist,
    /// Time since the episode started (s).
    pub time: f32,
    /// The global plan to the goal, corner points in the odometry frame, as a planner with
    /// the room's map gives a Nav2 controller (empty: none; then the goal alone).
    pub plan: std::sync::Arc<[Vec2]>,
}

impl RobotObservation {
    /// Goal distance (m) and bearing (rad, in the robot frame, wrapped to (-π, π]).
    pub fn goal_polar(&self) -> (f32, f32) {
        self.pose.polar_of(self.goal)
    }
}

/// A local planner: turns observations into velocity commands. The RL policy, DWA and any
/// future planner implement it; the benchmark runner, the ROS 2 node and the sim bridge only
/// see this trait.
pub trait Controller: Send {
    /// The command for this control period.
    fn act(&mut self, obs: &RobotObservation) -> Twist;

    /// Forget per-episode state (recurrent state, plans) before a new episode.
    fn reset(&mut self) {}

    /// A short name for tables and logs.
    fn name(&self) -> &str;
}

/// Drives straight ahead at a fixed speed (a baseline that only succeeds when the goal is
/// dead ahead with nothing in between).
#[derive(Clone, Debug)]
pub struct StraightAhead {
    /// Forward speed (m/s).
    pub speed: f32,
}

impl Controller for StraightAhead {
    fn act(&mut self, _obs: &RobotObservation) -> Twist {
        Twist::new(self.speed, 0.0)
    }

    fn name(&self) -> &str {
        "straight"
    }
}

/// Turns toward the goal and drives at it, slowing down while the goal is off to the side;
/// blind to obstacles (it succeeds in open space and shows what obstacles cost).
#[derive(Clone, Debug)]
pub struct GreedyGoal {
    /// Cruise speed (m/s).
    pub max_linear: f32,
    /// Turn-rate limit (rad/s).
    pub max_angular: f32,
    /// Proportional gain from bearing to turn rate (1/s).
    pub heading_gain: f32,
}

impl Default for GreedyGoal {
    fn default() -> Self {
        Self { max_linear: 0.5, max_angular: 0.5, heading_gain: 1.5 }
    }
}

impl Controller for GreedyGoal {
    fn act(&mut self, obs: &RobotObservation) -> Twist {
        let (_, bearing) = obs.goal_polar();
        let angular = (self.heading_gain * bearing).clamp(-self.max_angular, self.max_angular);
        let linear = self.max_linear * bearing.cos().max(0.0);
        Twist::new(linear, angular)
    }

    fn name(&self) -> &str {
        "greedy"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn greedy_turns_toward_goal() {
        let mut c = GreedyGoal::default();
        let obs = RobotObservation { goal: Vec2::new(0.0, 2.0), ..Default::default() };
        let t = c.act(&obs);
        assert!(t.angular > 0.0 && t.linear.abs() < 1e-6, "goal to the left: turn left in place, {t:?}");
        let obs = RobotObservation { goal: Vec2::new(2.0, 0.0), ..Default::default() };
        assert_eq!(c.act(&obs), Twist::new(0.5, 0.0));
    }
}
