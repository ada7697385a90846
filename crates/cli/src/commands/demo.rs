//! `rlnav demo`: a controller on a scenario, episode by episode.

use super::EnvArgs;
use anyhow::{Context, Result};
use rlnav_sim::Outcome;
use rlnav_sim::task::NavEnv;

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    env: EnvArgs,
    /// Controller: `greedy` (turn to the goal and drive), `straight`, `dwa` or
    /// `rl:POLICY.onnx[:CONTRACT.yaml]`.
    #[arg(long, default_value = "greedy")]
    controller: String,
    /// Episodes to run.
    #[arg(long, default_value_t = 20)]
    episodes: usize,
    /// Run seed.
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

pub fn run(a: Args) -> Result<()> {
    let setup = a.env.setup_for(&a.controller)?;
    let mut c = rlnav_bench::controllers::for_setup(&a.controller, &setup)?;
    println!(
        "scenario {} | robot {} | controller {} | {} episodes, seed {}",
        setup.scenario.spec().name,
        setup.robot.name,
        c.name(),
        a.episodes,
        a.seed
    );
    let mut env = NavEnv::new(setup.clone(), a.seed)?;
    println!(
        "{:>4} {:>9} {:>7} {:>7} {:>8} {:>8} {:>8}",
        "ep", "outcome", "time_s", "return", "min_lidar", "speed", "start_d"
    );
    let mut all = Vec::new();
    for ep in 0..a.episodes {
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
