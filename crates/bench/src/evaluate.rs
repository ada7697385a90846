//! Any controller through seeded episodes, in parallel: the success, collision and time-out
//! rates and the figures papers report (task time, minimum lidar range, mean speed).

use rayon::prelude::*;
use rlnav_sim::task::{EnvSetup, SimError};
use rlnav_sim::vec_env::env_seed;
use rlnav_sim::{Controller, EpisodeStats, NavEnv, Outcome, RobotObservation};
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

/// One episode step by step: after each control step, the time, the position, the distance to
/// the goal and the smallest lidar range (step 0 is the start).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct EpisodeTrace {
    /// Seconds since the start.
    pub time: Vec<f32>,
    /// Positions `[x, y]`.
    pub position: Vec<[f32; 2]>,
    /// Distance to the goal (m).
    pub distance: Vec<f32>,
    /// Smallest lidar range in the scan (m).
    pub min_range: Vec<f32>,
}

impl EpisodeTrace {
    fn push(&mut self, env: &NavEnv, time: f32) {
        let p = env.pose().position();
        self.time.push(time);
        self.position.push([p.x, p.y]);
        self.distance.push((env.goal() - p).length());
        self.min_range.push(env.ranges().iter().copied().fold(f32::INFINITY, f32::min));
    }
}

/// Runs the environment's current episode to its end under `c`, tracing it.
pub fn traced_episode(env: &mut NavEnv, c: &mut dyn Controller) -> (EpisodeStats, EpisodeTrace) {
    c.reset();
    let period = env.setup().task.control_period;
    let mut trace = EpisodeTrace::default();
    trace.push(env, 0.0);
    let mut obs = RobotObservation::default();
    loop {
        env.robot_observation(&mut obs);
        let out = env.step_twist(c.act(&obs));
        trace.push(env, trace.time.len() as f32 * period);
        if out.terminated || out.truncated {
            return (env.last_episode().expect("set when an episode ends"), trace);
        }
    }
}

/// Runs `episodes` episodes of `setup`, episode `k` seeded with `env_seed(seed, k)` (so the
/// same seed gives the same scenes to every controller, whatever the thread count), each
/// worker with its own controller from `make`. Returns the summary, every episode's figures
/// and its trace.
pub fn evaluate_controller<E: std::fmt::Display + Send>(
    setup: Arc<EnvSetup>,
    make: impl Fn() -> Result<Box<dyn Controller>, E> + Sync,
    episodes: usize,
    seed: u64,
    threads: usize,
) -> Result<(EvalSummary, Vec<EpisodeStats>, Vec<EpisodeTrace>), String> {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().map_err(|e| format!("thread pool: {e}"))?;
    let runs: Result<Vec<(EpisodeStats, EpisodeTrace)>, String> = pool.install(|| {
        (0..episodes)
            .into_par_iter()
            .map_init(
                || make().map_err(|e| e.to_string()),
                |c, k| {
                    let c = c.as_mut().map_err(|e| e.clone())?;
                    let mut env = NavEnv::new(setup.clone(), env_seed(seed, k)).map_err(|e: SimError| e.to_string())?;
                    Ok(traced_episode(&mut env, c.as_mut()))
                },
            )
            .collect()
    });
    let (stats, traces): (Vec<_>, Vec<_>) = runs?.into_iter().unzip();
    Ok((EvalSummary::of(&stats), stats, traces))
}
