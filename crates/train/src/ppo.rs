//! Proximal policy optimisation with the details that matter in practice (the "37
//! implementation details", rl_games and rsl_rl): GAE, clipped surrogate, clipped value loss,
//! advantage standardisation, minibatches over several epochs, global gradient-norm clipping,
//! the adaptive KL learning rate, entropy and bounds losses, observation and value
//! normalisation, bootstrapped time-outs, and truncated BPTT for LSTM policies.

use crate::config::{LrSchedule, PpoConfig};
use crate::fast::{AdamState, Batch, FastNet, LossConfig};
use crate::gae::compute_gae;
use crate::rollout::RolloutBuffer;
use crate::teacher::Teacher;
use burn::module::{ModuleVisitor, Param, ParamId};
use burn::nn::LstmState;
use burn::optim::{AdamConfig, GradientsParams, ModuleOptimizer};
use burn::prelude::*;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use rand_pcg::Pcg64Mcg;
use rlnav_policy::{ActorCritic, NetworkConfig, RunningMeanStd};
use rlnav_sim::observation::ObservationMirror;
use rlnav_sim::task::{EpisodeStats, SimError};
use rlnav_sim::vec_env::VecEnv;

/// Recurrent state of a batch of environments: (cell, hidden), each `[env][units]`.
pub type RecurrentState = (Vec<f32>, Vec<f32>);

/// `0.5 * ln(2π)`.
pub(crate) const HALF_LN_2PI: f32 = 0.918_938_5;
/// Action means beyond this are penalised by the bounds loss (rl_games' soft bound).
pub(crate) const SOFT_BOUND: f32 = 1.1;

/// The log-probability of action component `a` under `N(mu, exp(log_std))` and its
/// derivatives with respect to `mu` and `log_std`: `(log p, ∂/∂mu, ∂/∂log_std)`.
///
/// With `clipped`, `a` is scored as the robot executes it, clipped to `[-1, 1]` (Clipped
/// Action Policy Gradient, Fujita & Maeda 2018): a sample at or beyond a bound has the
/// probability of the whole tail beyond it. Scored as a density instead, a sample beyond a
/// bound acts as the bound whatever its distance, and the surrogate gains from ever wider
/// noise (the learned σ then grows past 1 with no entropy bonus).
pub(crate) fn action_log_prob(a: f32, mu: f32, log_std: f32, clipped: bool) -> (f32, f32, f32) {
    let std = log_std.exp();
    if clipped && (a >= 1.0 || a <= -1.0) {
        // Upper tail: ln Q(u), u = (1 - mu)/σ. Lower tail: ln Φ(l) = ln Q(-l), l = (-1 - mu)/σ.
        let upper = a >= 1.0;
        let t = if upper { (1.0 - mu) / std } else { (1.0 + mu) / std };
        let (log_q, hazard) = log_upper_tail(t as f64);
        let (log_q, hazard) = (log_q as f32, hazard as f32);
        // ∂ ln Q(t)/∂t = -hazard; ∂t/∂mu = ∓1/σ; ∂t/∂log σ = -t.
        let d_mu = if upper { hazard / std } else { -hazard / std };
        return (log_q, d_mu, hazard * t);
    }
    let z = (a - mu) / std;
    (-0.5 * z * z - log_std - HALF_LN_2PI, z / std, z * z - 1.0)
}

/// `ln Q(t)` for the standard normal's upper tail `Q(t) = P(X > t)`, and its hazard
/// `φ(t)/Q(t)`, accurate far into the tail (where `1 - Φ(t)` rounds to zero).
fn log_upper_tail(t: f64) -> (f64, f64) {
    const HALF_LN_2PI_64: f64 = 0.918_938_533_204_672_7;
    let log_phi = -0.5 * t * t - HALF_LN_2PI_64;
    if t < 25.0 {
        let q = 0.5 * libm::erfc(t / std::f64::consts::SQRT_2);
        let log_q = q.ln();
        (log_q, (log_phi - log_q).exp())
    } else {
        // Asymptotic series: Q(t) ≈ φ(t)/t · (1 - 1/t² + 3/t⁴).
        let s = 1.0 - 1.0 / (t * t) + 3.0 / t.powi(4);
        let log_q = log_phi - t.ln() + s.ln();
        (log_q, t / s)
    }
}

/// What one update measured (means over minibatches).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct UpdateStats {
    /// Clipped-surrogate loss.
    pub policy_loss: f32,
    /// Value loss.
    pub value_loss: f32,
    /// Approximate KL(old || new).
    pub kl: f32,
    /// Policy entropy.
    pub entropy: f32,
    /// Fraction of samples whose ratio was clipped.
    pub clip_fraction: f32,
    /// Learning rate after the update.
    pub learning_rate: f32,
    /// Mean squared distance of the means from a teacher's actions (0 without one).
    pub teacher_loss: f32,
}

/// The learner: network, optimiser, normalisers, rollout storage.
pub struct Ppo {
    /// Seconds the last [`Ppo::collect`] spent stepping the simulator.
    pub sim_s: f64,
    cfg: PpoConfig,
    /// Device gradients are tracked on.
    device: Device,
    /// Plain device for inference while collecting experience.
    plain: Device,
    /// `None` only while the optimiser is stepping it.
    model: Option<ActorCritic>,
    optim: ModuleOptimizer,
    /// Running observation statistics.
    pub obs_norm: RunningMeanStd,
    /// Running return statistics (value normalisation).
    pub value_norm: RunningMeanStd,
    /// Running statistics of a privileged critic's values (`network.critic_movers`).
    pub privileged_norm: RunningMeanStd,
    /// Privileged values per sample (0: the critic sees the observation only).
    privileged_dim: usize,
    lr: f32,
    rng: Pcg64Mcg,
    buffer: RolloutBuffer,
    /// Per-environment recurrent state (cell, hidden), `[env][units]`.
    state: Option<RecurrentState>,
    act_dim: usize,
    /// The hand-written CPU learner (MLP and LSTM networks); `None` when burn learns.
    /// While it exists its parameters are the network's, copied into `model` after each update.
    fast: Option<FastNet>,
    /// Kickstarting: the teacher and the imitation weight of this epoch.
    teacher: Option<Teacher>,
    teacher_weight: f32,
    /// This epoch's ceiling on the log standard deviations (`train.max_log_std`).
    log_std_ceiling: Option<f32>,
    /// `train.mirror`: half of each minibatch is trained on as its mirror image.
    mirror: Option<ObservationMirror>,
}

/// Gradient-norm clipping over all parameters together (burn's own clipping is per tensor).
struct GlobalNorm<'a> {
    grads: &'a mut GradientsParams,
    sum_sq: f32,
    scale: Option<f32>,
}

impl ModuleVisitor for GlobalNorm<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let id: ParamId = param.id;
        match self.scale {
            None => {
                if let Some(g) = self.grads.get::<D>(id) {
                    self.sum_sq += g.powf_scalar(2.0).sum().into_scalar::<f32>();
                }
            }
            Some(s) => {
                if let Some(g) = self.grads.remove::<D>(id) {
                    self.grads.register::<D>(id, g * s);
                }
            }
        }
    }
}

fn tensor2(data: Vec<f32>, rows: usize, cols: usize, device: &Device) -> Tensor<2> {
    Tensor::from_data(TensorData::new(data, [rows, cols]), device)
}

fn tensor1(data: Vec<f32>, device: &Device) -> Tensor<1> {
    let n = data.len();
    Tensor::from_data(TensorData::new(data, [n]), device)
}

pub(crate) fn to_vec<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data().try_to_vec::<f32>().expect("float tensor")
}

/// A minibatch's targets as tensors on the autodiff device.
pub(crate) struct BurnBatch {
    pub actions: Tensor<2>,
    pub old_log_probs: Tensor<1>,
    pub advantages: Tensor<1>,
    pub returns: Tensor<1>,
    pub old_values: Tensor<1>,
    /// Teacher actions (0 where unlabelled), the labelled-row mask and the labelled count.
    pub teacher: Option<(Tensor<2>, Tensor<1>, usize)>,
}

impl BurnBatch {
    /// The teacher part of a batch from actions `[rows][act]` with NaN rows unlabelled
    /// (`None` when no row is labelled).
    pub(crate) fn teacher(labels: &[f32], act: usize, device: &Device) -> Option<(Tensor<2>, Tensor<1>, usize)> {
        let rows = labels.len() / act.max(1);
        let mask: Vec<f32> = (0..rows).map(|k| if labels[k * act].is_finite() { 1.0 } else { 0.0 }).collect();
        let n = mask.iter().filter(|m| **m > 0.0).count();
        (n > 0).then(|| {
            let zeroed: Vec<f32> = labels.iter().map(|x| if x.is_finite() { *x } else { 0.0 }).collect();
            (tensor2(zeroed, rows, act, device), tensor1(mask, device), n)
        })
    }
}

/// The PPO loss and its parts, as burn tensors.
pub(crate) struct BurnLoss {
    pub total: Tensor<1>,
    pub policy: Tensor<1>,
    pub value: Tensor<1>,
    pub entropy: Tensor<1>,
    pub ratio: Tensor<1>,
    /// Mean squared distance from the teacher's actions on labelled rows.
    pub teacher: Option<Tensor<1>>,
}

/// The PPO loss of means `mu`, values `v` and `log_std` on `batch`: clipped surrogate, (clipped)
/// value loss, entropy bonus, bounds loss, imitation of a teacher. The hand-written learner
/// computes the same.
pub(crate) fn burn_loss(
    mu: Tensor<2>,
    v: Tensor<1>,
    log_std: Tensor<1>,
    batch: BurnBatch,
    cfg: &LossConfig,
) -> BurnLoss {
    let BurnBatch { actions, old_log_probs, advantages: adv, returns: ret, old_values: old_v, teacher } = batch;
    let teacher = teacher.map(|(target, mask, n)| {
        ((mu.clone() - target).powf_scalar(2.0).sum_dim(1).squeeze_dim::<1>(1) * mask).sum() / n as f32
    });
    let log_std2 = log_std.clone().unsqueeze::<2>();
    let std2 = log_std2.clone().exp();
    let z = (actions.clone() - mu.clone()) / std2.clone();
    let mut logp2 = z.powf_scalar(2.0) * -0.5 - log_std2 - HALF_LN_2PI;
    if cfg.clipped_actions {
        // The tails' masses (see `action_log_prob`): ln Q(t) = ln ½ + ln(1 - erf(t/√2)), floored
        // where f32's erf rounds to one (the hand-written learner is exact there).
        let log_tail = |t: Tensor<2>| {
            ((t * std::f32::consts::FRAC_1_SQRT_2).erf().neg() + 1.0).clamp_min(1e-30).log() - std::f32::consts::LN_2
        };
        let upper = log_tail((mu.clone().neg() + 1.0) / std2.clone());
        let lower = log_tail((mu.clone() + 1.0) / std2);
        logp2 = logp2
            .mask_where(actions.clone().greater_equal_elem(1.0), upper)
            .mask_where(actions.lower_equal_elem(-1.0), lower);
    }
    let logp: Tensor<1> = logp2.sum_dim(1).squeeze_dim(1);
    let ratio = (logp - old_log_probs).exp();
    let e = cfg.e_clip;
    let surr = (ratio.clone() * adv.clone()).min_pair(ratio.clone().clamp(1.0 - e, 1.0 + e) * adv);
    let policy = surr.mean().neg();
    let value = if cfg.clip_value {
        let clipped = old_v.clone() + (v.clone() - old_v).clamp(-e, e);
        (v - ret.clone()).powf_scalar(2.0).max_pair((clipped - ret).powf_scalar(2.0)).mean()
    } else {
        (v - ret).powf_scalar(2.0).mean()
    };
    let entropy = (log_std + 0.5 + HALF_LN_2PI).sum();
    let bounds = ((mu.clone() - SOFT_BOUND).clamp_min(0.0).powf_scalar(2.0)
        + (mu + SOFT_BOUND).clamp_max(0.0).powf_scalar(2.0))
    .sum_dim(1)
    .mean();
    let mut total = policy.clone() + value.clone() * (0.5 * cfg.critic_coef) - entropy.clone() * cfg.entropy_coef
        + bounds * cfg.bounds_loss_coef;
    if let Some(t) = &teacher {
        total = total + t.clone() * cfg.teacher_coef;
    }
    BurnLoss { total, policy, value, entropy, ratio, teacher }
}

/// `log_std` capped at `max`, as a fresh leaf (so that the clamp does not enter the next
/// step's graph).
fn cap_log_std(log_std: Param<Tensor<1>>, max: f32) -> Param<Tensor<1>> {
    log_std.map(|t| {
        let tracked = t.is_require_grad();
        let data = t.clone().clamp_max(max).into_data();
        let capped = Tensor::<1>::from_data(data, &t.device());
        if tracked { capped.require_grad() } else { capped }
    })
}

impl Ppo {
    /// A new learner for observations of `obs_dim` and `act_dim` actions, on `plain` (with
    /// gradients on `plain.autodiff()`).
    pub fn new(
        cfg: &PpoConfig,
        network: &NetworkConfig,
        obs_dim: usize,
        act_dim: usize,
        plain: Device,
        seed: u64,
    ) -> Self {
        let device = plain.clone().autodiff();
        let mut model = ActorCritic::seeded(network, obs_dim, act_dim, &device, seed);
        if let Some(start) = cfg.max_log_std.map(|c| c.start()) {
            model.log_std = cap_log_std(model.log_std, start);
        }
        let units = model.lstm_units();
        let privileged_dim = model.critic_extra;
        let fast = cfg.uses_fast_learner().then(|| FastNet::from_model(&model, cfg.threads));
        let mut buffer = RolloutBuffer::new(cfg.num_actors, cfg.horizon_length, obs_dim, act_dim, units, cfg.seq_len);
        buffer.privileged = vec![0.0; cfg.num_actors * cfg.horizon_length * privileged_dim];
        Self {
            sim_s: 0.0,
            cfg: cfg.clone(),
            optim: AdamConfig::new().with_epsilon(1e-8).init(),
            model: Some(model),
            device,
            plain,
            obs_norm: RunningMeanStd::new(obs_dim),
            value_norm: RunningMeanStd::new(1),
            privileged_norm: RunningMeanStd::new(privileged_dim),
            privileged_dim,
            lr: cfg.learning_rate,
            rng: Pcg64Mcg::seed_from_u64(seed ^ 0x9e37_79b9_7f4a_7c15),
            buffer,
            state: (units > 0).then(|| (vec![0.0; cfg.num_actors * units], vec![0.0; cfg.num_actors * units])),
            act_dim,
            fast,
            teacher: cfg.teacher.as_ref().map(|t| Teacher::new(t, cfg.num_actors)),
            teacher_weight: 0.0,
            log_std_ceiling: cfg.max_log_std.map(|c| c.start()),
            mirror: None,
        }
    }

    /// Trains a random half of each minibatch as its mirror image (`train.mirror`), mirrored
    /// by `mirror` (which must fit the observation length). The observation statistics are updated with
    /// both copies from now on, so that they stay mirror-symmetric and mirroring a normalised
    /// observation is normalising the mirrored one.
    pub fn set_mirror(&mut self, mirror: ObservationMirror) {
        assert_eq!(mirror.len(), self.buffer.obs_dim, "a mirror of the observation's length");
        assert_eq!(self.act_dim, 2, "a mirror of (linear, angular) actions");
        self.mirror = Some(mirror);
    }

    /// Sets the imitation weight for `epoch` (`train.teacher`'s schedule); while it is 0 the
    /// teacher labels nothing.
    pub fn set_teacher_epoch(&mut self, epoch: usize) {
        self.teacher_weight = self.cfg.teacher.as_ref().map_or(0.0, |t| t.weight_at(epoch));
    }

    /// The imitation weight of this epoch.
    pub fn teacher_weight(&self) -> f32 {
        self.teacher_weight
    }

    /// The network (on the autodiff device).
    pub fn model(&self) -> &ActorCritic {
        self.model.as_ref().expect("the network is only absent during a step")
    }

    /// Replaces network and optimiser state (resuming a run). With the hand-written learner,
    /// `optim` is unused and Adam starts afresh unless [`Self::restore_adam`] follows.
    pub fn restore(&mut self, model: ActorCritic, optim: ModuleOptimizer, lr: f32) {
        if self.fast.is_some() {
            self.fast = Some(FastNet::from_model(&model, self.cfg.threads));
        }
        self.model = Some(model);
        self.optim = optim;
        self.lr = lr;
    }

    /// The optimiser (for checkpoints) when burn learns.
    pub fn optimizer(&self) -> &ModuleOptimizer {
        &self.optim
    }

    /// Adam's state when the hand-written learner learns (for checkpoints); `None` when burn does.
    pub fn fast_adam(&self) -> Option<&AdamState> {
        self.fast.as_ref().map(|f| f.adam())
    }

    /// Restores the hand-written learner's Adam state (resuming); an error names what does not
    /// match.
    pub fn restore_adam(&mut self, adam: AdamState) -> Result<(), String> {
        match &mut self.fast {
            Some(f) => f.set_adam(adam),
            None => Err("this run's learner is burn's, not the hand-written one".into()),
        }
    }

    /// Current learning rate.
    pub fn learning_rate(&self) -> f32 {
        self.lr
    }

    /// Reseeds action sampling (each epoch draws from `(seed, epoch)`, so a resumed run
    /// samples as an uninterrupted one would).
    pub fn reseed(&mut self, seed: u64, epoch: u64) {
        self.rng = Pcg64Mcg::seed_from_u64(rlnav_sim::vec_env::env_seed(seed, epoch as usize));
    }

    /// Forgets recurrent state (after the environments were rebuilt).
    pub fn reset_state(&mut self) {
        if let Some((c, h)) = &mut self.state {
            c.fill(0.0);
            h.fill(0.0);
        }
    }

    fn normalized(&mut self, raw: &[f32], update: bool) -> Vec<f32> {
        let mut x = raw.to_vec();
        if self.cfg.normalize_input {
            if update {
                match &self.mirror {
                    // Both copies in one update: the statistics of a mirrored value and of its
                    // partner stay equal, and those of a negated one stay centred on 0.
                    Some(m) => {
                        let mut both = raw.to_vec();
                        both.extend(m.mirrored(raw));
                        self.obs_norm.update(&both);
                    }
                    None => self.obs_norm.update(raw),
                }
            }
            self.obs_norm.normalize(&mut x);
        }
        x
    }

    /// A privileged critic's values normalised (statistics updated with `update`).
    fn normalized_privileged(&mut self, raw: &[f32], update: bool) -> Vec<f32> {
        let mut x = raw.to_vec();
        if self.cfg.normalize_input && !x.is_empty() {
            if update {
                self.privileged_norm.update(raw);
            }
            self.privileged_norm.normalize(&mut x);
        }
        x
    }

    fn denorm_values(&self, v: &mut [f32]) {
        if self.cfg.normalize_value {
            self.value_norm.denormalize(v);
        }
    }

    /// Runs the inference network on normalised observations `[n][obs]` with recurrent state
    /// rows `rows` (all environments when `None`); returns means `[n][act]` and values in
    /// return units, and the next state.
    fn infer(
        &self,
        net: &ActorCritic,
        obs: Vec<f32>,
        privileged: &[f32],
        state: Option<RecurrentState>,
    ) -> (Vec<f32>, Vec<f32>, Option<RecurrentState>) {
        if let Some(fast) = &self.fast {
            let (mu, mut v, next) = fast.infer_privileged(&obs, privileged, state);
            self.denorm_values(&mut v);
            return (mu, v, next);
        }
        let n = obs.len() / self.buffer.obs_dim;
        let x = tensor2(obs, n, self.buffer.obs_dim, &self.plain);
        let units = net.lstm_units();
        let st =
            state.map(|(c, h)| LstmState::new(tensor2(c, n, units, &self.plain), tensor2(h, n, units, &self.plain)));
        let (mu, v, next) = if self.privileged_dim > 0 {
            // Privileged critics are feed-forward (NetworkConfig::check). Without the values
            // (the actor's mean is wanted) the critic reads zeros.
            let (mu, v) = if privileged.is_empty() {
                net.heads(x)
            } else {
                net.heads_privileged(x, Some(tensor2(privileged.to_vec(), n, self.privileged_dim, &self.plain)))
            };
            (mu, v, st)
        } else {
            net.step(x, st)
        };
        let mut v = to_vec(v);
        self.denorm_values(&mut v);
        (to_vec(mu), v, next.map(|s| (to_vec(s.cell), to_vec(s.hidden))))
    }

    /// Collects one epoch of experience from `env` (which must have `num_actors`
    /// environments); finished episodes' statistics go to `episodes`.
    pub fn collect(&mut self, env: &mut VecEnv, episodes: &mut Vec<EpisodeStats>) -> Result<(), SimError> {
        let (n, d, a) = (self.buffer.n_envs, self.buffer.obs_dim, self.act_dim);
        assert_eq!(env.len(), n, "one environment per actor");
        let net = self.model().valid();
        let log_std: Vec<f32> = to_vec(net.log_std.val());
        let std: Vec<f32> = log_std.iter().map(|l| l.exp()).collect();
        let mut actions = vec![[0.0f32; 2]; n];
        let clipped = self.cfg.clipped_actions;
        let units = net.lstm_units();
        self.sim_s = 0.0;
        let mut truncated: Vec<usize> = Vec::with_capacity(n);
        let mut bootstrap = vec![0.0f32; n];
        let p = self.privileged_dim;
        assert_eq!(env.privileged_dim(), p, "the environments keep the critic's privileged state");
        for t in 0..self.buffer.horizon {
            let obs = self.normalized(&env.obs, true);
            let privileged = self.normalized_privileged(&env.privileged, true);
            self.buffer.privileged[t * n * p..(t + 1) * n * p].copy_from_slice(&privileged);
            if units > 0 && t % self.cfg.seq_len == 0 {
                let (c, h) = self.state.as_ref().expect("recurrent state");
                let k = t / self.cfg.seq_len;
                self.buffer.cells[k * n * units..(k + 1) * n * units].copy_from_slice(c);
                self.buffer.hiddens[k * n * units..(k + 1) * n * units].copy_from_slice(h);
            }
            self.buffer.obs[t * n * d..(t + 1) * n * d].copy_from_slice(&obs);
            let labels = &mut self.buffer.teacher[t * n * a..(t + 1) * n * a];
            match &mut self.teacher {
                Some(teacher) if self.teacher_weight > 0.0 => teacher.label(env, labels, a),
                _ => labels.fill(f32::NAN),
            }
            let state = self.state.take();
            let (mu, values, next) = self.infer(&net, obs, &privileged, state);
            self.state = next;
            for e in 0..n {
                let i = t * n + e;
                let mut logp = 0.0;
                for j in 0..a {
                    let eps: f32 = self.rng.sample(StandardNormal);
                    let act = mu[e * a + j] + std[j] * eps;
                    self.buffer.actions[i * a + j] = act;
                    self.buffer.mus[i * a + j] = mu[e * a + j];
                    logp += action_log_prob(act, mu[e * a + j], log_std[j], clipped).0;
                    if j < 2 {
                        actions[e][j] = act;
                    }
                }
                self.buffer.log_probs[i] = logp;
                self.buffer.values[i] = values[e];
            }
            let t_sim = std::time::Instant::now();
            env.step(&actions)?;
            self.sim_s += t_sim.elapsed().as_secs_f64();
            // Time-outs are not failures of the policy: bootstrap them with γ·V(final obs).
            truncated.clear();
            truncated.extend((0..n).filter(|e| env.truncated[*e]));
            bootstrap.fill(0.0);
            if !truncated.is_empty() {
                let mut rows = Vec::with_capacity(truncated.len() * d);
                for &e in &truncated {
                    rows.extend_from_slice(&env.final_obs[e * d..(e + 1) * d]);
                }
                let rows = self.normalized(&rows, false);
                let finals: Vec<f32> =
                    truncated.iter().flat_map(|&e| env.final_privileged[e * p..(e + 1) * p].iter().copied()).collect();
                let finals = self.normalized_privileged(&finals, false);
                let st = self.state.as_ref().map(|(c, h)| {
                    let pick =
                        |v: &Vec<f32>| truncated.iter().flat_map(|e| v[e * units..(e + 1) * units].to_vec()).collect();
                    (pick(c), pick(h))
                });
                let (_, v, _) = self.infer(&net, rows, &finals, st);
                for (k, &e) in truncated.iter().enumerate() {
                    bootstrap[e] = self.cfg.gamma * v[k];
                }
            }
            for e in 0..n {
                let i = t * n + e;
                let done = env.terminated[e] || env.truncated[e];
                self.buffer.rewards[i] = env.rewards[e] + bootstrap[e];
                self.buffer.dones[i] = done;
                if t + 1 < self.buffer.horizon {
                    self.buffer.starts[i + n] = done;
                }
                if let Some(s) = env.finished[e] {
                    episodes.push(s);
                }
                if done && let Some(teacher) = &mut self.teacher {
                    teacher.episode_ended(e);
                }
                if done && let Some((c, h)) = &mut self.state {
                    c[e * units..(e + 1) * units].fill(0.0);
                    h[e * units..(e + 1) * units].fill(0.0);
                }
            }
        }
        // The first observation of the next rollout starts an episode where the last step ended one.
        for e in 0..n {
            self.buffer.starts[e] = self.buffer.dones[(self.buffer.horizon - 1) * n + e];
        }
        let obs = self.normalized(&env.obs, false);
        let privileged = self.normalized_privileged(&env.privileged, false);
        let (_, last_values, _) = self.infer(&net, obs, &privileged, self.state.clone());
        let b = &mut self.buffer;
        compute_gae(
            &b.rewards,
            &b.values,
            &b.dones,
            &last_values,
            n,
            self.cfg.gamma,
            self.cfg.tau,
            &mut b.advantages,
            &mut b.returns,
        );
        Ok(())
    }

    /// Minibatch order: sample indices, or (for LSTM) sequence indices.
    fn order(&mut self, units: usize) -> Vec<usize> {
        let count = if units > 0 { self.buffer.len() / self.cfg.seq_len } else { self.buffer.len() };
        let mut idx: Vec<usize> = (0..count).collect();
        for i in (1..idx.len()).rev() {
            let j = self.rng.random_range(0..=i);
            idx.swap(i, j);
        }
        idx
    }

    /// Updates the network on the collected epoch.
    pub fn update(&mut self) -> UpdateStats {
        let (n, d, a) = (self.buffer.n_envs, self.buffer.obs_dim, self.act_dim);
        let units = self.model().lstm_units();
        let seq = if units > 0 { self.cfg.seq_len } else { 1 };
        // Value targets and old values in the network's (normalised) units.
        let mut targets = self.buffer.returns.clone();
        let mut old_values = self.buffer.values.clone();
        if self.cfg.normalize_value {
            self.value_norm.update(&self.buffer.returns);
            let clip = self.value_norm.clip;
            self.value_norm.clip = f32::INFINITY;
            self.value_norm.normalize(&mut targets);
            self.value_norm.normalize(&mut old_values);
            self.value_norm.clip = clip;
        }
        let old_log_std: Vec<f32> = to_vec(self.model().log_std.val());
        let mb_items = self.cfg.minibatch_size / seq;
        let loss_cfg = LossConfig {
            e_clip: self.cfg.e_clip,
            clip_value: self.cfg.clip_value,
            critic_coef: self.cfg.critic_coef,
            entropy_coef: self.cfg.entropy_coef,
            bounds_loss_coef: self.cfg.bounds_loss_coef,
            teacher_coef: self.teacher_weight,
            clipped_actions: self.cfg.clipped_actions,
        };
        let teach = self.teacher_weight > 0.0;
        let mut stats = UpdateStats::default();
        let mut count = 0.0f32;
        for _ in 0..self.cfg.mini_epochs {
            let order = self.order(units);
            for chunk in order.chunks(mb_items) {
                // Sample index of item k at time offset s (t-major within sequences).
                let index = |item: usize, s: usize| {
                    if units > 0 {
                        let (k, e) = (item / n, item % n);
                        (k * seq + s) * n + e
                    } else {
                        item
                    }
                };
                let rows = chunk.len() * seq;
                let mut obs = Vec::with_capacity(rows * d);
                let mut act = Vec::with_capacity(rows * a);
                let mut old_mu_v = Vec::with_capacity(rows * a);
                let (mut old_logp, mut adv, mut ret, mut old_v) = (
                    Vec::with_capacity(rows),
                    Vec::with_capacity(rows),
                    Vec::with_capacity(rows),
                    Vec::with_capacity(rows),
                );
                let mut starts = Vec::with_capacity(rows);
                let mut teacher = Vec::with_capacity(if teach { rows * a } else { 0 });
                let p = self.privileged_dim;
                let mut privileged = Vec::with_capacity(rows * p);
                for s in 0..seq {
                    for &item in chunk {
                        let i = index(item, s);
                        if teach {
                            teacher.extend_from_slice(&self.buffer.teacher[i * a..(i + 1) * a]);
                        }
                        obs.extend_from_slice(&self.buffer.obs[i * d..(i + 1) * d]);
                        privileged.extend_from_slice(&self.buffer.privileged[i * p..(i + 1) * p]);
                        act.extend_from_slice(&self.buffer.actions[i * a..(i + 1) * a]);
                        old_mu_v.extend_from_slice(&self.buffer.mus[i * a..(i + 1) * a]);
                        old_logp.push(self.buffer.log_probs[i]);
                        adv.push(self.buffer.advantages[i]);
                        ret.push(targets[i]);
                        old_v.push(old_values[i]);
                        starts.push(if self.buffer.starts[i] { 0.0f32 } else { 1.0 });
                    }
                }
                if let Some(m) = &self.mirror {
                    // A random half of the samples is replaced by its mirror image, which has
                    // the same return and advantage (the task is symmetric) and the behaviour
                    // probability of the sample it mirrors (the collecting policy, mirrored,
                    // drew it with that probability). In place, so an update costs what it
                    // did; RSL-RL appends the mirrored copies instead, doubling it.
                    let mut row = vec![0.0f32; d];
                    for k in 0..rows {
                        if self.rng.random_bool(0.5) {
                            m.apply(&obs[k * d..(k + 1) * d], &mut row);
                            obs[k * d..(k + 1) * d].copy_from_slice(&row);
                            act[k * a + 1] = -act[k * a + 1];
                            old_mu_v[k * a + 1] = -old_mu_v[k * a + 1];
                            if teach {
                                teacher[k * a + 1] = -teacher[k * a + 1];
                            }
                        }
                    }
                }
                if self.cfg.normalize_advantage && adv.len() > 1 {
                    let mean = adv.iter().sum::<f32>() / adv.len() as f32;
                    let var = adv.iter().map(|x| (x - mean).powi(2)).sum::<f32>() / adv.len() as f32;
                    let inv = 1.0 / (var.sqrt() + 1e-8);
                    adv.iter_mut().for_each(|x| *x = (*x - mean) * inv);
                }
                let (lr, max_norm) = (self.lr, self.cfg.grad_norm);
                // Each sequence's stored state before its first step.
                let gather = |v: &[f32]| -> Vec<f32> {
                    chunk.iter().flat_map(|item| v[item * units..(item + 1) * units].iter().copied()).collect()
                };
                let (cell, hidden) = if units > 0 {
                    (gather(&self.buffer.cells), gather(&self.buffer.hiddens))
                } else {
                    (Vec::new(), Vec::new())
                };
                let (new_mu, new_ls, ratios, losses) = if let Some(fast) = self.fast.as_mut() {
                    let ls = fast.log_std().to_vec();
                    let batch = Batch {
                        obs: &obs,
                        seq,
                        starts: if units > 0 { &starts } else { &[] },
                        cell: &cell,
                        hidden: &hidden,
                        actions: &act,
                        old_log_probs: &old_logp,
                        advantages: &adv,
                        returns: &ret,
                        old_values: &old_v,
                        teacher: &teacher,
                        privileged: &privileged,
                    };
                    let r = fast.step(&batch, &loss_cfg, lr, max_norm);
                    if let Some(max) = self.log_std_ceiling {
                        fast.cap_log_std(max);
                    }
                    (r.mu, ls, r.ratios, [r.policy_loss, r.value_loss, r.entropy, r.teacher_loss])
                } else {
                    let dev = self.device.clone();
                    let (mu, v) = if units > 0 {
                        let b = chunk.len();
                        let mut state =
                            Some(LstmState::new(tensor2(cell, b, units, &dev), tensor2(hidden, b, units, &dev)));
                        let (mut mus, mut vs) = (Vec::with_capacity(seq), Vec::with_capacity(seq));
                        for s in 0..seq {
                            let x = tensor2(obs[s * b * d..(s + 1) * b * d].to_vec(), b, d, &dev);
                            let mask = tensor2(starts[s * b..(s + 1) * b].to_vec(), b, 1, &dev);
                            let st = state.take().map(|st| LstmState::new(st.cell * mask.clone(), st.hidden * mask));
                            let (mu, v, next) = self.model().step(x, st);
                            state = next;
                            mus.push(mu);
                            vs.push(v);
                        }
                        (Tensor::cat(mus, 0), Tensor::cat(vs, 0))
                    } else if p > 0 {
                        let x = tensor2(obs, rows, d, &dev);
                        self.model().heads_privileged(x, Some(tensor2(privileged, rows, p, &dev)))
                    } else {
                        self.model().forward(tensor2(obs, rows, d, &dev))
                    };
                    let batch = BurnBatch {
                        actions: tensor2(act, rows, a, &dev),
                        old_log_probs: tensor1(old_logp, &dev),
                        advantages: tensor1(adv, &dev),
                        returns: tensor1(ret, &dev),
                        old_values: tensor1(old_v, &dev),
                        teacher: BurnBatch::teacher(&teacher, a, &dev),
                    };
                    let log_std = self.model().log_std.val();
                    let l = burn_loss(mu.clone(), v, log_std.clone(), batch, &loss_cfg);
                    let mut grads = GradientsParams::from_grads(l.total.backward(), self.model());
                    let mut clip = GlobalNorm { grads: &mut grads, sum_sq: 0.0, scale: None };
                    self.model().visit(&mut clip);
                    let norm = clip.sum_sq.sqrt();
                    if norm > max_norm {
                        clip.scale = Some(max_norm / norm);
                        self.model().visit(&mut clip);
                    }
                    // The optimiser takes the network by value; moving it out (rather than
                    // cloning) lets burn update the parameters in place.
                    let model = self.model.take().expect("the network is only absent during a step");
                    let mut model = self.optim.step(lr as f64, model, grads);
                    if let Some(max) = self.log_std_ceiling {
                        model.log_std = cap_log_std(model.log_std, max);
                    }
                    self.model = Some(model);
                    // Values read after the backward pass (burn's tape allows one backward,
                    // and detach() would cut the graph the loss needs).
                    let losses = [
                        l.policy.into_scalar::<f32>(),
                        l.value.into_scalar::<f32>(),
                        l.entropy.into_scalar::<f32>(),
                        l.teacher.map_or(0.0, |t| t.into_scalar::<f32>()),
                    ];
                    (to_vec(mu), to_vec(log_std), to_vec(l.ratio), losses)
                };

                // KL(old || new) of the diagonal Gaussians (for the adaptive learning rate) and
                // the clipped fraction, with the network as it was before this step.
                let mut kl = 0.0f64;
                for (m_new, m_old) in new_mu.chunks(a).zip(old_mu_v.chunks(a)) {
                    for j in 0..a {
                        let (ls_new, ls_old) = (new_ls[j], old_log_std[j]);
                        let var_new = (2.0 * ls_new).exp();
                        kl += (ls_new - ls_old
                            + ((2.0 * ls_old).exp() + (m_old[j] - m_new[j]).powi(2)) / (2.0 * var_new)
                            - 0.5) as f64;
                    }
                }
                let kl = (kl / rows as f64) as f32;
                let e = self.cfg.e_clip;
                let clipped = ratios.iter().filter(|r| (*r - 1.0).abs() > e).count() as f32 / rows as f32;

                if self.cfg.lr_schedule == LrSchedule::Adaptive && kl.is_finite() {
                    if kl > 2.0 * self.cfg.kl_threshold {
                        self.lr = (self.lr / 1.5).max(1e-6);
                    } else if kl < 0.5 * self.cfg.kl_threshold {
                        self.lr = (self.lr * 1.5).min(1e-2);
                    }
                }
                stats.policy_loss += losses[0];
                stats.value_loss += losses[1];
                stats.entropy += losses[2];
                stats.teacher_loss += losses[3];
                stats.kl += kl;
                stats.clip_fraction += clipped;
                count += 1.0;
            }
        }
        if let Some(fast) = &self.fast {
            let model = self.model.take().expect("the network is only absent during a step");
            self.model = Some(fast.write_into(model));
        }
        stats.policy_loss /= count;
        stats.value_loss /= count;
        stats.entropy /= count;
        stats.teacher_loss /= count;
        stats.kl /= count;
        stats.clip_fraction /= count;
        stats.learning_rate = self.lr;
        stats
    }

    /// Sets the learning rate of the linear schedule and the noise ceiling
    /// (`train.max_log_std`) for `epoch` of `max_epochs`.
    pub fn schedule(&mut self, epoch: usize) {
        self.log_std_ceiling = self.cfg.max_log_std.map(|c| c.at(epoch, self.cfg.max_epochs));
        if self.cfg.lr_schedule == LrSchedule::Linear {
            let frac = 1.0 - epoch as f32 / self.cfg.max_epochs as f32;
            self.lr = (self.cfg.learning_rate * frac).max(1e-7);
        }
    }

    /// The network without gradient tracking, for acting: build it once, then call
    /// [`Self::act_mean`] with it for every step.
    pub fn inference_net(&self) -> ActorCritic {
        self.model().valid()
    }

    /// Deterministic actions (the Gaussian means) of `net` (from [`Self::inference_net`]) for
    /// raw observations `[n][obs]`, carrying `state` for recurrent policies; used by evaluation.
    pub fn act_mean(
        &self,
        net: &ActorCritic,
        raw_obs: &[f32],
        state: Option<RecurrentState>,
    ) -> (Vec<f32>, Option<RecurrentState>) {
        let mut x = raw_obs.to_vec();
        if self.cfg.normalize_input {
            self.obs_norm.normalize(&mut x);
        }
        let (mu, _, next) = self.infer(net, x, &[], state);
        (mu, next)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{Learner, LogStdCeiling};

    /// An epoch whose far-out samples (the actions at ±1, 2.7 σ from a mean near 0) did well
    /// and whose samples at the mean did badly: the update widens the noise, up to
    /// `train.max_log_std` when it is set, on either learner.
    fn log_std_after_update(learner: Learner, max_log_std: Option<LogStdCeiling>, epoch: usize) -> Vec<f32> {
        let cfg = PpoConfig { max_log_std, ..Default::default() };
        log_std_after(learner, cfg, 1.0, epoch)
    }

    /// [`log_std_after_update`]'s epoch with `cfg`'s options and the far samples at `±far`.
    fn log_std_after(learner: Learner, cfg: PpoConfig, far_action: f32, epoch: usize) -> Vec<f32> {
        let cfg = PpoConfig {
            num_actors: 8,
            horizon_length: 16,
            minibatch_size: 64,
            mini_epochs: 4,
            learning_rate: 0.01,
            lr_schedule: LrSchedule::Linear,
            learner,
            threads: 1,
            ..cfg
        };
        let network = NetworkConfig { hidden: vec![8], init_log_std: -1.0, ..Default::default() };
        let mut ppo = Ppo::new(&cfg, &network, 3, 2, rlnav_policy::training_device(), 1);
        let b = &mut ppo.buffer;
        for i in 0..b.log_probs.len() {
            let far = i % 2 == 0;
            let a = if far { if i % 4 == 0 { far_action } else { -far_action } } else { 0.0 };
            b.obs[i * 3..(i + 1) * 3].copy_from_slice(&[0.1 * (i % 5) as f32, 0.2, -0.3]);
            b.actions[i * 2..(i + 1) * 2].copy_from_slice(&[a, -a]);
            // An old log-probability far above the new one keeps every ratio below the clip
            // range, where the surrogate of a good action is not clipped.
            b.log_probs[i] = 10.0;
            b.advantages[i] = if far { 1.0 } else { -1.0 };
            b.returns[i] = 0.0;
            b.values[i] = 0.0;
        }
        ppo.schedule(epoch);
        ppo.update();
        to_vec(ppo.model().log_std.val())
    }

    #[test]
    fn max_log_std_caps_the_noise_on_both_learners() {
        for learner in [Learner::Fast, Learner::Burn] {
            let free = log_std_after_update(learner, None, 0);
            assert!(free.iter().all(|&l| l > -0.95), "{learner:?}: the update widens the noise: {free:?}");
            let capped = log_std_after_update(learner, Some(LogStdCeiling::Fixed(-1.0)), 0);
            assert!(capped.iter().all(|&l| l <= -1.0 + 1e-6), "{learner:?}: capped at -1: {capped:?}");
            // A ceiling that falls from -1 at the first epoch (of 200) holds -1 there, and -1.5
            // halfway.
            let falling = |epoch| log_std_after_update(learner, Some(LogStdCeiling::Linear([-1.0, -2.0])), epoch);
            assert_eq!(falling(0), capped, "{learner:?}");
            let half = falling(100);
            assert!(half.iter().all(|&l| (l + 1.5).abs() < 0.01), "{learner:?}: {half:?}");
            // An initial noise above the ceiling starts at the ceiling.
            let cfg = PpoConfig { max_log_std: Some(LogStdCeiling::Fixed(-1.5)), learner, ..Default::default() };
            let ppo = Ppo::new(&cfg, &NetworkConfig::default(), 3, 2, rlnav_policy::training_device(), 1);
            assert_eq!(to_vec(ppo.model().log_std.val()), vec![-1.5, -1.5]);
        }
    }

    /// With `train.clipped_actions` a sample is scored as the robot executes it: samples at
    /// ±1 and at ±3 (both executed as ±1) give the same update, on either learner; scored as
    /// densities, they do not.
    #[test]
    fn clipped_actions_score_what_the_robot_executes() {
        for learner in [Learner::Fast, Learner::Burn] {
            let run = |clipped_actions, far| {
                log_std_after(learner, PpoConfig { clipped_actions, ..Default::default() }, far, 0)
            };
            let (at, beyond) = (run(true, 1.0), run(true, 3.0));
            for (a, b) in at.iter().zip(&beyond) {
                assert!((a - b).abs() < 1e-5, "{learner:?}: clipped: {at:?} vs {beyond:?}");
            }
            let (at, beyond) = (run(false, 1.0), run(false, 3.0));
            assert!(
                at.iter().zip(&beyond).all(|(a, b)| (a - b).abs() > 0.01),
                "{learner:?}: density: {at:?} vs {beyond:?}"
            );
        }
    }

    /// An epoch in which the goal always lies to the left and turning left paid: with
    /// `train.mirror` the update also teaches turning right when the goal lies to the right,
    /// on either learner; without it, the policy learns to turn left there too.
    #[test]
    fn mirror_teaches_the_side_never_seen() {
        // goal_distance, goal_bearing, last_angular: the two last change sign in a mirror.
        let layout = rlnav_sim::observation::ObservationLayout(vec![
            rlnav_sim::observation::ObsTerm::GoalDistance,
            rlnav_sim::observation::ObsTerm::GoalBearing,
            rlnav_sim::observation::ObsTerm::LastAngular,
        ]);
        let mirror = layout.mirror(&Default::default()).unwrap();
        for learner in [Learner::Fast, Learner::Burn] {
            let turn = |mirrored: bool| {
                let cfg = PpoConfig {
                    num_actors: 8,
                    horizon_length: 16,
                    minibatch_size: 32,
                    mini_epochs: 8,
                    learning_rate: 0.01,
                    lr_schedule: LrSchedule::Linear,
                    learner,
                    threads: 1,
                    ..Default::default()
                };
                let network = NetworkConfig { hidden: vec![16], init_log_std: -1.0, ..Default::default() };
                let mut ppo = Ppo::new(&cfg, &network, 3, 2, rlnav_policy::training_device(), 3);
                if mirrored {
                    ppo.set_mirror(mirror.clone());
                }
                let b = &mut ppo.buffer;
                for i in 0..b.log_probs.len() {
                    let good = i % 2 == 0;
                    let w = if good { 0.8 } else { -0.8 };
                    b.obs[i * 3..(i + 1) * 3].copy_from_slice(&[
                        1.0 + 0.1 * (i % 7) as f32,
                        0.3 + 0.1 * (i % 5) as f32,
                        0.2,
                    ]);
                    b.actions[i * 2..(i + 1) * 2].copy_from_slice(&[0.0, w]);
                    b.mus[i * 2..(i + 1) * 2].copy_from_slice(&[0.0, 0.0]);
                    b.log_probs[i] = action_log_prob(0.0, 0.0, -1.0, false).0 + action_log_prob(w, 0.0, -1.0, false).0;
                    b.advantages[i] = if good { 1.0 } else { -1.0 };
                }
                ppo.update();
                let net = ppo.inference_net();
                let left = [1.2, 0.5, 0.2];
                let (mu, _) = ppo.act_mean(&net, &[left, mirror.mirrored(&left).try_into().unwrap()].concat(), None);
                (mu[1], mu[3])
            };
            let (left, right) = turn(true);
            // One update moves each mean until the clip stops it; the two sides start from an
            // untrained network's different means. Over network seeds 0-7: mirrored +0.16 to
            // +0.37 (left) and -0.16 to -0.30 (right); plain +0.34 to +0.61 and +0.22 to +0.49.
            assert!(
                left > 0.05 && right < -0.05,
                "{learner:?}, mirrored: turns {left} (goal left), {right} (goal right)"
            );
            let (left, right) = turn(false);
            assert!(left > 0.1 && right > 0.1, "{learner:?}, plain: turns {left} (goal left), {right} (goal right)");
        }
    }

    /// With `train.mirror` the observation statistics gathered while collecting stay
    /// mirror-symmetric, so that the mirror of a normalised observation (what the update
    /// trains on) is the normalised mirrored observation.
    #[test]
    fn mirrored_statistics_commute_with_normalising() {
        use rlnav_sim::observation::{ObsTerm, ObservationLayout};
        let observation = ObservationLayout(vec![
            ObsTerm::Lidar { beams: 120, clip: [0.15, 3.0], sweep: 0.0 },
            ObsTerm::GoalDistance,
            ObsTerm::GoalBearing,
            ObsTerm::PlanAhead { points: 2, spacing: 0.3 },
            ObsTerm::LastAngular,
            ObsTerm::Angular,
        ]);
        let task = rlnav_sim::task::TaskConfig { observation, ..Default::default() };
        let robot = rlnav_sim::RobotSpec::load("turtlebot3-burger").unwrap();
        let mirror = task.observation.mirror(&robot.lidar).unwrap();
        let scenario = rlnav_sim::scenario::ScenarioSpec::load("random-static").unwrap();
        let setup = std::sync::Arc::new(rlnav_sim::task::EnvSetup::new(scenario, robot, task).unwrap());
        let cfg = PpoConfig { num_actors: 4, horizon_length: 16, minibatch_size: 32, threads: 1, ..Default::default() };
        let mut ppo = Ppo::new(&cfg, &NetworkConfig::default(), setup.obs_dim(), 2, rlnav_policy::training_device(), 5);
        ppo.set_mirror(mirror.clone());
        let mut env = VecEnv::new(setup.clone(), 4, 5, 1).unwrap();
        ppo.collect(&mut env, &mut Vec::new()).unwrap();
        let (mean, var) = (&ppo.obs_norm.mean, &ppo.obs_norm.var);
        let bearing = 121;
        assert!(
            mean[bearing].abs() < 1e-9 && var[bearing] > 0.01,
            "bearing centred: {} {}",
            mean[bearing],
            var[bearing]
        );
        assert!((mean[0] - mean[119]).abs() < 1e-9 && (mean[10] - mean[109]).abs() < 1e-9, "paired bins alike");
        let raw = env.obs.clone();
        let mut a = mirror.mirrored(&raw);
        ppo.obs_norm.normalize(&mut a);
        let mut b = raw.clone();
        ppo.obs_norm.normalize(&mut b);
        let b = mirror.mirrored(&b);
        for (i, (x, y)) in a.iter().zip(&b).enumerate() {
            assert!((x - y).abs() < 1e-4, "value {i}: {x} vs {y}");
        }
        // Without the mirror the statistics are those of one side.
        let mut plain =
            Ppo::new(&cfg, &NetworkConfig::default(), setup.obs_dim(), 2, rlnav_policy::training_device(), 5);
        let mut env = VecEnv::new(setup, 4, 5, 1).unwrap();
        plain.collect(&mut env, &mut Vec::new()).unwrap();
        assert!(plain.obs_norm.mean[bearing].abs() > 1e-3, "one-sided: {}", plain.obs_norm.mean[bearing]);
    }

    /// The tail log-probability and its derivatives agree with central differences, on both
    /// sides, near the bound and far into the tail (where `1 - Φ` rounds to zero in f32).
    #[test]
    fn action_log_prob_derivatives_match_differences() {
        let h = 1e-3f32;
        for &(a, mu, log_std) in
            &[(1.3, 0.2, -0.5), (-2.0, 0.4, -1.0), (1.0, 1.4, 0.1), (-1.0, 0.9, -2.5), (0.3, -0.2, -0.7)]
        {
            let (lp, d_mu, d_ls) = action_log_prob(a, mu, log_std, true);
            assert!(lp.is_finite() && lp <= 0.5, "{a} {mu} {log_std}: {lp}");
            let num_mu =
                (action_log_prob(a, mu + h, log_std, true).0 - action_log_prob(a, mu - h, log_std, true).0) / (2.0 * h);
            let num_ls =
                (action_log_prob(a, mu, log_std + h, true).0 - action_log_prob(a, mu, log_std - h, true).0) / (2.0 * h);
            let tol = |x: f32| 2e-2 * (1.0 + x.abs());
            assert!((num_mu - d_mu).abs() < tol(d_mu), "{a} {mu} {log_std}: d/dmu {d_mu} vs {num_mu}");
            assert!((num_ls - d_ls).abs() < tol(d_ls), "{a} {mu} {log_std}: d/dlogstd {d_ls} vs {num_ls}");
        }
        // Far into the tail: ln Q(t) ≈ -t²/2 - ln(t √(2π)), hazard ≈ t; continuous at the switch.
        let (lq, hz) = log_upper_tail(40.0);
        assert!((lq - (-800.0 - (40.0f64).ln() - 0.918_938_533)).abs() < 1e-2 && (hz - 40.0).abs() < 0.1);
        let (below, above) = (log_upper_tail(25.0 - 1e-9), log_upper_tail(25.0));
        assert!((below.0 - above.0).abs() < 1e-6 && (below.1 - above.1).abs() < 1e-4, "{below:?} {above:?}");
        // A sample inside the bounds keeps the Gaussian density.
        let (lp, _, _) = action_log_prob(0.3, -0.2, -0.7, false);
        assert_eq!(lp, action_log_prob(0.3, -0.2, -0.7, true).0);
    }
}
