//! Training runs end to end: determinism, checkpoints and resume, and clear errors.

use rlnav_train::config::load_run_config;
use rlnav_train::run::{TrainError, load_model, read_run_config};
use rlnav_train::{RunConfig, TrainOptions, train};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

fn tmp(name: &str) -> PathBuf {
    let p = std::env::temp_dir().join(format!("rlnav-train-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&p);
    p
}

fn smoke(epochs: usize) -> RunConfig {
    load_run_config(Some("smoke"), &[format!("train.max_epochs={epochs}"), "train.threads=2".into()]).unwrap()
}

fn opts(out: &Path, resume: bool) -> TrainOptions {
    TrainOptions { out: out.to_path_buf(), resume, stop: Arc::new(AtomicBool::new(false)) }
}

/// metrics.csv without the wall-clock columns.
fn metrics(dir: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(dir.join("metrics.csv")).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let timing = ["wall_s", "steps_per_s", "sim_s", "rollout_s", "update_s"];
    text.lines()
        .map(|l| {
            l.split(',').zip(&header).filter(|(_, h)| !timing.contains(h)).map(|(v, _)| v).collect::<Vec<_>>().join(",")
        })
        .collect()
}

#[test]
fn same_seed_same_run() {
    let (a, b) = (tmp("det-a"), tmp("det-b"));
    train(&smoke(3), &opts(&a, false), &mut |_| {}).unwrap();
    train(&smoke(3), &opts(&b, false), &mut |_| {}).unwrap();
    let (ma, mb) = (metrics(&a), metrics(&b));
    assert_eq!(ma.len(), 4);
    assert_eq!(ma, mb, "same seed, same thread count: bit-identical metrics");
    let c = tmp("det-c");
    let mut other = smoke(3);
    other.seed = 1;
    train(&other, &opts(&c, false), &mut |_| {}).unwrap();
    assert_ne!(ma, metrics(&c));
    for d in [a, b, c] {
        std::fs::remove_dir_all(d).ok();
    }
}

#[test]
fn a_run_stops_once_an_evaluation_reaches_its_target() {
    let out = tmp("target");
    let mut cfg = smoke(20);
    cfg.eval.every = 2;
    // Any success rate reaches 0: the run must stop after its first evaluation.
    cfg.eval.stop_at_success = Some(0.0);
    let s = train(&cfg, &opts(&out, false), &mut |_| {}).unwrap();
    assert!(s.reached_stop_target && !s.interrupted, "{s:?}");
    assert_eq!(s.iterations, 2, "stopped after the first evaluation");
    assert!(s.final_eval.is_some(), "the final test still runs");
    assert_eq!(metrics(&out).len(), 3, "header + 2 epochs");
    // A target no evaluation reaches runs the whole budget and records no milestone.
    let out2 = tmp("target-unreached");
    cfg.eval.stop_at_success = Some(1.0);
    cfg.train.max_epochs = 4;
    let s = train(&cfg, &opts(&out2, false), &mut |_| {}).unwrap();
    let best = s.best_success_rate;
    assert!(best < 1.0, "an untrained policy does not reach every goal ({best})");
    assert!(!s.reached_stop_target && s.iterations == 4 && s.first_95.is_none(), "{s:?}");
    // Without an evaluation schedule the target cannot be checked: refused.
    cfg.eval.every = 0;
    let e = rlnav_sim::config::Validate::validate(&cfg).unwrap_err();
    assert_eq!(e.key, "eval.every", "{e:?}");
    for d in [out, out2] {
        std::fs::remove_dir_all(d).ok();
    }
}

#[test]
fn stop_checkpoint_and_resume() {
    let out = tmp("resume");
    let cfg = smoke(6);
    // Stop after the second epoch, as Ctrl-C would.
    let o = opts(&out, false);
    let stop = o.stop.clone();
    let s = train(&cfg, &o, &mut |r| {
        if r.epoch == 2 {
            stop.store(true, Ordering::Relaxed);
        }
    })
    .unwrap();
    assert!(s.interrupted && s.iterations == 2);
    for f in [
        "config.yaml",
        "metrics.csv",
        "summary.json",
        "checkpoint/model.bpk",
        "checkpoint/optimizer.bpk",
        "checkpoint/state.json",
    ] {
        assert!(out.join(f).is_file(), "{f} written");
    }
    // Starting a new run in the same folder is refused, and overwrites nothing.
    let before = std::fs::read(out.join("metrics.csv")).unwrap();
    let e = train(&cfg, &opts(&out, false), &mut |_| {}).unwrap_err();
    assert!(e.to_string().contains("already holds a run"), "{e}");
    assert_eq!(std::fs::read(out.join("metrics.csv")).unwrap(), before);
    // The default folder choice moves on to a free name.
    assert_eq!(rlnav_train::run::fresh_run_dir(&out), PathBuf::from(format!("{}-2", out.display())));
    // Resume to the end.
    let cfg = read_run_config(&out).unwrap();
    let mut epochs = Vec::new();
    let s = train(&cfg, &opts(&out, true), &mut |r| epochs.push(r.epoch)).unwrap();
    assert_eq!(epochs, vec![3, 4, 5, 6]);
    assert!(!s.interrupted && s.iterations == 6 && s.env_steps == 6 * 16 * 32);
    assert!(s.final_eval.is_some());
    assert_eq!(metrics(&out).len(), 7, "header + 6 epochs");
    // TensorBoard: one event file per session, scalars for every epoch.
    let mut steps = Vec::new();
    for f in std::fs::read_dir(out.join("tensorboard")).unwrap() {
        let events = rlnav_train::tensorboard::read_scalars(&f.unwrap().path()).unwrap();
        steps.extend(events.iter().filter(|(_, t, _)| t == "episodes/success_rate").map(|(s, _, _)| *s));
    }
    steps.sort();
    assert_eq!(steps, (1..=6).map(|e| e * 16 * 32).collect::<Vec<i64>>());
    // The finished run exported its policy with the contract of its configuration.
    let runner = rlnav_policy::PolicyRunner::load(&out.join("policy.onnx"), None).unwrap();
    let c = runner.contract();
    assert_eq!((c.task.as_str(), c.robot.as_str(), c.obs_dim()), (cfg.name.as_str(), "jetbot", 124));
    assert_eq!(c.action.linear, cfg.task.action.linear);
    assert_eq!(c.control_period, cfg.task.control_period);
    let svg = std::fs::read_to_string(out.join("training.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("success rate") && svg.contains("<polyline"), "training.svg drawn");
    std::fs::remove_dir_all(out).ok();
}

#[test]
fn resume_errors_are_clear() {
    let not_a_run = tmp("not-a-run");
    std::fs::create_dir_all(&not_a_run).unwrap();
    let e = read_run_config(&not_a_run).unwrap_err();
    assert!(matches!(e, TrainError::Resume { .. }) && e.to_string().contains("not a run folder"), "{e}");

    // A checkpoint of another network shape.
    let out = tmp("shape");
    train(&smoke(1), &opts(&out, false), &mut |_| {}).unwrap();
    let mut other = smoke(1);
    other.network.hidden = vec![16];
    let device = burn::prelude::Device::flex();
    let e = load_model(&other, &out.join("checkpoint"), 124, &device).unwrap_err().to_string();
    assert!(e.contains("does not match the configured one"), "{e}");
    assert!(load_model(&smoke(1), &out.join("checkpoint"), 124, &device).is_ok());
    // Resuming with a different network is refused.
    let e = train(&other, &opts(&out, true), &mut |_| {}).unwrap_err().to_string();
    assert!(e.contains("network configuration differs"), "{e}");
    std::fs::remove_dir_all(out).ok();
    std::fs::remove_dir_all(not_a_run).ok();
}
