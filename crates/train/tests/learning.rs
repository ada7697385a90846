//! Learning is tested by learning: a short seeded run on an easy configuration must reach a
//! stated success rate on episodes it did not train on, and the same run with learning
//! switched off (learning rate 1e-8) must not — so this test fails if learning breaks.

use rlnav_train::config::load_run_config;
use rlnav_train::{TrainOptions, train};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

fn run(extra: &[&str], name: &str) -> f32 {
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
    std::fs::remove_dir_all(out).ok();
    let e = summary.final_eval.unwrap();
    eprintln!("{name}: success {:.2} collision {:.2} timeout {:.2}", e.success_rate, e.collision_rate, e.timeout_rate);
    e.success_rate
}

#[test]
fn ppo_learns_to_reach_goals() {
    // Evaluation episodes come from a seed stream the training never drew from.
    let learned = run(&[], "ppo");
    assert!(learned >= 0.8, "trained policy reaches {learned:.2} of unseen goals, expected >= 0.80");
    let frozen = run(&["train.learning_rate=1e-8", "train.lr_schedule=constant"], "frozen");
    assert!(frozen < 0.6, "without learning the policy should not succeed: {frozen:.2}");
}
