//! The batched environment: determinism whatever the thread count, automatic reset, and the
//! buffers a learner reads.

use rand::{RngExt, SeedableRng};
use rlnav_sim::task::{EnvSetup, Outcome};
use rlnav_sim::vec_env::VecEnv;
use std::sync::Arc;

/// Final observations, every reward, and (step * 1000 + env, outcome, length) of every episode end.
type Trace = (Vec<f32>, Vec<f32>, Vec<(usize, Outcome, u32)>);

fn run(scenario: &str, threads: usize, seed: u64, steps: usize) -> Trace {
    let setup = Arc::new(EnvSetup::from_scenario_name(scenario).unwrap());
    let mut env = VecEnv::new(setup, 37, seed, threads).unwrap();
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(99);
    let mut actions = vec![[0.0f32; 2]; env.len()];
    let mut rewards = Vec::new();
    let mut ends = Vec::new();
    for t in 0..steps {
        for a in &mut actions {
            *a = [rng.random_range(-1.0..=1.0), rng.random_range(-1.0..=1.0)];
        }
        env.step(&actions).unwrap();
        rewards.extend_from_slice(&env.rewards);
        for (i, f) in env.finished.iter().enumerate() {
            if let Some(s) = f {
                ends.push((t * 1000 + i, s.outcome, s.length));
            }
        }
    }
    (env.obs.clone(), rewards, ends)
}

#[test]
fn same_seed_same_results_whatever_the_thread_count() {
    for scenario in ["static-room", "random-static"] {
        let one = run(scenario, 1, 5, 150);
        let two = run(scenario, 2, 5, 150);
        let four = run(scenario, 4, 5, 150);
        assert!(!one.2.is_empty(), "episodes ended");
        assert_eq!(one, two, "{scenario}: 1 vs 2 threads");
        assert_eq!(one, four, "{scenario}: 1 vs 4 threads");
        let other = run(scenario, 2, 6, 150);
        assert_ne!(one.1, other.1, "{scenario}: another seed, another run");
    }
}

#[test]
fn finished_episodes_reset_and_report() {
    let setup = Arc::new(EnvSetup::from_scenario_name("empty-room").unwrap());
    let d = setup.obs_dim();
    let mut env = VecEnv::new(setup, 8, 1, 2).unwrap();
    // Full speed straight ahead: every robot eventually hits a wall or (rarely) its goal.
    let actions = vec![[1.0f32, 0.0]; 8];
    let mut seen = 0;
    for _ in 0..400 {
        let before: Vec<_> = env.envs().iter().map(|e| (e.pose(), e.goal())).collect();
        env.step(&actions).unwrap();
        for (i, before) in before.iter().enumerate() {
            let done = env.terminated[i] || env.truncated[i];
            assert_eq!(done, env.finished[i].is_some());
            if let Some(s) = env.finished[i] {
                seen += 1;
                assert_eq!(env.terminated[i], s.outcome != Outcome::Timeout);
                assert_eq!(env.truncated[i], s.outcome == Outcome::Timeout);
                if s.outcome == Outcome::Collision {
                    assert!(env.rewards[i] <= -29.0);
                    // The final observation saw the wall close; the new one is a fresh start.
                    let final_min = env.final_obs[i * d..i * d + 120].iter().copied().fold(f32::INFINITY, f32::min);
                    assert!(final_min < 0.3, "final obs min {final_min}");
                }
                let (pose, goal) = (env.envs()[i].pose(), env.envs()[i].goal());
                assert!(pose != before.0 || goal != before.1, "environment {i} was reset");
                // A fresh episode starts with a zero previous command.
                assert_eq!(&env.obs[i * d + 122..i * d + 124], &[0.0, 0.0]);
            }
        }
    }
    assert!(seen >= 8, "{seen} episodes ended");
}

#[test]
fn every_robot_runs_in_every_scenario() {
    use rlnav_sim::RobotSpec;
    use rlnav_sim::robot::ROBOT_PRESETS;
    use rlnav_sim::scenario::{SCENARIO_PRESETS, ScenarioSpec};
    use rlnav_sim::task::TaskConfig;
    // The held-out indoor rooms are sized for the four indoor robots: the Jackal (0.43 m of
    // clearance, BARN's robot) does not fit their 0.85-0.9 m doors and gaps, and says so.
    let too_narrow_for_jackal = ["heldout-static-corridor", "heldout-static-doorway", "heldout-static-narrow"];
    for (robot, _) in ROBOT_PRESETS {
        for (scenario, _) in SCENARIO_PRESETS {
            if *robot == "jackal" && too_narrow_for_jackal.contains(scenario) {
                let e = EnvSetup::new(
                    ScenarioSpec::load(scenario).unwrap(),
                    RobotSpec::load(robot).unwrap(),
                    TaskConfig::default(),
                )
                .unwrap_err();
                assert!(e.to_string().contains("start/goal"), "{e}");
                continue;
            }
            let setup = EnvSetup::new(
                ScenarioSpec::load(scenario).unwrap(),
                RobotSpec::load(robot).unwrap(),
                TaskConfig::default(),
            )
            .unwrap_or_else(|e| panic!("{robot} in {scenario}: {e}"));
            let mut env = VecEnv::new(Arc::new(setup), 4, 1, 1).unwrap();
            for _ in 0..50 {
                env.step(&[[0.0, 0.3]; 4]).unwrap();
                assert!(env.obs.iter().all(|x| x.is_finite()), "{robot} in {scenario}");
            }
        }
    }
}

#[test]
fn moving_obstacles_are_seen_and_hit() {
    use rlnav_sim::RobotSpec;
    use rlnav_sim::scenario::ScenarioSpec;
    use rlnav_sim::task::{NavEnv, TaskConfig};
    // A wide box sweeping down the corridor straight at a robot that stands still-ish.
    let yaml = "name: sweep\narena: {size: [6, 2]}\nmovers:\n  - {shape: {box: {size: [0.3, 1.6]}}, waypoints: [[1.2, 0], [-2.5, 0]], speed: [0.5, 0.5], random_phase: false}\nstart: {poses: [[-1.5, 0, 3.14159]]}\ngoal: {points: [[-2.5, 0.5]]}\nstart_goal_distance: [0.5, 5]\n";
    let spec: ScenarioSpec = rlnav_sim::config::from_yaml_str("sweep.yaml", yaml).unwrap();
    let setup = Arc::new(EnvSetup::new(spec, RobotSpec::load("jetbot").unwrap(), TaskConfig::default()).unwrap());
    let mut env = NavEnv::new(setup, 0).unwrap();
    // The robot faces -x (away); beam 0 looks backwards (+x), where the box comes from.
    let first = env.ranges()[0];
    assert!((first - (2.7 - 0.15)).abs() < 1e-3, "box seen 2.55 m behind: {first}");
    let mut last = first;
    let mut outcome = None;
    for _ in 0..100 {
        let out = env.step([-1.0, 0.0]);
        if out.terminated || out.truncated {
            outcome = env.last_episode().map(|e| e.outcome);
            break;
        }
        assert!(env.ranges()[0] < last, "closing in");
        last = env.ranges()[0];
    }
    assert_eq!(outcome, Some(Outcome::Collision), "the box runs the slow robot down");
}

#[test]
fn moving_goal_moves_within_the_room_and_can_be_reached() {
    use rlnav_sim::task::NavEnv;
    use rlnav_sim::{GreedyGoal, Outcome};
    let setup = Arc::new(EnvSetup::from_scenario_name("moving-goal").unwrap());
    let area = setup.scenario.area();
    let mut env = NavEnv::new(setup.clone(), 3).unwrap();
    let mut speeds = Vec::new();
    for _ in 0..300 {
        let before = env.goal();
        let out = env.step([-1.0, 1.0]);
        if out.terminated || out.truncated {
            env.reset().unwrap();
            continue;
        }
        let g = env.goal();
        assert!(area.contains(g), "goal {g:?} left the room");
        speeds.push((g - before).length() / 0.1);
    }
    // 0.05-0.15 m/s; a bounce can only shorten a step.
    assert!(speeds.iter().all(|s| *s <= 0.15 + 1e-4), "{speeds:?}");
    assert!(speeds.iter().any(|s| *s > 0.05), "the goal moves");
    let mut c = GreedyGoal::default();
    let ok = (0..30).filter(|_| env.run_episode(&mut c).unwrap().outcome == Outcome::Success).count();
    assert!(ok >= 22, "greedy catches a slow target: {ok}/30");
}

/// One difficulty parameter scales the generator: at 0 the rooms hold fewer obstacles and no
/// partitions, at 1 they are the scenario as written; the automatic curriculum moves each
/// environment's level by its episodes' outcomes.
#[test]
fn difficulty_levels_scale_the_rooms_and_follow_outcomes() {
    use rlnav_sim::ScenarioSpec;
    let spec = ScenarioSpec::load("random-rooms").unwrap();
    assert_eq!(spec.at_difficulty(1.0), spec, "full difficulty is the scenario as written");
    let easy = spec.at_difficulty(0.0);
    let g = easy.procedural.as_ref().unwrap();
    let full = spec.procedural.as_ref().unwrap();
    assert_eq!(g.count, [full.count[0], full.count[0]]);
    assert_eq!((g.on_line, g.goal_behind, g.partitions.as_ref().unwrap().probability), (0.0, 0.0, 0.0));
    let door = g.partitions.as_ref().unwrap().door;
    assert_eq!(door, [full.partitions.as_ref().unwrap().door[1]; 2], "only the widest door");
    assert!(easy.start_goal_distance[1] < spec.start_goal_distance[1]);

    // Mean obstacle count over drawn rooms grows with the level.
    let setup = EnvSetup::from_scenario_name("random-rooms").unwrap().with_difficulty_levels(3).unwrap();
    let setup = Arc::new(setup);
    let mut env = rlnav_sim::NavEnv::new(setup.clone(), 3).unwrap();
    let mut mean = Vec::new();
    for level in 0..3 {
        env.set_level(Some(level));
        let mut n = 0;
        for _ in 0..30 {
            env.reset().unwrap();
            n += env.world().obstacles().len();
        }
        mean.push(n as f32 / 30.0);
    }
    // Measured over seeds 1-8: 8.0, 10.3-11.4, 11.9-13.0 obstacles (walls included).
    assert!(mean[0] < mean[1] && mean[1] < mean[2], "obstacles per room by level: {mean:?}");

    // Success goes up, failure down (not below 0); success on the top level goes anywhere.
    env.set_level(Some(1));
    env.advance_level(true);
    assert_eq!(env.level(), Some(2));
    env.advance_level(false);
    env.advance_level(false);
    env.advance_level(false);
    assert_eq!(env.level(), Some(0));
    env.set_level(Some(7));
    assert_eq!(env.level(), Some(2), "clamped to the top level");

    // In a batch: driving straight into walls, every environment falls to level 0.
    let mut venv = VecEnv::new(setup, 8, 1, 2).unwrap();
    assert_eq!(venv.mean_difficulty(), None, "off until started");
    venv.start_levels(2, 5).unwrap();
    let start = venv.mean_difficulty().unwrap();
    assert!((0.0..=1.0).contains(&start));
    for _ in 0..600 {
        venv.step(&[[1.0f32, 0.0]; 8]).unwrap();
    }
    let after = venv.mean_difficulty().unwrap();
    // Measured over seeds 1-8: from 0.19-0.75 down to 0-0.125 (a robot that meets its goal
    // straight ahead goes up a level).
    assert!(start > 0.0 && after < start, "collisions lower the levels: {start} -> {after}");
}

#[test]
fn environments_left_out_of_a_step_stand_still_and_the_rest_are_unaffected() {
    let setup = Arc::new(EnvSetup::from_scenario_name("random-static").unwrap());
    let d = setup.obs_dim();
    let mut all = VecEnv::new(setup.clone(), 6, 3, 2).unwrap();
    let mut some = VecEnv::new(setup, 6, 3, 2).unwrap();
    let actions = vec![[0.8f32, 0.3]; 6];
    // Environment 4 sits out the first 50 steps, then joins in.
    let active = [true, true, true, true, false, true];
    let frozen = some.obs[4 * d..5 * d].to_vec();
    let mut ends = 0;
    for t in 0..200 {
        all.step(&actions).unwrap();
        some.step_some(&actions, Some(if t < 50 { &active } else { &[true; 6] })).unwrap();
        for e in [0, 1, 2, 3, 5] {
            assert_eq!(all.obs[e * d..(e + 1) * d], some.obs[e * d..(e + 1) * d], "env {e} at step {t}");
            assert_eq!((all.rewards[e], all.finished[e].is_some()), (some.rewards[e], some.finished[e].is_some()));
            ends += all.finished[e].is_some() as usize;
        }
        if t < 50 {
            assert_eq!(some.obs[4 * d..5 * d], frozen[..], "the left-out environment moved at step {t}");
            assert_eq!((some.rewards[4], some.terminated[4], some.finished[4].is_some()), (0.0, false, false));
        }
    }
    assert!(ends > 0, "episodes ended in 200 steps");
    assert_ne!(some.obs[4 * d..5 * d], frozen[..], "it moves once it is back in");
}

#[test]
fn privileged_state_is_kept_now_and_at_each_episode_end() {
    use rlnav_sim::task::{PRIVILEGED_PER_MOVER, privileged_len};
    let setup = Arc::new(EnvSetup::from_scenario_name("heldout-dynamic-fast-crossing").unwrap());
    let mut env = VecEnv::new(setup, 8, 3, 2).unwrap();
    assert_eq!(env.privileged_dim(), 0, "none kept unless asked");
    env.step(&[[1.0, 0.0]; 8]).unwrap();
    assert!(env.privileged.is_empty() && env.final_privileged.is_empty());
    let k = 2;
    env.set_privileged(k);
    let p = privileged_len(k);
    assert_eq!(env.privileged_dim(), p);
    let mut row = vec![0.0; p];
    let (mut ends, mut hit_by_mover) = (0, 0);
    for _ in 0..300 {
        // Towards the goal at full speed, blind: the crossing box meets some robots.
        let actions: Vec<[f32; 2]> = env
            .envs()
            .iter()
            .map(|e| {
                let (_, bearing) = e.pose().polar_of(e.goal());
                [1.0, (2.0 * bearing).clamp(-1.0, 1.0)]
            })
            .collect();
        env.step(&actions).unwrap();
        for (i, e) in env.envs().iter().enumerate() {
            e.write_privileged(k, &mut row);
            assert_eq!(&env.privileged[i * p..(i + 1) * p], row.as_slice(), "env {i}: the current state");
            if !(env.terminated[i] || env.truncated[i]) {
                continue;
            }
            ends += 1;
            let last = &env.final_privileged[i * p..(i + 1) * p];
            assert_ne!(last, row.as_slice(), "env {i}: the episode's last state, not the new episode's first");
            let gap = (last[0].hypot(last[1]) - last[4]).max(0.0);
            if env.finished[i].is_some_and(|s| s.outcome == Outcome::Collision) && gap < 0.6 {
                hit_by_mover += 1;
            }
            assert!(last[..PRIVILEGED_PER_MOVER * k].iter().all(|v| v.is_finite()));
        }
    }
    assert!(ends >= 4, "episodes ended: {ends}");
    assert!(hit_by_mover >= 1, "a blind robot is hit by the box, its final state shows it near");
}
