//! What several policy tests share.

use rlnav_policy::PolicyRunner;
use rlnav_sim::{Controller, NavEnv, RobotObservation};

/// Drives `env` with `runner` for three episodes and checks, at every step, that the runner
/// builds from the robot's report the observation the simulator writes for training; returns
/// the steps compared. `label` names the case in failures.
pub fn runner_matches_simulator(runner: &mut PolicyRunner, env: &mut NavEnv, label: &str) -> usize {
    let n = env.setup().obs_dim();
    let (mut sim_obs, mut robot) = (vec![0.0; n], RobotObservation::default());
    let mut steps = 0;
    for _ in 0..3 {
        runner.reset();
        loop {
            env.write_observation(&mut sim_obs);
            env.robot_observation(&mut robot);
            let built = runner.build_observation(&robot).unwrap().to_vec();
            for (i, (a, b)) in built.iter().zip(&sim_obs).enumerate() {
                assert!((a - b).abs() <= 1e-6, "{label} step {steps} value {i}: runner {a} simulator {b}");
            }
            let cmd = runner.act(&robot);
            assert!(runner.fault().is_none(), "{label}: {:?}", runner.fault());
            steps += 1;
            let s = env.step_twist(cmd);
            if s.terminated || s.truncated {
                env.reset().unwrap();
                break;
            }
        }
    }
    steps
}
