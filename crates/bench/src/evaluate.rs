//! Any controller through seeded episodes, in parallel: the success, collision and time-out
//! rates and the figures papers report (task time, minimum lidar range, mean speed).

use rayon::prelude::*;
use rlnav_sim::task::{EnvSetup, SimError};
use rlnav_sim::vec_env::env_seed;
use rlnav_sim::{Controller, EpisodeStats, NavEnv, Outcome};
use serde::Serialize;
use std::sync::Arc;

/// Aggregate figures over episodes.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EvalSummary {
    /// Episodes run.
    pub episodes: usize,
    /// Share that reached the goal.
    pub success_rate: f32,
    /// Share that collided.
    pub collision_rate: f32,
    /// Share that ran out of time.
    pub timeout_rate: f32,
    /// Mean time to the goal over successful episodes (s; NaN without any).
    pub mean_task_time: f32,
    /// Mean over episodes of the smallest lidar range seen (m).
    pub mean_min_range: f32,
    /// Mean over episodes of the mean linear speed (m/s).
    pub mean_speed: f32,
    /// Mean path length (m).
    pub mean_path_length: f32,
}

impl EvalSummary {
    /// The summary of these episodes.
    pub fn of(eps: &[EpisodeStats]) -> Self {
        let n = eps.len().max(1) as f32;
        let rate = |o: Outcome| eps.iter().filter(|e| e.outcome == o).count() as f32 / n;
        let mean = |f: &dyn Fn(&EpisodeStats) -> f32| eps.iter().map(f).sum::<f32>() / n;
        let wins: Vec<f32> = eps.iter().filter(|e| e.outcome == Outcome::Success).map(|e| e.time).collect();
        Self {
            episodes: eps.len(),
            success_rate: rate(Outcome::Success),
            collision_rate: rate(Outcome::Collision),
            timeout_rate: rate(Outcome::Timeout),
            mean_task_time: if wins.is_empty() { f32::NAN } else { wins.iter().sum::<f32>() / wins.len() as f32 },
            mean_min_range: mean(&|e| if e.min_range.is_finite() { e.min_range } else { 0.0 }),
            mean_speed: mean(&|e| e.mean_speed),
            mean_path_length: mean(&|e| e.path_length),
        }
    }
}

/// Runs `episodes` episodes of `setup`, episode `k` seeded with `env_seed(seed, k)` (so the
/// same seed gives the same scenes to every controller, whatever the thread count), each
/// worker with its own controller from `make`.
pub fn evaluate_controller<E: std::fmt::Display + Send>(
    setup: Arc<EnvSetup>,
    make: impl Fn() -> Result<Box<dyn Controller>, E> + Sync,
    episodes: usize,
    seed: u64,
    threads: usize,
) -> Result<(EvalSummary, Vec<EpisodeStats>), String> {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().map_err(|e| format!("thread pool: {e}"))?;
    let stats: Result<Vec<EpisodeStats>, String> = pool.install(|| {
        (0..episodes)
            .into_par_iter()
            .map_init(
                || make().map_err(|e| e.to_string()),
                |c, k| {
                    let c = c.as_mut().map_err(|e| e.clone())?;
                    let mut env = NavEnv::new(setup.clone(), env_seed(seed, k)).map_err(|e: SimError| e.to_string())?;
                    env.run_episode(c.as_mut()).map_err(|e| e.to_string())
                },
            )
            .collect()
    });
    let stats = stats?;
    Ok((EvalSummary::of(&stats), stats))
}
