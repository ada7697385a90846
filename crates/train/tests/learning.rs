//! Learning is tested by learning: a short seeded run on an easy configuration must reach a
//! stated success rate on episodes it did not train on, and the same run with learning
//! switched off (learning rate 1e-8) must not — so this test fails if learning breaks.

use rlnav_train::config::load_run_config;
use rlnav_train::{TrainOptions, train};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

/// Trains; returns the final evaluation's success rate and, for `keep`, the run folder.
fn run(extra: &[&str], name: &str, keep: bool) -> (f32, Option<std::path::PathBuf>) {
    let mut sets: Vec<String> = [
        "scenario=empty-room",
        "eval.scenario=empty-room",
        "network.hidden=[64, 64]",
        "task.reward.progress=10",
        "train.num_actors=32",
        "train.horizon_length=64",
        "train.minibatch_size=1024",
        "train.mini_epochs=4",
        "train.max_epochs=120",
        "train.threads=2",
        "eval.episodes=100",
        "eval.envs=50",
        "eval.every=0",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    sets.extend(extra.iter().map(|s| s.to_string()));
    let cfg = load_run_config(Some("smoke"), &sets).unwrap();
    let out = std::env::temp_dir().join(format!("rlnav-learning-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let opts = TrainOptions { out: out.clone(), resume: false, stop: Arc::new(AtomicBool::new(false)) };
    let summary = train(&cfg, &opts, &mut |_| {}).unwrap();
    let e = summary.final_eval.unwrap();
    eprintln!("{name}: success {:.2} collision {:.2} timeout {:.2}", e.success_rate, e.collision_rate, e.timeout_rate);
    if keep {
        (e.success_rate, Some(out))
    } else {
        std::fs::remove_dir_all(out).ok();
        (e.success_rate, None)
    }
}

/// The run's exported `policy.onnx`, run by tract through its contract as a `Controller`, on
/// fresh empty-room episodes.
fn exported_success(dir: &std::path::Path) -> f32 {
    use rlnav_sim::task::EnvSetup;
    use rlnav_sim::{NavEnv, Outcome};
    let mut runner = rlnav_policy::PolicyRunner::load(&dir.join("policy.onnx"), None).unwrap();
    let setup = Arc::new(EnvSetup::from_scenario_name("empty-room").unwrap());
    let mut wins = 0;
    for k in 0..100 {
        let mut env = NavEnv::new(setup.clone(), 777_000 + k).unwrap();
        wins += (env.run_episode(&mut runner).unwrap().outcome == Outcome::Success) as u32;
    }
    wins as f32 / 100.0
}

#[test]
fn ppo_learns_to_reach_goals() {
    // Evaluation episodes come from a seed stream the training never drew from.
    let (learned, dir) = run(&[], "ppo", true);
    assert!(learned >= 0.8, "trained policy reaches {learned:.2} of unseen goals, expected >= 0.80");
    // The same policy as an ONNX file, through tract and the contract, still navigates.
    let dir = dir.unwrap();
    let exported = exported_success(&dir);
    std::fs::remove_dir_all(dir).ok();
    eprintln!("exported policy.onnx: success {exported:.2}");
    assert!(exported >= 0.8, "the exported policy reaches {exported:.2} of unseen goals, expected >= 0.80");
    let (frozen, _) = run(&["train.learning_rate=1e-8", "train.lr_schedule=constant"], "frozen", false);
    assert!(frozen < 0.6, "without learning the policy should not succeed: {frozen:.2}");
}
