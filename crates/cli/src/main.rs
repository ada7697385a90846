//! `rlnav`: train, evaluate and deploy RL local planners for wheeled robots with a 2D lidar.
//! This binary parses arguments, shows progress and wires the library crates together.

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use rlnav_sim::scenario::{SCENARIO_PRESETS, ScenarioSpec};
use rlnav_sim::task::{EnvSetup, NavEnv, TaskConfig};
use rlnav_sim::vec_env::{VecEnv, measure_speed};
use rlnav_sim::{Controller, GreedyGoal, Outcome, RobotSpec, StraightAhead};
use std::path::PathBuf;
use std::sync::Arc;

#[derive(Parser)]
#[command(name = "rlnav", version, about = "End-to-end RL local planners for wheeled robots with a 2D lidar")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a simple controller on a scenario and print what happened.
    Demo {
        #[command(flatten)]
        env: EnvArgs,
        /// Controller: `greedy` (turn to the goal and drive) or `straight`.
        #[arg(long, default_value = "greedy")]
        controller: String,
        /// Episodes to run.
        #[arg(long, default_value_t = 20)]
        episodes: usize,
        /// Run seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
    },
    /// Measure simulator throughput with random actions; the last line is a JSON object.
    SimSpeed {
        #[command(flatten)]
        env: EnvArgs,
        /// Environments stepped together.
        #[arg(long, default_value_t = 256)]
        envs: usize,
        /// Worker threads (0: one per core).
        #[arg(long, default_value_t = 2)]
        threads: usize,
        /// Steps per environment to measure.
        #[arg(long, default_value_t = 2000)]
        steps: usize,
        /// Run seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Also time parry2d's brute-force ray casts for the same scans (one thread).
        #[arg(long)]
        reference_lidar: bool,
    },
    /// List the shipped scenarios and robots.
    List,
}

#[derive(clap::Args)]
struct EnvArgs {
    /// Scenario: a shipped name (see `rlnav list`) or a YAML file.
    #[arg(long, default_value = "static-room")]
    scenario: String,
    /// Robot: a shipped name or a YAML file (default: the scenario's).
    #[arg(long)]
    robot: Option<String>,
    /// Task file (default: configs/task.yaml's values, built in).
    #[arg(long)]
    task: Option<PathBuf>,
}

impl EnvArgs {
    fn setup(&self) -> Result<Arc<EnvSetup>> {
        let scenario = ScenarioSpec::load(&self.scenario)?;
        let robot = RobotSpec::load(self.robot.as_deref().unwrap_or(&scenario.robot))?;
        let task = match &self.task {
            Some(p) => TaskConfig::from_file(p)?,
            None => TaskConfig::default(),
        };
        Ok(Arc::new(EnvSetup::new(scenario, robot, task)?))
    }
}

fn main() {
    if let Err(e) = run(Cli::parse()) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Demo { env, controller, episodes, seed } => demo(&env, &controller, episodes, seed),
        Command::SimSpeed { env, envs, threads, steps, seed, reference_lidar } => {
            sim_speed(&env, envs, threads, steps, seed, reference_lidar)
        }
        Command::List => {
            println!("scenarios:");
            for (name, _) in SCENARIO_PRESETS {
                let s = ScenarioSpec::load(name)?;
                println!("  {name:<16} {}", s.description);
            }
            println!("robots:");
            for (name, _) in rlnav_sim::robot::ROBOT_PRESETS {
                let r = RobotSpec::load(name)?;
                println!("  {name:<18} {}", r.description);
            }
            Ok(())
        }
    }
}

fn demo(args: &EnvArgs, controller: &str, episodes: usize, seed: u64) -> Result<()> {
    let setup = args.setup()?;
    let mut c: Box<dyn Controller> = match controller {
        "greedy" => Box::new(GreedyGoal::default()),
        "straight" => Box::new(StraightAhead { speed: 0.3 }),
        other => anyhow::bail!("unknown controller `{other}`: expected `greedy` or `straight`"),
    };
    println!(
        "scenario {} | robot {} | controller {} | {} episodes, seed {seed}",
        setup.scenario.spec().name,
        setup.robot.name,
        c.name(),
        episodes
    );
    let mut env = NavEnv::new(setup.clone(), seed)?;
    println!(
        "{:>4} {:>9} {:>7} {:>7} {:>8} {:>8} {:>8}",
        "ep", "outcome", "time_s", "return", "min_lidar", "speed", "start_d"
    );
    let mut all = Vec::new();
    for ep in 0..episodes {
        let s = env.run_episode(c.as_mut()).context("running an episode")?;
        println!(
            "{ep:>4} {:>9} {:>7.1} {:>7.1} {:>8.2} {:>8.2} {:>8.2}",
            format!("{:?}", s.outcome).to_lowercase(),
            s.time,
            s.episode_return,
            s.min_range,
            s.mean_speed,
            s.initial_distance
        );
        all.push(s);
    }
    let rate = |o: Outcome| 100.0 * all.iter().filter(|s| s.outcome == o).count() as f32 / all.len().max(1) as f32;
    println!(
        "success {:.0}% | collision {:.0}% | timeout {:.0}%",
        rate(Outcome::Success),
        rate(Outcome::Collision),
        rate(Outcome::Timeout)
    );
    Ok(())
}

fn sim_speed(args: &EnvArgs, envs: usize, threads: usize, steps: usize, seed: u64, reference: bool) -> Result<()> {
    anyhow::ensure!(envs > 0 && steps > 0, "--envs and --steps must be at least 1");
    let setup = args.setup()?;
    let mut venv = VecEnv::new(setup.clone(), envs, seed, threads)?;
    eprintln!(
        "scenario {} | robot {} | {} beams | {} envs on {} threads | {} steps each",
        setup.scenario.spec().name,
        setup.robot.name,
        setup.lidar.beams(),
        envs,
        venv.threads(),
        steps
    );
    let report = measure_speed(&mut venv, steps, steps / 10, seed)?;
    if reference {
        let (fast, slow) = rlnav_sim::lidar::compare_casters(&venv.envs()[0], 2000);
        eprintln!(
            "lidar, one thread: culled caster {:.0} scans/s, parry2d brute force {:.0} scans/s ({:.1}x)",
            fast,
            slow,
            fast / slow
        );
    }
    eprintln!(
        "{:.0} env steps/s, {:.1} M rays/s, {} episodes finished",
        report.env_steps_per_s,
        report.rays_per_s / 1e6,
        report.episodes
    );
    println!("{}", serde_json::to_string(&report)?);
    Ok(())
}
