//! Evaluation of the current policy (deterministic: the Gaussian mean) on a scenario, each
//! environment running the same number of episodes so that short episodes are not favoured.

use crate::ppo::Ppo;
use rlnav_sim::task::{EnvSetup, EpisodeStats, Outcome, SimError};
use rlnav_sim::vec_env::VecEnv;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// Aggregate results of an evaluation.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct EvalResult {
    /// Episodes run.
    pub episodes: usize,
    /// Fraction that reached the goal.
    pub success_rate: f32,
    /// Fraction that collided.
    pub collision_rate: f32,
    /// Fraction that timed out.
    pub timeout_rate: f32,
    /// Mean return.
    pub mean_return: f32,
    /// Mean time of successful episodes (s).
    pub mean_success_time: f32,
}

impl EvalResult {
    /// Aggregates episode statistics.
    pub fn from_episodes(eps: &[EpisodeStats]) -> Self {
        let n = eps.len().max(1) as f32;
        let rate = |o: Outcome| eps.iter().filter(|e| e.outcome == o).count() as f32 / n;
        let succ: Vec<_> = eps.iter().filter(|e| e.outcome == Outcome::Success).collect();
        Self {
            episodes: eps.len(),
            success_rate: rate(Outcome::Success),
            collision_rate: rate(Outcome::Collision),
            timeout_rate: rate(Outcome::Timeout),
            mean_return: eps.iter().map(|e| e.episode_return).sum::<f32>() / n,
            mean_success_time: succ.iter().map(|e| e.time).sum::<f32>() / succ.len().max(1) as f32,
        }
    }
}

/// Runs `episodes` episodes (`envs` at a time, `episodes / envs` each) of the learner's
/// deterministic policy. `seed` should differ from the training seeds so that procedurally
/// generated scenes are new to the policy.
pub fn evaluate(
    ppo: &Ppo,
    setup: Arc<EnvSetup>,
    episodes: usize,
    envs: usize,
    seed: u64,
    threads: usize,
) -> Result<(EvalResult, Vec<EpisodeStats>), SimError> {
    let mut venv = VecEnv::new(setup, envs, seed, threads)?;
    let quota = episodes / envs;
    let mut done = vec![0usize; envs];
    let mut results = Vec::with_capacity(episodes);
    let units = ppo.model().lstm_units();
    let mut state = (units > 0).then(|| (vec![0.0f32; envs * units], vec![0.0f32; envs * units]));
    let mut actions = vec![[0.0f32; 2]; envs];
    let net = ppo.inference_net();
    while done.iter().any(|d| *d < quota) {
        let (mu, next) = ppo.act_mean(&net, &venv.obs, state.take());
        state = next;
        let a = mu.len() / envs;
        for (e, act) in actions.iter_mut().enumerate() {
            *act = [mu[e * a], mu[e * a + 1]];
        }
        venv.step(&actions)?;
        for e in 0..envs {
            if let Some(s) = venv.finished[e] {
                if done[e] < quota {
                    results.push(s);
                    done[e] += 1;
                }
                if let Some((c, h)) = &mut state {
                    c[e * units..(e + 1) * units].fill(0.0);
                    h[e * units..(e + 1) * units].fill(0.0);
                }
            }
        }
    }
    Ok((EvalResult::from_episodes(&results), results))
}
