//! A training run: curriculum stages, epochs of rollout + update, periodic evaluation on
//! unseen scenes, checkpoints, and the run folder's logs.

use crate::config::{RunConfig, StageConfig, apply_task_overrides};
use crate::eval::{EvalSummary, evaluate};
use crate::ppo::{Ppo, UpdateStats};
use burn::optim::AdamConfig;
use burn::store::{BurnpackStore, ModuleSnapshot};
use rlnav_policy::{ActorCritic, RunningMeanStd, training_device};
use rlnav_sim::RobotSpec;
use rlnav_sim::config::ConfigError;
use rlnav_sim::observation::ObservationMirror;
use rlnav_sim::scenario::ScenarioSpec;
use rlnav_sim::task::{EnvSetup, EpisodeStats, Outcome, SimError, TaskConfig};
use rlnav_sim::vec_env::VecEnv;
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;
use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

/// Errors of a training run.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    /// Configuration.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// Simulation.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// Files of the run folder.
    #[error("{path}: {message}")]
    Io {
        /// The file or folder.
        path: String,
        /// What went wrong.
        message: String,
    },
    /// `--resume` was given something that is not a run folder, or an incompatible one.
    #[error("cannot resume from {path}: {message}")]
    Resume {
        /// The folder.
        path: String,
        /// Why.
        message: String,
    },
}

fn io_err(path: &Path, e: impl std::fmt::Display) -> TrainError {
    TrainError::Io { path: path.display().to_string(), message: e.to_string() }
}

/// What happened in one epoch, for progress displays and logs.
#[derive(Clone, Debug, Serialize)]
pub struct EpochReport {
    /// Epoch number (1-based).
    pub epoch: usize,
    /// Epochs planned.
    pub max_epochs: usize,
    /// Environment steps so far.
    pub env_steps: u64,
    /// Wall-clock seconds so far (over all sessions of a resumed run).
    pub wall_s: f64,
    /// Environment steps per second in this epoch (rollout and update).
    pub steps_per_s: f64,
    /// Mean return of episodes finished this epoch.
    pub mean_return: f32,
    /// Mean length (steps) of episodes finished this epoch.
    pub mean_length: f32,
    /// Outcome rates of episodes finished this epoch.
    pub success_rate: f32,
    /// See `success_rate`.
    pub collision_rate: f32,
    /// See `success_rate`.
    pub timeout_rate: f32,
    /// Episodes finished this epoch.
    pub episodes: usize,
    /// Curriculum stage (0-based) and its name.
    pub stage: usize,
    /// Stage name.
    pub stage_name: String,
    /// The update's statistics.
    #[serde(skip)]
    pub update: UpdateStats,
    /// Seconds spent collecting experience this epoch (simulation and inference).
    pub rollout_s: f64,
    /// Of which stepping the simulator.
    pub sim_s: f64,
    /// Seconds spent updating the network this epoch.
    pub update_s: f64,
    /// Evaluation, when one ran after this epoch.
    pub eval: Option<EvalSummary>,
    /// Evaluation on the held-out scenarios (pooled), when one ran after this epoch.
    pub heldout: Option<EvalSummary>,
    /// Mean difficulty of the training environments' levels in [0, 1] under an automatic
    /// curriculum.
    pub difficulty: Option<f32>,
}

/// When the periodic evaluation first reached a success rate: the cost of getting there.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Milestone {
    /// The success rate that was reached (what the evaluation measured, at least the target).
    pub success_rate: f32,
    /// Epoch after which that evaluation ran.
    pub epoch: usize,
    /// Environment steps of training by then.
    pub env_steps: u64,
    /// Wall-clock seconds by then, the evaluation included.
    pub wall_s: f64,
}

/// The run's final record (`summary.json`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Summary {
    /// Run name.
    pub name: String,
    /// Epochs completed.
    pub iterations: usize,
    /// Environment steps.
    pub env_steps: u64,
    /// Wall-clock seconds.
    pub wall_s: f64,
    /// Environment steps per second, overall.
    pub steps_per_s: f64,
    /// Whether the run was stopped before `max_epochs` (Ctrl-C).
    pub interrupted: bool,
    /// The final test: the best checkpoint (chosen by the periodic evaluations; the last one
    /// with `eval.select: last`) evaluated on `eval.episodes` fresh episodes, drawn from a seed
    /// neither training nor model selection used.
    pub final_eval: Option<EvalSummary>,
    /// Epoch of the checkpoint the final test ran on.
    pub final_epoch: usize,
    /// The periodic evaluation after the last epoch (on the selection seed).
    pub last_epoch_eval: Option<EvalSummary>,
    /// Scenario of the final evaluation (`eval.scenario`, with `eval.mix` after ` + `).
    pub eval_scenario: String,
    /// Best success rate of the evaluation that selects checkpoints (`eval.select`).
    pub best_success_rate: f32,
    /// Epoch of the best evaluation.
    pub best_epoch: usize,
    /// When a periodic evaluation first reached 90% success (absent: never).
    pub first_90: Option<Milestone>,
    /// When a periodic evaluation first reached 95% success (absent: never).
    pub first_95: Option<Milestone>,
    /// Whether the run ended early because an evaluation reached `eval.stop_at_success`.
    pub reached_stop_target: bool,
    /// The held-out scenarios (`eval.heldout`), if any.
    #[serde(default)]
    pub heldout_scenarios: Vec<String>,
    /// The chosen checkpoint on the held-out scenarios, on the final test's seed (other
    /// starts, goals and headings than selection saw, in the same rooms).
    #[serde(default)]
    pub final_heldout: Option<EvalSummary>,
}

/// Trainer state saved with each checkpoint.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct TrainerState {
    epoch: usize,
    env_steps: u64,
    wall_s: f64,
    learning_rate: f32,
    stage: usize,
    stage_epochs: usize,
    obs_norm: RunningMeanStd,
    value_norm: RunningMeanStd,
    /// A privileged critic's input statistics (absent without one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    privileged_norm: Option<RunningMeanStd>,
    best_success_rate: f32,
    best_epoch: usize,
    #[serde(default)]
    first_90: Option<Milestone>,
    #[serde(default)]
    first_95: Option<Milestone>,
}

/// Options of [`train`].
pub struct TrainOptions {
    /// Run folder (created; must not already hold a run unless resuming).
    pub out: PathBuf,
    /// Continue the run in `out` from its last checkpoint.
    pub resume: bool,
    /// Set to stop after the current epoch (Ctrl-C); a checkpoint is written first.
    pub stop: Arc<AtomicBool>,
}

fn stages(cfg: &RunConfig) -> Vec<StageConfig> {
    if cfg.curriculum.is_empty() {
        vec![StageConfig {
            name: "main".into(),
            scenario: cfg.scenario.clone(),
            mix: cfg.mix.clone(),
            task: Default::default(),
            advance: Default::default(),
        }]
    } else {
        cfg.curriculum.clone()
    }
}

/// The scenario set up for each of the run's robots (`robots`, or `robot` alone), with
/// `levels` difficulty levels when given.
fn env_setup(
    cfg: &RunConfig,
    scenario: &str,
    task: TaskConfig,
    levels: Option<usize>,
) -> Result<Vec<Arc<EnvSetup>>, TrainError> {
    setups_for(cfg, ScenarioSpec::load(scenario)?, task, levels)
}

/// [`env_setup`] for a scenario already loaded.
fn setups_for(
    cfg: &RunConfig,
    spec: ScenarioSpec,
    task: TaskConfig,
    levels: Option<usize>,
) -> Result<Vec<Arc<EnvSetup>>, TrainError> {
    let names = if cfg.robots.is_empty() { std::slice::from_ref(&cfg.robot) } else { cfg.robots.as_slice() };
    names
        .iter()
        .map(|r| {
            let setup = EnvSetup::new(spec.clone(), RobotSpec::load(r)?, task.clone())?;
            Ok(Arc::new(match levels {
                Some(n) => setup.with_difficulty_levels(n)?,
                None => setup,
            }))
        })
        .collect()
}

/// The evaluation's setups: `eval.scenario`, then `eval.mix`, each for every robot (the
/// order [`stage_setup`] gives a stage's, so that environments share them out alike).
fn eval_setups(cfg: &RunConfig) -> Result<Vec<Arc<EnvSetup>>, TrainError> {
    scenarios_setups(cfg, cfg.eval.scenarios(), &cfg.task, None)
}

/// Every robot's setup for each of `scenarios` in turn (scenario-major).
fn scenarios_setups<'a>(
    cfg: &RunConfig,
    scenarios: impl IntoIterator<Item = &'a String>,
    task: &TaskConfig,
    levels: Option<usize>,
) -> Result<Vec<Arc<EnvSetup>>, TrainError> {
    let mut setups = Vec::new();
    for scenario in scenarios {
        setups.extend(env_setup(cfg, scenario, task.clone(), levels)?);
    }
    Ok(setups)
}

/// What the evaluation runs on, for logs: `eval.scenario`, and `eval.mix` joined by ` + `.
pub fn eval_scenarios(cfg: &RunConfig) -> String {
    cfg.eval.scenarios().map(String::as_str).collect::<Vec<_>>().join(" + ")
}

/// A training stage's setups, with difficulty levels under an automatic curriculum: each of
/// the stage's scenarios (`scenario`, then `mix`) for each robot, in that order, so that
/// environment `i` takes setup `i % len` (`VecEnv::new_mixed`) and every pair gets an equal
/// share.
fn stage_setup(cfg: &RunConfig, stage: &StageConfig) -> Result<Vec<Arc<EnvSetup>>, TrainError> {
    let task = apply_task_overrides(&cfg.task, &stage.task, &stage.name)?;
    let levels = cfg.auto_curriculum.as_ref().map(|a| a.levels);
    scenarios_setups(cfg, std::iter::once(&stage.scenario).chain(&stage.mix), &task, levels)
}

/// The one observation mirror of every stage's setups (`train.mirror`): each robot's scan must
/// mirror, each stage's turn range be symmetric, and all agree on where each value goes.
fn mirror_of(setups: &[Vec<Arc<EnvSetup>>]) -> Result<ObservationMirror, TrainError> {
    let invalid = |setup: &EnvSetup, expected: String| {
        TrainError::Config(ConfigError::Invalid {
            file: format!("<robot {}>", setup.robot.name),
            key: "train.mirror".into(),
            expected,
        })
    };
    let mut found: Option<ObservationMirror> = None;
    for setup in setups.iter().flatten() {
        let [lo, hi] = setup.task.action.angular;
        if (lo + hi).abs() > 1e-6 {
            return Err(invalid(
                setup,
                format!(
                    "task.action.angular symmetric about 0 (a turn mirrors to the opposite turn), got [{lo}, {hi}]"
                ),
            ));
        }
        let m = setup
            .task
            .observation
            .mirror(&setup.robot.lidar)
            .map_err(|e| invalid(setup, format!("{}: {}", e.key, e.expected)))?;
        match &found {
            Some(f) if *f != m => {
                return Err(invalid(setup, "robots whose scans mirror alike (bins paired the same way)".into()));
            }
            Some(_) => {}
            None => found = Some(m),
        }
    }
    Ok(found.expect("a run has at least one setup"))
}

/// The hand-written learner's Adam state in a checkpoint (burn's learner writes `optimizer.bpk`).
const ADAM_FILE: &str = "adam.bin";

/// Reads a checkpoint's trainer state.
fn read_state(ck: &Path) -> Result<TrainerState, TrainError> {
    let path = ck.join("state.json");
    let text = fs::read_to_string(&path).map_err(|e| io_err(&path, e))?;
    serde_json::from_str(&text)
        .map_err(|e| TrainError::Resume { path: path.display().to_string(), message: e.to_string() })
}

/// Puts a checkpoint's network, normalisers and learning rate (and, when `optimizer`, the
/// Adam state) into `ppo`.
fn restore_checkpoint(
    ppo: &mut Ppo,
    cfg: &RunConfig,
    ck: &Path,
    st: &TrainerState,
    optimizer: bool,
) -> Result<(), TrainError> {
    let model = load_model(cfg, ck, st.obs_norm.dim(), &training_device().autodiff())?;
    let fresh = AdamConfig::new().with_epsilon(1e-8).init();
    let optim = if optimizer && ppo.fast_adam().is_none() {
        let path = ck.join("optimizer.bpk");
        fresh
            .load(&path)
            .map_err(|e| TrainError::Resume { path: path.display().to_string(), message: e.to_string() })?
    } else {
        fresh
    };
    ppo.restore(model, optim, st.learning_rate);
    if optimizer && ppo.fast_adam().is_some() {
        let path = ck.join(ADAM_FILE);
        let resume_err = |message: String| TrainError::Resume { path: path.display().to_string(), message };
        let bytes = fs::read(&path).map_err(|e| {
            resume_err(if ck.join("optimizer.bpk").is_file() {
                "missing: this checkpoint was written by burn's learner; resume with --set train.learner=burn".into()
            } else {
                e.to_string()
            })
        })?;
        let adam = crate::fast::AdamState::from_bytes(&bytes).map_err(resume_err)?;
        ppo.restore_adam(adam).map_err(resume_err)?;
    }
    ppo.obs_norm = st.obs_norm.clone();
    ppo.value_norm = st.value_norm.clone();
    if let Some(p) = &st.privileged_norm {
        ppo.privileged_norm = p.clone();
    }
    Ok(())
}

/// Evaluation seeds are far from every training environment's stream.
fn eval_seed(seed: u64) -> u64 {
    seed ^ 0xE7A1_5EED_0000_0000
}

/// The final test's seed, distinct from the evaluations that select the best checkpoint.
fn test_seed(seed: u64) -> u64 {
    seed ^ 0x7E57_5EED_0000_0000
}

/// Writes `write(tmp)` into a fresh folder, then swaps it in for `dir` (no half-written
/// checkpoint is ever left under `dir`'s name).
fn atomic_dir(dir: &Path, write: impl FnOnce(&Path) -> Result<(), TrainError>) -> Result<(), TrainError> {
    let tmp = dir.with_extension("tmp");
    let old = dir.with_extension("old");
    let _ = fs::remove_dir_all(&tmp);
    fs::create_dir_all(&tmp).map_err(|e| io_err(&tmp, e))?;
    write(&tmp)?;
    let _ = fs::remove_dir_all(&old);
    if dir.exists() {
        fs::rename(dir, &old).map_err(|e| io_err(dir, e))?;
    }
    fs::rename(&tmp, dir).map_err(|e| io_err(dir, e))?;
    let _ = fs::remove_dir_all(&old);
    Ok(())
}

fn save_checkpoint(dir: &Path, ppo: &Ppo, state: &TrainerState) -> Result<(), TrainError> {
    atomic_dir(dir, |tmp| {
        let mut store = BurnpackStore::from_file(tmp.join("model.bpk")).overwrite(true);
        ppo.model().save_into(&mut store).map_err(|e| io_err(&tmp.join("model.bpk"), e))?;
        match ppo.fast_adam() {
            Some(adam) => {
                fs::write(tmp.join(ADAM_FILE), adam.to_bytes()).map_err(|e| io_err(&tmp.join(ADAM_FILE), e))?
            }
            None => {
                ppo.optimizer().save(tmp.join("optimizer.bpk")).map_err(|e| io_err(&tmp.join("optimizer.bpk"), e))?
            }
        }
        let json = serde_json::to_string_pretty(state).expect("state serialises");
        fs::write(tmp.join("state.json"), json).map_err(|e| io_err(&tmp.join("state.json"), e))
    })
}

/// Loads a network saved by a run with configuration `cfg` from checkpoint folder `dir`.
pub fn load_model(
    cfg: &RunConfig,
    dir: &Path,
    obs_dim: usize,
    device: &burn::prelude::Device,
) -> Result<ActorCritic, TrainError> {
    let mut model = ActorCritic::seeded(&cfg.network, obs_dim, 2, device, cfg.seed);
    let path = dir.join("model.bpk");
    let mut store = BurnpackStore::from_file(&path);
    let mismatch = |detail: String| TrainError::Resume {
        path: path.display().to_string(),
        message: format!(
            "the checkpoint's network does not match the configured one (hidden {:?}, lstm {}): {detail}",
            cfg.network.hidden, cfg.network.lstm_units
        ),
    };
    if !path.is_file() {
        return Err(TrainError::Resume { path: path.display().to_string(), message: "no such checkpoint file".into() });
    }
    let result = model.load_from(&mut store).map_err(|e| mismatch(e.to_string()))?;
    if !result.is_success() || !result.missing.is_empty() || !result.unused.is_empty() {
        return Err(mismatch(format!(
            "{} errors, missing {:?}, unexpected {:?}",
            result.errors.len(),
            result.missing.iter().map(|m| &m.0).collect::<Vec<_>>(),
            result.unused
        )));
    }
    Ok(model)
}

/// Success rates of the last `window` episodes.
struct Window {
    outcomes: VecDeque<bool>,
    size: usize,
}

impl Window {
    fn push(&mut self, success: bool) {
        self.outcomes.push_back(success);
        while self.outcomes.len() > self.size {
            self.outcomes.pop_front();
        }
    }
    fn rate(&self) -> Option<f32> {
        (self.outcomes.len() == self.size)
            .then(|| self.outcomes.iter().filter(|s| **s).count() as f32 / self.size as f32)
    }
}

const CSV_HEADER: &str = "epoch,env_steps,wall_s,steps_per_s,mean_return,mean_length,success_rate,collision_rate,timeout_rate,episodes,policy_loss,value_loss,kl,learning_rate,entropy,clip_fraction,stage,eval_success_rate,eval_collision_rate,eval_timeout_rate,sim_s,rollout_s,update_s,heldout_success_rate,heldout_collision_rate,difficulty,teacher_loss";

fn csv_row(r: &EpochReport) -> String {
    let u = &r.update;
    let (es, ec, et) = match &r.eval {
        Some(e) => (e.success_rate.to_string(), e.collision_rate.to_string(), e.timeout_rate.to_string()),
        None => (String::new(), String::new(), String::new()),
    };
    let (hs, hc) = match &r.heldout {
        Some(e) => (e.success_rate.to_string(), e.collision_rate.to_string()),
        None => (String::new(), String::new()),
    };
    let difficulty = r.difficulty.map(|d| format!("{d:.4}")).unwrap_or_default();
    format!(
        "{},{},{:.3},{:.1},{},{},{},{},{},{},{},{},{},{},{},{},{},{es},{ec},{et},{:.4},{:.4},{:.4},{hs},{hc},{difficulty},{}",
        r.epoch,
        r.env_steps,
        r.wall_s,
        r.steps_per_s,
        r.mean_return,
        r.mean_length,
        r.success_rate,
        r.collision_rate,
        r.timeout_rate,
        r.episodes,
        u.policy_loss,
        u.value_loss,
        u.kl,
        u.learning_rate,
        u.entropy,
        u.clip_fraction,
        r.stage,
        r.sim_s,
        r.rollout_s,
        r.update_s,
        u.teacher_loss
    )
}

/// Keeps metrics.csv's header and its rows up to `epoch` (the checkpoint's), rewriting the
/// file atomically when anything goes: rows a killed session wrote after its last checkpoint,
/// and a last line it left half-written. A row whose first column is not an epoch number is
/// an error naming its line.
fn trim_metrics(path: &Path, epoch: usize) -> Result<(), TrainError> {
    let text = fs::read_to_string(path).map_err(|e| io_err(path, e))?;
    let mut lines = text.split_inclusive('\n');
    let mut kept = String::with_capacity(text.len());
    match lines.next() {
        Some(header) if header.ends_with('\n') => kept.push_str(header),
        _ => return Err(io_err(path, "no header line")),
    }
    for (i, line) in lines.enumerate() {
        if !line.ends_with('\n') {
            break;
        }
        let row: usize =
            line.split(',').next().and_then(|e| e.trim().parse().ok()).ok_or_else(|| TrainError::Resume {
                path: format!("{}:{}", path.display(), i + 2),
                message: "expected a row starting with its epoch number".into(),
            })?;
        if row <= epoch {
            kept.push_str(line);
        }
    }
    if kept.len() == text.len() {
        return Ok(());
    }
    let tmp = path.with_extension("csv.tmp");
    fs::write(&tmp, &kept).map_err(|e| io_err(&tmp, e))?;
    fs::rename(&tmp, path).map_err(|e| io_err(path, e))
}

/// `base` if no run lives there yet, else the first free `base-2`, `base-3`, ... (so that
/// running the default command twice starts a second run instead of failing).
pub fn fresh_run_dir(base: &Path) -> PathBuf {
    if !base.join("config.yaml").exists() {
        return base.to_path_buf();
    }
    (2..)
        .map(|i| PathBuf::from(format!("{}-{i}", base.display())))
        .find(|p| !p.join("config.yaml").exists())
        .expect("some suffix is free")
}

/// Reads a run folder's resolved configuration.
pub fn read_run_config(dir: &Path) -> Result<RunConfig, TrainError> {
    let path = dir.join("config.yaml");
    if !path.is_file() || !dir.join("checkpoint").join("state.json").is_file() {
        return Err(TrainError::Resume {
            path: dir.display().to_string(),
            message: "not a run folder (needs config.yaml and checkpoint/state.json)".into(),
        });
    }
    Ok(rlnav_sim::config::from_yaml_file(&path)?)
}

/// Trains a policy as `cfg` says, writing the run folder `opts.out`. Calls `progress` after
/// every epoch.
pub fn train(
    cfg: &RunConfig,
    opts: &TrainOptions,
    progress: &mut dyn FnMut(&EpochReport),
) -> Result<Summary, TrainError> {
    let out = &opts.out;
    let stages = stages(cfg);
    let setups = stages.iter().map(|s| stage_setup(cfg, s)).collect::<Result<Vec<_>, _>>()?;
    let obs_dim = setups[0][0].obs_dim();
    if let Some(s) = setups.iter().flatten().find(|s| s.obs_dim() != obs_dim) {
        return Err(TrainError::Config(ConfigError::Invalid {
            file: "<curriculum>".into(),
            key: "curriculum".into(),
            expected: format!(
                "stages and robots with the same observation length ({obs_dim}), got {} ({})",
                s.obs_dim(),
                s.robot.name
            ),
        }));
    }
    let eval = eval_setups(cfg)?;
    let mut heldout = Vec::new();
    for name in &cfg.eval.heldout {
        for spec in rlnav_sim::barn::load_scenarios(name)? {
            heldout.push(setups_for(cfg, spec, cfg.task.clone(), None)?);
        }
    }
    // Every held-out scenario, one episode per environment (no bias to short episodes), pooled.
    let eval_heldout = |ppo: &Ppo, seed: u64| -> Result<Option<EvalSummary>, TrainError> {
        if heldout.is_empty() {
            return Ok(None);
        }
        let mut all = Vec::new();
        for setup in &heldout {
            let n = cfg.eval.heldout_episodes;
            all.extend(evaluate(ppo, setup, n, n, seed, cfg.train.threads, &mut |_| {})?.1);
        }
        Ok(Some(EvalSummary::of(&all)))
    };
    let mut ppo = Ppo::new(&cfg.train, &cfg.network, obs_dim, 2, training_device(), cfg.seed);
    if cfg.train.mirror {
        ppo.set_mirror(mirror_of(&setups)?);
    }

    let mut st = TrainerState {
        epoch: 0,
        env_steps: 0,
        wall_s: 0.0,
        learning_rate: cfg.train.learning_rate,
        stage: 0,
        stage_epochs: 0,
        obs_norm: RunningMeanStd::new(obs_dim),
        value_norm: RunningMeanStd::new(1),
        privileged_norm: None,
        best_success_rate: -1.0,
        best_epoch: 0,
        first_90: None,
        first_95: None,
    };
    if opts.resume {
        let saved = read_run_config(out)?;
        if saved.network != cfg.network {
            return Err(TrainError::Resume {
                path: out.display().to_string(),
                message: "the run's network configuration differs from the one given".into(),
            });
        }
        let ck = out.join("checkpoint");
        st = read_state(&ck)?;
        restore_checkpoint(&mut ppo, cfg, &ck, &st, true)?;
        // A session killed after its last checkpoint logged epochs that this one runs again.
        trim_metrics(&out.join("metrics.csv"), st.epoch)?;
        let tb_dir = out.join("tensorboard");
        crate::tensorboard::drop_events_after(&tb_dir, st.env_steps as i64).map_err(|e| io_err(&tb_dir, e))?;
        // A `best/` saved after the checkpoint comes from those epochs, and it replaced the best
        // the checkpoint knew of: the choice of the best starts afresh.
        let best = out.join("best");
        if best.join("state.json").is_file() && read_state(&best)?.epoch > st.epoch {
            fs::remove_dir_all(&best).map_err(|e| io_err(&best, e))?;
            st.best_success_rate = -1.0;
            st.best_epoch = 0;
        }
    } else {
        if out.join("config.yaml").exists() {
            return Err(TrainError::Io {
                path: out.display().to_string(),
                message: "already holds a run; choose another --out, or --resume it".into(),
            });
        }
        fs::create_dir_all(out).map_err(|e| io_err(out, e))?;
        fs::write(out.join("config.yaml"), rlnav_sim::config::to_yaml_string(cfg)).map_err(|e| io_err(out, e))?;
        fs::write(out.join("metrics.csv"), format!("{CSV_HEADER}\n")).map_err(|e| io_err(out, e))?;
    }
    let mut csv = fs::OpenOptions::new().append(true).open(out.join("metrics.csv")).map_err(|e| io_err(out, e))?;
    let tb_dir = out.join("tensorboard");
    let mut tb = crate::tensorboard::EventWriter::create(&tb_dir).map_err(|e| io_err(&tb_dir, e))?;

    let threads = cfg.train.threads;
    let env_for = |stage: usize, epoch: usize| -> Result<VecEnv, TrainError> {
        let seed = rlnav_sim::vec_env::env_seed(cfg.seed, epoch << 8 | stage);
        let mut env = VecEnv::new_mixed(&setups[stage], cfg.train.num_actors, seed, threads)?;
        if let Some(a) = &cfg.auto_curriculum {
            env.start_levels(a.start_max, seed ^ 0x1E7E_1500)?;
        }
        env.set_privileged(cfg.network.critic_movers);
        Ok(env)
    };
    let mut env = env_for(st.stage, st.epoch)?;
    let mut window = Window { outcomes: VecDeque::new(), size: stages[st.stage].advance.window };
    let session = Instant::now();
    let wall_before = st.wall_s;
    let mut episodes: Vec<EpisodeStats> = Vec::new();
    let mut last_eval = None;
    let mut interrupted = false;
    let mut reached_stop_target = false;

    while st.epoch < cfg.train.max_epochs && !reached_stop_target {
        if opts.stop.load(Ordering::Relaxed) {
            interrupted = true;
            break;
        }
        let t0 = Instant::now();
        ppo.reseed(cfg.seed, st.epoch as u64);
        ppo.schedule(st.epoch);
        ppo.set_teacher_epoch(st.epoch);
        episodes.clear();
        ppo.collect(&mut env, &mut episodes)?;
        let t1 = Instant::now();
        let update = ppo.update();
        let t2 = Instant::now();
        st.epoch += 1;
        st.stage_epochs += 1;
        let steps = (cfg.train.num_actors * cfg.train.horizon_length) as u64;
        st.env_steps += steps;
        st.wall_s = wall_before + session.elapsed().as_secs_f64();
        for e in &episodes {
            window.push(e.outcome == Outcome::Success);
        }
        let stats = EvalSummary::of(&episodes);
        let eval_now = (cfg.eval.every > 0 && st.epoch % cfg.eval.every == 0) || st.epoch == cfg.train.max_epochs;
        let eval_result = if eval_now {
            let (r, _) =
                evaluate(&ppo, &eval, cfg.eval.episodes, cfg.eval.envs, eval_seed(cfg.seed), threads, &mut |_| {})?;
            last_eval = Some(r);
            let reached = Milestone {
                success_rate: r.success_rate,
                epoch: st.epoch,
                env_steps: st.env_steps,
                wall_s: wall_before + session.elapsed().as_secs_f64(),
            };
            for (target, slot) in [(0.9, &mut st.first_90), (0.95, &mut st.first_95)] {
                if slot.is_none() && r.success_rate >= target {
                    *slot = Some(reached);
                }
            }
            reached_stop_target = cfg.eval.stop_at_success.is_some_and(|t| r.success_rate >= t);
            Some(r)
        } else {
            None
        };
        let heldout_result = if eval_now { eval_heldout(&ppo, eval_seed(cfg.seed))? } else { None };
        let report = EpochReport {
            epoch: st.epoch,
            max_epochs: cfg.train.max_epochs,
            env_steps: st.env_steps,
            wall_s: st.wall_s,
            steps_per_s: steps as f64 / (t2 - t0).as_secs_f64(),
            mean_return: stats.mean_return,
            mean_length: episodes.iter().map(|e| e.length as f32).sum::<f32>() / episodes.len().max(1) as f32,
            success_rate: stats.success_rate,
            collision_rate: stats.collision_rate,
            timeout_rate: stats.timeout_rate,
            episodes: episodes.len(),
            stage: st.stage,
            stage_name: stages[st.stage].name.clone(),
            update,
            rollout_s: (t1 - t0).as_secs_f64(),
            sim_s: ppo.sim_s,
            update_s: (t2 - t1).as_secs_f64(),
            eval: eval_result,
            heldout: heldout_result,
            difficulty: env.mean_difficulty(),
        };
        writeln!(csv, "{}", csv_row(&report)).map_err(|e| io_err(&out.join("metrics.csv"), e))?;
        let step = st.env_steps as i64;
        let mut scalars = vec![
            ("rewards/mean_return", report.mean_return),
            ("episodes/mean_length", report.mean_length),
            ("episodes/success_rate", report.success_rate),
            ("episodes/collision_rate", report.collision_rate),
            ("episodes/timeout_rate", report.timeout_rate),
            ("losses/policy", update.policy_loss),
            ("losses/value", update.value_loss),
            ("info/kl", update.kl),
            ("info/learning_rate", update.learning_rate),
            ("info/entropy", update.entropy),
            ("info/clip_fraction", update.clip_fraction),
            ("performance/steps_per_s", report.steps_per_s as f32),
            ("curriculum/stage", st.stage as f32),
        ];
        if let Some(d) = report.difficulty {
            scalars.push(("curriculum/difficulty", d));
        }
        if cfg.train.teacher.is_some() {
            scalars.extend([("losses/teacher", update.teacher_loss), ("info/teacher_weight", ppo.teacher_weight())]);
        }
        if let Some(e) = &report.eval {
            scalars.extend([("eval/success_rate", e.success_rate), ("eval/collision_rate", e.collision_rate)]);
        }
        if let Some(e) = &report.heldout {
            scalars.extend([
                ("eval/heldout_success_rate", e.success_rate),
                ("eval/heldout_collision_rate", e.collision_rate),
            ]);
        }
        tb.scalars(step, &scalars).map_err(|e| io_err(tb.path(), e))?;
        st.learning_rate = ppo.learning_rate();
        st.obs_norm = ppo.obs_norm.clone();
        st.value_norm = ppo.value_norm.clone();
        st.privileged_norm = (cfg.network.critic_movers > 0).then(|| ppo.privileged_norm.clone());
        // The best checkpoint: on the held-out rooms when there are any (unless told not to).
        let selected = match cfg.eval.select {
            crate::config::Selection::Heldout => heldout_result.or(eval_result),
            crate::config::Selection::Scenario | crate::config::Selection::Last => eval_result,
        };
        if let Some(rate) = selected.map(|r| r.success_rate)
            && rate > st.best_success_rate
        {
            st.best_success_rate = rate;
            st.best_epoch = st.epoch;
            // With `last` the best evaluation is reported, not kept.
            if cfg.eval.select != crate::config::Selection::Last {
                save_checkpoint(&out.join("best"), &ppo, &st)?;
            }
        }
        progress(&report);

        // Curriculum: move on after the stage's epoch budget, or once its success holds.
        let rule = &stages[st.stage].advance;
        let last = st.stage + 1 == stages.len();
        let by_epochs = rule.max_epochs > 0 && st.stage_epochs >= rule.max_epochs;
        let by_success = rule
            .success_rate
            .is_some_and(|thr| st.stage_epochs >= rule.min_epochs && window.rate().is_some_and(|r| r >= thr));
        if !last && (by_epochs || by_success) {
            st.stage += 1;
            st.stage_epochs = 0;
            window = Window { outcomes: VecDeque::new(), size: stages[st.stage].advance.window };
            env = env_for(st.stage, st.epoch)?;
            ppo.reset_state();
        }
        let checkpoint_now = st.epoch % 10 == 0
            || st.epoch == cfg.train.max_epochs
            || reached_stop_target
            || opts.stop.load(Ordering::Relaxed);
        if checkpoint_now {
            save_checkpoint(&out.join("checkpoint"), &ppo, &st)?;
        }
    }
    save_checkpoint(&out.join("checkpoint"), &ppo, &st)?;
    let (final_eval, final_epoch, final_heldout) = if interrupted {
        (None, 0, None)
    } else {
        let (which, epoch) = if out.join("best").join("state.json").is_file() {
            ("best", st.best_epoch)
        } else {
            ("checkpoint", st.epoch)
        };
        let (_, learner) = load_learner(out, which)?;
        let (r, _) =
            evaluate(&learner, &eval, cfg.eval.episodes, cfg.eval.envs, test_seed(cfg.seed), threads, &mut |_| {})?;
        (Some(r), epoch, eval_heldout(&learner, test_seed(cfg.seed))?)
    };
    let summary = Summary {
        name: cfg.name.clone(),
        iterations: st.epoch,
        env_steps: st.env_steps,
        wall_s: st.wall_s,
        steps_per_s: st.env_steps as f64 / st.wall_s.max(1e-9),
        interrupted,
        final_eval,
        final_epoch,
        last_epoch_eval: if interrupted { None } else { last_eval },
        eval_scenario: eval_scenarios(cfg),
        best_success_rate: st.best_success_rate.max(0.0),
        best_epoch: st.best_epoch,
        first_90: st.first_90,
        first_95: st.first_95,
        reached_stop_target,
        heldout_scenarios: cfg.eval.heldout.clone(),
        final_heldout,
    };
    if !interrupted {
        crate::export::write_policy(out, &out.join("policy.onnx"))?;
    }
    crate::plots::training_svg(&out.join("metrics.csv"), &out.join("training.svg"))
        .map_err(|e| TrainError::Io { path: out.join("training.svg").display().to_string(), message: e })?;
    fs::write(out.join("summary.json"), serde_json::to_string_pretty(&summary).expect("summary serialises"))
        .map_err(|e| io_err(out, e))?;
    Ok(summary)
}

/// Loads the network and normalisation of a run folder's checkpoint (`best` or
/// `checkpoint`) into a learner ready for [`evaluate`].
pub fn load_learner(dir: &Path, which: &str) -> Result<(RunConfig, Ppo), TrainError> {
    let cfg = read_run_config(dir)?;
    let ck = dir.join(which);
    let st = read_state(&ck)?;
    let mut ppo = Ppo::new(&cfg.train, &cfg.network, st.obs_norm.dim(), 2, training_device(), cfg.seed);
    restore_checkpoint(&mut ppo, &cfg, &ck, &st, false)?;
    Ok((cfg, ppo))
}

/// What `rlnav eval` reports (and writes as `eval.json`).
#[derive(Clone, Debug, Serialize)]
pub struct RunEvaluation {
    /// Scenario evaluated on.
    pub scenario: String,
    /// Seed of the episodes.
    pub seed: u64,
    /// Aggregate results.
    pub summary: EvalSummary,
    /// Every episode.
    pub episodes: Vec<EpisodeStats>,
}

/// Evaluates a run's final checkpoint on `scenario` (default: the run's evaluation scenarios)
/// with the run's robot and task: `episodes` episodes, `envs` at a time; `progress` hears the
/// count of finished episodes.
pub fn evaluate_run(
    dir: &Path,
    scenario: Option<&str>,
    episodes: usize,
    envs: usize,
    seed: u64,
    progress: &dyn Fn(usize),
) -> Result<RunEvaluation, TrainError> {
    let (cfg, ppo) = load_learner(dir, "checkpoint")?;
    let (scenario, setup) = match scenario {
        Some(s) => (s.to_string(), env_setup(&cfg, s, cfg.task.clone(), None)?),
        None => (eval_scenarios(&cfg), eval_setups(&cfg)?),
    };
    let envs = envs.clamp(1, episodes.max(1));
    let episodes = episodes / envs * envs;
    let (summary, episodes) = evaluate(&ppo, &setup, episodes, envs, seed, cfg.train.threads, &mut |n| progress(n))?;
    Ok(RunEvaluation { scenario, seed, summary, episodes })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_mixed_stage_gives_every_scenario_and_robot_pair_an_equal_share() {
        let mut cfg = RunConfig {
            robots: vec!["jetbot".into(), "turtlebot3-burger".into()],
            scenario: "random-static".into(),
            mix: vec!["empty-room".into()],
            ..Default::default()
        };
        let stage = &stages(&cfg)[0];
        let setups = stage_setup(&cfg, stage).unwrap();
        let pairs: Vec<(String, String)> =
            setups.iter().map(|s| (s.scenario.spec().name.clone(), s.robot.name.clone())).collect();
        let want = [
            ("random-static", "jetbot"),
            ("random-static", "turtlebot3-burger"),
            ("empty-room", "jetbot"),
            ("empty-room", "turtlebot3-burger"),
        ];
        assert_eq!(pairs, want.map(|(s, r)| (s.to_string(), r.to_string())));
        // A mixed scenario that does not load is named.
        cfg.mix = vec!["no-such-room".into()];
        let e = stage_setup(&cfg, &stages(&cfg)[0]).unwrap_err().to_string();
        assert!(e.contains("no-such-room"), "{e}");
    }

    #[test]
    fn the_evaluation_shares_its_scenarios_out_as_training_does() {
        let mut cfg = RunConfig { robots: vec!["jetbot".into(), "turtlebot3-burger".into()], ..Default::default() };
        cfg.eval.scenario = "random-static".into();
        let names = |setups: Vec<Arc<EnvSetup>>| -> Vec<(String, String)> {
            setups.iter().map(|s| (s.scenario.spec().name.clone(), s.robot.name.clone())).collect()
        };
        // Without a mix, the evaluation scenario for every robot, as before.
        assert_eq!(names(eval_setups(&cfg).unwrap()).len(), 2);
        assert_eq!(eval_scenarios(&cfg), "random-static");
        cfg.eval.mix = vec!["empty-room".into()];
        let want = [
            ("random-static", "jetbot"),
            ("random-static", "turtlebot3-burger"),
            ("empty-room", "jetbot"),
            ("empty-room", "turtlebot3-burger"),
        ];
        assert_eq!(names(eval_setups(&cfg).unwrap()), want.map(|(s, r)| (s.to_string(), r.to_string())));
        assert_eq!(eval_scenarios(&cfg), "random-static + empty-room");
        cfg.eval.mix = vec!["no-such-room".into()];
        let e = eval_setups(&cfg).unwrap_err().to_string();
        assert!(e.contains("no-such-room"), "{e}");
    }
}
