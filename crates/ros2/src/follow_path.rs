//! Nav2's `FollowPath` action (`nav2_msgs/action/FollowPath`, ROS 2 Jazzy), served by the
//! policy node as Nav2's `controller_server` serves it, so that bt_navigator can drive the robot
//! through rlnav with no controller_server running: a goal's path becomes the node's plan,
//! feedback (distance left along the path, speed) goes out at every tick, and the goal ends as
//! controller_server's do:
//! - succeeded when the robot is within the goal tolerance of the path's end;
//! - aborted with `INVALID_PATH` for an empty path or one with a non-finite pose;
//! - aborted with `TF_ERROR` or `NO_VALID_CONTROL` when the node has stopped (no transform for
//!   the path's frame; no scan, no pose, an unusable scan) for longer than `failure_tolerance`;
//! - aborted with `FAILED_TO_MAKE_PROGRESS` when the robot moved less than
//!   `required_movement_radius` in `movement_time_allowance` (stuck against an obstacle, or
//!   turning in place for ever), Nav2's simple progress checker;
//! - canceled on a cancel request, the robot stopped;
//! - a new goal preempts the one running: its path replaces the old one and the old goal is
//!   aborted with no error code, as nav2_util's SimpleActionServer does.
//!
//! An aborted goal stops the robot. [`GoalWatch`] holds the decisions without DDS, so they are
//! tested directly; [`FollowPathServer`] puts them on the wire with ros2-client's action
//! server.

use crate::bus::{Bus, BusError};
use crate::msg::Path;
use crate::msg::follow_path::{FollowPathFeedback, FollowPathGoal, FollowPathResult};
use crate::node::{NodeState, PolicyNode};
use rlnav_sim::Vec2;
use ros2_client::action::{
    ActionServer, CancelGoalResponse, GetResultResponse, GoalId, GoalInfo, GoalStatusEnum, SendGoalResponse,
};
use ros2_client::action_msgs::{CancelGoalResponseEnum, GoalStatus, GoalStatusArray};
use ros2_client::builtin_interfaces::Time as RosTime;
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;

/// A message of rlnav's types carried by ros2-client, which wants its own `Message` trait on
/// what it sends (the bytes are the inner type's: the wrapper is transparent).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Wire<T>(pub T);

impl<T: Serialize + serde::de::DeserializeOwned> ros2_client::Message for Wire<T> {}

/// The action server's goal, result and feedback types.
pub type FollowPathActionServer = ActionServer<Wire<FollowPathGoal>, Wire<FollowPathResult>, Wire<FollowPathFeedback>>;

/// Why a path cannot be followed, if it cannot (controller_server's `INVALID_PATH`).
pub fn path_error(path: &Path) -> Option<String> {
    if path.poses.is_empty() {
        return Some("the path is empty".into());
    }
    path.poses
        .iter()
        .position(|p| !(p.pose.position.x.is_finite() && p.pose.position.y.is_finite()))
        .map(|k| format!("pose {k} of the path is not finite"))
}

/// How a goal ended.
#[derive(Clone, Debug, PartialEq)]
pub enum GoalEnd {
    /// At the path's end.
    Succeeded,
    /// Canceled by the client.
    Canceled,
    /// Given up, with the error code and why.
    Aborted(FollowPathResult),
}

impl GoalEnd {
    fn status(&self) -> GoalStatusEnum {
        match self {
            GoalEnd::Succeeded => GoalStatusEnum::Succeeded,
            GoalEnd::Canceled => GoalStatusEnum::Canceled,
            GoalEnd::Aborted(_) => GoalStatusEnum::Aborted,
        }
    }

    fn result(&self) -> FollowPathResult {
        match self {
            GoalEnd::Aborted(r) => r.clone(),
            _ => FollowPathResult::default(),
        }
    }
}

/// The limits a running goal is held to (Nav2's names and meanings).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GoalLimits {
    /// How long the node may stay stopped (no usable input) before the goal is aborted (s).
    pub failure_tolerance: f64,
    /// The progress checker's radius (m) ...
    pub required_movement_radius: f32,
    /// ... to leave within this time (s).
    pub movement_time_allowance: f64,
}

/// Judges a running goal after each tick of the node: success, a failure to abort it for, or
/// nothing yet.
#[derive(Clone, Debug)]
pub struct GoalWatch {
    limits: GoalLimits,
    /// Where and when the robot last left the progress checker's circle.
    anchor: Option<(Vec2, f64)>,
    /// Since when the node has been stopped.
    stopped_since: Option<f64>,
}

impl GoalWatch {
    /// A watch for a goal that starts now.
    pub fn new(limits: GoalLimits) -> Self {
        Self { limits, anchor: None, stopped_since: None }
    }

    /// The node's state after a tick at `now` (s) and the robot's position then.
    pub fn check(&mut self, state: &NodeState, position: Option<Vec2>, now: f64) -> Option<GoalEnd> {
        match state {
            NodeState::GoalReached => Some(GoalEnd::Succeeded),
            NodeState::Idle => Some(GoalEnd::Aborted(FollowPathResult::error(FollowPathResult::UNKNOWN, "no path"))),
            NodeState::Stopped(why) => {
                // Time stopped does not count against progress: that clock starts again.
                self.anchor = None;
                let since = *self.stopped_since.get_or_insert(now);
                if now - since <= self.limits.failure_tolerance {
                    return None;
                }
                let code = if why.contains("transform") {
                    FollowPathResult::TF_ERROR
                } else {
                    FollowPathResult::NO_VALID_CONTROL
                };
                Some(GoalEnd::Aborted(FollowPathResult::error(
                    code,
                    format!("stopped for {:.1} s: {why}", now - since),
                )))
            }
            NodeState::Driving => {
                self.stopped_since = None;
                let here = position?;
                match self.anchor {
                    Some((at, _)) if (here - at).length() > self.limits.required_movement_radius => {
                        self.anchor = Some((here, now));
                        None
                    }
                    Some((_, t)) if now - t > self.limits.movement_time_allowance => {
                        Some(GoalEnd::Aborted(FollowPathResult::error(
                            FollowPathResult::FAILED_TO_MAKE_PROGRESS,
                            format!(
                                "moved less than {} m in {} s",
                                self.limits.required_movement_radius, self.limits.movement_time_allowance
                            ),
                        )))
                    }
                    Some(_) => None,
                    None => {
                        self.anchor = Some((here, now));
                        None
                    }
                }
            }
        }
    }
}

/// The goal being driven.
struct Active {
    info: GoalInfo,
    watch: GoalWatch,
    /// Result requests waiting for it to end.
    waiting: Vec<ros2_client::service::RmwRequestId>,
}

/// Finished goals kept for late result requests.
const KEEP_FINISHED: usize = 32;

/// The `follow_path` action on the wire.
pub struct FollowPathServer {
    server: FollowPathActionServer,
    limits: GoalLimits,
    active: Option<Active>,
    finished: VecDeque<(GoalInfo, GoalEnd)>,
    /// Requests that could not be read (counted, never fatal).
    pub rejected: u64,
}

impl FollowPathServer {
    /// Serves `action` (resolved, e.g. `/follow_path`) on `bus`.
    pub fn new(bus: &mut Bus, action: &str, limits: GoalLimits) -> Result<Self, BusError> {
        let server = bus.action_server(action, crate::msg::follow_path::PACKAGE, crate::msg::follow_path::NAME)?;
        Ok(Self { server, limits, active: None, finished: VecDeque::new(), rejected: 0 })
    }

    /// The services to wake the node's poll for (goal, cancel and result requests).
    pub fn register(&mut self, registry: &rustdds::mio1::Registry, first: usize) -> std::io::Result<()> {
        use rustdds::mio1::{Interest, Token};
        registry.register(self.server.goal_server(), Token(first), Interest::READABLE)?;
        registry.register(self.server.cancel_server(), Token(first + 1), Interest::READABLE)?;
        registry.register(self.server.result_server(), Token(first + 2), Interest::READABLE)
    }

    /// Whether a goal is being driven (the node's goal and plan topics are then ignored: the
    /// action owns the robot).
    pub fn is_active(&self) -> bool {
        self.active.is_some()
    }

    /// Takes the waiting goal, cancel and result requests. Returns lines to log.
    pub fn handle_requests(&mut self, node: &mut PolicyNode) -> Vec<String> {
        let mut log = Vec::new();
        for _ in 0..100 {
            let (req_id, req) = match self.server.receive_goal() {
                Ok(Some(r)) => r,
                Ok(None) => break,
                Err(_) => {
                    self.rejected += 1;
                    continue;
                }
            };
            let info = GoalInfo { goal_id: req.goal_id, stamp: RosTime::now() };
            // Accepted, then judged: a bad path is an aborted goal with a reason, as
            // controller_server answers, rather than a bare rejection.
            let _ = self.server.send_goal_response(req_id, SendGoalResponse { accepted: true, stamp: info.stamp });
            if let Some(old) = self.active.take() {
                let end = GoalEnd::Aborted(FollowPathResult::error(FollowPathResult::NONE, "preempted by a new goal"));
                log.push(format!("follow_path: goal {:?} preempted", old.info.goal_id));
                self.finish(old, end);
            }
            let goal = req.goal.0;
            let active = Active { info, watch: GoalWatch::new(self.limits), waiting: Vec::new() };
            if let Some(why) = path_error(&goal.path) {
                log.push(format!("follow_path: goal {:?} aborted: {why}", active.info.goal_id));
                node.clear_goal();
                self.finish(active, GoalEnd::Aborted(FollowPathResult::error(FollowPathResult::INVALID_PATH, why)));
                continue;
            }
            log.push(format!(
                "follow_path: goal {:?}: {} poses in `{}`",
                active.info.goal_id,
                goal.path.poses.len(),
                goal.path.header.frame_id
            ));
            node.on_plan(&goal.path);
            self.active = Some(active);
            self.publish_statuses();
        }
        for _ in 0..100 {
            let (req_id, req) = match self.server.receive_cancel_request() {
                Ok(Some(r)) => r,
                Ok(None) => break,
                Err(_) => {
                    self.rejected += 1;
                    continue;
                }
            };
            let response = self.cancel(&req, node, &mut log);
            let _ = self.server.send_cancel_response(req_id, response);
        }
        for _ in 0..100 {
            let (req_id, req) = match self.server.receive_result_request() {
                Ok(Some(r)) => r,
                Ok(None) => break,
                Err(_) => {
                    self.rejected += 1;
                    continue;
                }
            };
            if let Some(a) = self.active.as_mut().filter(|a| a.info.goal_id == req.goal_id) {
                a.waiting.push(req_id);
            } else if let Some((_, end)) = self.finished.iter().find(|(i, _)| i.goal_id == req.goal_id) {
                let r = GetResultResponse { status: end.status(), result: Wire(end.result()) };
                let _ = self.server.send_result(req_id, r);
            } else {
                let r =
                    GetResultResponse { status: GoalStatusEnum::Unknown, result: Wire(FollowPathResult::default()) };
                let _ = self.server.send_result(req_id, r);
            }
        }
        log
    }

    /// Answers a cancel request (ROS 2's rules: a zero id and stamp cancel every goal, a zero
    /// id with a stamp those accepted up to it, an id that goal).
    fn cancel(
        &mut self,
        req: &ros2_client::action::CancelGoalRequest,
        node: &mut PolicyNode,
        log: &mut Vec<String>,
    ) -> CancelGoalResponse {
        let none = |code| CancelGoalResponse { return_code: code, goals_canceling: vec![] };
        // ros2-client keeps the request's fields private: its own bytes give them back.
        let Some(info) = cdr_encoding::to_vec::<_, byteorder::LittleEndian>(req)
            .ok()
            .and_then(|b| cdr_encoding::from_bytes::<GoalInfo, byteorder::LittleEndian>(&b).ok())
            .map(|(i, _)| i)
        else {
            self.rejected += 1;
            return none(CancelGoalResponseEnum::Rejected);
        };
        let all = info.goal_id == GoalId::ZERO;
        let hit = self.active.as_ref().is_some_and(|a| {
            a.info.goal_id == info.goal_id || (all && (info.stamp == RosTime::ZERO || a.info.stamp <= info.stamp))
        });
        if hit {
            let a = self.active.take().expect("checked above");
            let canceling = a.info.clone();
            log.push(format!("follow_path: goal {:?} canceled", a.info.goal_id));
            node.clear_goal();
            self.finish(a, GoalEnd::Canceled);
            return CancelGoalResponse { return_code: CancelGoalResponseEnum::None, goals_canceling: vec![canceling] };
        }
        if all {
            none(CancelGoalResponseEnum::None)
        } else if self.finished.iter().any(|(i, _)| i.goal_id == info.goal_id) {
            none(CancelGoalResponseEnum::GoalTerminated)
        } else {
            none(CancelGoalResponseEnum::UnknownGoal)
        }
    }

    /// After the node's tick at `now` (s): ends the goal when it succeeded or failed (an
    /// aborted goal stops the robot), else publishes feedback. Returns a line to log.
    pub fn after_tick(&mut self, node: &mut PolicyNode, now: f64) -> Option<String> {
        let a = self.active.as_mut()?;
        let motion = node.motion();
        match a.watch.check(node.state(), motion.map(|m| m.0), now) {
            Some(end) => {
                let a = self.active.take().expect("checked above");
                if matches!(end, GoalEnd::Aborted(_)) {
                    node.clear_goal();
                }
                let line = format!("follow_path: goal {:?} {end:?}", a.info.goal_id);
                self.finish(a, end);
                Some(line)
            }
            None => {
                let feedback = FollowPathFeedback {
                    distance_to_goal: node.distance_to_goal().unwrap_or(f32::NAN),
                    speed: motion.map_or(0.0, |m| m.1),
                };
                if self.server.send_feedback(a.info.goal_id, Wire(feedback)).is_err() {
                    self.rejected += 1;
                }
                None
            }
        }
    }

    fn finish(&mut self, a: Active, end: GoalEnd) {
        for req_id in a.waiting {
            let r = GetResultResponse { status: end.status(), result: Wire(end.result()) };
            let _ = self.server.send_result(req_id, r);
        }
        self.finished.push_back((a.info, end));
        while self.finished.len() > KEEP_FINISHED {
            self.finished.pop_front();
        }
        self.publish_statuses();
    }

    /// Every known goal's status (the running one and the finished ones kept), as rcl_action
    /// publishes it on each change.
    fn publish_statuses(&mut self) {
        let mut status_list: Vec<GoalStatus> =
            self.finished.iter().map(|(i, e)| GoalStatus { goal_info: i.clone(), status: e.status() }).collect();
        if let Some(a) = &self.active {
            status_list.push(GoalStatus { goal_info: a.info.clone(), status: GoalStatusEnum::Executing });
        }
        let _ = self.server.send_goal_statuses(GoalStatusArray { status_list });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIMITS: GoalLimits =
        GoalLimits { failure_tolerance: 1.0, required_movement_radius: 0.5, movement_time_allowance: 10.0 };

    fn code(end: Option<GoalEnd>) -> Option<u16> {
        match end {
            Some(GoalEnd::Aborted(r)) => Some(r.error_code),
            _ => None,
        }
    }

    #[test]
    fn reaching_the_end_succeeds() {
        let mut w = GoalWatch::new(LIMITS);
        assert_eq!(w.check(&NodeState::Driving, Some(Vec2::new(0.0, 0.0)), 0.0), None);
        assert_eq!(w.check(&NodeState::GoalReached, Some(Vec2::new(1.0, 0.0)), 3.0), Some(GoalEnd::Succeeded));
    }

    #[test]
    fn a_stop_longer_than_the_tolerance_aborts_with_its_cause() {
        let mut w = GoalWatch::new(LIMITS);
        let tf = NodeState::Stopped("plan in frame `map`, which has no transform to `odom`".into());
        assert_eq!(w.check(&tf, None, 0.0), None);
        assert_eq!(w.check(&tf, None, 0.9), None, "within the tolerance");
        assert_eq!(code(w.check(&tf, None, 1.1)), Some(FollowPathResult::TF_ERROR));
        let mut w = GoalWatch::new(LIMITS);
        let scan = NodeState::Stopped("no scan for 0.60 s".into());
        assert_eq!(w.check(&scan, None, 0.0), None);
        // Driving again in between restarts the clock.
        assert_eq!(w.check(&NodeState::Driving, Some(Vec2::new(0.0, 0.0)), 0.8), None);
        assert_eq!(w.check(&scan, None, 1.5), None);
        assert_eq!(code(w.check(&scan, None, 2.6)), Some(FollowPathResult::NO_VALID_CONTROL));
    }

    #[test]
    fn a_robot_that_does_not_move_fails_to_make_progress() {
        let mut w = GoalWatch::new(LIMITS);
        let driving = NodeState::Driving;
        // Moving on: each 0.6 m restarts the progress clock.
        for k in 0..10 {
            let t = 8.0 * k as f64;
            assert_eq!(w.check(&driving, Some(Vec2::new(0.6 * k as f32, 0.0)), t), None, "at {t} s");
        }
        // Then turning in place near x = 5.4 from t = 72 s.
        assert_eq!(w.check(&driving, Some(Vec2::new(5.5, 0.1)), 80.0), None);
        assert_eq!(
            code(w.check(&driving, Some(Vec2::new(5.6, 0.0)), 82.1)),
            Some(FollowPathResult::FAILED_TO_MAKE_PROGRESS)
        );
    }

    #[test]
    fn empty_and_non_finite_paths_are_invalid() {
        use crate::msg::{Pose, PoseStamped};
        let mut p = Path::default();
        assert_eq!(path_error(&p).as_deref(), Some("the path is empty"));
        p.poses =
            (0..3).map(|k| PoseStamped { pose: Pose::planar(k as f64, 0.0, 0.0), ..Default::default() }).collect();
        assert_eq!(path_error(&p), None);
        p.poses[2].pose.position.x = f64::INFINITY;
        assert_eq!(path_error(&p).as_deref(), Some("pose 2 of the path is not finite"));
    }
}
