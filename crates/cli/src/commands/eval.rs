//! `rlnav eval`: a trained run or any ONNX policy on a scenario, with a progress bar; writes
//! eval.json.

use super::{progress_bar, write_json};
use anyhow::Result;
use rlnav_sim::EvalSummary;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Run folder written by `rlnav train`.
    #[arg(long, required_unless_present = "policy", conflicts_with = "policy")]
    run: Option<PathBuf>,
    /// ONNX policy (its contract inside, or given with --contract).
    #[arg(long)]
    policy: Option<PathBuf>,
    /// Side contract for a policy rlnav did not export (see contracts/).
    #[arg(long, requires = "policy")]
    contract: Option<PathBuf>,
    /// Robot for --policy (default: the contract's robot when it is a preset, else the
    /// scenario's).
    #[arg(long, requires = "policy")]
    robot: Option<String>,
    /// Scenario: a shipped name or a YAML file (default for --run: the run's evaluation
    /// scenarios, `eval.scenario` and `eval.mix`).
    #[arg(long)]
    scenario: Option<String>,
    /// Worker threads for --policy.
    #[arg(long, default_value_t = 2)]
    threads: usize,
    /// Episodes.
    #[arg(long, default_value_t = 200)]
    episodes: usize,
    /// Seed of the evaluation episodes.
    #[arg(long, default_value_t = 12345)]
    seed: u64,
    /// Folder for eval.json (default: the run folder, or the current folder for --policy).
    #[arg(long)]
    out: Option<PathBuf>,
}

pub fn run(a: Args) -> Result<()> {
    anyhow::ensure!(a.episodes > 0, "--episodes must be at least 1");
    let bar = progress_bar(a.episodes as u64, "episodes");
    let progress = |done: usize| bar.set_position(done as u64);
    if let Some(run) = &a.run {
        let ev = rlnav_train::run::evaluate_run(run, a.scenario.as_deref(), a.episodes, 50, a.seed, &progress)?;
        bar.finish_and_clear();
        println!("{} on {} ({} episodes, seed {})", run.display(), ev.scenario, ev.summary.episodes, a.seed);
        print_summary(&ev.summary);
        return write_json(&a.out.unwrap_or_else(|| run.clone()).join("eval.json"), &ev);
    }
    let Some(policy) = &a.policy else { anyhow::bail!("give --run DIR or --policy FILE") };
    let scenario = a.scenario.as_deref().unwrap_or("static-room");
    let ev = rlnav_bench::evaluate::evaluate_policy(
        policy,
        a.contract.as_deref(),
        scenario,
        a.robot.as_deref(),
        a.episodes,
        a.seed,
        a.threads.max(1),
        &progress,
    )?;
    bar.finish_and_clear();
    println!(
        "{} ({}) on {} with {} ({} episodes, seed {})",
        ev.policy, ev.contract.task, ev.scenario, ev.robot, a.episodes, a.seed
    );
    print_summary(&ev.summary);
    write_json(&a.out.unwrap_or_else(|| PathBuf::from(".")).join("eval.json"), &ev)
}

/// The figures of an evaluation as a two-line table.
fn print_summary(r: &EvalSummary) {
    println!(
        "{:>8} {:>9} {:>8} {:>10} {:>10} {:>9} {:>8}",
        "success", "collision", "timeout", "task_time", "min_lidar", "speed", "return"
    );
    let task_time = if r.mean_task_time.is_finite() { format!("{:.1}s", r.mean_task_time) } else { "-".into() };
    println!(
        "{:>7.1}% {:>8.1}% {:>7.1}% {:>10} {:>9.2}m {:>5.2}m/s {:>8.1}",
        100.0 * r.success_rate,
        100.0 * r.collision_rate,
        100.0 * r.timeout_rate,
        task_time,
        r.mean_min_range,
        r.mean_speed,
        r.mean_return
    );
}
