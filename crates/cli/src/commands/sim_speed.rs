//! `rlnav sim-speed`: simulator throughput with random actions.

use super::EnvArgs;
use anyhow::Result;
use rlnav_sim::vec_env::{VecEnv, measure_speed};

#[derive(clap::Args)]
pub struct Args {
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
}

pub fn run(a: Args) -> Result<()> {
    anyhow::ensure!(a.envs > 0 && a.steps > 0, "--envs and --steps must be at least 1");
    let setup = a.env.setup()?;
    let mut venv = VecEnv::new(setup.clone(), a.envs, a.seed, a.threads)?;
    eprintln!(
        "scenario {} | robot {} | {} beams | {} envs on {} threads | {} steps each",
        setup.scenario.spec().name,
        setup.robot.name,
        setup.lidar.beams(),
        a.envs,
        venv.threads(),
        a.steps
    );
    let report = measure_speed(&mut venv, a.steps, a.steps / 10, a.seed)?;
    if a.reference_lidar {
        let (fast, slow) = rlnav_sim::vec_env::compare_casters(&venv.envs()[0], 2000);
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
