//! Domain randomisation: each term does what it says (statistics over many samples), and with
//! every term off episodes are bit-identical to the default task.

use rlnav_sim::RobotSpec;
use rlnav_sim::scenario::ScenarioSpec;
use rlnav_sim::task::{EnvSetup, NavEnv, RandomizationConfig, TaskConfig};
use std::sync::Arc;

fn env(scenario: &str, dr: RandomizationConfig, seed: u64) -> NavEnv {
    let spec = if scenario.contains("name:") {
        rlnav_sim::config::from_yaml_str("test.yaml", scenario).unwrap()
    } else {
        ScenarioSpec::load(scenario).unwrap()
    };
    let task = TaskConfig { randomization: dr, ..Default::default() };
    NavEnv::new(Arc::new(EnvSetup::new(spec, RobotSpec::load("jetbot").unwrap(), task).unwrap()), seed).unwrap()
}

fn mean_std(v: &[f32]) -> (f32, f32) {
    let m = v.iter().sum::<f32>() / v.len() as f32;
    (m, (v.iter().map(|x| (x - m).powi(2)).sum::<f32>() / v.len() as f32).sqrt())
}

/// A 2.6 m square room: every beam of a 3 m lidar hits a wall.
const SMALL_ROOM: &str = "name: small\narena: {size: [2.6, 2.6]}\nstart_goal_distance: [0.5, 1.5]\n";

#[test]
fn all_off_is_bit_identical() {
    let (mut a, mut b) =
        (env("static-room", RandomizationConfig::default(), 3), env("static-room", RandomizationConfig::default(), 3));
    let base = NavEnv::new(Arc::new(EnvSetup::from_scenario_name("static-room").unwrap()), 3).unwrap();
    assert_eq!((a.pose(), a.goal()), (base.pose(), base.goal()));
    let (mut oa, mut ob) = (vec![0.0; 124], vec![0.0; 124]);
    for i in 0..2000 {
        let act = [((i * 7) % 11) as f32 / 5.0 - 1.0, ((i * 3) % 7) as f32 / 3.0 - 1.0];
        let (ra, rb) = (a.step(act), b.step(act));
        assert_eq!(ra, rb);
        a.write_observation(&mut oa);
        b.write_observation(&mut ob);
        assert_eq!(oa, ob);
        if ra.terminated || ra.truncated {
            a.reset().unwrap();
            b.reset().unwrap();
        }
    }
}

#[test]
fn observation_noise_has_the_stated_spread() {
    let dr = RandomizationConfig {
        obs_lidar_std: 0.05,
        obs_goal_distance_std: 0.1,
        obs_goal_bearing_std: 0.02,
        ..Default::default()
    };
    let (mut lidar, mut dist, mut bearing) = (Vec::new(), Vec::new(), Vec::new());
    for seed in 0..200 {
        let mut clean = env(SMALL_ROOM, RandomizationConfig::default(), seed);
        let mut noisy = env(SMALL_ROOM, dr.clone(), seed);
        let (mut c, mut n) = (vec![0.0; 124], vec![0.0; 124]);
        clean.write_observation(&mut c);
        noisy.write_observation(&mut n);
        // Values well inside the clip range, so clipping does not shrink the noise.
        lidar.extend(c[..120].iter().zip(&n[..120]).filter(|(c, _)| (0.4..2.6).contains(*c)).map(|(c, n)| n - c));
        dist.push(n[120] - c[120]);
        bearing.push(rlnav_sim::wrap_angle(n[121] - c[121]));
    }
    let (m, s) = mean_std(&lidar);
    assert!(m.abs() < 0.003 && (s - 0.05).abs() < 0.003, "lidar noise mean {m} std {s}");
    let (m, s) = mean_std(&dist);
    assert!(m.abs() < 0.02 && (s - 0.1).abs() < 0.015, "distance noise mean {m} std {s}");
    let (_, s) = mean_std(&bearing);
    assert!((s - 0.02).abs() < 0.003, "bearing noise std {s}");
}

#[test]
fn action_noise_and_latency() {
    let mut e = env("empty-room", RandomizationConfig { action_std: 0.2, ..Default::default() }, 1);
    let mut lin = Vec::new();
    for _ in 0..3000 {
        let out = e.step([0.0, 0.0]);
        lin.push(e.applied_command().linear);
        if out.terminated || out.truncated {
            e.reset().unwrap();
        }
    }
    // a = 0 + N(0, 0.2) maps to v = 0.3 + a * 0.2 m/s: std 0.04 m/s.
    let (m, s) = mean_std(&lin);
    assert!((m - 0.3).abs() < 0.005 && (s - 0.04).abs() < 0.004, "applied v mean {m} std {s}");

    let mut e = env("empty-room", RandomizationConfig { latency_steps: 3, ..Default::default() }, 2);
    let actions: Vec<[f32; 2]> = (0..10).map(|i| [i as f32 / 10.0, -(i as f32) / 10.0]).collect();
    let task = TaskConfig::default();
    for (i, a) in actions.iter().enumerate() {
        e.step(*a);
        let expected = if i >= 3 { task.action.to_twist(actions[i - 3]) } else { Default::default() };
        assert_eq!(e.applied_command(), expected, "step {i}");
    }
}

#[test]
fn lidar_dropout_rate() {
    let mut e = env(SMALL_ROOM, RandomizationConfig { lidar_dropout: 0.1, ..Default::default() }, 4);
    let mut dropped = 0usize;
    let mut total = 0usize;
    for _ in 0..200 {
        let out = e.step([-1.0, 1.0]);
        dropped += e.ranges().iter().filter(|r| r.is_infinite()).count();
        total += e.ranges().len();
        if out.terminated || out.truncated {
            e.reset().unwrap();
        }
    }
    let rate = dropped as f32 / total as f32;
    assert!((rate - 0.1).abs() < 0.01, "dropout {rate}");
    let clean = env(SMALL_ROOM, RandomizationConfig::default(), 4);
    assert!(clean.ranges().iter().all(|r| r.is_finite()), "without dropout every beam hits a wall");
}

#[test]
fn per_episode_jitter_is_within_bounds_and_logged() {
    let dr = RandomizationConfig {
        wheel_radius_jitter: 0.1,
        wheel_separation_jitter: 0.05,
        speed_limit_jitter: 0.2,
        ..Default::default()
    };
    let robot = RobotSpec::load("jetbot").unwrap();
    let mut e = env("empty-room", dr, 5);
    let (mut radii, mut scales) = (Vec::new(), Vec::new());
    for _ in 0..300 {
        let p = e.drive_params();
        assert!((p.wheel_radius / robot.wheel_radius - 1.0).abs() <= 0.1 + 1e-6);
        assert!((p.wheel_separation / robot.wheel_separation - 1.0).abs() <= 0.05 + 1e-6);
        let scale = p.max_angular / robot.max_angular;
        assert!((scale - 1.0).abs() <= 0.2 + 1e-6 && (p.linear[1] / robot.max_linear - scale).abs() < 1e-5);
        radii.push(p.wheel_radius / robot.wheel_radius);
        scales.push(scale);
        // Drive the episode to its end: the statistics log what was drawn.
        let stats = loop {
            let out = e.step([1.0, 0.0]);
            if out.terminated || out.truncated {
                break e.last_episode().unwrap();
            }
        };
        assert_eq!((stats.wheel_radius, stats.speed_scale), (p.wheel_radius, scale));
        e.reset().unwrap();
    }
    // Uniform on [-j, j]: std j / sqrt(3).
    let (m, s) = mean_std(&radii);
    assert!((m - 1.0).abs() < 0.01 && (s - 0.1 / 3f32.sqrt()).abs() < 0.008, "radius scale mean {m} std {s}");
    let (m, s) = mean_std(&scales);
    assert!((m - 1.0).abs() < 0.02 && (s - 0.2 / 3f32.sqrt()).abs() < 0.015, "speed scale mean {m} std {s}");
}
