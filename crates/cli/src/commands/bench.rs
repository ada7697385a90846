//! `rlnav bench`: controllers on scenario suites, the article's table, figures and timings.

use super::{progress_bar, write_json};
use anyhow::{Context, Result};
use rlnav_bench::suite::{RunOptions, SuiteSpec, run_suite, suite_setups_under};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    #[arg(long, help = suite_help())]
    suite: Vec<String>,
    /// Controller: dwa, greedy, straight or rl:POLICY.onnx[:CONTRACT.yaml] (repeat;
    /// default the shipped policies and dwa).
    #[arg(long)]
    controller: Vec<String>,
    /// Robot for every scenario (default: each scenario's).
    #[arg(long)]
    robot: Option<String>,
    /// Episodes per scenario and controller (default: the suite's).
    #[arg(long)]
    episodes: Option<usize>,
    /// Seed of the episodes.
    #[arg(long, default_value_t = 7)]
    seed: u64,
    /// Worker threads.
    #[arg(long, default_value_t = 2)]
    threads: usize,
    /// Output folder.
    #[arg(long, default_value = "bench-out")]
    out: PathBuf,
    /// Also record every episode as MCAP (ROS 2 CDR: /scan, /odom, /tf, /cmd_vel,
    /// /goal_pose, /clock) under OUT/mcap/SUITE/SCENARIO/CONTROLLER/.
    #[arg(long)]
    record: bool,
    /// Task file every controller runs under (default: configs/task.yaml's values, built in):
    /// action ranges, time limit, collision range, goal tolerance. A policy keeps its own
    /// action ranges, control period and plan on top of it; BARN worlds keep the challenge's
    /// rules. Give a classical planner a policy's action ranges with it, for a like-for-like
    /// comparison.
    #[arg(long)]
    task: Option<PathBuf>,
    /// Control cycles timed per controller for the per-cycle compute table (0: none).
    #[arg(long, default_value_t = 3000)]
    timing_cycles: usize,
}

/// `--suite`'s help: the shipped suites.
fn suite_help() -> String {
    let names: Vec<&str> = rlnav_bench::suite::SUITE_PRESETS.iter().map(|p| p.0).collect();
    format!("Suite: {}, or a YAML file (repeat for several; default paper-static and paper-dynamic)", names.join(", "))
}

/// The shipped policies `rlnav bench` runs by default (with DWA).
const SHIPPED_POLICIES: [&str; 3] =
    ["policies/default.onnx", "policies/jetbot-static-mlp.onnx", "policies/jetbot-dynamic-lstm.onnx"];

pub fn run(a: Args) -> Result<()> {
    let out = &a.out;
    let suites = if a.suite.is_empty() { vec!["paper-static".into(), "paper-dynamic".into()] } else { a.suite };
    let controllers = if a.controller.is_empty() {
        SHIPPED_POLICIES.iter().map(|p| format!("rl:{p}")).chain(["dwa".to_string()]).collect()
    } else {
        a.controller
    };
    anyhow::ensure!(a.episodes != Some(0), "--episodes must be at least 1");
    // Load every suite first: a bad name fails before any episode runs.
    let specs = suites.iter().map(|s| SuiteSpec::load(s)).collect::<Result<Vec<_>, _>>()?;
    let task = a.task.as_deref().map(rlnav_sim::TaskConfig::from_file).transpose()?;
    let base = task.clone().unwrap_or_default();
    let mut md = String::new();
    let mut all = Vec::new();
    for spec in &specs {
        let n = a.episodes.unwrap_or(spec.episodes);
        eprintln!(
            "{}: {} scenarios x {} controllers x {n} episodes...",
            spec.name,
            spec.scenarios.len(),
            controllers.len()
        );
        let bar = progress_bar(1, "scenario x controller");
        bar.set_message(spec.name.clone());
        let record = a.record.then(|| out.join("mcap").join(rlnav_bench::plots::slug(&spec.name)));
        let opts = RunOptions {
            robot: a.robot.as_deref(),
            episodes: n,
            seed: a.seed,
            threads: a.threads.max(1),
            record: record.as_deref(),
            task: task.as_ref(),
        };
        let r = run_suite(spec, &controllers, &opts, &mut |done, total| {
            bar.set_length(total as u64);
            bar.set_position(done as u64);
        })?;
        bar.finish_and_clear();
        for w in &r.warnings {
            eprintln!("warning: {w}");
        }
        std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
        let setups = suite_setups_under(spec, a.robot.as_deref(), &base)?;
        let figures = rlnav_bench::plots::write_suite_figures(&r, &setups, out).map_err(|e| anyhow::anyhow!(e))?;
        eprintln!("{}: {} figures in {}", spec.name, figures.len(), out.display());
        if let Some(dir) = &record {
            eprintln!("{}: MCAP recordings in {}", spec.name, dir.display());
        }
        let table = r.markdown();
        println!("{table}");
        md += &table;
        md += "\n";
        all.push(r);
    }
    // Per-cycle compute, one controller at a time on one thread, on the first suite's first
    // scenario: what each costs per control step on this machine.
    let mut timing = Vec::new();
    if a.timing_cycles > 0 {
        let setup = suite_setups_under(&specs[0], a.robot.as_deref(), &base)?.remove(0);
        timing = rlnav_bench::latency::measure_controllers(&controllers, &setup, a.timing_cycles, a.seed)?;
        let t = rlnav_bench::latency::markdown(&timing, &setup.scenario.spec().name);
        println!("{t}");
        md += &t;
    }
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    std::fs::write(out.join("report.md"), md).with_context(|| format!("writing {}/report.md", out.display()))?;
    let html = rlnav_bench::report::write_html(out, &all).map_err(|e| anyhow::anyhow!(e))?;
    eprintln!("report: {}", html.display());
    write_json(&out.join("report.json"), &serde_json::json!({ "suites": all, "per_cycle_compute": timing }))
}
