//! Actor-critic networks for continuous actions: a Gaussian policy whose mean comes from an MLP
//! and whose log standard deviation is a learned, state-independent vector (the article's
//! `fixed_sigma`), and a value head; the critic has its own MLP or shares the actor's. The
//! recurrent variant puts an LSTM between the input and the MLPs (rl_games' `before_mlp`).

use burn::module::{Initializer, ModuleVisitor, Param};
use burn::nn::{Linear, LinearConfig, Lstm, LstmConfig, LstmState};
use burn::prelude::*;
use burn::tensor::activation;
use serde::{Deserialize, Serialize};

/// Hidden-layer nonlinearity.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ActivationKind {
    /// ELU (α = 1), the article's choice.
    Elu,
    /// ReLU.
    Relu,
    /// tanh.
    Tanh,
}

impl ActivationKind {
    /// Applies the nonlinearity.
    pub fn apply<const D: usize>(self, x: Tensor<D>) -> Tensor<D> {
        match self {
            ActivationKind::Elu => activation::elu(x, 1.0),
            ActivationKind::Relu => activation::relu(x),
            ActivationKind::Tanh => activation::tanh(x),
        }
    }
}

/// Network shape.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NetworkConfig {
    /// Hidden layer sizes of the MLPs (article: [256, 128, 64]).
    pub hidden: Vec<usize>,
    /// Hidden nonlinearity (default ELU).
    pub activation: ActivationKind,
    /// Give the critic its own MLP (default true); otherwise the value head reads the actor's
    /// last hidden layer.
    pub separate_critic: bool,
    /// LSTM units between input and MLPs; 0 for a feed-forward policy (article's LSTM: 128).
    pub lstm_units: usize,
    /// Initial log standard deviation of the Gaussian policy (default 0, σ = 1).
    pub init_log_std: f32,
    /// Moving obstacles and people whose privileged state the critic reads beside the
    /// observation in training (`rlnav_sim::task::NavEnv::write_privileged`: each one's
    /// position and velocity relative to the robot, in its frame, and its radius; then the
    /// robot's top speed and radius). An asymmetric actor-critic: the actor, the only part
    /// a robot runs, still sees the observation alone. Default 0: the critic sees what the
    /// actor sees. Needs `separate_critic` and a feed-forward policy.
    pub critic_movers: usize,
}

impl Default for NetworkConfig {
    fn default() -> Self {
        Self {
            hidden: vec![256, 128, 64],
            activation: ActivationKind::Elu,
            separate_critic: true,
            lstm_units: 0,
            init_log_std: 0.0,
            critic_movers: 0,
        }
    }
}

impl NetworkConfig {
    /// Checks sizes; returns `(key, expected)` on failure.
    pub fn check(&self) -> Result<(), (String, String)> {
        if self.hidden.is_empty() || self.hidden.iter().any(|h| *h == 0 || *h > 4096) {
            return Err(("hidden".into(), "1 to 8 layer sizes, each in [1, 4096]".into()));
        }
        if self.hidden.len() > 8 {
            return Err(("hidden".into(), "at most 8 layers".into()));
        }
        if self.lstm_units > 4096 {
            return Err(("lstm_units".into(), "0 (no LSTM) to 4096".into()));
        }
        if !(-5.0..=2.0).contains(&self.init_log_std) {
            return Err(("init_log_std".into(), "a number in [-5, 2]".into()));
        }
        if self.critic_movers > 64 {
            return Err(("critic_movers".into(), "0 (no privileged critic) to 64".into()));
        }
        if self.critic_movers > 0 && (!self.separate_critic || self.is_recurrent()) {
            return Err((
                "critic_movers".into(),
                "0 unless the critic has its own MLP (separate_critic: true) and the policy is feed-forward (lstm_units: 0)"
                    .into(),
            ));
        }
        Ok(())
    }

    /// Whether the policy is recurrent.
    pub fn is_recurrent(&self) -> bool {
        self.lstm_units > 0
    }

    /// Privileged values the critic reads beside the observation (0 without `critic_movers`).
    pub fn critic_privileged_len(&self) -> usize {
        rlnav_sim::task::privileged_len(self.critic_movers)
    }
}

/// The device networks train on: burn's pure-Rust CPU backend, or a GPU when built with the
/// `cuda` or `wgpu` feature and `RLNAV_DEVICE=cuda`/`wgpu` is set.
pub fn training_device() -> Device {
    #[cfg(feature = "cuda")]
    if std::env::var("RLNAV_DEVICE").as_deref() == Ok("cuda") {
        return Device::cuda(0);
    }
    #[cfg(feature = "wgpu")]
    if std::env::var("RLNAV_DEVICE").as_deref() == Ok("wgpu") {
        return Device::wgpu(Default::default());
    }
    Device::flex()
}

/// Actor-critic network.
#[derive(Module, Debug)]
pub struct ActorCritic {
    /// Recurrent layer after the input (LSTM policies only).
    pub lstm: Option<Lstm>,
    /// Actor hidden layers.
    pub actor: Vec<Linear>,
    /// Gaussian mean head.
    pub mu: Linear,
    /// Critic hidden layers (empty when the critic shares the actor's).
    pub critic: Vec<Linear>,
    /// Value head.
    pub value: Linear,
    /// State-independent log standard deviation per action.
    pub log_std: Param<Tensor<1>>,
    /// Hidden nonlinearity.
    #[module(skip)]
    pub activation: ActivationKind,
    /// Observation length.
    #[module(skip)]
    pub obs_dim: usize,
    /// Privileged values the critic reads after the observation (0: none; see
    /// [`NetworkConfig::critic_movers`]).
    #[module(skip)]
    pub critic_extra: usize,
}

fn mlp(sizes: &[usize], device: &Device) -> Vec<Linear> {
    sizes.windows(2).map(|w| LinearConfig::new(w[0], w[1]).init(device)).collect()
}

impl ActorCritic {
    /// A freshly initialised network for `obs_dim` inputs and `action_dim` actions (weights
    /// from the backend's generator in whatever state it is: see [`Self::seeded`]).
    pub fn new(cfg: &NetworkConfig, obs_dim: usize, action_dim: usize, device: &Device) -> Self {
        let input = if cfg.is_recurrent() { cfg.lstm_units } else { obs_dim };
        let lstm = cfg.is_recurrent().then(|| LstmConfig::new(obs_dim, cfg.lstm_units, true).init(device));
        let mut sizes = vec![input];
        sizes.extend(&cfg.hidden);
        let last = *sizes.last().expect("at least the input");
        // A small initial mean keeps the first actions near the middle of their range (the
        // "last policy layer scaled by 0.01" of PPO practice). Set through the initialiser:
        // scaling the initialised weights would record an operation on the autodiff tape.
        let bound = 0.01 / (last as f64).sqrt();
        let critic_extra = cfg.critic_privileged_len();
        let mut critic_sizes = sizes.clone();
        critic_sizes[0] += critic_extra;
        let mu = LinearConfig::new(last, action_dim)
            .with_initializer(Initializer::Uniform { min: -bound, max: bound })
            .init(device);
        Self {
            lstm,
            actor: mlp(&sizes, device),
            mu,
            critic: if cfg.separate_critic { mlp(&critic_sizes, device) } else { Vec::new() },
            value: LinearConfig::new(last, 1).init(device),
            log_std: Param::from_tensor(Tensor::full([action_dim], cfg.init_log_std, device)),
            activation: cfg.activation,
            obs_dim,
            critic_extra,
        }
    }

    /// Like [`Self::new`], with the initial weights determined by `seed`. burn's initialisers
    /// draw from the backend's (possibly process-global) generator, so seeding and building
    /// happen under one lock: concurrent constructions (parallel tests, several runs in one
    /// process) cannot interleave their draws.
    pub fn seeded(cfg: &NetworkConfig, obs_dim: usize, action_dim: usize, device: &Device, seed: u64) -> Self {
        /// Touches every parameter: burn initialises parameters lazily, on first use, and
        /// the draws must happen here, under the lock.
        struct Materialise;
        impl ModuleVisitor for Materialise {
            fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
                let _ = param.val();
            }
        }
        static INIT: std::sync::Mutex<()> = std::sync::Mutex::new(());
        let _guard = INIT.lock().unwrap_or_else(|p| p.into_inner());
        device.seed(seed);
        let net = Self::new(cfg, obs_dim, action_dim, device);
        net.visit(&mut Materialise);
        net
    }

    fn trunk(&self, layers: &[Linear], mut x: Tensor<2>) -> Tensor<2> {
        for l in layers {
            x = self.activation.apply(l.forward(x));
        }
        x
    }

    /// Gaussian mean `[batch, actions]` and value `[batch]` from features `[batch, features]`
    /// (the observation, or the LSTM's output). A privileged critic reads zeros in place of
    /// its privileged values here: see [`Self::heads_privileged`].
    pub fn heads(&self, features: Tensor<2>) -> (Tensor<2>, Tensor<1>) {
        let privileged =
            (self.critic_extra > 0).then(|| Tensor::zeros([features.dims()[0], self.critic_extra], &features.device()));
        self.heads_privileged(features, privileged)
    }

    /// [`Self::heads`] with the critic's privileged values `[batch, critic_extra]` (needed
    /// exactly when `critic_extra > 0`).
    pub fn heads_privileged(&self, features: Tensor<2>, privileged: Option<Tensor<2>>) -> (Tensor<2>, Tensor<1>) {
        let a = self.trunk(&self.actor, features.clone());
        let mu = self.mu.forward(a.clone());
        let c = if self.critic.is_empty() {
            a
        } else {
            let input = match privileged {
                Some(p) => Tensor::cat(vec![features, p], 1),
                None => features,
            };
            self.trunk(&self.critic, input)
        };
        let value = self.value.forward(c).squeeze_dim(1);
        (mu, value)
    }

    /// Feed-forward pass (ignores the LSTM; use [`Self::step`] for recurrent policies).
    pub fn forward(&self, obs: Tensor<2>) -> (Tensor<2>, Tensor<1>) {
        self.heads(obs)
    }

    /// One control step of a recurrent policy: observation `[batch, obs]` and state (zeros
    /// when `None`) to mean, value and the next state. For an MLP the state passes through.
    pub fn step(&self, obs: Tensor<2>, state: Option<LstmState<2>>) -> (Tensor<2>, Tensor<1>, Option<LstmState<2>>) {
        match &self.lstm {
            None => {
                let (mu, v) = self.heads(obs);
                (mu, v, state)
            }
            Some(lstm) => {
                let (out, next) = lstm.forward(obs.unsqueeze_dim(1), state);
                let (mu, v) = self.heads(out.squeeze_dim(1));
                (mu, v, Some(next))
            }
        }
    }

    /// LSTM hidden size (0 for an MLP).
    pub fn lstm_units(&self) -> usize {
        self.lstm.as_ref().map_or(0, |l| l.d_hidden)
    }

    /// Number of actions.
    pub fn action_dim(&self) -> usize {
        self.log_std.val().dims()[0]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shapes_and_initial_mean() {
        let device = Device::flex();
        for cfg in [
            NetworkConfig::default(),
            NetworkConfig { separate_critic: false, hidden: vec![32], ..Default::default() },
            NetworkConfig { lstm_units: 16, hidden: vec![32, 16], ..Default::default() },
        ] {
            let net = ActorCritic::new(&cfg, 124, 2, &device);
            let obs = Tensor::<2>::ones([5, 124], &device);
            let (mu, v, state) = net.step(obs, None);
            assert_eq!(mu.dims(), [5, 2]);
            assert_eq!(v.dims(), [5]);
            assert_eq!(state.is_some(), cfg.is_recurrent());
            let mu: Vec<f32> = mu.into_data().try_to_vec::<f32>().unwrap();
            assert!(mu.iter().all(|m| m.abs() < 0.1), "small initial mean: {mu:?}");
            assert_eq!(net.action_dim(), 2);
        }
    }

    #[test]
    fn lstm_state_carries_information() {
        let device = Device::flex();
        let cfg = NetworkConfig { lstm_units: 8, hidden: vec![16], ..Default::default() };
        let net = ActorCritic::new(&cfg, 4, 2, &device);
        let x = Tensor::<2>::ones([1, 4], &device);
        let (_, v0, s) = net.step(x.clone(), None);
        let (_, v1, _) = net.step(x, s);
        let (a, b): (Vec<f32>, Vec<f32>) =
            (v0.into_data().try_to_vec::<f32>().unwrap(), v1.into_data().try_to_vec::<f32>().unwrap());
        assert_ne!(a, b, "same input, different state, different value");
    }
}
