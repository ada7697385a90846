//! Evaluation of the current policy (deterministic: the Gaussian mean) on a scenario, each
//! environment running the same number of episodes so that short episodes are not favoured.

use crate::ppo::Ppo;
pub use rlnav_sim::task::EvalSummary;
use rlnav_sim::task::{EnvSetup, EpisodeStats, SimError};
use rlnav_sim::vec_env::VecEnv;
use std::sync::Arc;

/// Runs `episodes` episodes (`envs` at a time, `episodes / envs` each) of the learner's
/// deterministic policy, environment `i` with `setups[i % setups.len()]` (one robot each, say).
/// `seed` should differ from the training seeds so that procedurally generated scenes are new
/// to the policy. `progress` hears the count of finished episodes.
pub fn evaluate(
    ppo: &Ppo,
    setups: &[Arc<EnvSetup>],
    episodes: usize,
    envs: usize,
    seed: u64,
    threads: usize,
    progress: &mut dyn FnMut(usize),
) -> Result<(EvalSummary, Vec<EpisodeStats>), SimError> {
    let mut venv = VecEnv::new_mixed(setups, envs, seed, threads)?;
    let quota = episodes / envs;
    let mut done = vec![0usize; envs];
    let mut results = Vec::with_capacity(episodes);
    let units = ppo.model().lstm_units();
    let mut state = (units > 0).then(|| (vec![0.0f32; envs * units], vec![0.0f32; envs * units]));
    let mut actions = vec![[0.0f32; 2]; envs];
    // Environments past their quota stand still instead of simulating episodes no one counts.
    let mut active = vec![true; envs];
    let net = ppo.inference_net();
    while done.iter().any(|d| *d < quota) {
        let (mu, next) = ppo.act_mean(&net, &venv.obs, state.take());
        state = next;
        let a = mu.len() / envs;
        for (e, act) in actions.iter_mut().enumerate() {
            *act = [mu[e * a], mu[e * a + 1]];
        }
        active.iter_mut().zip(&done).for_each(|(a, d)| *a = *d < quota);
        venv.step_some(&actions, Some(&active))?;
        for e in 0..envs {
            if let Some(s) = venv.finished[e] {
                if done[e] < quota {
                    results.push(s);
                    done[e] += 1;
                    progress(results.len());
                }
                if let Some((c, h)) = &mut state {
                    c[e * units..(e + 1) * units].fill(0.0);
                    h[e * units..(e + 1) * units].fill(0.0);
                }
            }
        }
    }
    Ok((EvalSummary::of(&results), results))
}
