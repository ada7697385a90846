//! Pedestrians: they reach their goals, avoid each other, the furniture and the robot (ORCA);
//! the lidar sees them; touching one ends the episode; the social-safety penalty is off by
//! default and grows as the robot comes closer.

use rand::SeedableRng;
use rlnav_sim::Vec2;
use rlnav_sim::geometry::{Obstacle, ObstacleSpec};
use rlnav_sim::people::{Crowd, PersonSpec};
use rlnav_sim::task::{EnvSetup, NavEnv, TaskConfig};
use rlnav_sim::{Outcome, RobotSpec, Twist, World};
use std::sync::Arc;

fn person(goals: Vec<[f32; 2]>, speed: f32) -> PersonSpec {
    PersonSpec { radius: 0.25, goals, speed: [speed, speed], order: Default::default(), random_start: false }
}

/// dodgy_2d's linear program panics on NaN constraints; a person whose ORCA solve fails
/// stands still for the step rather than the simulator aborting.
#[test]
fn a_failed_orca_solve_stops_the_person_not_the_simulator() {
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(0);
    let a = person(vec![[-3.0, 0.0], [3.0, 0.0]], 1.0).instantiate(&mut rng);
    let mut crowd = Crowd::new(vec![a], &World::new(Vec::new()));
    // The solver itself panics here (a NaN neighbour makes every constraint NaN).
    let nan = Vec2::new(f32::NAN, f32::NAN);
    let failed = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        let mut c = crowd.clone();
        c.plan(nan, 0.2, 0.1, &mut rand_pcg::Pcg64Mcg::seed_from_u64(1));
        c.people[0].velocity
    }));
    let v = failed.expect("plan does not panic");
    assert_eq!(v, Vec2::ZERO, "the person stands still");
    // With a sane robot the same person walks again.
    crowd.plan(Vec2::new(50.0, 50.0), 0.2, 0.1, &mut rng);
    assert!(crowd.people[0].velocity.length() > 0.5, "{:?}", crowd.people[0].velocity);
}

#[test]
fn two_people_swap_places_without_touching() {
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(0);
    let a = person(vec![[-3.0, 0.0], [3.0, 0.0]], 1.0).instantiate(&mut rng);
    let b = person(vec![[3.0, 0.01], [-3.0, 0.01]], 1.0).instantiate(&mut rng);
    let mut crowd = Crowd::new(vec![a, b], &World::new(Vec::new()));
    // The robot stands far away.
    let far = Vec2::new(50.0, 50.0);
    let mut closest = f32::INFINITY;
    let mut reached = [false, false];
    for _ in 0..150 {
        crowd.plan(far, 0.2, 0.1, &mut rng);
        for _ in 0..5 {
            crowd.advance(0.02);
        }
        let (p, q) = (&crowd.people[0], &crowd.people[1]);
        closest = closest.min((p.position - q.position).length() - p.radius - q.radius);
        reached[0] |= (p.position - Vec2::new(3.0, 0.0)).length() < 0.25;
        reached[1] |= (q.position - Vec2::new(-3.0, 0.01)).length() < 0.25;
    }
    assert!(reached[0] && reached[1], "both cross the room");
    assert!(closest > -0.02, "they pass each other ({closest} m)");
    assert!(closest < 0.5, "and they do meet on the way ({closest} m)");
}

#[test]
fn a_person_walks_around_the_robot_and_the_furniture() {
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(1);
    let world =
        World::new(vec![Obstacle::new(ObstacleSpec::Box { center: [1.5, 0.0], size: [0.6, 0.6], yaw: 0.0 }).unwrap()]);
    let p = person(vec![[-3.0, 0.0], [4.0, 0.0], [-3.0, 0.0]], 0.8).instantiate(&mut rng);
    let mut crowd = Crowd::new(vec![p], &world);
    let robot = Vec2::new(-1.0, 0.05);
    let (mut gap_robot, mut gap_box) = (f32::INFINITY, f32::INFINITY);
    let mut far_end = false;
    for _ in 0..200 {
        crowd.plan(robot, 0.3, 0.1, &mut rng);
        for _ in 0..5 {
            crowd.advance(0.02);
            let q = &crowd.people[0];
            gap_robot = gap_robot.min((q.position - robot).length() - q.radius - 0.3);
            gap_box = gap_box.min(world.clearance(q.position) - q.radius);
            far_end |= q.position.x > 3.7;
        }
    }
    assert!(far_end, "the person gets past both (ends at {:?})", crowd.people[0].position);
    assert!(gap_robot > -0.02, "keeps off the robot ({gap_robot})");
    assert!(gap_box > -0.02, "keeps off the box ({gap_box})");
}

fn people_env(yaml: &str, task: TaskConfig, seed: u64) -> NavEnv {
    let spec = rlnav_sim::config::from_yaml_str("test.yaml", yaml).unwrap();
    NavEnv::new(Arc::new(EnvSetup::new(spec, RobotSpec::load("jetbot").unwrap(), task).unwrap()), seed).unwrap()
}

/// A robot facing a person who walks straight at it down a corridor too narrow to pass.
const HEAD_ON: &str = "name: head-on\narena: {size: [8.0, 1.2]}\n\
    start: {poses: [[-3.0, 0.0, 0.0]]}\ngoal: {points: [[3.0, 0.0]]}\nstart_goal_distance: [5, 7]\nmargin: 0\n\
    people:\n  - {goals: [[3.2, 0.0], [-3.6, 0.0]], speed: [1.0, 1.0], random_start: false}\n";

#[test]
fn the_lidar_sees_people_and_touching_one_is_a_collision() {
    let mut env = people_env(HEAD_ON, TaskConfig::default(), 0);
    assert_eq!(env.people().len(), 1);
    // Beam 180 of the Jetbot's lidar looks straight ahead: it reads the person, not the wall.
    let ahead = env.ranges()[180];
    assert!((ahead - (6.2 - 0.25)).abs() < 1e-3 || ahead.is_infinite(), "{ahead}");
    let mut saw = false;
    let mut outcome = None;
    for _ in 0..100 {
        let s = env.step_twist(Twist::new(0.3, 0.0));
        // The beam pointing at the person's centre reads the distance to their surface.
        let (dist, bearing) = env.pose().polar_of(env.people()[0].position);
        let d = dist - 0.25;
        let beam = ((bearing + std::f32::consts::PI) / (std::f32::consts::TAU / 360.0)).round() as usize % 360;
        if d < 2.5 && d > 0.3 {
            assert!((env.ranges()[beam] - d).abs() < 0.01, "beam {beam}: {} vs {d}", env.ranges()[beam]);
            saw = true;
        }
        if s.terminated {
            outcome = env.last_episode().map(|e| (e.outcome, e.min_person_gap));
            break;
        }
    }
    assert!(saw, "the person is in the scan where they are");
    let (o, gap) = outcome.expect("the episode ends");
    assert_eq!(o, Outcome::Collision);
    assert!(gap < 0.2, "logged closest gap {gap}");
}

#[test]
fn social_penalty_is_off_by_default_and_grows_near_people() {
    assert_eq!(TaskConfig::default().reward.social, 0.0);
    let mut social = TaskConfig::default();
    social.reward.social = 1.0;
    social.reward.social_radius = 1.5;
    let (mut off, mut on) = (people_env(HEAD_ON, TaskConfig::default(), 4), people_env(HEAD_ON, social, 4));
    let mut penalties = Vec::new();
    for _ in 0..100 {
        let a = off.step_twist(Twist::new(0.2, 0.0));
        let b = on.step_twist(Twist::new(0.2, 0.0));
        // Same seed, same motion: only the reward differs.
        assert_eq!(off.pose(), on.pose());
        let gap = (on.people()[0].position - on.pose().position()).length() - 0.25 - on.setup().footprint.radius();
        let expected = ((1.5 - gap.max(0.0)) / 1.5).max(0.0);
        assert!((a.reward - b.reward - expected).abs() < 1e-4, "gap {gap}: {} vs {}", a.reward, b.reward);
        penalties.push(a.reward - b.reward);
        if a.terminated || a.truncated {
            break;
        }
    }
    assert!(penalties.first().unwrap() == &0.0 && *penalties.last().unwrap() > 0.5, "{penalties:?}");
    assert!(penalties.windows(2).all(|w| w[1] >= w[0] - 1e-4), "grows as they close in: {penalties:?}");
}

#[test]
fn people_room_is_deterministic_and_bad_people_are_named() {
    let run = |seed| {
        let mut env = NavEnv::new(Arc::new(EnvSetup::from_scenario_name("people-room").unwrap()), seed).unwrap();
        let mut trace = Vec::new();
        for _ in 0..300 {
            env.step([0.5, 0.2]);
            trace.extend(env.people().iter().map(|p| p.position));
        }
        trace
    };
    assert_eq!(run(3), run(3));
    let e = rlnav_sim::config::from_yaml_str::<rlnav_sim::ScenarioSpec>(
        "p.yaml",
        "name: p\narena: {size: [4, 4]}\npeople:\n  - {goals: [[0, 0]]}\n",
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("p.yaml") && e.contains("people[0].goals") && e.contains("at least two"), "{e}");
}

/// A cart coming head-on 0.6 m beside the robot's line, which it passes without touching.
const CART: &str = "name: cart\narena: {size: [8.0, 3.0]}\n\
    start: {poses: [[-3.0, 0.0, 0.0]]}\ngoal: {points: [[3.5, 0.0]]}\nstart_goal_distance: [5, 7]\nmargin: 0\n\
    movers:\n  - {shape: {box: {size: [0.4, 0.4]}}, waypoints: [[3.0, 0.6], [-3.5, 0.6]], speed: [0.3, 0.3], random_phase: false}\n";

#[test]
fn social_penalty_counts_movers_on_request_and_looks_ahead() {
    let task = |movers: bool, horizon: f32| {
        let mut t = TaskConfig::default();
        t.reward.social = 1.0;
        t.reward.social_radius = 1.0;
        t.reward.social_movers = movers;
        t.reward.social_horizon = horizon;
        people_env(CART, t, 0)
    };
    let mut envs = [people_env(CART, TaskConfig::default(), 0), task(false, 0.0), task(true, 0.0), task(true, 3.0)];
    let (mut now, mut ahead, mut behind) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..150 {
        let r: Vec<f32> = envs.iter_mut().map(|e| e.step_twist(Twist::new(0.3, 0.0)).reward).collect();
        assert!(envs.iter().all(|e| e.pose() == envs[0].pose()), "same motion");
        let env = &envs[2];
        let cart = &env.movers()[0];
        assert!((cart.velocity - Vec2::new(-0.3, 0.0)).length() < 1e-4, "{:?}", cart.velocity);
        // Without `social_movers` a cart costs nothing; with it, the gap now.
        assert_eq!(r[0], r[1]);
        let gap = cart.signed_distance(env.pose().position()) - env.setup().footprint.radius();
        let expected = ((1.0 - gap.max(0.0)) / 1.0).max(0.0);
        assert!((r[0] - r[2] - expected).abs() < 1e-4, "gap {gap}: {} vs {}", r[0], r[2]);
        now.push(r[0] - r[2]);
        ahead.push(r[0] - r[3]);
        behind.push(cart.pose.x < env.pose().x - 0.3);
        if cart.pose.x < env.pose().x - 1.5 {
            break;
        }
    }
    let onset = |p: &[f32]| p.iter().position(|&v| v > 0.0).expect("charged at some point");
    // Closing at 0.6 m/s, the look-ahead charges the crossing about 3 s (30 steps) before the
    // gap itself falls under the radius, and charges at least as much while they close in.
    assert!(onset(&ahead) + 20 < onset(&now), "onset {} vs {}", onset(&ahead), onset(&now));
    assert!(now.iter().zip(&ahead).all(|(n, a)| a >= &(n - 1e-5)), "{now:?}\n{ahead:?}");
    // Once the cart is past, the nearest approach is now: the same charge.
    let passed = behind.iter().position(|&b| b).expect("the cart passes");
    assert!((now[passed] - ahead[passed]).abs() < 1e-5 && now[passed] > 0.0, "{} vs {}", now[passed], ahead[passed]);
    assert!(*now.iter().max_by(|a, b| a.total_cmp(b)).unwrap() > 0.5, "{now:?}");
}
