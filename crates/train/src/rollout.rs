//! Rollout storage: one epoch of experience from every environment, time-major (`[t][env]`),
//! in flat buffers reused from epoch to epoch.

/// Experience of `horizon` steps of `n_envs` environments.
#[derive(Clone, Debug)]
pub struct RolloutBuffer {
    /// Environments.
    pub n_envs: usize,
    /// Steps per environment.
    pub horizon: usize,
    /// Observation length.
    pub obs_dim: usize,
    /// Action length.
    pub act_dim: usize,
    /// Normalised observations `[t][env][obs]`.
    pub obs: Vec<f32>,
    /// Sampled (unclipped) actions `[t][env][act]`.
    pub actions: Vec<f32>,
    /// Gaussian means when acting `[t][env][act]` (for the KL of the update).
    pub mus: Vec<f32>,
    /// Log-probabilities of the actions `[t][env]`.
    pub log_probs: Vec<f32>,
    /// Value estimates, in return units `[t][env]`.
    pub values: Vec<f32>,
    /// Rewards, time-outs already bootstrapped `[t][env]`.
    pub rewards: Vec<f32>,
    /// The episode ended at this step `[t][env]`.
    pub dones: Vec<bool>,
    /// This observation is the first of an episode `[t][env]` (resets recurrent state).
    pub starts: Vec<bool>,
    /// GAE advantages `[t][env]`.
    pub advantages: Vec<f32>,
    /// Returns (advantage + value) `[t][env]`.
    pub returns: Vec<f32>,
    /// Recurrent (cell, hidden) state at each sequence start `[seq][env][units]`.
    pub cells: Vec<f32>,
    /// See `cells`.
    pub hiddens: Vec<f32>,
    /// A teacher's actions `[t][env][act]` (NaN where it gave none; see `crate::teacher`).
    pub teacher: Vec<f32>,
    /// A privileged critic's normalised values `[t][env][privileged]` (empty without one).
    pub privileged: Vec<f32>,
}

impl RolloutBuffer {
    /// Buffers for the given shape; `lstm_units` and `seq_len` size the recurrent states.
    pub fn new(
        n_envs: usize,
        horizon: usize,
        obs_dim: usize,
        act_dim: usize,
        lstm_units: usize,
        seq_len: usize,
    ) -> Self {
        let n = n_envs * horizon;
        let seqs = if lstm_units > 0 { horizon / seq_len } else { 0 };
        Self {
            n_envs,
            horizon,
            obs_dim,
            act_dim,
            obs: vec![0.0; n * obs_dim],
            actions: vec![0.0; n * act_dim],
            mus: vec![0.0; n * act_dim],
            log_probs: vec![0.0; n],
            values: vec![0.0; n],
            rewards: vec![0.0; n],
            dones: vec![false; n],
            starts: vec![false; n],
            advantages: vec![0.0; n],
            returns: vec![0.0; n],
            cells: vec![0.0; seqs * n_envs * lstm_units],
            hiddens: vec![0.0; seqs * n_envs * lstm_units],
            teacher: vec![f32::NAN; n * act_dim],
            privileged: Vec::new(),
        }
    }

    /// Samples in the buffer.
    pub fn len(&self) -> usize {
        self.n_envs * self.horizon
    }

    /// Whether it holds no samples.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}
