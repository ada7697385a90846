//! A hand-written learner for feed-forward actor-critics on the CPU: forward pass, the PPO
//! loss's gradient, backward pass and Adam over one flat parameter buffer, on
//! `matrixmultiply`'s SIMD GEMM.
//!
//! Why: for the small networks used here (124 → 128 → 64, minibatches of 4,096) burn's CPU
//! backend spends most of an update building and walking its autodiff graph and allocating
//! tensors, not multiplying; the PPO update was 80% of a training epoch. The loss and the
//! optimiser are the same as the burn path in `ppo.rs` (a test compares gradients with burn's
//! autodiff and the parameters after an Adam step), and the burn network stays the canonical
//! form between updates: checkpoints, export and evaluation do not change.
//!
//! Work is split into chunks of [`CHUNK`] rows that run in parallel, and their gradients are
//! summed in chunk order, so a seed gives the same run for any thread count on one machine.

use crate::ppo::{HALF_LN_2PI, SOFT_BOUND, to_vec};
use burn::module::Param;
use burn::prelude::*;
use rayon::prelude::*;
use rlnav_policy::{ActivationKind, ActorCritic};

/// Rows per parallel chunk.
const CHUNK: usize = 256;

/// ELU, `x` above zero and `e^x − 1` below, branch-free so that a loop over a layer
/// vectorises.
///
/// Why not `f32::exp_m1`: it is a scalar libm call, and with it the activation took 39% of a
/// training run (perf, default config). Here `e^x − 1 = 2^n·(p(r) + 1) − 1` with `x = n·ln 2 + r`,
/// `|r| ≤ ln 2 / 2`, and `p` the degree-7 Taylor polynomial of `e^r − 1` (truncation under
/// 3e-9); the result is within 2e-7 of `exp_m1` on `[-87, 0]` (tested) and exactly `-1` below.
#[inline(always)]
fn elu(x: f32) -> f32 {
    const LN2_HI: f32 = 0.693_145_75;
    const LN2_LO: f32 = 1.428_606_8e-6;
    // Adding 1.5·2^23 rounds to an integer held in the low mantissa bits.
    const ROUND: f32 = 12_582_912.0;
    let z = x.clamp(-87.0, 0.0);
    let t = z * std::f32::consts::LOG2_E + ROUND;
    let n = t.to_bits() as i32 - ROUND.to_bits() as i32;
    let nf = t - ROUND;
    let r = (z - nf * LN2_HI) - nf * LN2_LO;
    let mut p = 1.0 / 5040.0;
    p = p * r + 1.0 / 720.0;
    p = p * r + 1.0 / 120.0;
    p = p * r + 1.0 / 24.0;
    p = p * r + 1.0 / 6.0;
    p = p * r + 0.5;
    p = p * r + 1.0;
    p *= r;
    let scale = f32::from_bits(((n + 127) << 23) as u32);
    let neg = scale * p + (scale - 1.0);
    if x > 0.0 { x } else { neg }
}

/// [`elu`] over a slice, on AVX2's 8 lanes where the CPU has them (SSE2's 4 otherwise). The
/// same operations in the same order either way (no FMA), so the results are bit-identical.
fn elu_slice(y: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        #[target_feature(enable = "avx2")]
        fn wide(y: &mut [f32]) {
            y.iter_mut().for_each(|v| *v = elu(*v));
        }
        // SAFETY: the CPU has AVX2 (checked just above).
        unsafe { wide(y) };
        return;
    }
    y.iter_mut().for_each(|v| *v = elu(*v));
}

/// A dense layer: offsets of its weight (`[in][out]`, burn's layout) and bias in the flat
/// parameter buffer.
#[derive(Clone, Copy, Debug)]
struct Dense {
    w: usize,
    b: usize,
    inp: usize,
    out: usize,
}

/// Adam's moments and step count, in the parameter buffer's layout.
#[derive(Clone, Debug, PartialEq)]
pub struct AdamState {
    /// Steps taken.
    pub step: u64,
    /// First moment.
    pub m: Vec<f32>,
    /// Second moment.
    pub v: Vec<f32>,
}

/// Magic bytes of [`AdamState::to_bytes`].
const ADAM_MAGIC: &[u8; 8] = b"RLNADAM1";

impl AdamState {
    /// Little-endian bytes: magic, step (u64), length (u64), then `m` and `v` as f32.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(24 + 8 * self.m.len());
        out.extend_from_slice(ADAM_MAGIC);
        out.extend_from_slice(&self.step.to_le_bytes());
        out.extend_from_slice(&(self.m.len() as u64).to_le_bytes());
        for x in self.m.iter().chain(&self.v) {
            out.extend_from_slice(&x.to_le_bytes());
        }
        out
    }

    /// Parses [`Self::to_bytes`]; the error says what is wrong.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, String> {
        if bytes.len() < 24 || &bytes[..8] != ADAM_MAGIC {
            return Err("not an rlnav Adam state (expected the RLNADAM1 header)".into());
        }
        let word = |i: usize| u64::from_le_bytes(bytes[i..i + 8].try_into().expect("8 bytes"));
        let (step, n) = (word(8), word(16) as usize);
        if n.checked_mul(8).and_then(|b| b.checked_add(24)) != Some(bytes.len()) {
            return Err(format!("truncated or padded: {} bytes for {n} parameters", bytes.len()));
        }
        let floats: Vec<f32> =
            bytes[24..].chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes"))).collect();
        let (m, v) = floats.split_at(n);
        Ok(Self { step, m: m.to_vec(), v: v.to_vec() })
    }
}

/// One minibatch, rows in order; observations normalised, values and returns in the network's
/// (normalised) units, advantages already standardised.
pub struct Batch<'a> {
    /// Observations `[rows][obs]`.
    pub obs: &'a [f32],
    /// Sampled actions `[rows][act]`.
    pub actions: &'a [f32],
    /// Log-probabilities of the actions under the collecting policy.
    pub old_log_probs: &'a [f32],
    /// Advantages.
    pub advantages: &'a [f32],
    /// Value targets.
    pub returns: &'a [f32],
    /// Values the collecting network predicted.
    pub old_values: &'a [f32],
    /// A teacher's actions `[rows][act]` to imitate (kickstarting), NaN on rows it did not
    /// label; empty: none.
    pub teacher: &'a [f32],
}

/// PPO loss settings (from `PpoConfig`).
#[derive(Clone, Copy, Debug)]
pub struct LossConfig {
    /// Ratio clip ε (also the value clip).
    pub e_clip: f32,
    /// Clip the value loss.
    pub clip_value: bool,
    /// Value loss weight (the loss uses half of it, as rl_games).
    pub critic_coef: f32,
    /// Entropy bonus weight.
    pub entropy_coef: f32,
    /// Bounds loss weight.
    pub bounds_loss_coef: f32,
    /// Weight of the imitation term `mean ‖μ − a_teacher‖²` over the labelled rows.
    pub teacher_coef: f32,
}

/// What one minibatch's loss measured, and the network's outputs needed for the KL.
#[derive(Clone, Debug, Default)]
pub struct LossReport {
    /// Clipped-surrogate loss.
    pub policy_loss: f32,
    /// Value loss.
    pub value_loss: f32,
    /// Policy entropy.
    pub entropy: f32,
    /// Gaussian means before the step `[rows][act]`.
    pub mu: Vec<f32>,
    /// Probability ratios before the step.
    pub ratios: Vec<f32>,
    /// Global gradient norm before clipping.
    pub grad_norm: f32,
    /// Mean squared distance of the means from the teacher's actions on the labelled rows
    /// (0 with none).
    pub teacher_loss: f32,
}

/// A trunk's activations, its input first, one `[rows][width]` buffer per layer.
type Activations = Vec<Vec<f32>>;

/// The actor-critic as flat buffers (see the module docs).
pub struct FastMlp {
    activation: ActivationKind,
    obs_dim: usize,
    act_dim: usize,
    actor: Vec<Dense>,
    mu: Dense,
    /// Empty when the critic reads the actor's last hidden layer.
    critic: Vec<Dense>,
    value: Dense,
    log_std: usize,
    /// Every parameter.
    params: Vec<f32>,
    adam: AdamState,
    pool: rayon::ThreadPool,
}

/// `c[m×n] = beta·c + a·b`, `a` being `m×k` and `b` `k×n`, each given with its row and column
/// strides.
#[allow(clippy::too_many_arguments)]
fn gemm(
    (m, k, n): (usize, usize, usize),
    a: &[f32],
    (rsa, csa): (usize, usize),
    b: &[f32],
    (rsb, csb): (usize, usize),
    beta: f32,
    c: &mut [f32],
    rsc: usize,
) {
    if m == 0 || n == 0 {
        return;
    }
    assert!(k == 0 || (m - 1) * rsa + (k - 1) * csa < a.len(), "gemm: a too short");
    assert!(k == 0 || (k - 1) * rsb + (n - 1) * csb < b.len(), "gemm: b too short");
    assert!((m - 1) * rsc + n - 1 < c.len(), "gemm: c too short");
    // SAFETY: the asserts above keep every index the kernel reads or writes inside the slices,
    // and `c` does not alias `a` or `b` (it is borrowed mutably).
    unsafe {
        matrixmultiply::sgemm(
            m,
            k,
            n,
            1.0,
            a.as_ptr(),
            rsa as isize,
            csa as isize,
            b.as_ptr(),
            rsb as isize,
            csb as isize,
            beta,
            c.as_mut_ptr(),
            rsc as isize,
            1,
        );
    }
}

impl FastMlp {
    /// The flat copy of a feed-forward `model`, working on `threads` threads (0: one per core).
    /// `None` for a recurrent network.
    pub fn from_model(model: &ActorCritic, threads: usize) -> Option<Self> {
        if model.lstm.is_some() {
            return None;
        }
        let mut params = Vec::new();
        let mut push = |l: &burn::nn::Linear| {
            let [inp, out] = l.weight.val().dims();
            let w = params.len();
            params.extend(to_vec(l.weight.val()));
            let b = params.len();
            match &l.bias {
                Some(bias) => params.extend(to_vec(bias.val())),
                None => params.extend(std::iter::repeat_n(0.0, out)),
            }
            Dense { w, b, inp, out }
        };
        let actor: Vec<Dense> = model.actor.iter().map(&mut push).collect();
        let mu = push(&model.mu);
        let critic: Vec<Dense> = model.critic.iter().map(&mut push).collect();
        let value = push(&model.value);
        let log_std = params.len();
        params.extend(to_vec(model.log_std.val()));
        let n = params.len();
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("learner threads");
        Some(Self {
            activation: model.activation,
            obs_dim: model.obs_dim,
            act_dim: mu.out,
            actor,
            mu,
            critic,
            value,
            log_std,
            params,
            adam: AdamState { step: 0, m: vec![0.0; n], v: vec![0.0; n] },
            pool,
        })
    }

    /// Writes the parameters into `model` (the network this learner was made from).
    pub fn write_into(&self, model: ActorCritic) -> ActorCritic {
        fn set<const D: usize>(p: Param<Tensor<D>>, data: &[f32]) -> Param<Tensor<D>> {
            p.map(|t| {
                let shape = t.dims();
                let tracked = t.is_require_grad();
                let fresh = Tensor::<D>::from_data(TensorData::new(data.to_vec(), shape), &t.device());
                if tracked { fresh.require_grad() } else { fresh }
            })
        }
        let p = &self.params;
        let layer = |mut l: burn::nn::Linear, d: Dense| {
            l.weight = set(l.weight, &p[d.w..d.w + d.inp * d.out]);
            l.bias = l.bias.map(|b| set(b, &p[d.b..d.b + d.out]));
            l
        };
        let mut model = model;
        model.actor = model.actor.into_iter().zip(&self.actor).map(|(l, d)| layer(l, *d)).collect();
        model.mu = layer(model.mu, self.mu);
        model.critic = model.critic.into_iter().zip(&self.critic).map(|(l, d)| layer(l, *d)).collect();
        model.value = layer(model.value, self.value);
        model.log_std = set(model.log_std, &p[self.log_std..self.log_std + self.act_dim]);
        model
    }

    /// The flat parameters (weights `[in][out]` then bias per layer: actor, mean head,
    /// critic, value head; then the log standard deviations).
    pub fn params(&self) -> &[f32] {
        &self.params
    }

    /// The state-independent log standard deviations.
    pub fn log_std(&self) -> &[f32] {
        &self.params[self.log_std..self.log_std + self.act_dim]
    }

    /// Adam's state (for checkpoints).
    pub fn adam(&self) -> &AdamState {
        &self.adam
    }

    /// Replaces Adam's state (resuming); a state of another length is refused.
    pub fn set_adam(&mut self, adam: AdamState) -> Result<(), String> {
        if adam.m.len() != self.params.len() || adam.v.len() != self.params.len() {
            return Err(format!("Adam state for {} parameters, the network has {}", adam.m.len(), self.params.len()));
        }
        self.adam = adam;
        Ok(())
    }

    fn dense(&self, d: Dense, x: &[f32], rows: usize) -> Vec<f32> {
        let mut y = Vec::with_capacity(rows * d.out);
        for _ in 0..rows {
            y.extend_from_slice(&self.params[d.b..d.b + d.out]);
        }
        gemm((rows, d.inp, d.out), x, (d.inp, 1), &self.params[d.w..], (d.out, 1), 1.0, &mut y, d.out);
        y
    }

    fn activate(&self, y: &mut [f32]) {
        match self.activation {
            ActivationKind::Elu => elu_slice(y),
            ActivationKind::Relu => y.iter_mut().for_each(|v| *v = v.max(0.0)),
            ActivationKind::Tanh => y.iter_mut().for_each(|v| *v = v.tanh()),
        }
    }

    /// `dh · f'(z)` in place, from the activation's output `h`.
    fn activate_backward(&self, h: &[f32], dh: &mut [f32]) {
        match self.activation {
            // Written as selects, not branches, so that the loops vectorise.
            ActivationKind::Elu => {
                dh.iter_mut().zip(h).for_each(|(g, &h)| *g = if h <= 0.0 { *g * (h + 1.0) } else { *g })
            }
            ActivationKind::Relu => dh.iter_mut().zip(h).for_each(|(g, &h)| *g = if h <= 0.0 { 0.0 } else { *g }),
            ActivationKind::Tanh => dh.iter_mut().zip(h).for_each(|(g, &h)| *g *= 1.0 - h * h),
        }
    }

    /// Hidden activations of a trunk, the input first.
    fn trunk(&self, layers: &[Dense], x: &[f32], rows: usize) -> Activations {
        let mut hs = vec![x.to_vec()];
        for &d in layers {
            let mut y = self.dense(d, hs.last().expect("input"), rows);
            self.activate(&mut y);
            hs.push(y);
        }
        hs
    }

    /// Means `[rows][act]`, values, and the trunks' activations (actor, critic).
    fn forward_rows(&self, x: &[f32], rows: usize) -> (Vec<f32>, Vec<f32>, Activations, Activations) {
        let a = self.trunk(&self.actor, x, rows);
        let mu = self.dense(self.mu, a.last().expect("actor output"), rows);
        let c = if self.critic.is_empty() { Vec::new() } else { self.trunk(&self.critic, x, rows) };
        let feat = if self.critic.is_empty() { a.last() } else { c.last() };
        let v = self.dense(self.value, feat.expect("critic output"), rows);
        (mu, v, a, c)
    }

    /// Gaussian means `[rows][act]` and values (network units) for observations `[rows][obs]`.
    pub fn forward(&self, obs: &[f32]) -> (Vec<f32>, Vec<f32>) {
        let rows = obs.len() / self.obs_dim;
        // A rollout step's batch (128 rows, say) is smaller than a chunk: split it so that every
        // thread gets a share. Rows are independent, so the split does not change the results.
        let chunk = rows.div_ceil(self.pool.current_num_threads()).clamp(1, CHUNK);
        let parts: Vec<(Vec<f32>, Vec<f32>)> = self.pool.install(|| {
            obs.par_chunks(chunk * self.obs_dim)
                .map(|x| {
                    let (mu, v, _, _) = self.forward_rows(x, x.len() / self.obs_dim);
                    (mu, v)
                })
                .collect()
        });
        let mut mu = Vec::with_capacity(rows * self.act_dim);
        let mut v = Vec::with_capacity(rows);
        for (m, val) in parts {
            mu.extend(m);
            v.extend(val);
        }
        (mu, v)
    }

    /// Adds a trunk's weight and bias gradients into `g`, given the gradient `dh` of its last
    /// hidden layer's output (activations `hs`, the input first); the input's own gradient is
    /// not computed (observations need none).
    fn backward_trunk(&self, layers: &[Dense], hs: &[Vec<f32>], mut dh: Vec<f32>, rows: usize, g: &mut [f32]) {
        for (i, &d) in layers.iter().enumerate().rev() {
            self.activate_backward(&hs[i + 1], &mut dh);
            let dx = self.backward_dense(d, &hs[i], &dh, rows, g, i > 0);
            dh = dx;
        }
    }

    /// Adds a dense layer's weight and bias gradient into `g` and returns the input gradient
    /// (empty unless `want_dx`).
    fn backward_dense(&self, d: Dense, x: &[f32], dy: &[f32], rows: usize, g: &mut [f32], want_dx: bool) -> Vec<f32> {
        gemm((d.inp, rows, d.out), x, (1, d.inp), dy, (d.out, 1), 1.0, &mut g[d.w..d.w + d.inp * d.out], d.out);
        let gb = &mut g[d.b..d.b + d.out];
        for row in dy.chunks_exact(d.out) {
            gb.iter_mut().zip(row).for_each(|(s, v)| *s += v);
        }
        if !want_dx {
            return Vec::new();
        }
        let mut dx = vec![0.0; rows * d.inp];
        gemm((rows, d.out, d.inp), dy, (d.out, 1), &self.params[d.w..], (1, d.out), 0.0, &mut dx, d.inp);
        dx
    }

    /// The PPO loss on `batch` and its gradient with respect to every parameter (flat layout).
    pub fn loss_and_grad(&self, batch: &Batch, cfg: &LossConfig) -> (LossReport, Vec<f32>) {
        let (d, act) = (self.obs_dim, self.act_dim);
        let rows = batch.old_log_probs.len();
        let inv = 1.0 / rows as f32;
        let log_std = self.log_std().to_vec();
        let std: Vec<f32> = log_std.iter().map(|l| l.exp()).collect();
        let e = cfg.e_clip;
        let n_chunks = rows.div_ceil(CHUNK);
        let labelled = |k: usize| !batch.teacher.is_empty() && batch.teacher[k * act].is_finite();
        let n_labelled = (0..rows).filter(|&k| labelled(k)).count();
        let teach = if n_labelled > 0 { cfg.teacher_coef / n_labelled as f32 } else { 0.0 };
        struct Part {
            grad: Vec<f32>,
            surr: f32,
            value: f32,
            imitation: f32,
            mu: Vec<f32>,
            ratios: Vec<f32>,
        }
        let parts: Vec<Part> = self.pool.install(|| {
            (0..n_chunks)
                .into_par_iter()
                .map(|c| {
                    let (lo, hi) = (c * CHUNK, ((c + 1) * CHUNK).min(rows));
                    let r = hi - lo;
                    let (mu, v, ha, hc) = self.forward_rows(&batch.obs[lo * d..hi * d], r);
                    let mut dmu = vec![0.0f32; r * act];
                    let mut dv = vec![0.0f32; r];
                    let mut grad = vec![0.0f32; self.params.len()];
                    let (mut surr_sum, mut value_sum, mut imitation) = (0.0f32, 0.0f32, 0.0f32);
                    let mut ratios = Vec::with_capacity(r);
                    for i in 0..r {
                        let k = lo + i;
                        let mut logp = 0.0;
                        for j in 0..act {
                            let z = (batch.actions[k * act + j] - mu[i * act + j]) / std[j];
                            logp += -0.5 * z * z - log_std[j] - HALF_LN_2PI;
                        }
                        let ratio = (logp - batch.old_log_probs[k]).exp();
                        ratios.push(ratio);
                        let adv = batch.advantages[k];
                        let (t1, t2) = (ratio * adv, ratio.clamp(1.0 - e, 1.0 + e) * adv);
                        surr_sum += t1.min(t2);
                        // d(min(t1, t2))/d logp: the unclipped term's when it is the smaller (or
                        // the clipped one is, inside the clip range, where they are equal).
                        let inside = ratio > 1.0 - e && ratio < 1.0 + e;
                        let g_logp = if t1 <= t2 || inside { -ratio * adv * inv } else { 0.0 };
                        for j in 0..act {
                            let m = mu[i * act + j];
                            let z = (batch.actions[k * act + j] - m) / std[j];
                            let bound = (m - SOFT_BOUND).max(0.0) + (m + SOFT_BOUND).min(0.0);
                            dmu[i * act + j] = g_logp * z / std[j] + cfg.bounds_loss_coef * 2.0 * bound * inv;
                            grad[self.log_std + j] += g_logp * (z * z - 1.0);
                        }
                        if labelled(k) {
                            for j in 0..act {
                                let diff = mu[i * act + j] - batch.teacher[k * act + j];
                                imitation += diff * diff;
                                dmu[i * act + j] += teach * 2.0 * diff;
                            }
                        }
                        // Value loss and its gradient.
                        let (val, ret, old) = (v[i], batch.returns[k], batch.old_values[k]);
                        let unclipped = (val - ret).powi(2);
                        let scale = cfg.critic_coef * 0.5 * inv;
                        if cfg.clip_value {
                            let delta = (val - old).clamp(-e, e);
                            let clipped = (old + delta - ret).powi(2);
                            if unclipped >= clipped {
                                value_sum += unclipped;
                                dv[i] = scale * 2.0 * (val - ret);
                            } else {
                                value_sum += clipped;
                                let through = (val - old).abs() < e;
                                dv[i] = if through { scale * 2.0 * (old + delta - ret) } else { 0.0 };
                            }
                        } else {
                            value_sum += unclipped;
                            dv[i] = scale * 2.0 * (val - ret);
                        }
                    }
                    // Heads, then trunks.
                    let a_last = ha.last().expect("actor output");
                    let mut dha = self.backward_dense(self.mu, a_last, &dmu, r, &mut grad, true);
                    if self.critic.is_empty() {
                        let dhv = self.backward_dense(self.value, a_last, &dv, r, &mut grad, true);
                        dha.iter_mut().zip(&dhv).for_each(|(a, b)| *a += b);
                    } else {
                        let dhc =
                            self.backward_dense(self.value, hc.last().expect("critic output"), &dv, r, &mut grad, true);
                        self.backward_trunk(&self.critic, &hc, dhc, r, &mut grad);
                    }
                    self.backward_trunk(&self.actor, &ha, dha, r, &mut grad);
                    Part { grad, surr: surr_sum, value: value_sum, imitation, mu, ratios }
                })
                .collect()
        });
        let mut grad = vec![0.0f32; self.params.len()];
        let mut report = LossReport::default();
        let (mut surr, mut value, mut imitation) = (0.0f32, 0.0f32, 0.0f32);
        for p in parts {
            grad.iter_mut().zip(&p.grad).for_each(|(g, x)| *g += x);
            surr += p.surr;
            value += p.value;
            imitation += p.imitation;
            report.mu.extend(p.mu);
            report.ratios.extend(p.ratios);
        }
        // Entropy of the diagonal Gaussian: Σ (log σ + ½ + ½ ln 2π); its bonus pulls log σ up.
        report.entropy = log_std.iter().map(|l| l + 0.5 + HALF_LN_2PI).sum();
        for j in 0..act {
            grad[self.log_std + j] -= cfg.entropy_coef;
        }
        report.policy_loss = -surr * inv;
        report.value_loss = value * inv;
        report.teacher_loss = if n_labelled > 0 { imitation / n_labelled as f32 } else { 0.0 };
        report.grad_norm = grad.iter().map(|g| g * g).sum::<f32>().sqrt();
        (report, grad)
    }

    /// One minibatch update: the loss's gradient, clipped to global norm `max_norm`, and an
    /// Adam step (β = 0.9, 0.999, ε = 1e-8, as the burn path) at learning rate `lr`.
    pub fn step(&mut self, batch: &Batch, cfg: &LossConfig, lr: f32, max_norm: f32) -> LossReport {
        let (report, mut grad) = self.loss_and_grad(batch, cfg);
        if report.grad_norm > max_norm {
            let s = max_norm / report.grad_norm;
            grad.iter_mut().for_each(|g| *g *= s);
        }
        self.adam_step(&grad, lr);
        report
    }

    fn adam_step(&mut self, grad: &[f32], lr: f32) {
        let (b1, b2, eps) = (0.9f32, 0.999f32, 1e-8f32);
        let a = &mut self.adam;
        a.step += 1;
        let t = a.step.min(i32::MAX as u64) as i32;
        let c2 = (1.0 - b2.powi(t)).sqrt();
        let factor = lr * c2 / (1.0 - b1.powi(t));
        let denom_eps = eps * c2;
        for (((p, g), m), v) in self.params.iter_mut().zip(grad).zip(a.m.iter_mut()).zip(a.v.iter_mut()) {
            *m = b1 * *m + (1.0 - b1) * g;
            *v = b2 * *v + (1.0 - b2) * g * g;
            *p -= factor * *m / (v.sqrt() + denom_eps);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ppo::{BurnBatch, burn_loss};
    use burn::module::{ModuleVisitor, ParamId};
    use burn::optim::{AdamConfig, GradientsParams};
    use rand::{RngExt, SeedableRng};
    use rand_distr::StandardNormal;
    use rand_pcg::Pcg64Mcg;
    use rlnav_policy::NetworkConfig;

    #[test]
    fn elu_agrees_with_libm() {
        let mut worst = 0.0f32;
        let mut x = -90.0f32;
        while x < 3.0 {
            let want = if x > 0.0 { x } else { x.exp_m1() };
            worst = worst.max((elu(x) - want).abs());
            x += 0.000_37;
        }
        assert!(worst < 2e-7, "largest difference from exp_m1: {worst:e}");
        for x in [0.0f32, -0.0, 1e-30, -1e-30, -1e-7, 5.0, f32::MAX, -f32::MAX] {
            let want = if x > 0.0 { x } else { x.exp_m1() };
            assert!((elu(x) - want).abs() <= 2e-7 * want.abs().max(1.0), "elu({x:e}) = {:e}, want {want:e}", elu(x));
        }
        assert!(elu(f32::NAN).is_nan());
        // The vectorised slice (with its scalar tail) gives exactly the scalar function.
        let xs: Vec<f32> = (0..1003).map(|k| -20.0 + 0.021 * k as f32).collect();
        let mut ys = xs.clone();
        elu_slice(&mut ys);
        assert!(xs.iter().zip(&ys).all(|(x, y)| elu(*x).to_bits() == y.to_bits()));
        assert_eq!(elu(f32::NEG_INFINITY), -1.0);
    }

    /// Every parameter's gradient in visiting order, flattened like [`FastMlp::params`].
    struct Collect<'a> {
        grads: &'a GradientsParams,
        out: Vec<f32>,
        ids: Vec<ParamId>,
    }
    impl ModuleVisitor for Collect<'_> {
        fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
            let n = param.val().dims().iter().product::<usize>();
            match self.grads.get::<D>(param.id) {
                Some(g) => self.out.extend(g.into_data().try_to_vec::<f32>().unwrap()),
                None => self.out.extend(std::iter::repeat_n(0.0, n)),
            }
            self.ids.push(param.id);
        }
    }

    fn random(rng: &mut Pcg64Mcg, n: usize, scale: f32) -> Vec<f32> {
        (0..n).map(|_| rng.sample::<f32, _>(StandardNormal) * scale).collect()
    }

    /// The hand-written loss, gradient and Adam step agree with burn's autodiff and Adam on
    /// random networks and minibatches, for each activation, shared and separate critics,
    /// clipped and unclipped value losses, and ratios on both sides of the clip range.
    #[test]
    fn gradients_and_adam_match_burn() {
        let device = Device::flex().autodiff();
        let cases = [
            (ActivationKind::Elu, true, true),
            (ActivationKind::Relu, true, false),
            (ActivationKind::Tanh, false, true),
        ];
        for (case, (activation, separate_critic, clip_value)) in cases.into_iter().enumerate() {
            let cfg = NetworkConfig { hidden: vec![24, 16], activation, separate_critic, ..Default::default() };
            let (obs_dim, act_dim, rows) = (11, 2, 700); // rows span three chunks, the last partial
            let model = ActorCritic::seeded(&cfg, obs_dim, act_dim, &device, case as u64);
            // A larger mean head than the initial one, so that the ratios move and the bounds
            // loss is active for some rows.
            let mut rng = Pcg64Mcg::seed_from_u64(case as u64 + 10);
            let mut fast = FastMlp::from_model(&model, 2).unwrap();
            let mu_w = fast.mu.w;
            for k in 0..fast.mu.inp * fast.mu.out {
                fast.params[mu_w + k] = rng.sample::<f32, _>(StandardNormal) * 0.8;
            }
            fast.params[fast.log_std] = -0.3;
            let model = fast.write_into(model);
            let obs = random(&mut rng, rows * obs_dim, 1.0);
            let actions = random(&mut rng, rows * act_dim, 1.0);
            let old_log_probs: Vec<f32> = random(&mut rng, rows, 0.3).iter().map(|x| x - 2.0).collect();
            let advantages = random(&mut rng, rows, 1.0);
            let returns = random(&mut rng, rows, 1.0);
            let old_values = random(&mut rng, rows, 0.5);
            // A teacher labels every third row (the rest NaN) in two of the cases.
            let mut teacher = random(&mut rng, rows * act_dim, 0.7);
            for k in (0..rows).filter(|k| k % 3 != 0) {
                teacher[k * act_dim..(k + 1) * act_dim].fill(f32::NAN);
            }
            let teacher = if case == 1 { Vec::new() } else { teacher };
            let loss_cfg = LossConfig {
                e_clip: 0.2,
                clip_value,
                critic_coef: 2.0,
                entropy_coef: 0.01,
                bounds_loss_coef: 0.5,
                teacher_coef: 0.8,
            };
            let batch = Batch {
                obs: &obs,
                actions: &actions,
                old_log_probs: &old_log_probs,
                advantages: &advantages,
                returns: &returns,
                old_values: &old_values,
                teacher: &teacher,
            };
            let (report, grad) = fast.loss_and_grad(&batch, &loss_cfg);

            let t2 =
                |v: &[f32], c: usize| Tensor::<2>::from_data(TensorData::new(v.to_vec(), [v.len() / c, c]), &device);
            let t1 = |v: &[f32]| Tensor::<1>::from_data(TensorData::new(v.to_vec(), [v.len()]), &device);
            let (mu, v) = model.forward(t2(&obs, obs_dim));
            let l = burn_loss(
                mu,
                v,
                model.log_std.val(),
                BurnBatch {
                    actions: t2(&actions, act_dim),
                    old_log_probs: t1(&old_log_probs),
                    advantages: t1(&advantages),
                    returns: t1(&returns),
                    old_values: t1(&old_values),
                    teacher: BurnBatch::teacher(&teacher, act_dim, &device),
                },
                &loss_cfg,
            );
            let close = |a: f32, b: f32, what: &str| {
                assert!((a - b).abs() <= 1e-4 * (1.0 + a.abs().max(b.abs())), "case {case}: {what}: fast {a}, burn {b}")
            };
            close(report.policy_loss, l.policy.clone().into_scalar::<f32>(), "policy loss");
            close(report.value_loss, l.value.clone().into_scalar::<f32>(), "value loss");
            close(report.entropy, l.entropy.clone().into_scalar::<f32>(), "entropy");
            let imitation = l.teacher.clone().map_or(0.0, |t| t.into_scalar::<f32>());
            close(report.teacher_loss, imitation, "imitation loss");
            assert_eq!(report.teacher_loss > 0.0, case != 1, "case {case}: the teacher term is on where labelled");
            let ratios = l.ratio.clone().into_data().try_to_vec::<f32>().unwrap();
            assert!(ratios.iter().any(|r| *r > 1.2) && ratios.iter().any(|r| *r < 0.8), "both clip sides exercised");
            let grads = GradientsParams::from_grads(l.total.backward(), &model);
            let mut collect = Collect { grads: &grads, out: Vec::new(), ids: Vec::new() };
            model.visit(&mut collect);
            assert_eq!(collect.out.len(), grad.len(), "same parameter count and layout");
            let scale = grad.iter().fold(0.0f32, |m, g| m.max(g.abs()));
            for (k, (a, b)) in grad.iter().zip(&collect.out).enumerate() {
                assert!((a - b).abs() <= 1e-4 * scale + 1e-6, "case {case}: gradient {k}: fast {a}, burn {b}");
            }

            // One Adam step from the same gradient gives the same parameters.
            let mut burn_opt = AdamConfig::new().with_epsilon(1e-8).init();
            let stepped = burn_opt.step(1e-3, model, grads);
            fast.adam_step(&grad, 1e-3);
            let after = FastMlp::from_model(&stepped, 1).unwrap();
            for (k, (a, b)) in fast.params.iter().zip(after.params()).enumerate() {
                assert!(
                    (a - b).abs() <= 1e-6 + 1e-5 * a.abs(),
                    "case {case}: parameter {k} after Adam: fast {a}, burn {b}"
                );
            }
        }
    }

    #[test]
    fn forward_matches_burn_and_does_not_depend_on_threads() {
        let device = Device::flex();
        let cfg = NetworkConfig { hidden: vec![32, 16], ..Default::default() };
        let model = ActorCritic::seeded(&cfg, 9, 2, &device, 3);
        let mut rng = Pcg64Mcg::seed_from_u64(4);
        let obs = random(&mut rng, 600 * 9, 1.0);
        let (mu1, v1) = FastMlp::from_model(&model, 1).unwrap().forward(&obs);
        let (mu2, v2) = FastMlp::from_model(&model, 2).unwrap().forward(&obs);
        assert_eq!((&mu1, &v1), (&mu2, &v2), "bit-identical for 1 and 2 threads");
        // A rollout-sized batch is split by thread count (130 rows: one chunk, or 44 + 44 + 42).
        let small = &obs[..130 * 9];
        let one = FastMlp::from_model(&model, 1).unwrap().forward(small);
        assert_eq!(one, FastMlp::from_model(&model, 3).unwrap().forward(small), "bit-identical for 1 and 3 threads");
        assert_eq!(one.0[..], mu1[..260]);
        let (mu, v) = model.forward(Tensor::<2>::from_data(TensorData::new(obs, [600, 9]), &device));
        let (mu, v) = (mu.into_data().try_to_vec::<f32>().unwrap(), v.into_data().try_to_vec::<f32>().unwrap());
        for (a, b) in mu1.iter().chain(&v1).zip(mu.iter().chain(&v)) {
            assert!((a - b).abs() < 1e-5 * (1.0 + b.abs()), "fast {a}, burn {b}");
        }
    }

    #[test]
    fn adam_state_round_trips_and_bad_bytes_are_named() {
        let a = AdamState { step: 7, m: vec![1.0, -2.0, 3.5], v: vec![0.5, 0.25, 9.0] };
        assert_eq!(AdamState::from_bytes(&a.to_bytes()).unwrap(), a);
        let bytes = a.to_bytes();
        let err = AdamState::from_bytes(&bytes[..bytes.len() - 3]).unwrap_err();
        assert!(err.contains("truncated"), "{err}");
        let err = AdamState::from_bytes(b"something else entirely").unwrap_err();
        assert!(err.contains("RLNADAM1"), "{err}");
    }

    #[test]
    fn a_recurrent_network_is_left_to_burn() {
        let cfg = NetworkConfig { lstm_units: 8, hidden: vec![16], ..Default::default() };
        let model = ActorCritic::seeded(&cfg, 5, 2, &Device::flex(), 0);
        assert!(FastMlp::from_model(&model, 1).is_none());
    }
}
