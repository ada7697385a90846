//! Generalised advantage estimation (Schulman et al. 2016) over a rollout stored time-major
//! (`[t][env]`), with time-outs bootstrapped rather than treated as terminal.

/// Computes advantages and returns (`advantages + values`) in place.
///
/// - `rewards`, `values`, `dones` are `[horizon][n_envs]`; `dones[t][e]` says the episode of
///   env `e` ended at step `t` (terminated or truncated: either way the next step belongs to a
///   new episode). Time-outs are bootstrapped by the caller adding `γ·V(final_obs)` to the
///   reward of the truncated step, so here a done always cuts the trace.
/// - `last_values` is `V(obs)` after the last step, `[n_envs]`.
#[allow(clippy::too_many_arguments)]
pub fn compute_gae(
    rewards: &[f32],
    values: &[f32],
    dones: &[bool],
    last_values: &[f32],
    n_envs: usize,
    gamma: f32,
    lambda: f32,
    advantages: &mut [f32],
    returns: &mut [f32],
) {
    let horizon = rewards.len() / n_envs;
    debug_assert_eq!(horizon * n_envs, rewards.len());
    for (e, &last) in last_values.iter().enumerate().take(n_envs) {
        let mut next_adv = 0.0f32;
        let mut next_value = last;
        for t in (0..horizon).rev() {
            let i = t * n_envs + e;
            let not_done = if dones[i] { 0.0 } else { 1.0 };
            let delta = rewards[i] + gamma * next_value * not_done - values[i];
            next_adv = delta + gamma * lambda * not_done * next_adv;
            advantages[i] = next_adv;
            returns[i] = next_adv + values[i];
            next_value = values[i];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lambda_one_gives_discounted_returns_minus_values() {
        // One env, 4 steps, no done: A_t = sum_k γ^k r_{t+k} + γ^{T-t} V_T - V_t.
        let r = [1.0, 0.0, 2.0, 1.0];
        let v = [0.5, 0.2, 0.1, 0.3];
        let (mut a, mut ret) = ([0.0; 4], [0.0; 4]);
        compute_gae(&r, &v, &[false; 4], &[2.0], 1, 0.9, 1.0, &mut a, &mut ret);
        let g: f32 = 0.9;
        let expected_return0 = 1.0 + g * 0.0 + g * g * 2.0 + g.powi(3) * 1.0 + g.powi(4) * 2.0;
        assert!((ret[0] - expected_return0).abs() < 1e-5);
        assert!((a[0] - (expected_return0 - 0.5)).abs() < 1e-5);
    }

    #[test]
    fn lambda_zero_is_one_step_td_and_dones_cut() {
        // Two envs interleaved; env 1's episode ends at t = 0.
        let r = [1.0, 5.0, 1.0, 1.0];
        let v = [0.0, 1.0, 0.5, 0.5];
        let d = [false, true, false, false];
        let (mut a, mut ret) = ([0.0; 4], [0.0; 4]);
        compute_gae(&r, &v, &d, &[1.0, 1.0], 2, 0.5, 0.0, &mut a, &mut ret);
        assert!((a[0] - (1.0 + 0.5 * 0.5 - 0.0)).abs() < 1e-6);
        assert!((a[1] - (5.0 - 1.0)).abs() < 1e-6, "terminal: no bootstrap");
        assert!((a[3] - (1.0 + 0.5 * 1.0 - 0.5)).abs() < 1e-6);
    }
}
