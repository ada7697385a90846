//! The run configuration: robot, scenarios, task, network, PPO hyper-parameters (rl_games key
//! names, the article's values as defaults) and the curriculum. YAML, every field defaulted,
//! unknown keys rejected; `--set a.b.c=VALUE` overrides any value by its dotted path.

use rlnav_policy::NetworkConfig;
use rlnav_sim::config::{ConfigError, Invalid, Validate, check_positive, check_range, preset_or_file};
use rlnav_sim::task::TaskConfig;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use serde_norway::Value;

/// Training configurations shipped in `configs/`, embedded: `(name, yaml)`.
pub const TRAIN_PRESETS: &[(&str, &str)] = &[
    ("static-mlp", include_str!("../../../configs/static-mlp.yaml")),
    ("dynamic-lstm", include_str!("../../../configs/dynamic-lstm.yaml")),
    ("smoke", include_str!("../../../configs/smoke.yaml")),
    ("barn-jackal", include_str!("../../../configs/barn-jackal.yaml")),
    ("allrobots-plan-mlp", include_str!("../../../configs/allrobots-plan-mlp.yaml")),
    ("allrobots-hall-traffic-mlp", include_str!("../../../configs/allrobots-hall-traffic-mlp.yaml")),
];

/// The built-in default run (`rlnav train` with no `--config`).
pub const DEFAULT_CONFIG: &str = "static-mlp";

/// How the learning rate evolves.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LrSchedule {
    /// Fixed.
    Constant,
    /// rl_games' adaptive schedule: divide by 1.5 when the KL divergence of a minibatch
    /// update exceeds 2 × `kl_threshold`, multiply by 1.5 when it is under half of it.
    Adaptive,
    /// Linear decay to zero over `max_epochs`.
    Linear,
}

/// Which code computes the PPO update.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Learner {
    /// The hand-written CPU learner, or burn when a GPU is chosen with `RLNAV_DEVICE`.
    #[default]
    Auto,
    /// The hand-written CPU learner (`crate::fast`).
    Fast,
    /// burn's autodiff and Adam (any network, any device).
    Burn,
}

/// PPO hyper-parameters (rl_games names).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PpoConfig {
    /// Parallel environments.
    pub num_actors: usize,
    /// Steps per environment per epoch.
    pub horizon_length: usize,
    /// Samples per minibatch (divides `num_actors * horizon_length`).
    pub minibatch_size: usize,
    /// Passes over the batch per epoch.
    pub mini_epochs: usize,
    /// Discount.
    pub gamma: f32,
    /// GAE λ.
    pub tau: f32,
    /// Initial learning rate.
    pub learning_rate: f32,
    /// Learning-rate schedule.
    pub lr_schedule: LrSchedule,
    /// KL target of the adaptive schedule.
    pub kl_threshold: f32,
    /// Clip range of the surrogate (and of the value when `clip_value`).
    pub e_clip: f32,
    /// Clip the value update like the policy's.
    pub clip_value: bool,
    /// Global gradient-norm limit.
    pub grad_norm: f32,
    /// Value-loss weight (the loss uses `0.5 * critic_coef * value_loss`).
    pub critic_coef: f32,
    /// Entropy bonus weight.
    pub entropy_coef: f32,
    /// Weight of the penalty on action means beyond ±1.1.
    pub bounds_loss_coef: f32,
    /// Ceiling on the policy's learned log standard deviations, applied after every update
    /// step (absent: none): a number, or `[start, end]` moving linearly from `start` at the
    /// first epoch to `end` at the last (noise annealing); an `init_log_std` above the start is
    /// lowered to it. With actions clipped to ±1 the
    /// surrogate can gain from ever wider noise (samples beyond a bound act as the bound),
    /// and the policy then trains on near-random commands while it is judged on its mean.
    pub max_log_std: Option<LogStdCeiling>,
    /// Score sampled actions as the robot executes them, clipped to ±1: a sample beyond a
    /// bound has the probability of the Gaussian's tail beyond it (Clipped Action Policy
    /// Gradient, Fujita & Maeda 2018), which removes the surrogate's gain from wider noise
    /// without capping σ. Default false (the Gaussian density, as rl_games).
    pub clipped_actions: bool,
    /// Running observation normalisation.
    pub normalize_input: bool,
    /// Running value (return) normalisation.
    pub normalize_value: bool,
    /// Standardise advantages per minibatch.
    pub normalize_advantage: bool,
    /// Truncated BPTT length for LSTM policies (divides `horizon_length`).
    pub seq_len: usize,
    /// Epochs (rollout + update) to run.
    pub max_epochs: usize,
    /// Simulator and learner worker threads (0: one per core).
    pub threads: usize,
    /// Which code computes the update: `auto` (default), `fast` or `burn`.
    pub learner: Learner,
    /// A classical controller whose commands the policy is also taught to imitate early in
    /// training (kickstarting; absent: PPO alone).
    pub teacher: Option<TeacherConfig>,
    /// Replace a random half of every minibatch by its left-right mirror image (the world
    /// reflected about the robot's x axis: scan bins exchanged across the x axis, bearings,
    /// plan `y` and turn rates negated; see `rlnav_sim::observation::ObservationMirror`),
    /// with the same advantages and returns, so that the policy learns each lesson for both
    /// sides (symmetry augmentation, as RSL-RL's, which appends the copies instead).
    /// Feed-forward networks only; the observation statistics are kept mirror-symmetric too.
    /// Default false.
    pub mirror: bool,
}

/// `train.max_log_std`: a fixed ceiling or one that moves linearly over the run.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged, expecting = "train.max_log_std: a number or a [start, end] pair")]
pub enum LogStdCeiling {
    /// The same ceiling throughout.
    Fixed(f32),
    /// `[start, end]`: from `start` at epoch 0 to `end` at the last epoch.
    Linear([f32; 2]),
}

impl LogStdCeiling {
    /// The ceiling at `epoch` of `max_epochs`.
    pub fn at(&self, epoch: usize, max_epochs: usize) -> f32 {
        match *self {
            Self::Fixed(c) => c,
            Self::Linear([a, b]) => {
                let f = epoch as f32 / max_epochs.saturating_sub(1).max(1) as f32;
                a + (b - a) * f.min(1.0)
            }
        }
    }

    /// The ceiling at the first epoch.
    pub fn start(&self) -> f32 {
        self.at(0, 1)
    }
}

/// Kickstarting from a classical controller (Schmitt et al. 2018, "Kickstarting deep
/// reinforcement learning"): while the policy collects its own experience, the teacher
/// labels the states it visits with the command it would give (as in DAgger), and the update
/// adds `weight · mean ‖μ(s) − a_teacher(s)‖²` to the PPO loss. The weight falls linearly to
/// `final_weight` over `epochs` and stays there; at 0, PPO alone trains the policy from then on
/// (and no labels are computed).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TeacherConfig {
    /// The teacher: `dwa` (the benchmark's A* + DWA planner, given each episode's world as its
    /// prior map).
    pub controller: String,
    /// Weight of the imitation term at epoch 0.
    pub weight: f32,
    /// Epochs over which the weight falls to `final_weight`.
    pub epochs: usize,
    /// Weight from `epochs` on.
    pub final_weight: f32,
    /// Share of the environments whose states the teacher labels (the teacher costs far more
    /// per step than the simulator).
    pub share: f32,
}

impl Default for TeacherConfig {
    fn default() -> Self {
        Self { controller: "dwa".into(), weight: 1.0, epochs: 200, final_weight: 0.0, share: 0.25 }
    }
}

impl TeacherConfig {
    /// The imitation weight at `epoch` (`final_weight` from `epochs` on).
    pub fn weight_at(&self, epoch: usize) -> f32 {
        let f = (epoch as f32 / self.epochs.max(1) as f32).min(1.0);
        self.weight + (self.final_weight - self.weight) * f
    }
}

impl Default for PpoConfig {
    fn default() -> Self {
        Self {
            num_actors: 64,
            horizon_length: 64,
            minibatch_size: 2048,
            mini_epochs: 4,
            gamma: 0.99,
            tau: 0.95,
            learning_rate: 3e-4,
            lr_schedule: LrSchedule::Adaptive,
            kl_threshold: 0.008,
            e_clip: 0.2,
            clip_value: true,
            grad_norm: 1.0,
            critic_coef: 2.0,
            entropy_coef: 0.0,
            bounds_loss_coef: 0.0001,
            max_log_std: None,
            clipped_actions: false,
            normalize_input: true,
            normalize_value: true,
            normalize_advantage: true,
            seq_len: 8,
            max_epochs: 200,
            threads: 0,
            learner: Learner::Auto,
            teacher: None,
            mirror: false,
        }
    }
}

impl PpoConfig {
    /// Whether the hand-written learner trains the network.
    pub fn uses_fast_learner(&self) -> bool {
        match self.learner {
            Learner::Burn => false,
            Learner::Fast => true,
            Learner::Auto => std::env::var_os("RLNAV_DEVICE").is_none(),
        }
    }
}

/// When a curriculum stage hands over to the next.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AdvanceRule {
    /// Advance after this many epochs in the stage at the latest (0: no limit).
    pub max_epochs: usize,
    /// Advance earlier once the success rate over the last `window` episodes is at least
    /// this (disabled when absent), but not before `min_epochs`.
    pub success_rate: Option<f32>,
    /// Episodes the success rate is measured over.
    pub window: usize,
    /// Epochs to spend in the stage before a success-rate advance.
    pub min_epochs: usize,
}

impl Default for AdvanceRule {
    fn default() -> Self {
        Self { max_epochs: 0, success_rate: None, window: 200, min_epochs: 0 }
    }
}

/// One curriculum stage.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StageConfig {
    /// Name shown in logs.
    pub name: String,
    /// Scenario (shipped name or file).
    pub scenario: String,
    /// More scenarios trained beside `scenario` in this stage, in equal shares (see
    /// [`RunConfig::mix`]).
    #[serde(default)]
    pub mix: Vec<String>,
    /// Task values changed in this stage, by dotted key (`reward.goal: 40`).
    #[serde(default)]
    pub task: std::collections::BTreeMap<String, Value>,
    /// When to move on (ignored for the last stage).
    #[serde(default)]
    pub advance: AdvanceRule,
}

/// Periodic evaluation on scenes the policy did not train on.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EvalConfig {
    /// Scenario (with a generator, every episode is a new scene).
    pub scenario: String,
    /// More scenarios evaluated beside `scenario`, shared out as in training
    /// ([`RunConfig::mix`]): with `n` robots, environment `i` drives robot `i % n` in scenario
    /// `(i / n) % (1 + mix.len())`. One success rate pools them, so that the checkpoint chosen
    /// on this evaluation (`select: scenario`) is good on unseen scenes of every training
    /// world, not of the first alone. `envs` a multiple of the pairs gives each an equal share.
    pub mix: Vec<String>,
    /// Episodes per evaluation.
    pub episodes: usize,
    /// Environments evaluated in parallel (divides `episodes`).
    pub envs: usize,
    /// Evaluate every this many epochs (0: only at the end).
    pub every: usize,
    /// Stop the run once a periodic evaluation reaches this success rate (absent: run all
    /// `max_epochs`). The final test still runs, on fresh episodes.
    pub stop_at_success: Option<f32>,
    /// Held-out scenarios (hand-built rooms no training scenario samples, such as the
    /// `heldout-static` suite's) evaluated beside `scenario` at every evaluation; when given,
    /// the best checkpoint is the one with the highest success over them. `SET#*` stands for
    /// every world of a BARN set (`barn#*`: the 250 shipped worlds).
    pub heldout: Vec<String>,
    /// Episodes per held-out scenario and evaluation (default 20).
    pub heldout_episodes: usize,
    /// Which evaluation picks the best checkpoint: `heldout` (the default; `scenario` when
    /// there are no held-out scenarios), `scenario`, which keeps the held-out rooms for
    /// measuring alone (no selection bias on them), or `last`: no pick, the run's last policy.
    pub select: Selection,
}

/// Which evaluation picks the best checkpoint.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Selection {
    /// The held-out scenarios, when there are any.
    #[default]
    Heldout,
    /// The evaluation scenario.
    Scenario,
    /// None: the policy of the last epoch. The evaluations only measure. Picking the highest
    /// of many evaluations picks their noise as well as the policy (the winner's curse), and
    /// a schedule that ends on a settled policy (`lr_schedule: linear`) has nothing to pick
    /// from.
    Last,
}

impl EvalConfig {
    /// The scenarios evaluated: `scenario`, then `mix`.
    pub fn scenarios(&self) -> impl Iterator<Item = &String> {
        std::iter::once(&self.scenario).chain(&self.mix)
    }
}

impl Default for EvalConfig {
    fn default() -> Self {
        Self {
            scenario: "random-static".into(),
            mix: Vec::new(),
            episodes: 200,
            envs: 50,
            every: 20,
            stop_at_success: None,
            heldout: Vec::new(),
            heldout_episodes: 20,
            select: Selection::Heldout,
        }
    }
}

/// A training run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RunConfig {
    /// Run name.
    pub name: String,
    /// Run seed.
    pub seed: u64,
    /// Robot (shipped name or file).
    pub robot: String,
    /// Training scenario when there is no curriculum.
    pub scenario: String,
    /// More scenarios trained beside `scenario` when there is no curriculum, in equal shares:
    /// with `n` robots, environment `i` draws scenario `(i / n) % (1 + mix.len())` of
    /// `[scenario, mix...]` (static rooms beside rooms with traffic, say), so that one policy
    /// keeps both skills rather than trading one for the other stage by stage.
    pub mix: Vec<String>,
    /// Robots trained together, environment `i` driving `robots[i % n]` (in training and in
    /// evaluations), so that one policy learns to drive them all; empty (the default): `robot`
    /// alone. Their observations must have one length.
    pub robots: Vec<String>,
    /// The task.
    pub task: TaskConfig,
    /// The network.
    pub network: NetworkConfig,
    /// PPO.
    pub train: PpoConfig,
    /// Curriculum stages, in order (empty: train on `scenario` throughout).
    pub curriculum: Vec<StageConfig>,
    /// Automatic curriculum: a difficulty level per environment, moved by its episodes'
    /// outcomes (absent: every episode at the scenario's full difficulty).
    pub auto_curriculum: Option<AutoCurriculum>,
    /// Evaluation.
    pub eval: EvalConfig,
}

/// An automatic curriculum, as Isaac Lab moves terrain levels: each training environment
/// has a difficulty level; a success moves it one level up, a collision or time-out one down,
/// and a success on the top level sends it to a random level. Level `k` of `levels` draws the
/// scenario at difficulty `k / (levels - 1)` (`ScenarioSpec::at_difficulty`: fewer, smaller
/// challenges at 0; the scenario as written at the top). Evaluations run at full difficulty.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AutoCurriculum {
    /// Number of levels (default 10).
    pub levels: usize,
    /// Environments start on a level drawn from `0..=start_max` (default 3).
    pub start_max: usize,
}

impl Default for AutoCurriculum {
    fn default() -> Self {
        Self { levels: 10, start_max: 3 }
    }
}

impl Default for RunConfig {
    fn default() -> Self {
        Self {
            name: "run".into(),
            seed: 0,
            robot: "jetbot".into(),
            scenario: "random-static".into(),
            mix: Vec::new(),
            robots: Vec::new(),
            task: TaskConfig::default(),
            network: NetworkConfig::default(),
            train: PpoConfig::default(),
            curriculum: Vec::new(),
            auto_curriculum: None,
            eval: EvalConfig::default(),
        }
    }
}

impl Validate for RunConfig {
    fn validate(&self) -> Result<(), Invalid> {
        self.task.validate().map_err(|e| e.under("task"))?;
        self.network.check().map_err(|(k, e)| Invalid::new(format!("network.{k}"), e))?;
        let t = &self.train;
        let ints = [
            ("train.num_actors", t.num_actors, 1, 65_536),
            ("train.horizon_length", t.horizon_length, 1, 100_000),
            ("train.minibatch_size", t.minibatch_size, 1, 10_000_000),
            ("train.mini_epochs", t.mini_epochs, 1, 1000),
            ("train.seq_len", t.seq_len, 1, 10_000),
            ("train.max_epochs", t.max_epochs, 1, 100_000_000),
            ("train.threads", t.threads, 0, 1024),
            ("eval.episodes", self.eval.episodes, 1, 1_000_000),
            ("eval.envs", self.eval.envs, 1, 65_536),
            ("eval.heldout_episodes", self.eval.heldout_episodes, 1, 65_536),
        ];
        for (k, v, lo, hi) in ints {
            if !(lo..=hi).contains(&v) {
                return Err(Invalid::new(k, format!("an integer in [{lo}, {hi}], got {v}")));
            }
        }
        if !self.robots.is_empty() && !self.robots.contains(&self.robot) {
            return Err(Invalid::new(
                "robot",
                format!("one of `robots` ({}): the contract's scan is this robot's", self.robots.join(", ")),
            ));
        }
        // Every scenario-robot pair needs an environment, or a mixed scenario is never trained.
        let robots = self.robots.len().max(1);
        let pairs = std::iter::once(self.mix.len())
            .chain(self.curriculum.iter().map(|s| s.mix.len()))
            .map(|m| (1 + m) * robots)
            .max()
            .unwrap_or(1);
        if t.num_actors < pairs {
            return Err(Invalid::new(
                "train.num_actors",
                format!("at least one environment per scenario and robot ({pairs}), got {}", t.num_actors),
            ));
        }
        let batch = t.num_actors * t.horizon_length;
        if batch % t.minibatch_size != 0 {
            return Err(Invalid::new(
                "train.minibatch_size",
                format!("a divisor of num_actors * horizon_length = {batch}, got {}", t.minibatch_size),
            ));
        }
        if let Some(a) = &self.auto_curriculum {
            if !(2..=1000).contains(&a.levels) {
                return Err(Invalid::new(
                    "auto_curriculum.levels",
                    format!("an integer in [2, 1000], got {}", a.levels),
                ));
            }
            if a.start_max >= a.levels {
                return Err(Invalid::new(
                    "auto_curriculum.start_max",
                    format!("a level below `levels` ({}), got {}", a.levels, a.start_max),
                ));
            }
        }
        if self.network.is_recurrent() {
            if t.horizon_length % t.seq_len != 0 {
                return Err(Invalid::new("train.seq_len", "a divisor of horizon_length"));
            }
            if t.minibatch_size % t.seq_len != 0 {
                return Err(Invalid::new("train.minibatch_size", "a multiple of seq_len for an LSTM policy"));
            }
        }
        // The scan and the action range are checked per robot and stage when training starts.
        if t.mirror && self.network.critic_movers > 0 {
            return Err(Invalid::new(
                "train.mirror",
                "false with a privileged critic (network.critic_movers): its values are not mirrored",
            ));
        }
        if t.mirror && self.network.is_recurrent() {
            return Err(Invalid::new("train.mirror", "false for a recurrent network (its state cannot be mirrored)"));
        }
        if let Some(k) = &t.teacher {
            if k.controller != "dwa" {
                return Err(Invalid::new("train.teacher.controller", format!("dwa, got `{}`", k.controller)));
            }
            check_range("train.teacher.weight", k.weight, 0.0, 1000.0)?;
            check_range("train.teacher.final_weight", k.final_weight, 0.0, 1000.0)?;
            check_range("train.teacher.share", k.share, 1e-6, 1.0)?;
        }
        if self.eval.episodes % self.eval.envs != 0 {
            return Err(Invalid::new("eval.envs", "a divisor of eval.episodes"));
        }
        check_range("train.gamma", t.gamma, 0.0, 1.0)?;
        check_range("train.tau", t.tau, 0.0, 1.0)?;
        check_range("train.learning_rate", t.learning_rate, 1e-8, 1.0)?;
        check_positive("train.kl_threshold", t.kl_threshold)?;
        check_range("train.e_clip", t.e_clip, 0.0, 1.0)?;
        check_positive("train.grad_norm", t.grad_norm)?;
        check_range("train.critic_coef", t.critic_coef, 0.0, 1000.0)?;
        check_range("train.entropy_coef", t.entropy_coef, -1.0, 1.0)?;
        check_range("train.bounds_loss_coef", t.bounds_loss_coef, 0.0, 1000.0)?;
        if let Some(m) = t.max_log_std {
            let ends = match m {
                LogStdCeiling::Fixed(c) => [c, c],
                LogStdCeiling::Linear(r) => r,
            };
            for c in ends {
                check_range("train.max_log_std", c, -5.0, 2.0)?;
            }
        }
        if let Some(r) = self.eval.stop_at_success {
            check_range("eval.stop_at_success", r, 0.0, 1.0)?;
            if self.eval.every == 0 {
                return Err(Invalid::new("eval.every", "at least 1 when eval.stop_at_success is set"));
            }
        }
        for (i, s) in self.curriculum.iter().enumerate() {
            if let Some(r) = s.advance.success_rate {
                check_range(&format!("curriculum[{i}].advance.success_rate"), r, 0.0, 1.0)?;
            }
            if s.advance.window == 0 {
                return Err(Invalid::new(format!("curriculum[{i}].advance.window"), "at least 1"));
            }
        }
        Ok(())
    }
}

/// Sets `key` (dotted path, `a.b.c`) in a YAML mapping to `value`, creating maps on the way.
pub fn set_dotted(root: &mut Value, key: &str, value: Value) -> Result<(), String> {
    let mut node = root;
    let parts: Vec<&str> = key.split('.').collect();
    if parts.iter().any(|p| p.is_empty()) {
        return Err(format!("`{key}` is not a dotted key path"));
    }
    for (i, part) in parts.iter().enumerate() {
        let Value::Mapping(map) = node else {
            return Err(format!("`{}` is not a section, cannot set `{key}`", parts[..i].join(".")));
        };
        let k = Value::String((*part).to_string());
        if i + 1 == parts.len() {
            map.insert(k, value);
            return Ok(());
        }
        node = map.entry(k).or_insert_with(|| Value::Mapping(Default::default()));
    }
    unreachable!("the loop returns at the last part")
}

/// Builds a run config: a preset or file (default: the built-in default), then each
/// `KEY=VALUE` override (VALUE is YAML: `3`, `0.5`, `true`, `[64, 64]`, `name`).
pub fn load_run_config(config: Option<&str>, overrides: &[String]) -> Result<RunConfig, ConfigError> {
    let cfg: RunConfig = preset_or_file("training config", TRAIN_PRESETS, config.unwrap_or(DEFAULT_CONFIG))?;
    let pairs = overrides
        .iter()
        .map(|o| {
            let (k, v) = o.split_once('=').ok_or_else(|| ConfigError::Invalid {
                file: "--set".into(),
                key: o.clone(),
                expected: "KEY=VALUE".into(),
            })?;
            let v: Value = serde_norway::from_str(v)
                .map_err(|e| ConfigError::Parse { file: "--set".into(), message: format!("{k}: {e}") })?;
            Ok((k.trim().to_string(), v))
        })
        .collect::<Result<Vec<_>, ConfigError>>()?;
    with_overrides(&cfg, pairs, "--set", "")
}

/// Applies a stage's dotted task overrides to a task config.
pub fn apply_task_overrides(
    task: &TaskConfig,
    overrides: &std::collections::BTreeMap<String, Value>,
    stage: &str,
) -> Result<TaskConfig, ConfigError> {
    let pairs = overrides.iter().map(|(k, v)| (k.clone(), v.clone()));
    with_overrides(task, pairs, &format!("<curriculum stage {stage}>"), "task.")
}

/// `value` with each `(dotted key, value)` set, read back (so unknown keys and bad values are
/// rejected as in a file) and validated; errors name `file` and the key (after `prefix`).
fn with_overrides<T: Serialize + DeserializeOwned + Validate + Clone>(
    value: &T,
    overrides: impl IntoIterator<Item = (String, Value)>,
    file: &str,
    prefix: &str,
) -> Result<T, ConfigError> {
    let mut tree = rlnav_sim::config::to_yaml_value(value);
    let mut changed = false;
    for (k, v) in overrides {
        set_dotted(&mut tree, &k, v).map_err(|e| ConfigError::Invalid {
            file: file.into(),
            key: format!("{prefix}{k}"),
            expected: e,
        })?;
        changed = true;
    }
    if !changed {
        return Ok(value.clone());
    }
    let text = serde_norway::to_string(&tree).expect("a YAML value serialises");
    rlnav_sim::config::from_yaml_str(file, &text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_parse_and_overrides_apply() {
        for (name, _) in TRAIN_PRESETS {
            load_run_config(Some(name), &[]).unwrap();
        }
        let c = load_run_config(
            None,
            &["train.max_epochs=3".into(), "task.reward.goal=40".into(), "network.hidden=[32, 32]".into()],
        )
        .unwrap();
        assert_eq!(c.train.max_epochs, 3);
        assert_eq!(c.task.reward.goal, 40.0);
        assert_eq!(c.network.hidden, vec![32, 32]);
    }

    /// `train.max_log_std` reads as a number or a `[start, end]` pair; the pair moves
    /// linearly over the run; a bad value names the key.
    #[test]
    fn log_std_ceilings_parse_and_move() {
        let c = load_run_config(None, &["train.max_log_std=-1".into()]).unwrap();
        assert_eq!(c.train.max_log_std, Some(LogStdCeiling::Fixed(-1.0)));
        let set = ["train.max_log_std=[0.2, -1.2]".into(), "train.max_epochs=11".into()];
        let c = load_run_config(None, &set).unwrap();
        let ceiling = c.train.max_log_std.unwrap();
        assert_eq!((ceiling.at(0, 11), ceiling.at(10, 11)), (0.2, -1.2));
        assert!((ceiling.at(5, 11) + 0.5).abs() < 1e-6);
        for bad in ["[0, 9]", "[1, 2, 3]", "high"] {
            let e = load_run_config(None, &[format!("train.max_log_std={bad}")]).unwrap_err().to_string();
            assert!(e.contains("max_log_std"), "{bad}: {e}");
        }
    }

    #[test]
    fn stage_task_overrides() {
        let mut o = std::collections::BTreeMap::new();
        o.insert("reward.goal".to_string(), Value::from(40.0));
        let t = apply_task_overrides(&TaskConfig::default(), &o, "s").unwrap();
        assert_eq!(t.reward.goal, 40.0);
        o.insert("reward.gaol".to_string(), Value::from(1.0));
        let e = apply_task_overrides(&TaskConfig::default(), &o, "s").unwrap_err().to_string();
        assert!(e.contains("<curriculum stage s>") && e.contains("unknown field `gaol`"), "{e}");
        o.remove("reward.gaol");
        o.insert("goal_tolerance".to_string(), Value::from(-1.0));
        let e = apply_task_overrides(&TaskConfig::default(), &o, "s").unwrap_err().to_string();
        assert!(e.contains("goal_tolerance"), "{e}");
    }

    #[test]
    fn bad_overrides_name_the_key() {
        let e = load_run_config(None, &["train.max_epohs=3".into()]).unwrap_err().to_string();
        assert!(e.contains("unknown field `max_epohs`"), "{e}");
        let e = load_run_config(None, &["train.gamma=2".into()]).unwrap_err().to_string();
        assert!(e.contains("train.gamma") && e.contains("[0, 1]"), "{e}");
        let e = load_run_config(None, &["train.minibatch_size=1000".into()]).unwrap_err().to_string();
        assert!(e.contains("train.minibatch_size") && e.contains("divisor"), "{e}");
        let e = load_run_config(None, &["nonsense".into()]).unwrap_err().to_string();
        assert!(e.contains("KEY=VALUE"), "{e}");
        let e = load_run_config(None, &["mix=[a, b, c]".into(), "train.num_actors=3".into()]).unwrap_err().to_string();
        assert!(e.contains("train.num_actors") && e.contains("scenario and robot (4)"), "{e}");
        let e = load_run_config(Some("no-such-config"), &[]).unwrap_err().to_string();
        assert!(e.contains("static-mlp"), "{e}");
    }
}
