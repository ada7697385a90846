//! Nav2's FollowPath action over DDS (loopback, its own domain): the policy node runs as
//! `rlnav ros2 node` runs it, a fake robot in this test integrates its `/cmd_vel` and publishes
//! `/scan` (open space) and `/odom`, and ros2-client's action client, as bt_navigator would,
//! sends `nav2_msgs/action/FollowPath` goals to `follow_path`: a path is driven to its end with
//! feedback and succeeds, a cancel stops the robot, a new goal preempts the running one, and an
//! empty path is aborted with Jazzy's `INVALID_PATH`.

use rlnav_policy::PolicyRunner;
use rlnav_ros2::bus::{Bus, Qos, Reach, drain};
use rlnav_ros2::follow_path::Wire;
use rlnav_ros2::msg::follow_path::{FollowPathFeedback, FollowPathGoal, FollowPathResult, NAME, PACKAGE};
use rlnav_ros2::msg::*;
use rlnav_ros2::node::{NodeParams, PolicyNode, run_node};
use ros2_client::action::{ActionClient, GoalId, GoalStatusEnum};
use ros2_client::action_msgs::CancelGoalResponseEnum;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

const POLICY: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../policies/jetbot-static-mlp.onnx");

type Client = ActionClient<Wire<FollowPathGoal>, Wire<FollowPathResult>, Wire<FollowPathFeedback>>;

/// A unicycle driven by the node's commands, and the action client.
struct Rig {
    scan_pub: ros2_client::dds::Publisher<LaserScan>,
    odom_pub: ros2_client::dds::Publisher<Odometry>,
    cmd_sub: ros2_client::dds::Subscription<Twist>,
    client: Client,
    /// x, y, yaw.
    pose: [f64; 3],
    cmd: Twist,
    last: Instant,
    /// Every command received, in order.
    cmds: Vec<(f64, f64)>,
    _bus: Bus,
}

impl Rig {
    /// One step of the fake robot (the time since the last, at most 0.1 s, under the latest
    /// command), its scan and odometry out.
    fn step(&mut self) {
        let mut dropped = 0;
        for c in drain(&self.cmd_sub, &mut dropped) {
            self.cmds.push((c.linear.x, c.angular.z));
            self.cmd = c;
        }
        let dt = self.last.elapsed().as_secs_f64().min(0.1);
        self.last = Instant::now();
        let [x, y, yaw] = &mut self.pose;
        *x += self.cmd.linear.x * yaw.cos() * dt;
        *y += self.cmd.linear.x * yaw.sin() * dt;
        *yaw += self.cmd.angular.z * dt;
        let inc = std::f32::consts::TAU / 360.0;
        let _ = self.scan_pub.publish(LaserScan {
            header: Header::new(Time::default(), "laser"),
            angle_min: -std::f32::consts::PI,
            angle_max: -std::f32::consts::PI + inc * 359.0,
            angle_increment: inc,
            scan_time: 0.1,
            range_min: 0.05,
            range_max: 8.0,
            ranges: vec![3.0; 360],
            ..Default::default()
        });
        let mut odom = Odometry {
            header: Header::new(Time::default(), "odom"),
            child_frame_id: "base_link".into(),
            pose: PoseWithCovariance {
                pose: Pose::planar(self.pose[0], self.pose[1], self.pose[2]),
                ..Default::default()
            },
            ..Default::default()
        };
        odom.twist.twist = self.cmd;
        let _ = self.odom_pub.publish(odom);
        std::thread::sleep(Duration::from_millis(50));
    }

    /// Steps the robot until `f` gives a value, for at most `secs`.
    fn until<T>(&mut self, secs: f64, what: &str, mut f: impl FnMut(&mut Self) -> Option<T>) -> T {
        let start = Instant::now();
        loop {
            if let Some(v) = f(self) {
                return v;
            }
            assert!(start.elapsed().as_secs_f64() < secs, "{what}: nothing after {secs} s (robot at {:?})", self.pose);
            self.step();
        }
    }

    /// Sends a goal until the server answers (the first requests may go out before the
    /// services are matched); the goal's id once accepted.
    fn send(&mut self, path: Path) -> GoalId {
        let goal = FollowPathGoal {
            path,
            controller_id: "FollowPath".into(),
            goal_checker_id: "general_goal_checker".into(),
            progress_checker_id: "progress_checker".into(),
        };
        let start = Instant::now();
        loop {
            let (req, id) = self.client.send_goal(Wire(goal.clone())).expect("goal request sent");
            let t = Instant::now();
            while t.elapsed() < Duration::from_secs(2) {
                if let Some(r) = self.client.receive_goal_response(req).expect("goal response read") {
                    assert!(r.accepted, "the goal is accepted");
                    return id;
                }
                self.step();
            }
            assert!(start.elapsed() < Duration::from_secs(30), "no answer to a FollowPath goal in 30 s");
        }
    }

    /// The goal's result (status, result), asked for now.
    fn result(&mut self, id: GoalId, secs: f64) -> (GoalStatusEnum, FollowPathResult) {
        let req = self.client.request_result(id).expect("result request sent");
        self.until(secs, "result", |r| r.client.receive_result(req).expect("result read").map(|(s, w)| (s, w.0)))
    }

    /// The next feedback for `id`.
    fn feedback(&mut self, id: GoalId) -> FollowPathFeedback {
        self.until(10.0, "feedback", |r| r.client.receive_feedback(id).expect("feedback read").map(|w| w.0))
    }
}

/// A straight path from `from` to `to` in `odom`, a pose every 5 cm (as Nav2's planners space
/// them).
fn path(from: (f64, f64), to: (f64, f64)) -> Path {
    let n = (((to.0 - from.0).hypot(to.1 - from.1)) / 0.05).ceil().max(1.0) as usize;
    let header = Header::new(Time::default(), "odom");
    let poses = (0..=n)
        .map(|k| {
            let s = k as f64 / n as f64;
            PoseStamped {
                header: header.clone(),
                pose: Pose::planar(from.0 + (to.0 - from.0) * s, from.1 + (to.1 - from.1) * s, 0.0),
            }
        })
        .collect();
    Path { header, poses }
}

#[test]
fn follow_path_goals_succeed_cancel_preempt_and_reject_bad_paths_over_dds() {
    let domain = 72;
    let runner = PolicyRunner::load(std::path::Path::new(POLICY), None).unwrap();
    let tolerance = runner.contract().goal_tolerance as f64;
    let stop = Arc::new(AtomicBool::new(false));
    let s2 = stop.clone();
    let node = std::thread::spawn(move || {
        run_node(PolicyNode::new(runner, NodeParams::default()), domain, Reach::Localhost, s2, |_, _| {})
    });
    let mut bus = Bus::new("follow_path_peer", domain, Reach::Localhost).unwrap();
    let mut rig = Rig {
        scan_pub: bus.publisher::<LaserScan>("/scan", Qos::SensorData).unwrap(),
        odom_pub: bus.publisher::<Odometry>("/odom", Qos::Default).unwrap(),
        cmd_sub: bus.subscription::<Twist>("/cmd_vel", Qos::Default).unwrap(),
        client: bus.action_client("/follow_path", PACKAGE, NAME).unwrap(),
        pose: [0.0, 0.0, 0.0],
        cmd: Twist::default(),
        last: Instant::now(),
        cmds: Vec::new(),
        _bus: bus,
    };

    // 1. A 1.5 m path ahead: feedback while driving, then success at its end.
    let id = rig.send(path((0.0, 0.0), (1.5, 0.0)));
    let first = rig.feedback(id);
    assert!((1.2..=1.6).contains(&first.distance_to_goal), "distance left at the start: {first:?}");
    let mut later = first;
    for _ in 0..20 {
        later = rig.feedback(id);
    }
    assert!(later.distance_to_goal < first.distance_to_goal - 0.05, "{first:?} then {later:?}");
    assert!(later.speed > 0.02, "moving: {later:?}");
    let (status, result) = rig.result(id, 40.0);
    assert_eq!(status, GoalStatusEnum::Succeeded, "{result:?}");
    assert_eq!(result.error_code, FollowPathResult::NONE);
    let d = (rig.pose[0] - 1.5).hypot(rig.pose[1]);
    assert!(d < tolerance + 0.05, "at the path's end: {:?}, {d:.2} m off", rig.pose);
    eprintln!("succeeded {d:.3} m from the end; feedback {first:?} -> {later:?}");

    // 2. A long path, canceled while driving: canceled, and the robot commanded to stop.
    let here = (rig.pose[0], rig.pose[1]);
    let id = rig.send(path(here, (here.0 + 10.0, here.1)));
    rig.until(20.0, "driving", |r| r.cmds.last().filter(|c| c.0 > 0.05).map(|_| ()));
    let req = rig.client.cancel_goal(id).unwrap();
    let cancel = rig.until(10.0, "cancel response", |r| r.client.receive_cancel_response(req).unwrap());
    assert_eq!(cancel.return_code, CancelGoalResponseEnum::None);
    assert_eq!(cancel.goals_canceling.len(), 1);
    assert_eq!(cancel.goals_canceling[0].goal_id, id);
    let (status, _) = rig.result(id, 10.0);
    assert_eq!(status, GoalStatusEnum::Canceled);
    let n = rig.cmds.len();
    rig.until(5.0, "commands after the cancel", |r| (r.cmds.len() >= n + 5).then_some(()));
    assert!(rig.cmds[n..].iter().all(|c| *c == (0.0, 0.0)), "stopped after the cancel: {:?}", &rig.cmds[n..]);

    // 3. A long goal preempted by a short one to the side: the first aborted with no error code,
    //    the second driven to its end.
    let here = (rig.pose[0], rig.pose[1]);
    let long = rig.send(path(here, (here.0 + 10.0, here.1)));
    rig.feedback(long);
    let end = (here.0 + 0.8, here.1 + 0.8);
    let short = rig.send(path(here, end));
    let (status, result) = rig.result(long, 10.0);
    assert_eq!(status, GoalStatusEnum::Aborted);
    assert_eq!(result.error_code, FollowPathResult::NONE);
    assert!(result.error_msg.contains("preempted"), "{result:?}");
    let (status, result) = rig.result(short, 40.0);
    assert_eq!(status, GoalStatusEnum::Succeeded, "{result:?}");
    let d = (rig.pose[0] - end.0).hypot(rig.pose[1] - end.1);
    assert!(d < tolerance + 0.05, "at the second path's end: {:?}, {d:.2} m off", rig.pose);
    eprintln!("preempting goal succeeded {d:.3} m from its end");

    // 4. An empty path and one with a NaN pose: aborted, INVALID_PATH, with the reason.
    let id = rig.send(Path { header: Header::new(Time::default(), "odom"), poses: vec![] });
    let (status, result) = rig.result(id, 10.0);
    assert_eq!((status, result.error_code), (GoalStatusEnum::Aborted, FollowPathResult::INVALID_PATH));
    assert!(result.error_msg.contains("empty"), "{result:?}");
    let mut bad = path((0.0, 0.0), (1.0, 0.0));
    bad.poses[3].pose.position.y = f64::NAN;
    let id = rig.send(bad);
    let (status, result) = rig.result(id, 10.0);
    assert_eq!((status, result.error_code), (GoalStatusEnum::Aborted, FollowPathResult::INVALID_PATH));
    assert!(result.error_msg.contains("pose 3"), "{result:?}");

    stop.store(true, Ordering::Relaxed);
    node.join().unwrap().unwrap();
}
