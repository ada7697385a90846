//! `rlnav train`: a PPO run, with progress, and how well its policy navigates unseen scenes.

use super::progress_bar;
use anyhow::{Context, Result};
use rlnav_train::{TrainOptions, load_run_config};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

#[derive(clap::Args)]
pub struct Args {
    #[arg(long, help = config_help())]
    config: Option<String>,
    /// Run folder (default: runs/<config name>-<seed>, or the first free -2, -3... after it).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Run seed (overrides the config's).
    #[arg(long)]
    seed: Option<u64>,
    /// Override a config value by its dotted path, e.g. `--set train.max_epochs=3`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Continue the run in this folder from its last checkpoint.
    #[arg(long, conflicts_with_all = ["config", "out", "seed"])]
    resume: Option<PathBuf>,
}

/// `--config`'s help: the shipped configurations.
fn config_help() -> String {
    let names: Vec<&str> = rlnav_train::config::TRAIN_PRESETS.iter().map(|p| p.0).collect();
    format!("Training configuration: a shipped name ({}) or a YAML file", names.join(", "))
}

pub fn run(a: Args) -> Result<()> {
    let Args { config, out, seed, mut set, resume } = a;
    let (cfg, out, resuming) = match resume {
        Some(dir) => {
            let cfg = rlnav_train::run::read_run_config(&dir)?;
            if !set.is_empty() {
                anyhow::bail!("--set cannot change a run being resumed");
            }
            (cfg, dir, true)
        }
        None => {
            if let Some(s) = seed {
                set.push(format!("seed={s}"));
            }
            let cfg = load_run_config(config.as_deref(), &set)?;
            let out = out.unwrap_or_else(|| {
                rlnav_train::run::fresh_run_dir(&PathBuf::from(format!("runs/{}-{}", cfg.name, cfg.seed)))
            });
            (cfg, out, false)
        }
    };
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        ctrlc::set_handler(move || {
            if stop.swap(true, Ordering::SeqCst) {
                std::process::exit(130);
            }
            eprintln!("\nstopping after this epoch (a checkpoint will be written); Ctrl-C again to abort");
        })
        .context("installing the Ctrl-C handler")?;
    }
    println!(
        "training {} | robot {} | scenario {} | network {:?}{} | {} envs x {} steps | {} epochs -> {}",
        cfg.name,
        cfg.robot,
        if cfg.curriculum.is_empty() {
            cfg.scenario.clone()
        } else {
            format!("curriculum of {}", cfg.curriculum.len())
        },
        cfg.network.hidden,
        if cfg.network.lstm_units > 0 { format!(" + LSTM {}", cfg.network.lstm_units) } else { String::new() },
        cfg.train.num_actors,
        cfg.train.horizon_length,
        cfg.train.max_epochs,
        out.display()
    );
    let bar = progress_bar(cfg.train.max_epochs as u64, "epochs");
    let eval_on = rlnav_train::run::eval_scenarios(&cfg);
    // `suspend`, not `println`: a hidden bar (output to a file or pipe, as under nohup) drops
    // what `println` gives it, and the evaluations are what a log of a run is read for.
    let line = |text: String| bar.suspend(|| println!("{text}"));
    let opts = TrainOptions { out: out.clone(), resume: resuming, stop };
    let summary = rlnav_train::train(&cfg, &opts, &mut |r| {
        bar.set_position(r.epoch as u64);
        bar.set_message(format!(
            "{:.0} steps/s | return {:.1} | success {:.0}% | stage {}",
            r.steps_per_s,
            r.mean_return,
            100.0 * r.success_rate,
            r.stage_name
        ));
        if let Some(e) = &r.eval {
            line(format!(
                "epoch {:>5} | {:>9} steps | {:>6.1} s | eval on {}: success {:.1}% collision {:.1}% timeout {:.1}%",
                r.epoch,
                r.env_steps,
                r.wall_s,
                eval_on,
                100.0 * e.success_rate,
                100.0 * e.collision_rate,
                100.0 * e.timeout_rate
            ));
        }
        if let Some(e) = &r.heldout {
            line(format!(
                "                held-out rooms ({} scenes): success {:.1}% collision {:.1}%",
                cfg.eval.heldout.len(),
                100.0 * e.success_rate,
                100.0 * e.collision_rate
            ));
        }
    })?;
    bar.finish_and_clear();
    println!(
        "{} epochs, {} env steps in {:.1} s ({:.0} steps/s){}",
        summary.iterations,
        summary.env_steps,
        summary.wall_s,
        summary.steps_per_s,
        if summary.interrupted {
            ", stopped early: resume with --resume"
        } else if summary.reached_stop_target {
            ", stopped at eval.stop_at_success"
        } else {
            ""
        }
    );
    for (target, m) in [("90%", summary.first_90), ("95%", summary.first_95)] {
        match m {
            Some(m) => println!(
                "evaluation first reached {target} after epoch {} ({} env steps, {:.1} s): {:.1}%",
                m.epoch,
                m.env_steps,
                m.wall_s,
                100.0 * m.success_rate
            ),
            None => println!("evaluation never reached {target}"),
        }
    }
    if let Some(e) = summary.final_eval {
        println!(
            "evaluation of the epoch-{} policy on {} ({} episodes in scenes not seen in training): success {:.1}%, collision {:.1}%, timeout {:.1}%",
            summary.final_epoch,
            summary.eval_scenario,
            e.episodes,
            100.0 * e.success_rate,
            100.0 * e.collision_rate,
            100.0 * e.timeout_rate
        );
    }
    if let Some(e) = summary.final_heldout {
        println!(
            "on the held-out rooms ({}; {} episodes): success {:.1}% [95% CI {:.1}–{:.1}], collision {:.1}%, timeout {:.1}%",
            summary.heldout_scenarios.join(", "),
            e.episodes,
            100.0 * e.success_rate,
            100.0 * e.success_ci95[0],
            100.0 * e.success_ci95[1],
            100.0 * e.collision_rate,
            100.0 * e.timeout_rate
        );
    }
    println!("run folder: {}", out.display());
    Ok(())
}
