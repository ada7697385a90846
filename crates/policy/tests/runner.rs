//! `PolicyRunner` as a controller: it builds exactly the simulator's observation from what a
//! robot reports, adapts scans of other geometries, stops on garbage, and runs the article's
//! own policies through their side contracts.

mod common;

use burn::prelude::*;
use rlnav_policy::contract::{
    ActionContract, ActionScaling, BeamOrder, CONTRACT_FORMAT, GraphIo, PolicyContract, ScanContract,
};
use rlnav_policy::export::export_model;
use rlnav_policy::scan::{ScanAdapter, ScanError};
use rlnav_policy::{ActorCritic, NetworkConfig, PolicyRunner, RunningMeanStd};
use rlnav_sim::task::{EnvSetup, NavEnv};
use rlnav_sim::{Controller, LaserScan, LidarSpec, RobotObservation, Twist};
use std::f32::consts::PI;
use std::path::Path;
use std::sync::Arc;

fn contract_for(setup: &EnvSetup) -> PolicyContract {
    PolicyContract {
        format: CONTRACT_FORMAT,
        producer: "test".into(),
        task: "test".into(),
        robot: setup.robot.name.clone(),
        observation: setup.task.observation.clone(),
        scan: ScanContract::of(&setup.robot.lidar),
        action: ActionContract {
            scaling: ActionScaling::Normalized,
            linear: setup.task.action.linear,
            angular: setup.task.action.angular,
            linear_relative: false,
        },
        control_period: setup.task.control_period,
        goal_tolerance: setup.task.goal_tolerance,
        io: GraphIo::default(),
        plan: setup.task.plan.clone(),
        envelope: None,
    }
}

#[test]
fn runner_sees_what_the_simulator_feeds_training() {
    let setup = Arc::new(EnvSetup::from_scenario_name("static-room").unwrap());
    let net =
        ActorCritic::seeded(&NetworkConfig { hidden: vec![32], ..Default::default() }, 124, 2, &Device::flex(), 3);
    let proto = export_model(&net, &RunningMeanStd::new(124), &contract_for(&setup)).unwrap();
    let mut runner = PolicyRunner::from_proto("test.onnx", &proto, contract_for(&setup)).unwrap();
    let mut env = NavEnv::new(setup.clone(), 5).unwrap();
    let steps = common::runner_matches_simulator(&mut runner, &mut env, "static-room");
    assert!(steps > 20, "{steps} steps compared");
}

#[test]
fn runner_follows_the_plan_as_the_simulator_does() {
    // A U-shaped dead end between start and goal: the plan turns, so the target is not the goal.
    let spec = rlnav_sim::ScenarioSpec::load("heldout-static-u-trap").unwrap();
    let task =
        rlnav_sim::TaskConfig { plan: Some(rlnav_sim::task::PlanConfig { lookahead: 1.0 }), ..Default::default() };
    let setup = Arc::new(EnvSetup::new(spec, rlnav_sim::RobotSpec::load("jetbot").unwrap(), task).unwrap());
    let net =
        ActorCritic::seeded(&NetworkConfig { hidden: vec![32], ..Default::default() }, 124, 2, &Device::flex(), 4);
    let contract = contract_for(&setup);
    assert!(contract.plan.is_some());
    let proto = export_model(&net, &RunningMeanStd::new(124), &contract).unwrap();
    let mut runner = PolicyRunner::from_proto("test.onnx", &proto, contract).unwrap();
    let mut env = NavEnv::new(setup.clone(), 6).unwrap();
    assert!(env.plan().len() >= 3, "a plan round the U: {:?}", env.plan());
    assert!((env.target() - env.goal()).length() > 0.5, "the target is on the plan, not the goal");
    let steps = common::runner_matches_simulator(&mut runner, &mut env, "u-trap with a plan");
    assert!(steps > 20, "{steps} steps compared");
}

fn scan(n: usize, angle_min: f32, inc: f32, f: impl Fn(usize) -> f32) -> LaserScan {
    LaserScan { angle_min, angle_increment: inc, range_min: 0.1, range_max: 10.0, ranges: (0..n).map(f).collect() }
}

#[test]
fn scans_of_other_geometries_are_adapted_or_refused() {
    let c = ScanContract::of(&LidarSpec::default()); // 360 beams from -π, 0.15-3 m
    let mut out = vec![0.0; 360];
    // A 720-beam scan starting at 0 (the usual ROS order): rotated and min-pooled into place.
    let s720 = scan(720, 0.0, PI / 360.0, |i| if i == 11 { 0.5 } else { 2.0 });
    let a = ScanAdapter::new(&c, &s720, 0.0).unwrap();
    a.adapt(&s720, &mut out).unwrap();
    // Incoming beam 11 is at 5.5°; contract beam 180 is 0°, so it lands in beam 185 or 186.
    let hits: Vec<usize> = (0..360).filter(|j| out[*j] == 0.5).collect();
    assert!(hits == vec![186] || hits == vec![185], "{hits:?}");
    assert!(out.iter().all(|r| *r == 0.5 || *r == 2.0));
    // A lidar mounted backwards: the same scan with yaw π lands half a turn away.
    let a = ScanAdapter::new(&c, &s720, PI).unwrap();
    a.adapt(&s720, &mut out).unwrap();
    let hits: Vec<usize> = (0..360).filter(|j| out[*j] == 0.5).collect();
    assert!(hits == vec![6] || hits == vec![5], "{hits:?}");
    // A sparser scanner (180 beams) fills every beam from its nearest neighbour.
    let s180 = scan(180, -PI, 2.0 * PI / 180.0, |i| 1.0 + i as f32 * 0.01);
    ScanAdapter::new(&c, &s180, 0.0).unwrap().adapt(&s180, &mut out).unwrap();
    assert!(out.iter().all(|r| r.is_finite()));
    // Readings: NaN and beyond range are no return; below range_min (or 0) is very close.
    let odd = scan(360, -PI, 2.0 * PI / 360.0, |i| match i {
        0 => f32::NAN,
        1 => 50.0,
        2 => 0.0,
        _ => 1.0,
    });
    ScanAdapter::new(&c, &odd, 0.0).unwrap().adapt(&odd, &mut out).unwrap();
    assert_eq!((out[0], out[1], out[2], out[3]), (f32::INFINITY, f32::INFINITY, 0.15, 1.0));
    // A 270° scanner leaves the policy's rear quarter unseen: refused, with numbers.
    let s270 = scan(1081, -0.75 * PI, 1.5 * PI / 1080.0, |_| 1.0);
    let e = ScanAdapter::new(&c, &s270, 0.0).unwrap_err();
    assert!(matches!(e, ScanError::Coverage { uncovered, .. } if uncovered > 80), "{e}");
    assert!(e.to_string().contains("unseen"), "{e}");
    // Mostly NaN is garbage.
    let nan = scan(360, -PI, 2.0 * PI / 360.0, |i| if i % 3 == 0 { 1.0 } else { f32::NAN });
    let a = ScanAdapter::new(&c, &nan, 0.0).unwrap();
    assert!(matches!(a.adapt(&nan, &mut out), Err(ScanError::Garbage { .. })));
    // A clockwise contract reads the same world mirrored in index.
    let cw = ScanContract { direction: BeamOrder::Clockwise, ..c.clone() };
    let one = scan(360, -PI, 2.0 * PI / 360.0, |i| if i == 190 { 0.7 } else { 2.0 });
    ScanAdapter::new(&cw, &one, 0.0).unwrap().adapt(&one, &mut out).unwrap();
    assert_eq!((0..360).filter(|j| out[*j] == 0.7).collect::<Vec<_>>(), vec![170]);
}

#[test]
fn garbage_in_stops_the_robot_and_says_why() {
    let setup = Arc::new(EnvSetup::from_scenario_name("empty-room").unwrap());
    let net = ActorCritic::seeded(&NetworkConfig { hidden: vec![8], ..Default::default() }, 124, 2, &Device::flex(), 1);
    let proto = export_model(&net, &RunningMeanStd::new(124), &contract_for(&setup)).unwrap();
    let mut runner = PolicyRunner::from_proto("t.onnx", &proto, contract_for(&setup)).unwrap();
    let env = NavEnv::new(setup, 0).unwrap();
    let mut o = RobotObservation::default();
    env.robot_observation(&mut o);
    assert_ne!(runner.act(&o), Twist::default());
    let mut bad = o.clone();
    bad.pose.x = f32::NAN;
    assert_eq!(runner.act(&bad), Twist::default());
    assert!(runner.fault().unwrap().contains("not finite"), "{:?}", runner.fault());
    let mut bad = o.clone();
    bad.scan.ranges.iter_mut().for_each(|r| *r = f32::NAN);
    assert_eq!(runner.act(&bad), Twist::default());
    assert!(runner.fault().unwrap().contains("NaN"), "{:?}", runner.fault());
    let mut bad = o.clone();
    bad.scan.angle_increment = 0.0;
    assert_eq!(runner.act(&bad), Twist::default());
    assert!(runner.fault().unwrap().contains("malformed scan"));
    // Good data again: it drives again.
    assert_ne!(runner.act(&o), Twist::default());
    assert!(runner.fault().is_none());
}

#[test]
fn a_policy_in_shares_of_the_top_speed_needs_the_robot_and_then_drives_as_in_training() {
    use rlnav_sim::task::ActionConfig;
    let task = rlnav_sim::TaskConfig {
        action: ActionConfig { linear: [0.2, 1.0], linear_relative: true, ..Default::default() },
        ..Default::default()
    };
    let burger = rlnav_sim::RobotSpec::load("turtlebot3-burger").unwrap();
    let spec = rlnav_sim::ScenarioSpec::load("static-room").unwrap();
    let setup = Arc::new(EnvSetup::new(spec, burger.clone(), task.clone()).unwrap());
    // The simulator drives the Burger from a fifth of its top speed to all of it.
    let [lo, hi] = setup.task.action.linear;
    assert!((lo - 0.2 * burger.max_linear).abs() < 1e-6 && (hi - burger.max_linear).abs() < 1e-6, "{lo} {hi}");
    assert!(!setup.task.action.linear_relative);
    // The contract keeps the shares, and says so; one in m/s reads as before.
    let contract = PolicyContract::for_task("relative", &task, &burger, GraphIo::default(), None);
    assert_eq!((contract.action.linear, contract.action.linear_relative), ([0.2, 1.0], true));
    let yaml = contract.to_yaml();
    assert!(yaml.contains("linear_relative: true"), "{yaml}");
    assert_eq!(PolicyContract::from_yaml("c.yaml", &yaml).unwrap(), contract);
    assert!(!contract_for(&setup).to_yaml().contains("linear_relative"));
    // Shares beyond the top speed are refused, naming the key.
    let mut over = contract.clone();
    over.action.linear = [0.2, 1.5];
    let e = PolicyContract::from_yaml("over.yaml", &over.to_yaml()).unwrap_err().to_string();
    assert!(e.contains("action.linear") && e.contains("<= 1"), "{e}");

    let net =
        ActorCritic::seeded(&NetworkConfig { hidden: vec![16], ..Default::default() }, 124, 2, &Device::flex(), 5);
    let proto = export_model(&net, &RunningMeanStd::new(124), &contract).unwrap();
    let mut runner = PolicyRunner::from_proto("relative.onnx", &proto, contract).unwrap();
    let mut env = NavEnv::new(setup.clone(), 2).unwrap();
    let mut o = RobotObservation::default();
    env.robot_observation(&mut o);
    // Not told the robot's top speed: it stops, and says what it needs.
    assert!(runner.needs_top_speed());
    assert_eq!(runner.act(&o), Twist::default());
    assert!(runner.fault().unwrap().contains("top speed"), "{:?}", runner.fault());
    // Told nonsense: still none.
    for v in [f32::NAN, -0.22, 0.0] {
        runner.set_top_speed(v);
        assert!(runner.needs_top_speed(), "{v}");
    }
    // Told: the command is the simulator's for the same action, within the Burger's range.
    runner.set_top_speed(burger.max_linear);
    assert!(!runner.needs_top_speed());
    let obs = runner.build_observation(&o).unwrap().to_vec();
    let mu = runner.infer(&obs).unwrap().mu;
    runner.reset();
    let cmd = runner.act(&o);
    assert_eq!(cmd, setup.task.action.to_twist(mu));
    assert!((lo..=hi).contains(&cmd.linear), "{cmd:?}");
    let steps = common::runner_matches_simulator(&mut runner, &mut env, "shares of the Burger's top speed");
    assert!(steps > 20, "{steps} steps compared");
}

/// The reference article's policies, vendored with their licence.
const ARTICLE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../policies/article");

#[test]
fn the_articles_policies_run_through_their_side_contracts() {
    let contracts = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../contracts");
    for (model, n, recurrent) in [("static_120_new", 124, false), ("Jetbot_margin_dynamic", 70, true)] {
        let path = Path::new(ARTICLE).join(format!("{model}.onnx"));
        // Without a contract: refused, pointing at --contract.
        let e = PolicyRunner::load(&path, None).unwrap_err().to_string();
        assert!(e.contains("--contract"), "{e}");
        let mut runner = PolicyRunner::load(&path, Some(&contracts.join(format!("{model}.yaml")))).unwrap();
        assert_eq!(runner.contract().obs_dim(), n);
        assert_eq!(runner.contract().io.recurrent.len(), if recurrent { 2 } else { 0 });
        let setup = Arc::new(EnvSetup::from_scenario_name("static-room").unwrap());
        let mut env = NavEnv::new(setup, 1).unwrap();
        let mut o = RobotObservation::default();
        let mut cmds = Vec::new();
        for _ in 0..30 {
            env.robot_observation(&mut o);
            let t = runner.act(&o);
            assert!(runner.fault().is_none(), "{:?}", runner.fault());
            // Direct scaling: clipped to the article's node limits.
            assert!((0.1..=0.4).contains(&t.linear) && (-0.5..=0.5).contains(&t.angular), "{t:?}");
            cmds.push(t);
            if env.step_twist(t).terminated {
                break;
            }
        }
        assert!(cmds.windows(2).any(|w| w[0] != w[1]), "the policy reacts to what it sees");
        // A wrong side contract (the other model's) fails at load.
        let other = if recurrent { "static_120_new" } else { "Jetbot_margin_dynamic" };
        let e = PolicyRunner::load(&path, Some(&contracts.join(format!("{other}.yaml")))).unwrap_err().to_string();
        assert!(e.contains("does not match its contract"), "{e}");
    }
}
