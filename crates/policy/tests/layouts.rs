//! The reference article's other observation layouts (a 133-input MLP and a 73-input LSTM:
//! ranges, the last 5 goal bearings and distances, forward, lateral and angular velocity)
//! through their side contracts: models of exactly those shapes load, the runner puts every
//! value where the layout says, the goal history follows the steps taken and starts again at
//! `Controller::reset()`, and the simulator trains on the same vector the runner builds.

mod common;

use burn::prelude::*;
use rlnav_policy::contract::{ActionContract, ActionScaling, PolicyContract};
use rlnav_policy::export::{echo_model, export_model};
use rlnav_policy::{ActorCritic, NetworkConfig, PolicyRunner, RunningMeanStd};
use rlnav_sim::task::{EnvSetup, NavEnv, ObsTerm, TaskConfig};
use rlnav_sim::{Controller, LaserScan, Pose2, RobotObservation, RobotSpec, ScenarioSpec, Twist, Vec2};
use std::f32::consts::PI;
use std::path::{Path, PathBuf};
use std::sync::Arc;

fn contract_path(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../contracts").join(name)
}

/// The side contracts of the two layouts: `(file, observation length, ranges, recurrent)`.
const LAYOUTS: [(&str, usize, usize, bool); 2] =
    [("article-mlp-133.yaml", 133, 120, false), ("article-lstm-73.yaml", 73, 60, true)];

/// A runner of a small random network under contract `c` (given the robot's own scan geometry,
/// so that the scans need no re-sampling, and no recurrent state) beside an environment of
/// `setup`: the pair [`common::runner_matches_simulator`] compares. `name` names the model.
fn runner_beside(mut c: PolicyContract, setup: Arc<EnvSetup>, name: &str) -> (PolicyRunner, NavEnv) {
    let n = c.observation.len();
    c.scan = rlnav_policy::contract::ScanContract::of(&setup.robot.lidar);
    c.io.recurrent.clear();
    let net = ActorCritic::seeded(&NetworkConfig { hidden: vec![16], ..Default::default() }, n, 2, &Device::flex(), 2);
    let proto = export_model(&net, &RunningMeanStd::new(n), &c).unwrap();
    (PolicyRunner::from_proto(name, &proto, c).unwrap(), NavEnv::new(setup, 8).unwrap())
}

#[test]
fn every_side_contract_loads_and_the_new_layouts_have_their_length() {
    let mut names = Vec::new();
    for entry in std::fs::read_dir(contract_path("")).unwrap() {
        let path = entry.unwrap().path();
        let c = PolicyContract::from_file(&path).unwrap_or_else(|e| panic!("{e}"));
        // What an export would embed reads back the same.
        assert_eq!(PolicyContract::from_yaml("embedded", &c.to_yaml()).unwrap(), c, "{}", path.display());
        names.push(path.file_name().unwrap().to_string_lossy().into_owned());
    }
    for known in ["static_120_new.yaml", "Jetbot_margin_dynamic.yaml", "article-mlp-133.yaml", "article-lstm-73.yaml"] {
        assert!(names.iter().any(|n| n == known), "{known} missing from contracts/ ({names:?})");
    }
    for (file, n, ranges, recurrent) in LAYOUTS {
        let c = PolicyContract::from_file(&contract_path(file)).unwrap();
        assert_eq!(c.obs_dim(), n, "{file}");
        assert_eq!(c.observation.0[0].lidar(), Some((ranges, [0.15, 2.0])), "{file}");
        assert_eq!(&c.observation.0[3..], &[ObsTerm::Linear, ObsTerm::Lateral, ObsTerm::Angular], "{file}");
        let names: Vec<(&str, &str)> = c.io.recurrent.iter().map(|s| (s.input.as_str(), s.output.as_str())).collect();
        let want: &[(&str, &str)] =
            if recurrent { &[("out_state.1", "out_state"), ("hidden_state.1", "hidden_state")] } else { &[] };
        assert_eq!(names, want, "{file}");
    }
}

/// What the robot reports at step `t` of a made-up drive: a 360-beam scan in the contract's own
/// geometry (beam `i` reads `0.2 + 0.005 i` m), a goal that moves around the robot, and
/// velocities that change every step.
fn robot_at(t: usize) -> RobotObservation {
    let t = t as f32;
    RobotObservation {
        scan: LaserScan {
            angle_min: -PI,
            angle_increment: 2.0 * PI / 360.0,
            range_min: 0.1,
            range_max: 10.0,
            ranges: (0..360).map(|i| 0.2 + 0.005 * i as f32).collect(),
        },
        pose: Pose2::new(0.1 * t, -0.05 * t, 0.2 * t - 0.5),
        goal: Vec2::new(3.0 - 0.3 * t, 1.0 + 0.2 * t),
        velocity: Twist::new(0.1 + 0.02 * t, 0.3 - 0.07 * t),
        lateral_velocity: 0.01 * t - 0.004,
        ..Default::default()
    }
}

/// Value `i` of the layout `[ranges, bearings of the last 5 steps (oldest first), distances of
/// the last 5 steps, v_x, v_y, ω]`, written out independently of the runner: `seen` are the
/// robot observations of the episode so far, the current one last.
fn expected(ranges: usize, i: usize, seen: &[RobotObservation]) -> f32 {
    let now = seen.last().unwrap();
    if i < ranges {
        // Min-pooled: the first beam of each group of 360 / ranges is the smallest.
        return 0.2 + 0.005 * (i * 360 / ranges) as f32;
    }
    // Slot j of 5 holds the step 4 - j steps back; before the episode's first, its first.
    let back = |j: usize| &seen[(seen.len() + j).saturating_sub(5)];
    match i - ranges {
        j @ 0..5 => back(j).goal_polar().1,
        j @ 5..10 => back(j - 5).goal_polar().0,
        10 => now.velocity.linear,
        11 => now.lateral_velocity,
        12 => now.velocity.angular,
        _ => unreachable!("the layout has {} values", ranges + 13),
    }
}

#[test]
fn the_runner_puts_every_value_where_the_layout_says() {
    for (file, n, ranges, _) in LAYOUTS {
        let mut contract = PolicyContract::from_file(&contract_path(file)).unwrap();
        // Commands equal to mu: the echo model's outputs come back unclipped.
        contract.action = ActionContract {
            scaling: ActionScaling::Direct,
            linear: [-100.0, 100.0],
            angular: [-100.0, 100.0],
            linear_relative: false,
        };
        // Every non-range value, and ranges at both ends and in the middle.
        let mut probes: Vec<usize> = vec![0, ranges / 2, ranges - 1];
        probes.extend(ranges..n);
        for pair in probes.chunks(2) {
            let reads = [pair[0], *pair.last().unwrap()];
            let proto = echo_model(n, reads, &contract.io).unwrap();
            let mut runner = PolicyRunner::from_proto("echo.onnx", &proto, contract.clone()).unwrap();
            // Seven steps (the history fills and rolls), a reset, then two steps of a new episode.
            let mut seen = Vec::new();
            for t in 0..10 {
                if t == 7 {
                    runner.reset();
                    seen.clear();
                }
                let o = robot_at(t);
                seen.push(o.clone());
                // Building the observation to look at it does not advance the history.
                let built = runner.build_observation(&o).unwrap().to_vec();
                let cmd = runner.act(&o);
                assert!(runner.fault().is_none(), "{file}: {:?}", runner.fault());
                for (k, got) in [(reads[0], cmd.linear), (reads[1], cmd.angular)] {
                    let want = expected(ranges, k, &seen);
                    assert!((got - want).abs() < 1e-5, "{file} step {t}: value {k} is {got}, the layout says {want}");
                    assert_eq!(built[k], got, "{file} step {t}: value {k}");
                }
            }
        }
    }
}

#[test]
fn models_of_the_article_shapes_load_and_drive() {
    for (file, n, _, recurrent) in LAYOUTS {
        let contract = PolicyContract::from_file(&contract_path(file)).unwrap();
        // An rl_games-like net (normalisation inside) of the layout's shape, contract stripped:
        // a foreign model that needs the side file.
        let config =
            NetworkConfig { hidden: vec![32], lstm_units: if recurrent { 64 } else { 0 }, ..Default::default() };
        let net = ActorCritic::seeded(&config, n, 2, &Device::flex(), 4);
        let mut proto = export_model(&net, &RunningMeanStd::new(n), &contract).unwrap();
        proto.metadata_props.clear();
        let mut runner = PolicyRunner::from_proto(file, &proto, contract.clone()).unwrap();
        for t in 0..6 {
            let c = runner.act(&robot_at(t));
            assert!(runner.fault().is_none(), "{file}: {:?}", runner.fault());
            assert!((0.1..=0.4).contains(&c.linear) && (-0.5..=0.5).contains(&c.angular), "{file}: {c:?}");
        }
        // A model one value longer does not fit the layout.
        let mut feed_forward = contract.clone();
        feed_forward.io.recurrent.clear();
        let mut longer = feed_forward.clone();
        longer.observation.0.push(ObsTerm::Lateral);
        let other =
            ActorCritic::seeded(&NetworkConfig { hidden: vec![8], ..Default::default() }, n + 1, 2, &Device::flex(), 4);
        let proto = export_model(&other, &RunningMeanStd::new(n + 1), &longer).unwrap();
        let e = PolicyRunner::from_proto("wrong.onnx", &proto, feed_forward).unwrap_err().to_string();
        assert!(e.contains(&format!("{n} values")), "{e}");
    }
}

#[test]
fn the_simulator_trains_on_what_the_runner_builds_for_the_history_layouts() {
    for (file, n, _, _) in LAYOUTS {
        let contract = PolicyContract::from_file(&contract_path(file)).unwrap();
        let spec = ScenarioSpec::load("static-room").unwrap();
        let robot = RobotSpec::load(&spec.robot).unwrap();
        let task = TaskConfig { observation: contract.observation.clone(), ..Default::default() };
        let setup = Arc::new(EnvSetup::new(spec, robot, task).unwrap());
        assert_eq!(setup.obs_dim(), n);
        let (mut runner, mut env) = runner_beside(contract, setup, "sim.onnx");
        let steps = common::runner_matches_simulator(&mut runner, &mut env, file);
        assert!(steps > 20, "{file}: {steps} steps compared");
    }
}

/// A `plan_ahead` term, with and without a global plan: the runner shows the same points of
/// the path ahead as the simulator trained on, in a room known in advance (where both follow
/// the plan) and in generated ones (where both show the line to the goal).
#[test]
fn the_simulator_and_the_runner_agree_on_the_path_ahead() {
    use rlnav_sim::task::PlanConfig;
    for (scenario, plan) in [("heldout-static-u-trap", true), ("random-static", false)] {
        let mut c = PolicyContract::from_file(&contract_path("article-mlp-133.yaml")).unwrap();
        c.observation = rlnav_sim::ObservationLayout(vec![
            ObsTerm::Lidar { beams: 120, clip: [0.15, 3.0], sweep: 0.0 },
            ObsTerm::GoalDistance,
            ObsTerm::GoalBearing,
            ObsTerm::PlanAhead { points: 4, spacing: 0.3 },
        ]);
        c.plan = plan.then_some(PlanConfig { lookahead: 1.0 });
        let n = c.observation.len();
        assert_eq!(n, 130);
        let spec = ScenarioSpec::load(scenario).unwrap();
        let robot = RobotSpec::load("jetbot").unwrap();
        let task = TaskConfig { observation: c.observation.clone(), plan: c.plan.clone(), ..Default::default() };
        let setup = Arc::new(EnvSetup::new(spec, robot, task).unwrap());
        let (mut runner, mut env) = runner_beside(c, setup, "ahead.onnx");
        assert_eq!(env.plan().is_empty(), !plan, "{scenario}");
        let mut obs = vec![0.0; n];
        env.write_observation(&mut obs);
        // The first point lies 0.3 m along the path.
        let first = Vec2::new(obs[122], obs[123]).length();
        assert!((first - 0.3).abs() < 0.05, "{scenario}: first point {first} m away");
        let steps = common::runner_matches_simulator(&mut runner, &mut env, scenario);
        assert!(steps > 20, "{scenario}: {steps} steps compared");
    }
}

/// Past scans moved by the robot's motion (`ego_motion`), swept: the runner moves them by the
/// pose the robot reports, from the lidar's mount (the Burger's sits 3.2 cm behind
/// `base_link`), as the simulator does by the scanner's pose, so they agree value for value;
/// among movers, so do the predicted scans (`predict`).
#[test]
fn the_simulator_and_the_runner_agree_on_past_scans_moved_by_the_robot() {
    for (scenario, predict) in [("heldout-static-office", 0.0), ("heldout-dynamic-office", 1.5)] {
        let mut c = PolicyContract::from_file(&contract_path("article-mlp-133.yaml")).unwrap();
        c.observation = rlnav_sim::ObservationLayout(vec![
            ObsTerm::History {
                term: Box::new(ObsTerm::Lidar { beams: 120, clip: [0.15, 3.0], sweep: 0.25 }),
                steps: 3,
                stride: 2,
                order: rlnav_sim::task::HistoryOrder::OldestFirst,
                fill: rlnav_sim::task::HistoryFill::First,
                ego_motion: true,
                predict,
            },
            ObsTerm::GoalDistance,
            ObsTerm::GoalBearing,
        ]);
        let spec = ScenarioSpec::load(scenario).unwrap();
        let robot = RobotSpec::load("turtlebot3-burger").unwrap();
        assert!(robot.lidar.mount.x != 0.0);
        let task = TaskConfig { observation: c.observation.clone(), ..Default::default() };
        let setup = Arc::new(EnvSetup::new(spec, robot, task).unwrap());
        let (mut runner, mut env) = runner_beside(c, setup, "ego.onnx");
        let steps = common::runner_matches_simulator(&mut runner, &mut env, scenario);
        assert!(steps > 20, "{scenario}: {steps} steps compared");
    }
}

/// Past scans are moved by bearings counter-clockwise from `angle_min`: a contract whose beams
/// run clockwise is refused with the key to change, not moved the mirrored way.
#[test]
fn a_clockwise_scan_with_moved_past_scans_is_refused() {
    use rlnav_sim::config::Validate;
    let mut c = PolicyContract::from_file(&contract_path("article-mlp-133.yaml")).unwrap();
    c.observation = rlnav_sim::ObservationLayout(vec![ObsTerm::History {
        term: Box::new(ObsTerm::Lidar { beams: 120, clip: [0.15, 3.0], sweep: 0.0 }),
        steps: 2,
        stride: 1,
        order: rlnav_sim::task::HistoryOrder::OldestFirst,
        fill: rlnav_sim::task::HistoryFill::First,
        ego_motion: true,
        predict: 0.0,
    }]);
    c.validate().unwrap();
    c.scan.direction = rlnav_policy::contract::BeamOrder::Clockwise;
    let e = c.validate().unwrap_err();
    assert_eq!(e.key, "scan.direction");
}
