//! A hand-written learner for actor-critics on the CPU (MLPs, with or without an LSTM in
//! front): forward pass, the PPO loss's gradient, backward pass (through time for the LSTM)
//! and Adam over one flat parameter buffer, on `matrixmultiply`'s SIMD GEMM.
//!
//! Why: for the small networks used here (124 → 128 → 64, minibatches of 4,096) burn's CPU
//! backend spends most of an update building and walking its autodiff graph and allocating
//! tensors, not multiplying; the PPO update was 80% of a training epoch. The loss and the
//! optimiser are the same as the burn path in `ppo.rs` (a test compares gradients with burn's
//! autodiff and the parameters after an Adam step), and the burn network stays the canonical
//! form between updates: checkpoints, export and evaluation do not change.
//!
//! Work is split into chunks of [`CHUNK`] rows (whole sequences for an LSTM) that run in
//! parallel, and their gradients are summed in chunk order, so a seed gives the same run for
//! any thread count on one machine. With an LSTM, burn's learner took 0.34 s of an epoch's
//! 0.43 s (dynamic config) in its update; this one takes 0.07 s.

use crate::ppo::{HALF_LN_2PI, RecurrentState, SOFT_BOUND, action_log_prob, to_vec};
use burn::module::Param;
use burn::prelude::*;
use rayon::prelude::*;
use rlnav_policy::{ActivationKind, ActorCritic};

/// Rows per parallel chunk.
const CHUNK: usize = 256;

/// `e^x − 1` for `x ≤ 0`, branch-free so that a loop over a layer vectorises (`x` is clamped
/// to `[-87, 0]`).
///
/// Why not `f32::exp_m1`: it is a scalar libm call, and with it the ELU took 39% of a training
/// run (perf, default config). Here `e^x − 1 = 2^n·(p(r) + 1) − 1` with `x = n·ln 2 + r`,
/// `|r| ≤ ln 2 / 2`, and `p` the degree-7 Taylor polynomial of `e^r − 1` (truncation under
/// 3e-9); the result is within 2e-7 of `exp_m1` on `[-87, 0]` (tested) and exactly `-1` below.
#[inline(always)]
fn exp_m1_nonpositive(x: f32) -> f32 {
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
    scale * p + (scale - 1.0)
}

/// ELU: `x` above zero and `e^x − 1` below.
#[inline(always)]
fn elu(x: f32) -> f32 {
    let neg = exp_m1_nonpositive(x);
    if x > 0.0 { x } else { neg }
}

/// The logistic function (the LSTM's gates), from `e^{-|x|}` so that nothing overflows.
#[inline(always)]
fn sigmoid(x: f32) -> f32 {
    let e = exp_m1_nonpositive(-x.abs()) + 1.0;
    let r = 1.0 / (1.0 + e);
    if x >= 0.0 { r } else { e * r }
}

/// `tanh`, as `(1 − e^{-2|x|}) / (1 + e^{-2|x|})` with the sign of `x`; `e^{-2|x|} − 1` comes
/// whole from [`exp_m1_nonpositive`], so small arguments keep their precision.
#[inline(always)]
fn tanh(x: f32) -> f32 {
    let m = exp_m1_nonpositive(-2.0 * x.abs());
    (-m / (2.0 + m)).copysign(x)
}

/// `f` over a slice, on AVX2's 8 lanes where the CPU has them (SSE2's 4 otherwise). The same
/// operations in the same order either way (no FMA), so the results are bit-identical.
#[inline(always)]
fn map_lanes(y: &mut [f32], f: impl Fn(f32) -> f32 + Copy) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        #[target_feature(enable = "avx2")]
        fn wide(y: &mut [f32], f: impl Fn(f32) -> f32 + Copy) {
            y.iter_mut().for_each(|v| *v = f(*v));
        }
        // SAFETY: the CPU has AVX2 (checked just above).
        unsafe { wide(y, f) };
        return;
    }
    y.iter_mut().for_each(|v| *v = f(*v));
}

/// [`elu`] over a slice.
fn elu_slice(y: &mut [f32]) {
    map_lanes(y, elu);
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

/// The batch row of a chunk's row `i`: batch rows are `[step][sequence]` over `items`
/// sequences, and a chunk holds sequences `lo..lo + len` in the same order.
#[inline]
fn batch_row(i: usize, len: usize, lo: usize, items: usize) -> usize {
    (i / len) * items + lo + i % len
}

/// An LSTM layer (burn's: gates input, forget, output, cell, each `σ` or `tanh` of an input
/// transform plus a hidden transform, both with a bias) in the flat parameter buffer.
#[derive(Clone, Copy, Debug)]
struct LstmLayer {
    /// Per gate, in burn's order (input, forget, output, cell): the input transform
    /// `[obs][units]` and the hidden transform `[units][units]`.
    gates: [(Dense, Dense); 4],
    units: usize,
}

/// What an LSTM pass over `T` steps of `B` sequences keeps for its backward pass; rows are
/// `[step][sequence]`.
struct LstmPass {
    /// Gate values after their nonlinearities, `[T·B][4·units]` (input, forget, output, cell).
    gates: Vec<f32>,
    /// Cell and hidden state entering each step, after the episode-start mask, `[T·B][units]`.
    cell_in: Vec<f32>,
    hidden_in: Vec<f32>,
    /// `tanh` of the cell state leaving each step.
    tanh_cell: Vec<f32>,
    /// Hidden state leaving each step: the layer's output, `[T·B][units]`.
    out: Vec<f32>,
    /// Cell state after the last step, `[B][units]`.
    last_cell: Vec<f32>,
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
    /// Steps per sequence (1 for a feed-forward network). With `seq > 1` the rows are
    /// `[step][sequence]`: row `s · items + i` is step `s` of sequence `i`.
    pub seq: usize,
    /// Per row, 0 where an episode starts (the recurrent state is zeroed before that step) and
    /// 1 elsewhere; empty for a feed-forward network.
    pub starts: &'a [f32],
    /// Recurrent cell and hidden state before each sequence's first step, `[items][units]`;
    /// empty for a feed-forward network.
    pub cell: &'a [f32],
    /// As `cell`, the hidden state.
    pub hidden: &'a [f32],
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
    /// The critic's privileged values `[rows][critic_extra]` (normalised); empty without a
    /// privileged critic.
    pub privileged: &'a [f32],
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
    /// Score actions as executed, clipped to ±1 (see [`crate::ppo::action_log_prob`]).
    pub clipped_actions: bool,
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
pub struct FastNet {
    activation: ActivationKind,
    obs_dim: usize,
    act_dim: usize,
    /// Privileged values the critic reads after the observation (0: none).
    critic_extra: usize,
    /// The recurrent layer in front of the trunks (LSTM policies).
    lstm: Option<LstmLayer>,
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

impl FastNet {
    /// The flat copy of `model`, working on `threads` threads (0: one per core).
    pub fn from_model(model: &ActorCritic, threads: usize) -> Self {
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
        // burn's parameter order (the LSTM first, gate by gate), so that a gradient collected
        // from burn lines up with this buffer.
        let lstm = model.lstm.as_ref().map(|l| {
            let forget = l.forget_gate.as_ref().expect("rlnav's LSTM has a forget gate");
            let gates = [&l.input_gate, forget, &l.output_gate, &l.cell_gate]
                .map(|g| (push(&g.input_transform), push(&g.hidden_transform)));
            LstmLayer { gates, units: l.d_hidden }
        });
        let actor: Vec<Dense> = model.actor.iter().map(&mut push).collect();
        let mu = push(&model.mu);
        let critic: Vec<Dense> = model.critic.iter().map(&mut push).collect();
        let value = push(&model.value);
        let log_std = params.len();
        params.extend(to_vec(model.log_std.val()));
        let n = params.len();
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("learner threads");
        Self {
            activation: model.activation,
            obs_dim: model.obs_dim,
            act_dim: mu.out,
            critic_extra: model.critic_extra,
            lstm,
            actor,
            mu,
            critic,
            value,
            log_std,
            params,
            adam: AdamState { step: 0, m: vec![0.0; n], v: vec![0.0; n] },
            pool,
        }
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
        if let (Some(l), Some(d)) = (model.lstm.as_mut(), self.lstm) {
            let forget = l.forget_gate.as_mut().expect("rlnav's LSTM has a forget gate");
            for (g, (x, h)) in
                [&mut l.input_gate, forget, &mut l.output_gate, &mut l.cell_gate].into_iter().zip(d.gates)
            {
                g.input_transform = layer(g.input_transform.clone(), x);
                g.hidden_transform = layer(g.hidden_transform.clone(), h);
            }
        }
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

    /// Caps every log standard deviation at `max`.
    pub fn cap_log_std(&mut self, max: f32) {
        let at = self.log_std;
        self.params[at..at + self.act_dim].iter_mut().for_each(|l| *l = l.min(max));
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

    /// Means `[rows][act]`, values, and the trunks' activations (actor, critic), from features
    /// `x` `[rows][features]` and a privileged critic's values `[rows][critic_extra]` (zeros
    /// when empty).
    fn forward_rows(
        &self,
        x: &[f32],
        privileged: &[f32],
        rows: usize,
    ) -> (Vec<f32>, Vec<f32>, Activations, Activations) {
        let a = self.trunk(&self.actor, x, rows);
        let mu = self.dense(self.mu, a.last().expect("actor output"), rows);
        let c = if self.critic.is_empty() {
            Vec::new()
        } else if self.critic_extra > 0 {
            let (f, p) = (x.len() / rows.max(1), self.critic_extra);
            let mut xc = Vec::with_capacity(rows * (f + p));
            for r in 0..rows {
                xc.extend_from_slice(&x[r * f..(r + 1) * f]);
                match privileged.get(r * p..(r + 1) * p) {
                    Some(v) => xc.extend_from_slice(v),
                    None => xc.extend(std::iter::repeat_n(0.0, p)),
                }
            }
            self.trunk(&self.critic, &xc, rows)
        } else {
            self.trunk(&self.critic, x, rows)
        };
        let feat = if self.critic.is_empty() { a.last() } else { c.last() };
        let v = self.dense(self.value, feat.expect("critic output"), rows);
        (mu, v, a, c)
    }

    /// Gaussian means `[rows][act]` and values (network units) for observations `[rows][obs]`
    /// (a recurrent network starts from a zero state).
    pub fn forward(&self, obs: &[f32]) -> (Vec<f32>, Vec<f32>) {
        let (mu, v, _) = self.infer(obs, None);
        (mu, v)
    }

    /// One control step: means `[rows][act]`, values (network units) and, for a recurrent
    /// network, the next state, from observations `[rows][obs]` and the state (cell, hidden),
    /// `[rows][units]` each (zeros when `None`). A feed-forward network passes `state` through.
    pub fn infer(&self, obs: &[f32], state: Option<RecurrentState>) -> (Vec<f32>, Vec<f32>, Option<RecurrentState>) {
        self.infer_privileged(obs, &[], state)
    }

    /// [`Self::infer`] with a privileged critic's values `[rows][critic_extra]` (the values
    /// are the critic's on zeros when `privileged` is empty).
    pub fn infer_privileged(
        &self,
        obs: &[f32],
        privileged: &[f32],
        state: Option<RecurrentState>,
    ) -> (Vec<f32>, Vec<f32>, Option<RecurrentState>) {
        let rows = obs.len() / self.obs_dim;
        let Some(l) = self.lstm else {
            let (mu, v, _) = self.infer_rows(obs, privileged, rows, None);
            return (mu, v, state);
        };
        let state = state.unwrap_or_else(|| (vec![0.0; rows * l.units], vec![0.0; rows * l.units]));
        assert_eq!(state.0.len(), rows * l.units, "one recurrent state per row");
        let (mu, v, next) = self.infer_rows(obs, &[], rows, Some(&state));
        (mu, v, Some(next))
    }

    /// [`Self::infer`]'s work: the rows split across the threads; the next state is empty for
    /// a feed-forward network.
    fn infer_rows(
        &self,
        obs: &[f32],
        privileged: &[f32],
        rows: usize,
        state: Option<&RecurrentState>,
    ) -> (Vec<f32>, Vec<f32>, RecurrentState) {
        let units = self.lstm.map_or(0, |l| l.units);
        // A rollout step's batch (128 rows, say) is smaller than a chunk: split it so that every
        // thread gets a share. Rows are independent, so the split does not change the results.
        let chunk = rows.div_ceil(self.pool.current_num_threads()).clamp(1, CHUNK);
        let parts: Vec<_> = self.pool.install(|| {
            (0..rows.div_ceil(chunk))
                .into_par_iter()
                .map(|c| {
                    let (lo, hi) = (c * chunk, ((c + 1) * chunk).min(rows));
                    let x = &obs[lo * self.obs_dim..hi * self.obs_dim];
                    match (self.lstm, state) {
                        (Some(l), Some((cell, hidden))) => {
                            let ones = vec![1.0; hi - lo];
                            let (c0, h0) = (&cell[lo * units..hi * units], &hidden[lo * units..hi * units]);
                            let pass = self.lstm_forward(l, x, hi - lo, 1, &ones, c0, h0);
                            let (mu, v, _, _) = self.forward_rows(&pass.out, &[], hi - lo);
                            (mu, v, pass.last_cell, pass.out)
                        }
                        _ => {
                            let p = self.critic_extra;
                            let priv_rows = privileged.get(lo * p..hi * p).unwrap_or(&[]);
                            let (mu, v, _, _) = self.forward_rows(x, priv_rows, hi - lo);
                            (mu, v, Vec::new(), Vec::new())
                        }
                    }
                })
                .collect()
        });
        let mut mu = Vec::with_capacity(rows * self.act_dim);
        let mut v = Vec::with_capacity(rows);
        let (mut cell, mut hidden) = (Vec::with_capacity(rows * units), Vec::with_capacity(rows * units));
        for (m, val, c, h) in parts {
            mu.extend(m);
            v.extend(val);
            cell.extend(c);
            hidden.extend(h);
        }
        (mu, v, (cell, hidden))
    }

    /// The LSTM over `t` steps of `b` sequences: inputs `x` `[t·b][obs]` (rows `[step][sequence]`),
    /// `mask` `[t·b]` (0 zeroes the state before that step: an episode starts), and the state
    /// before the first step, `c0` and `h0` `[b][units]`.
    #[allow(clippy::too_many_arguments)]
    fn lstm_forward(
        &self,
        l: LstmLayer,
        x: &[f32],
        b: usize,
        t: usize,
        mask: &[f32],
        c0: &[f32],
        h0: &[f32],
    ) -> LstmPass {
        let (h, d, p) = (l.units, self.obs_dim, &self.params);
        let (g4, rows) = (4 * h, b * t);
        // Pre-activations: both biases, then the input transforms of every step at once.
        let mut bias = vec![0.0f32; g4];
        for (k, (wx, wh)) in l.gates.iter().enumerate() {
            for j in 0..h {
                bias[k * h + j] = p[wx.b + j] + p[wh.b + j];
            }
        }
        let mut z = Vec::with_capacity(rows * g4);
        for _ in 0..rows {
            z.extend_from_slice(&bias);
        }
        for (k, (wx, _)) in l.gates.iter().enumerate() {
            gemm((rows, d, h), x, (d, 1), &p[wx.w..], (h, 1), 1.0, &mut z[k * h..], g4);
        }
        let mut pass = LstmPass {
            gates: Vec::new(),
            cell_in: vec![0.0; rows * h],
            hidden_in: vec![0.0; rows * h],
            tanh_cell: vec![0.0; rows * h],
            out: vec![0.0; rows * h],
            last_cell: c0.to_vec(),
        };
        let mut hid = h0.to_vec();
        let cell = &mut pass.last_cell;
        for s in 0..t {
            let (lo, hi) = (s * b, (s + 1) * b);
            for (i, &m) in mask[lo..hi].iter().enumerate() {
                cell[i * h..(i + 1) * h].iter_mut().for_each(|c| *c *= m);
                hid[i * h..(i + 1) * h].iter_mut().for_each(|c| *c *= m);
            }
            pass.cell_in[lo * h..hi * h].copy_from_slice(cell);
            pass.hidden_in[lo * h..hi * h].copy_from_slice(&hid);
            let zs = &mut z[lo * g4..hi * g4];
            for (k, (_, wh)) in l.gates.iter().enumerate() {
                gemm((b, h, h), &hid, (h, 1), &p[wh.w..], (h, 1), 1.0, &mut zs[k * h..], g4);
            }
            for i in 0..b {
                let row = &mut zs[i * g4..(i + 1) * g4];
                map_lanes(&mut row[..3 * h], sigmoid);
                map_lanes(&mut row[3 * h..], tanh);
                let c = &mut cell[i * h..(i + 1) * h];
                for j in 0..h {
                    c[j] = row[h + j] * c[j] + row[j] * row[3 * h + j];
                }
                let r = (lo + i) * h..(lo + i + 1) * h;
                let tc = &mut pass.tanh_cell[r.clone()];
                tc.copy_from_slice(c);
                map_lanes(tc, tanh);
                let out = &mut pass.out[r];
                for j in 0..h {
                    out[j] = row[2 * h + j] * tc[j];
                }
                hid[i * h..(i + 1) * h].copy_from_slice(out);
            }
        }
        pass.gates = z;
        pass
    }

    /// Backpropagation through time of [`Self::lstm_forward`]: adds the layer's gradients into
    /// `g`, given the gradient `dout` of its outputs `[t·b][units]`. The state before the first
    /// step is data (stored by the rollout), so no gradient flows into it.
    #[allow(clippy::too_many_arguments)]
    fn lstm_backward(
        &self,
        l: LstmLayer,
        x: &[f32],
        b: usize,
        t: usize,
        mask: &[f32],
        pass: &LstmPass,
        dout: &[f32],
        g: &mut [f32],
    ) {
        let (h, d, p) = (l.units, self.obs_dim, &self.params);
        let (g4, rows) = (4 * h, b * t);
        let mut dz = vec![0.0f32; rows * g4];
        let (mut dh_next, mut dc_next) = (vec![0.0f32; b * h], vec![0.0f32; b * h]);
        for s in (0..t).rev() {
            let (lo, hi) = (s * b, (s + 1) * b);
            for i in 0..b {
                let r = lo + i;
                let gate = &pass.gates[r * g4..(r + 1) * g4];
                let dzr = &mut dz[r * g4..(r + 1) * g4];
                for j in 0..h {
                    let (ig, fg, og, cg) = (gate[j], gate[h + j], gate[2 * h + j], gate[3 * h + j]);
                    let tc = pass.tanh_cell[r * h + j];
                    let dh = dout[r * h + j] + dh_next[i * h + j];
                    let dc = dc_next[i * h + j] + dh * og * (1.0 - tc * tc);
                    dzr[j] = dc * cg * ig * (1.0 - ig);
                    dzr[h + j] = dc * pass.cell_in[r * h + j] * fg * (1.0 - fg);
                    dzr[2 * h + j] = dh * tc * og * (1.0 - og);
                    dzr[3 * h + j] = dc * ig * (1.0 - cg * cg);
                    dc_next[i * h + j] = dc * fg;
                }
            }
            let dzs = &dz[lo * g4..hi * g4];
            let hin = &pass.hidden_in[lo * h..hi * h];
            dh_next.fill(0.0);
            for (k, (_, wh)) in l.gates.iter().enumerate() {
                // Into the previous hidden state, and the hidden transform's weight.
                gemm((b, h, h), &dzs[k * h..], (g4, 1), &p[wh.w..], (1, h), 1.0, &mut dh_next, h);
                gemm((h, b, h), hin, (1, h), &dzs[k * h..], (g4, 1), 1.0, &mut g[wh.w..wh.w + h * h], h);
            }
            // An episode start cut the state: nothing flows back past it.
            for (i, &m) in mask[lo..hi].iter().enumerate() {
                dh_next[i * h..(i + 1) * h].iter_mut().for_each(|v| *v *= m);
                dc_next[i * h..(i + 1) * h].iter_mut().for_each(|v| *v *= m);
            }
        }
        for (k, (wx, wh)) in l.gates.iter().enumerate() {
            gemm((d, rows, h), x, (1, d), &dz[k * h..], (g4, 1), 1.0, &mut g[wx.w..wx.w + d * h], h);
            for row in dz.chunks_exact(g4) {
                for j in 0..h {
                    g[wx.b + j] += row[k * h + j];
                    g[wh.b + j] += row[k * h + j];
                }
            }
        }
    }

    /// Adds a trunk's weight and bias gradients into `g`, given the gradient `dh` of its last
    /// hidden layer's output (activations `hs`, the input first). Returns the input's gradient
    /// with `want_input` (an LSTM's output needs it; observations do not), else nothing.
    fn backward_trunk(
        &self,
        layers: &[Dense],
        hs: &[Vec<f32>],
        mut dh: Vec<f32>,
        rows: usize,
        g: &mut [f32],
        want_input: bool,
    ) -> Vec<f32> {
        for (i, &d) in layers.iter().enumerate().rev() {
            self.activate_backward(&hs[i + 1], &mut dh);
            let dx = self.backward_dense(d, &hs[i], &dh, rows, g, i > 0 || want_input);
            dh = dx;
        }
        if want_input { dh } else { Vec::new() }
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
        let clipped = cfg.clipped_actions;
        let e = cfg.e_clip;
        // Chunks of whole sequences (rows `[step][sequence]`): sequence `lo + i`'s step `s` is
        // the chunk's row `s · len + i` and the batch's row `s · items + lo + i` (`batch_row`).
        let seq = batch.seq.max(1);
        let items = rows / seq;
        let per = (CHUNK / seq).max(1);
        let n_chunks = items.div_ceil(per);
        let labelled = |k: usize| !batch.teacher.is_empty() && batch.teacher[k * act].is_finite();
        let n_labelled = (0..rows).filter(|&k| labelled(k)).count();
        let teach = if n_labelled > 0 { cfg.teacher_coef / n_labelled as f32 } else { 0.0 };
        struct Part {
            lo: usize,
            len: usize,
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
                    let (lo, hi) = (c * per, ((c + 1) * per).min(items));
                    let len = hi - lo;
                    let r = len * seq;
                    let global = |i: usize| batch_row(i, len, lo, items);
                    let gathered: Vec<f32>;
                    let x = if seq == 1 {
                        &batch.obs[lo * d..hi * d]
                    } else {
                        gathered = (0..seq)
                            .flat_map(|s| &batch.obs[(s * items + lo) * d..(s * items + hi) * d])
                            .copied()
                            .collect();
                        &gathered
                    };
                    let lstm = self.lstm.map(|l| {
                        let u = l.units;
                        let mask: Vec<f32> = (0..r).map(|i| batch.starts[global(i)]).collect();
                        let (c0, h0) = (&batch.cell[lo * u..hi * u], &batch.hidden[lo * u..hi * u]);
                        let pass = self.lstm_forward(l, x, len, seq, &mask, c0, h0);
                        (l, mask, pass)
                    });
                    let features = lstm.as_ref().map_or(x, |(_, _, pass)| pass.out.as_slice());
                    // Privileged critics are feed-forward (seq 1): rows lo..hi are the chunk's.
                    let p = self.critic_extra;
                    let privileged = batch.privileged.get(lo * p..hi * p).unwrap_or(&[]);
                    let (mu, v, ha, hc) = self.forward_rows(features, privileged, r);
                    let mut dmu = vec![0.0f32; r * act];
                    let mut dv = vec![0.0f32; r];
                    let mut grad = vec![0.0f32; self.params.len()];
                    let (mut surr_sum, mut value_sum, mut imitation) = (0.0f32, 0.0f32, 0.0f32);
                    let mut ratios = Vec::with_capacity(r);
                    let mut dlogp = vec![(0.0f32, 0.0f32); act];
                    for i in 0..r {
                        let k = global(i);
                        let mut logp = 0.0;
                        for j in 0..act {
                            let (lp, d_mu, d_ls) =
                                action_log_prob(batch.actions[k * act + j], mu[i * act + j], log_std[j], clipped);
                            logp += lp;
                            dlogp[j] = (d_mu, d_ls);
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
                            let bound = (m - SOFT_BOUND).max(0.0) + (m + SOFT_BOUND).min(0.0);
                            let (d_mu, d_ls) = dlogp[j];
                            dmu[i * act + j] = g_logp * d_mu + cfg.bounds_loss_coef * 2.0 * bound * inv;
                            grad[self.log_std + j] += g_logp * d_ls;
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
                    // Heads, then trunks, then the LSTM.
                    let a_last = ha.last().expect("actor output");
                    let mut dha = self.backward_dense(self.mu, a_last, &dmu, r, &mut grad, true);
                    let recurrent = lstm.is_some();
                    let mut dfeat = Vec::new();
                    if self.critic.is_empty() {
                        let dhv = self.backward_dense(self.value, a_last, &dv, r, &mut grad, true);
                        dha.iter_mut().zip(&dhv).for_each(|(a, b)| *a += b);
                    } else {
                        let dhc =
                            self.backward_dense(self.value, hc.last().expect("critic output"), &dv, r, &mut grad, true);
                        dfeat = self.backward_trunk(&self.critic, &hc, dhc, r, &mut grad, recurrent);
                    }
                    let dx = self.backward_trunk(&self.actor, &ha, dha, r, &mut grad, recurrent);
                    if let Some((l, mask, pass)) = &lstm {
                        if dfeat.is_empty() {
                            dfeat = dx;
                        } else {
                            dfeat.iter_mut().zip(&dx).for_each(|(a, b)| *a += b);
                        }
                        self.lstm_backward(*l, x, len, seq, mask, pass, &dfeat, &mut grad);
                    }
                    Part { lo, len, grad, surr: surr_sum, value: value_sum, imitation, mu, ratios }
                })
                .collect()
        });
        let mut grad = vec![0.0f32; self.params.len()];
        let mut report = LossReport { mu: vec![0.0; rows * act], ratios: vec![0.0; rows], ..Default::default() };
        let (mut surr, mut value, mut imitation) = (0.0f32, 0.0f32, 0.0f32);
        for p in parts {
            grad.iter_mut().zip(&p.grad).for_each(|(g, x)| *g += x);
            surr += p.surr;
            value += p.value;
            imitation += p.imitation;
            // Back into the batch's row order.
            for (i, &ratio) in p.ratios.iter().enumerate() {
                let k = batch_row(i, p.len, p.lo, items);
                report.ratios[k] = ratio;
                report.mu[k * act..(k + 1) * act].copy_from_slice(&p.mu[i * act..(i + 1) * act]);
            }
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

    /// Every parameter's gradient in visiting order, flattened like [`FastNet::params`].
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

    /// A larger mean head than the initial one, so that the ratios move and the bounds loss is
    /// active for some rows.
    fn spread_mean_head(fast: &mut FastNet, rng: &mut Pcg64Mcg) {
        for k in 0..fast.mu.inp * fast.mu.out {
            fast.params[fast.mu.w + k] = rng.sample::<f32, _>(StandardNormal) * 0.8;
        }
    }

    /// Random PPO targets for a minibatch.
    struct Targets {
        act_dim: usize,
        actions: Vec<f32>,
        old_log_probs: Vec<f32>,
        advantages: Vec<f32>,
        returns: Vec<f32>,
        old_values: Vec<f32>,
    }

    impl Targets {
        fn random(rng: &mut Pcg64Mcg, rows: usize, act_dim: usize) -> Self {
            Self {
                act_dim,
                actions: random(rng, rows * act_dim, 1.0),
                old_log_probs: random(rng, rows, 0.3).iter().map(|x| x - 2.0).collect(),
                advantages: random(rng, rows, 1.0),
                returns: random(rng, rows, 1.0),
                old_values: random(rng, rows, 0.5),
            }
        }

        /// A feed-forward batch of these targets.
        fn batch<'a>(&'a self, obs: &'a [f32], teacher: &'a [f32]) -> Batch<'a> {
            Batch {
                obs,
                seq: 1,
                starts: &[],
                cell: &[],
                hidden: &[],
                actions: &self.actions,
                old_log_probs: &self.old_log_probs,
                advantages: &self.advantages,
                returns: &self.returns,
                old_values: &self.old_values,
                teacher,
                privileged: &[],
            }
        }

        /// burn's loss of these targets for its means and values.
        fn burn_loss(
            &self,
            model: &ActorCritic,
            (mu, v): (Tensor<2>, Tensor<1>),
            teacher: &[f32],
            cfg: &LossConfig,
        ) -> crate::ppo::BurnLoss {
            let device = mu.device();
            let t2 =
                |v: &[f32], c: usize| Tensor::<2>::from_data(TensorData::new(v.to_vec(), [v.len() / c, c]), &device);
            let t1 = |v: &[f32]| Tensor::<1>::from_data(TensorData::new(v.to_vec(), [v.len()]), &device);
            let batch = BurnBatch {
                actions: t2(&self.actions, self.act_dim),
                old_log_probs: t1(&self.old_log_probs),
                advantages: t1(&self.advantages),
                returns: t1(&self.returns),
                old_values: t1(&self.old_values),
                teacher: BurnBatch::teacher(teacher, self.act_dim, &device),
            };
            burn_loss(mu, v, model.log_std.val(), batch, cfg)
        }
    }

    /// Asserts that burn's autodiff gradient of `total` is `grad` (same layout, every value),
    /// then that one Adam step from it moves `model` and `fast` to the same parameters. Returns
    /// burn's gradient and the largest gradient magnitude.
    fn assert_gradient_and_adam_match(
        case: usize,
        fast: &mut FastNet,
        model: ActorCritic,
        total: Tensor<1>,
        grad: &[f32],
    ) -> (Vec<f32>, f32) {
        let grads = GradientsParams::from_grads(total.backward(), &model);
        let mut collect = Collect { grads: &grads, out: Vec::new(), ids: Vec::new() };
        model.visit(&mut collect);
        assert_eq!(collect.out.len(), grad.len(), "same parameter count and layout");
        let scale = grad.iter().fold(0.0f32, |m, g| m.max(g.abs()));
        for (k, (a, b)) in grad.iter().zip(&collect.out).enumerate() {
            assert!((a - b).abs() <= 1e-4 * scale + 1e-6, "case {case}: gradient {k}: fast {a}, burn {b}");
        }
        let burn_grad = collect.out;
        // One Adam step from the same gradient gives the same parameters.
        let mut burn_opt = AdamConfig::new().with_epsilon(1e-8).init();
        let stepped = burn_opt.step(1e-3, model, grads);
        fast.adam_step(grad, 1e-3);
        let after = FastNet::from_model(&stepped, 1);
        for (k, (a, b)) in fast.params.iter().zip(after.params()).enumerate() {
            assert!(
                (a - b).abs() <= 1e-6 + 1e-5 * a.abs(),
                "case {case}: parameter {k} after Adam: fast {a}, burn {b}"
            );
        }
        (burn_grad, scale)
    }

    /// The hand-written loss, gradient and Adam step agree with burn's autodiff and Adam on
    /// random networks and minibatches, for each activation, shared and separate critics,
    /// clipped and unclipped value losses, ratios on both sides of the clip range, and actions
    /// scored as densities or, clipped to ±1, as tail masses (a third of them beyond a bound),
    /// and a critic that reads privileged values beside the observation.
    #[test]
    fn gradients_and_adam_match_burn() {
        let device = Device::flex().autodiff();
        let cases = [
            (ActivationKind::Elu, true, true, false, 0),
            (ActivationKind::Relu, true, false, true, 0),
            (ActivationKind::Tanh, false, true, false, 0),
            (ActivationKind::Elu, false, false, true, 0),
            (ActivationKind::Elu, true, true, true, 2),
        ];
        for (case, (activation, separate_critic, clip_value, clipped_actions, critic_movers)) in
            cases.into_iter().enumerate()
        {
            let cfg = NetworkConfig {
                hidden: vec![24, 16],
                activation,
                separate_critic,
                critic_movers,
                ..Default::default()
            };
            let extra = cfg.critic_privileged_len();
            let (obs_dim, act_dim, rows) = (11, 2, 700); // rows span three chunks, the last partial
            let model = ActorCritic::seeded(&cfg, obs_dim, act_dim, &device, case as u64);
            let mut rng = Pcg64Mcg::seed_from_u64(case as u64 + 10);
            let mut fast = FastNet::from_model(&model, 2);
            spread_mean_head(&mut fast, &mut rng);
            fast.params[fast.log_std] = -0.3;
            let model = fast.write_into(model);
            let obs = random(&mut rng, rows * obs_dim, 1.0);
            let targets = Targets::random(&mut rng, rows, act_dim);
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
                clipped_actions,
            };
            let privileged = random(&mut rng, rows * extra, 1.0);
            let batch = Batch { privileged: &privileged, ..targets.batch(&obs, &teacher) };
            let (report, grad) = fast.loss_and_grad(&batch, &loss_cfg);
            if extra > 0 {
                let (mu_with, with, _) = fast.infer_privileged(&obs, &privileged, None);
                let (mu_without, without) = fast.forward(&obs);
                assert_eq!(mu_with, mu_without, "the actor does not read the privileged values");
                assert!(with.iter().zip(&without).all(|(a, b)| a != b), "the critic does");
            }

            let x = Tensor::<2>::from_data(TensorData::new(obs.clone(), [rows, obs_dim]), &device);
            let heads = if extra > 0 {
                let p = Tensor::<2>::from_data(TensorData::new(privileged.clone(), [rows, extra]), &device);
                model.heads_privileged(x, Some(p))
            } else {
                model.forward(x)
            };
            let l = targets.burn_loss(&model, heads, &teacher, &loss_cfg);
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
            assert_gradient_and_adam_match(case, &mut fast, model, l.total, &grad);
        }
    }

    #[test]
    fn forward_matches_burn_and_does_not_depend_on_threads() {
        let device = Device::flex();
        let cfg = NetworkConfig { hidden: vec![32, 16], ..Default::default() };
        let model = ActorCritic::seeded(&cfg, 9, 2, &device, 3);
        let mut rng = Pcg64Mcg::seed_from_u64(4);
        let obs = random(&mut rng, 600 * 9, 1.0);
        let (mu1, v1) = FastNet::from_model(&model, 1).forward(&obs);
        let (mu2, v2) = FastNet::from_model(&model, 2).forward(&obs);
        assert_eq!((&mu1, &v1), (&mu2, &v2), "bit-identical for 1 and 2 threads");
        // A rollout-sized batch is split by thread count (130 rows: one chunk, or 44 + 44 + 42).
        let small = &obs[..130 * 9];
        let one = FastNet::from_model(&model, 1).forward(small);
        assert_eq!(one, FastNet::from_model(&model, 3).forward(small), "bit-identical for 1 and 3 threads");
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
    fn gates_agree_with_libm() {
        let (mut s_worst, mut t_worst) = (0.0f32, 0.0f32);
        let mut x = -100.0f32;
        while x < 100.0 {
            s_worst = s_worst.max((sigmoid(x) - 1.0 / (1.0 + (-x).exp())).abs());
            t_worst = t_worst.max((tanh(x) - x.tanh()).abs() / x.tanh().abs().clamp(1e-30, 1.0));
            x += 0.000_731;
        }
        assert!(s_worst < 3e-7 && t_worst < 1e-6, "sigmoid {s_worst:e}, tanh {t_worst:e}");
        assert_eq!((sigmoid(0.0), tanh(0.0), tanh(1e-20)), (0.5, 0.0, 1e-20));
        assert_eq!((sigmoid(1e4), sigmoid(-1e4) < 1e-37, tanh(-1e4)), (1.0, true, -1.0));
    }

    /// An LSTM policy's `[step][sequence]` rows, with episode starts inside the sequences and
    /// stored states before them, as `Ppo::update` builds them.
    struct Sequences {
        obs: Vec<f32>,
        starts: Vec<f32>,
        cell: Vec<f32>,
        hidden: Vec<f32>,
    }

    fn sequences(rng: &mut Pcg64Mcg, seq: usize, items: usize, obs_dim: usize, units: usize) -> Sequences {
        Sequences {
            obs: random(rng, seq * items * obs_dim, 1.0),
            starts: (0..seq * items).map(|_| if rng.random_range(0..8) == 0 { 0.0 } else { 1.0 }).collect(),
            cell: random(rng, items * units, 0.6),
            hidden: random(rng, items * units, 0.4),
        }
    }

    /// burn's recurrent forward over the sequences, as its learner runs it: means and values
    /// `[step][sequence]`.
    fn burn_sequences(model: &ActorCritic, q: &Sequences, seq: usize, device: &Device) -> (Tensor<2>, Tensor<1>) {
        let (d, units) = (model.obs_dim, model.lstm_units());
        let b = q.cell.len() / units;
        let t2 = |v: &[f32], c: usize| Tensor::<2>::from_data(TensorData::new(v.to_vec(), [v.len() / c, c]), device);
        let mut state = Some(burn::nn::LstmState::new(t2(&q.cell, units), t2(&q.hidden, units)));
        let (mut mus, mut vs) = (Vec::new(), Vec::new());
        for s in 0..seq {
            let mask = t2(&q.starts[s * b..(s + 1) * b], 1);
            let st = state.take().map(|st| burn::nn::LstmState::new(st.cell * mask.clone(), st.hidden * mask));
            let (mu, v, next) = model.step(t2(&q.obs[s * b * d..(s + 1) * b * d], d), st);
            state = next;
            mus.push(mu);
            vs.push(v);
        }
        (Tensor::cat(mus, 0), Tensor::cat(vs, 0))
    }

    /// Backpropagation through time agrees with burn's autodiff through its LSTM: every
    /// parameter's gradient, with sequences cut by episode starts, over several chunks of
    /// sequences (the last partial), with shared and separate critics; then one Adam step.
    #[test]
    fn recurrent_gradients_match_burn() {
        let device = Device::flex().autodiff();
        for (case, separate_critic) in [true, false].into_iter().enumerate() {
            let cfg = NetworkConfig { lstm_units: 12, hidden: vec![16, 10], separate_critic, ..Default::default() };
            let (obs_dim, act_dim, seq, items) = (7, 2, 4, 150); // 64 sequences per chunk: 64, 64, 22
            let model = ActorCritic::seeded(&cfg, obs_dim, act_dim, &device, 20 + case as u64);
            let mut rng = Pcg64Mcg::seed_from_u64(30 + case as u64);
            let mut fast = FastNet::from_model(&model, 2);
            spread_mean_head(&mut fast, &mut rng);
            let model = fast.write_into(model);
            let q = sequences(&mut rng, seq, items, obs_dim, 12);
            let targets = Targets::random(&mut rng, seq * items, act_dim);
            let loss_cfg = LossConfig {
                e_clip: 0.2,
                clip_value: true,
                critic_coef: 2.0,
                entropy_coef: 0.01,
                bounds_loss_coef: 0.5,
                teacher_coef: 0.0,
                clipped_actions: case == 1,
            };
            let batch =
                Batch { seq, starts: &q.starts, cell: &q.cell, hidden: &q.hidden, ..targets.batch(&q.obs, &[]) };
            let (report, grad) = fast.loss_and_grad(&batch, &loss_cfg);
            let (mu, v) = burn_sequences(&model, &q, seq, &device);
            let burn_mu = mu.clone().into_data().try_to_vec::<f32>().unwrap();
            for (k, (a, b)) in report.mu.iter().zip(&burn_mu).enumerate() {
                assert!((a - b).abs() < 1e-5 * (1.0 + b.abs()), "case {case}: mean {k}: fast {a}, burn {b}");
            }
            let l = targets.burn_loss(&model, (mu, v), &[], &loss_cfg);
            let burn_policy = l.policy.clone().into_scalar::<f32>();
            assert!((report.policy_loss - burn_policy).abs() < 1e-4, "{} vs {burn_policy}", report.policy_loss);
            let lstm = fast.lstm.unwrap();
            let (burn_grad, scale) = assert_gradient_and_adam_match(case, &mut fast, model, l.total, &grad);
            // The hidden transforms' gradients (through time only) are small beside the heads':
            // each is also checked against its own scale.
            for (gate, (_, wh)) in lstm.gates.iter().enumerate() {
                let block = wh.w..wh.w + 12 * 12;
                let own = burn_grad[block.clone()].iter().fold(0.0f32, |m, g| m.max(g.abs()));
                assert!(own > 1e-4 * scale, "case {case}: gate {gate}: hidden-transform gradient {own} of {scale}");
                for k in block {
                    let (a, b) = (grad[k], burn_grad[k]);
                    assert!((a - b).abs() <= 1e-3 * own, "case {case}: gradient {k} (gate {gate}): fast {a}, burn {b}");
                }
            }
        }
    }

    /// A control step of an LSTM policy: burn's outputs and next state, the same bits for any
    /// thread count, and the state carried from step to step.
    #[test]
    fn recurrent_inference_matches_burn_and_does_not_depend_on_threads() {
        let device = Device::flex();
        let cfg = NetworkConfig { lstm_units: 16, hidden: vec![32, 16], ..Default::default() };
        let model = ActorCritic::seeded(&cfg, 9, 2, &device, 5);
        let mut rng = Pcg64Mcg::seed_from_u64(6);
        let n = 130;
        let (one, three) = (FastNet::from_model(&model, 1), FastNet::from_model(&model, 3));
        let t2 = |v: &[f32], c: usize| Tensor::<2>::from_data(TensorData::new(v.to_vec(), [v.len() / c, c]), &device);
        let mut state = Some((random(&mut rng, n * 16, 0.5), random(&mut rng, n * 16, 0.5)));
        let mut burn_state = state.as_ref().map(|(c, h)| burn::nn::LstmState::new(t2(c, 16), t2(h, 16)));
        for step in 0..3 {
            let obs = random(&mut rng, n * 9, 1.0);
            let out = one.infer(&obs, state.clone());
            assert_eq!(out, three.infer(&obs, state.clone()), "1 and 3 threads, step {step}");
            let (mu, v, next) = out;
            let (bmu, bv, bnext) = model.step(t2(&obs, 9), burn_state.take());
            let bnext = bnext.unwrap();
            let want: Vec<f32> = [bmu, bv.unsqueeze_dim(1), bnext.cell.clone(), bnext.hidden.clone()]
                .into_iter()
                .flat_map(|t| t.into_data().try_to_vec::<f32>().unwrap())
                .collect();
            let (c, h) = next.clone().unwrap();
            let got: Vec<f32> = mu.iter().chain(&v).chain(&c).chain(&h).copied().collect();
            for (a, b) in got.iter().zip(&want) {
                assert!((a - b).abs() < 1e-5 * (1.0 + b.abs()), "step {step}: fast {a}, burn {b}");
            }
            state = next;
            burn_state = Some(bnext);
        }
        // No state: a zero one, and a feed-forward network passes the state through.
        let obs = random(&mut rng, 4 * 9, 1.0);
        let zeros = Some((vec![0.0; 64], vec![0.0; 64]));
        assert_eq!(one.infer(&obs, None), one.infer(&obs, zeros));
        let mlp = FastNet::from_model(&ActorCritic::seeded(&NetworkConfig::default(), 9, 2, &device, 1), 1);
        let kept = Some((vec![1.0], vec![2.0]));
        assert_eq!(mlp.infer(&obs, kept.clone()).2, kept);
    }
}
