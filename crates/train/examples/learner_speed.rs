//! Times the hand-written learner (`rlnav_train::fast`) at the default run's sizes: one PPO
//! minibatch step (4,096 rows: forward, loss, backward, Adam) and the rollout's batched
//! inference (128 rows per control step). Issue #15's before/after figures come from here.
//! With `--lstm UNITS` the network has an LSTM in front and minibatches are `--seq`-step
//! sequences (the dynamic config: `--lstm 64 --seq 8 --rows 2048 --envs 64`).
//!
//! `--clipped-actions` scores the actions as `train.clipped_actions` does.
//!
//! `cargo run --release -p rlnav-train --example learner_speed [-- --hidden 128,64 --threads 2
//! --rows 4096 --envs 128 --lstm 0 --seq 8 --clipped-actions]`

use burn::prelude::*;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use rand_pcg::Pcg64Mcg;
use rlnav_policy::{ActorCritic, NetworkConfig};
use rlnav_train::fast::{Batch, FastNet, LossConfig};
use std::time::Instant;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let arg = |name: &str| args.iter().position(|a| a == name).and_then(|i| args.get(i + 1)).cloned();
    let hidden: Vec<usize> = arg("--hidden")
        .unwrap_or_else(|| "128,64".into())
        .split(',')
        .map(|s| s.parse().expect("--hidden: comma-separated widths"))
        .collect();
    let count = |name: &str, default: usize| arg(name).map_or(default, |s| s.parse().expect("a count"));
    let threads = count("--threads", 0);
    let (rows, rollout_rows, lstm_units) = (count("--rows", 4096), count("--envs", 128), count("--lstm", 0));
    let seq = if lstm_units > 0 { count("--seq", 8) } else { 1 };
    let (obs_dim, act_dim) = (124, 2);
    let cfg = NetworkConfig { hidden: hidden.clone(), lstm_units, separate_critic: true, ..Default::default() };
    let model = ActorCritic::seeded(&cfg, obs_dim, act_dim, &Device::flex(), 0);
    let mut fast = FastNet::from_model(&model, threads);
    let mut rng = Pcg64Mcg::seed_from_u64(1);
    let mut random = |n: usize| -> Vec<f32> { (0..n).map(|_| rng.sample::<f32, _>(StandardNormal)).collect() };
    let obs = random(rows * obs_dim);
    let actions = random(rows * act_dim);
    let old_log_probs: Vec<f32> = random(rows).iter().map(|x| x - 2.0).collect();
    let (advantages, returns, old_values) = (random(rows), random(rows), random(rows));
    let state = if lstm_units > 0 { random(rows / seq * lstm_units) } else { Vec::new() };
    let starts: Vec<f32> =
        if lstm_units > 0 { (0..rows).map(|k| (k % 37 != 0) as u8 as f32).collect() } else { Vec::new() };
    let batch = Batch {
        obs: &obs,
        seq,
        starts: &starts,
        cell: &state,
        hidden: &state,
        actions: &actions,
        old_log_probs: &old_log_probs,
        advantages: &advantages,
        returns: &returns,
        old_values: &old_values,
        teacher: &[],
        privileged: &[],
    };
    let loss = LossConfig {
        e_clip: 0.2,
        clip_value: true,
        critic_coef: 4.0,
        entropy_coef: 0.0,
        bounds_loss_coef: 1e-4,
        teacher_coef: 0.0,
        clipped_actions: args.iter().any(|a| a == "--clipped-actions"),
    };
    let (mut step_ms, mut infer_us) = (Vec::new(), Vec::new());
    for _ in 0..40 {
        let t = Instant::now();
        std::hint::black_box(fast.step(&batch, &loss, 1e-4, 1.0));
        step_ms.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let blocks = rows / rollout_rows;
    for k in 0..400 {
        let x = &obs[(k % blocks) * rollout_rows * obs_dim..][..rollout_rows * obs_dim];
        let carried =
            (lstm_units > 0).then(|| (vec![0.1; rollout_rows * lstm_units], vec![0.2; rollout_rows * lstm_units]));
        let t = Instant::now();
        std::hint::black_box(fast.infer(x, carried));
        infer_us.push(t.elapsed().as_secs_f64() * 1e6);
    }
    let (step, infer) = (median(step_ms), median(infer_us));
    println!(
        "hidden {hidden:?}, lstm {lstm_units} (seq {seq}), threads {}: minibatch step ({rows} rows) {step:.2} ms = {:.0} k samples/s; \
         inference ({rollout_rows} rows) {infer:.0} µs = {:.0} k rows/s",
        if threads == 0 { rayon::current_num_threads() } else { threads },
        rows as f64 / step,
        rollout_rows as f64 / infer * 1e3,
    );
}
