//! Scenario suites: named lists of scenarios run together (`suites/`, embedded), and running
//! several controllers through all of them on the same seeded episodes.

use crate::batch::{BatchPolicy, evaluate_batch};
use crate::controllers::{check, for_setup, task_for};
use crate::evaluate::{EvalRun, EvalSummary, evaluate_controller};
use rlnav_sim::barn::{Difficulty, barn_score_k};
use rlnav_sim::config::{ConfigError, Invalid, Validate, preset_or_file};
use rlnav_sim::task::{EnvSetup, SimError, TaskConfig};
use rlnav_sim::{EpisodeStats, RobotSpec, ScenarioSpec};
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::sync::Arc;

/// The suites shipped in `suites/`: `(name, yaml)`.
pub const SUITE_PRESETS: &[(&str, &str)] = &[
    ("paper-static", include_str!("../../../suites/paper-static.yaml")),
    ("paper-dynamic", include_str!("../../../suites/paper-dynamic.yaml")),
    ("random-static", include_str!("../../../suites/random-static.yaml")),
    ("random-dynamic", include_str!("../../../suites/random-dynamic.yaml")),
    ("barn", include_str!("../../../suites/barn.yaml")),
    ("heldout-static", include_str!("../../../suites/heldout-static.yaml")),
    ("heldout-dynamic", include_str!("../../../suites/heldout-dynamic.yaml")),
    ("probe-corridor", include_str!("../../../suites/probe-corridor.yaml")),
];

/// A suite file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SuiteSpec {
    /// Name.
    pub name: String,
    /// What it is.
    #[serde(default)]
    pub description: String,
    /// Scenario names or files.
    #[serde(default)]
    pub scenarios: Vec<String>,
    /// BARN Challenge worlds, run under the challenge's rules (1 m success radius, 100 s, a
    /// collision is contact) and scored as the challenge scores them.
    #[serde(default)]
    pub barn: Option<BarnSuite>,
    /// Episodes per scenario and controller (default 20).
    #[serde(default = "default_episodes")]
    pub episodes: usize,
}

fn default_episodes() -> usize {
    20
}

/// Which BARN worlds a suite runs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BarnSuite {
    /// `barn` (the default): the 250 worlds shipped in `assets/barn/` and embedded in the
    /// binary; or the path of another BARN data file (`barn_worlds.json`).
    #[serde(default = "shipped_barn")]
    pub file: String,
    /// Every `every`-th world of the file, in index order (default 1: all), after `split`.
    #[serde(default = "one")]
    pub every: usize,
    /// `all` (the default), `test` (the challenge's 50 test worlds: indices 0, 6, ..., 294)
    /// or `train` (the other indices).
    #[serde(default)]
    pub split: BarnSplit,
}

/// A split of the BARN worlds (see [`rlnav_sim::barn::Split`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BarnSplit {
    /// Every world.
    #[default]
    All,
    /// Indices that are multiples of 6.
    Test,
    /// The others.
    Train,
}

impl From<BarnSplit> for rlnav_sim::barn::Split {
    fn from(s: BarnSplit) -> Self {
        match s {
            BarnSplit::All => Self::All,
            BarnSplit::Test => Self::Test,
            BarnSplit::Train => Self::Train,
        }
    }
}

fn one() -> usize {
    1
}

fn shipped_barn() -> String {
    rlnav_sim::barn::SHIPPED_NAME.to_string()
}

impl Validate for SuiteSpec {
    fn validate(&self) -> Result<(), Invalid> {
        if self.scenarios.is_empty() && self.barn.is_none() {
            return Err(Invalid::new("scenarios", "at least one scenario (or `barn`)"));
        }
        if self.barn.as_ref().is_some_and(|b| b.every == 0) {
            return Err(Invalid::new("barn.every", "at least 1"));
        }
        if self.episodes == 0 {
            return Err(Invalid::new("episodes", "at least 1"));
        }
        Ok(())
    }
}

impl SuiteSpec {
    /// A shipped suite by name, or a YAML file (whose relative `barn.file` is read from the
    /// suite's folder).
    pub fn load(name_or_path: &str) -> Result<Self, ConfigError> {
        let mut suite: Self = preset_or_file("suite", SUITE_PRESETS, name_or_path)?;
        let from_file = !SUITE_PRESETS.iter().any(|(n, _)| *n == name_or_path);
        if let (Some(b), true) = (&mut suite.barn, from_file) {
            let dir = std::path::Path::new(name_or_path).parent().unwrap_or(std::path::Path::new(""));
            if b.file != rlnav_sim::barn::SHIPPED_NAME && std::path::Path::new(&b.file).is_relative() {
                b.file = dir.join(&b.file).display().to_string();
            }
        }
        Ok(suite)
    }
}

/// Why a benchmark could not run.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// A scenario, robot or suite file.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// Scenario and robot do not fit.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// A controller that cannot be made or does not fit the robot.
    #[error("controller `{name}`: {message}")]
    Controller {
        /// Its spec.
        name: String,
        /// Why.
        message: String,
    },
    /// No controllers.
    #[error("no controllers to run: give at least one --controller")]
    NoControllers,
    /// An episode failed.
    #[error("{0}")]
    Run(String),
}

/// One controller on one scenario.
#[derive(Clone, Debug, Serialize)]
pub struct CellResult {
    /// Scenario name.
    pub scenario: String,
    /// Controller spec.
    pub controller: String,
    /// Aggregate figures.
    pub summary: EvalSummary,
    /// Mean BARN Challenge score over the episodes as scored since 2024 (k = 2, best 0.5;
    /// BARN worlds only).
    pub barn_score: Option<f32>,
    /// The same with the challenge's earlier lower clip (k = 4, best 0.25).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub barn_score_k4: Option<f32>,
    /// The BARN world's difficulty metrics (Perille et al. 2020), when its file has them.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub difficulty: Option<Difficulty>,
    /// Every episode, in seed order.
    pub episodes: Vec<EpisodeStats>,
    /// Every episode step by step (distance to goal over time, path, lidar minimum).
    pub traces: Vec<crate::evaluate::EpisodeTrace>,
}

/// A whole suite under several controllers.
#[derive(Clone, Debug, Serialize)]
pub struct SuiteResult {
    /// Suite name.
    pub suite: String,
    /// Robot.
    pub robot: String,
    /// Seed of the episodes (the same for every controller).
    pub seed: u64,
    /// Results, scenario-major.
    pub cells: Vec<CellResult>,
    /// What the checks before the first episode warned about (a robot outside a policy's
    /// trained envelope).
    pub warnings: Vec<String>,
}

/// The suite's scenarios compiled for `robot` (default: each scenario's) and the default task,
/// then its BARN worlds under the challenge's rules (1 m success radius, the time limit, a
/// collision is contact), in the order [`run_suite`] runs them.
pub fn suite_setups(suite: &SuiteSpec, robot: Option<&str>) -> Result<Vec<Arc<EnvSetup>>, BenchError> {
    suite_setups_under(suite, robot, &TaskConfig::default())
}

/// [`suite_setups`] under `task` in place of the default (`rlnav bench --task`).
pub fn suite_setups_under(
    suite: &SuiteSpec,
    robot: Option<&str>,
    task: &TaskConfig,
) -> Result<Vec<Arc<EnvSetup>>, BenchError> {
    Ok(suite_setups_scored(suite, robot, task)?.into_iter().map(|(s, _)| Arc::new(s)).collect())
}

/// What scoring a BARN world needs: its optimal time, and its difficulty for the tables.
#[derive(Clone, Copy, Debug)]
struct BarnRef {
    optimal_time: f32,
    difficulty: Option<Difficulty>,
}

/// A scenario compiled for the run, with what its score needs when it is a BARN world.
type ScoredSetup = (EnvSetup, Option<BarnRef>);

/// As [`suite_setups`], with `base` in place of the default task (BARN's rules on top).
fn suite_setups_scored(
    suite: &SuiteSpec,
    robot: Option<&str>,
    base: &TaskConfig,
) -> Result<Vec<ScoredSetup>, BenchError> {
    let mut setups = Vec::new();
    for name in &suite.scenarios {
        let spec = ScenarioSpec::load(name)?;
        let robot = RobotSpec::load(robot.unwrap_or(&spec.robot))?;
        setups.push((EnvSetup::new(spec, robot, base.clone())?, None));
    }
    if let Some(b) = &suite.barn {
        let set = rlnav_sim::barn::BarnSet::load_named(&b.file)?;
        let base = base.clone();
        let task = TaskConfig {
            goal_tolerance: set.success_radius,
            max_steps: (set.time_limit / base.control_period).round() as u32,
            collision_range: 0.0,
            ..base
        };
        let split = rlnav_sim::barn::Split::from(b.split);
        let worlds: Vec<_> = set.worlds.iter().filter(|w| split.contains(w.index)).collect();
        if worlds.is_empty() {
            return Err(ConfigError::Invalid {
                file: b.file.clone(),
                key: "worlds".into(),
                expected: format!("worlds in the suite's `{:?}` split; the file has none", b.split),
            }
            .into());
        }
        for w in worlds.into_iter().step_by(b.every) {
            let robot = RobotSpec::load(robot.unwrap_or(&w.spec.robot))?;
            let scored = BarnRef { optimal_time: w.optimal_time, difficulty: w.difficulty };
            setups.push((EnvSetup::new(w.spec.clone(), robot, task.clone())?, Some(scored)));
        }
    }
    Ok(setups)
}

/// How [`run_suite`] runs.
#[derive(Clone, Copy, Debug)]
pub struct RunOptions<'a> {
    /// Replaces the scenarios' robot.
    pub robot: Option<&'a str>,
    /// Episodes per scenario and controller.
    pub episodes: usize,
    /// Seed of the episodes (the same scenes for every controller).
    pub seed: u64,
    /// Worker threads.
    pub threads: usize,
    /// Record every episode as MCAP under `DIR/SCENARIO/CONTROLLER/episode_NNN.mcap`.
    pub record: Option<&'a Path>,
    /// The task every controller runs under (default [`TaskConfig::default`]); a policy keeps
    /// its own action ranges, control period and plan on top of it.
    pub task: Option<&'a TaskConfig>,
}

impl Default for RunOptions<'_> {
    fn default() -> Self {
        Self { robot: None, episodes: 20, seed: 0, threads: 1, record: None, task: None }
    }
}

/// A policy given as a batch callable rather than by name (a network in Python), run beside
/// the named controllers on the same episodes.
pub struct BatchEntry<'a> {
    /// Its name in the tables.
    pub name: &'a str,
    /// The task it was trained with: its observation, action ranges, control period and plan
    /// are used; the rest (time limit, goal tolerance, collision range) is the suite's.
    pub task: &'a TaskConfig,
    /// The policy.
    pub policy: &'a mut dyn BatchPolicy,
}

/// Runs every controller on every scenario of `suite` with the same seeded episodes each.
/// Controllers, scenarios and policy contracts are all checked before the first episode.
/// `progress(done, total)` is called as each (scenario, controller) pair finishes.
pub fn run_suite(
    suite: &SuiteSpec,
    controllers: &[String],
    opts: &RunOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<SuiteResult, BenchError> {
    run_suite_with(suite, None, controllers, opts, progress)
}

/// [`run_suite`] with a batch policy first on each scenario (all its episodes in lockstep,
/// [`evaluate_batch`]; not recorded), then the named controllers.
pub fn run_suite_with(
    suite: &SuiteSpec,
    mut batch: Option<BatchEntry>,
    controllers: &[String],
    opts: &RunOptions,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<SuiteResult, BenchError> {
    let RunOptions { robot, episodes, seed, threads, record, task } = *opts;
    if controllers.is_empty() && batch.is_none() {
        return Err(BenchError::NoControllers);
    }
    let bad = |name: &str, message: &str| BenchError::Controller { name: name.into(), message: message.into() };
    let base = task.cloned().unwrap_or_default();
    // Each controller runs under its own task (a policy's action ranges, control period and
    // plan on top of the base).
    let tasks = controllers
        .iter()
        .map(|c| task_for(c, &base).map_err(|e| bad(c, &e.to_string())))
        .collect::<Result<Vec<_>, _>>()?;
    // The batch policy's own observation, action and control period.
    let batch_task = batch.as_ref().map(|b| TaskConfig {
        physics_dt: b.task.physics_dt,
        control_period: b.task.control_period,
        action: b.task.action.clone(),
        observation: b.task.observation.clone(),
        plan: b.task.plan.clone(),
        ..base.clone()
    });
    // The scenes every controller gets, each drawn from one compiled scenario: the one whose
    // task needs the most room at the start (the largest turning radius on that scene's
    // robot, for a range in shares of its top speed), so that no controller starts closer to
    // a wall than it can turn away from. Compiled per task, starts (and so episodes) would
    // differ.
    let mut distinct: Vec<&TaskConfig> = vec![&base];
    for t in tasks.iter().chain(&batch_task) {
        if !distinct.contains(&t) {
            distinct.push(t);
        }
    }
    let compiled =
        distinct.iter().map(|t| suite_setups_scored(suite, robot, t)).collect::<Result<Vec<_>, BenchError>>()?;
    let barn_refs: Vec<Option<BarnRef>> = compiled[0].iter().map(|(_, b)| *b).collect();
    // Scene by scene, each task's setup.
    let mut by_scene: Vec<Vec<Option<EnvSetup>>> = barn_refs.iter().map(|_| Vec::new()).collect();
    for per_task in compiled {
        for (row, (s, _)) in by_scene.iter_mut().zip(per_task) {
            row.push(Some(s));
        }
    }
    let mut resolved: Vec<Vec<Arc<EnvSetup>>> = vec![Vec::with_capacity(barn_refs.len()); distinct.len()];
    for mut row in by_scene {
        let room = |s: &Option<EnvSetup>| s.as_ref().map_or(0.0, |s| s.scenario.start_clearance());
        let widest = (0..row.len()).fold(0, |w, i| if room(&row[i]) > room(&row[w]) { i } else { w });
        let scene = Arc::new(row[widest].take().expect("each scene is compiled once per task"));
        for (mine, s) in resolved.iter_mut().zip(row) {
            mine.push(match s {
                None => scene.clone(),
                Some(s) => Arc::new(s.on_scenes_of(&scene)?),
            });
        }
    }
    let under = |t: &TaskConfig| resolved[distinct.iter().position(|d| *d == t).expect("every task is listed")].clone();
    let setups: Vec<(Arc<EnvSetup>, Option<BarnRef>)> = under(&base).into_iter().zip(barn_refs).collect();
    let own_setups: Vec<Vec<Arc<EnvSetup>>> = tasks.iter().map(under).collect();
    let mut warnings = Vec::new();
    for (c, mine) in controllers.iter().zip(&own_setups) {
        for setup in mine {
            for w in check(c, setup)
                .map_err(|e| bad(c, &format!("{} on {}: {e}", setup.robot.name, setup.scenario.spec().name)))?
            {
                if !warnings.contains(&w) {
                    warnings.push(w);
                }
            }
        }
    }
    let total = setups.len() * (controllers.len() + usize::from(batch.is_some()));
    // The batch policy's scenes under its own observation, action and control period.
    let mut batch_runs = match (&mut batch, &batch_task) {
        (Some(b), Some(t)) => {
            let own = under(t);
            let runs = evaluate_batch(&own, episodes, seed, threads, b.policy).map_err(|e| bad(b.name, &e))?;
            runs.into_iter().map(Some).collect()
        }
        _ => vec![None; setups.len()],
    };
    let mut done = if batch.is_some() { setups.len() } else { 0 };
    if done > 0 {
        progress(done, total);
    }
    let mut cells = Vec::new();
    for (k, ((setup, optimal), own)) in setups.iter().zip(&mut batch_runs).enumerate() {
        let cell = |controller: &str, (summary, eps, traces): EvalRun| CellResult {
            scenario: setup.scenario.spec().name.clone(),
            controller: controller.to_string(),
            summary,
            barn_score: optimal.map(|b| mean_barn_score(&eps, b.optimal_time, 2.0)),
            barn_score_k4: optimal.map(|b| mean_barn_score(&eps, b.optimal_time, 4.0)),
            difficulty: optimal.and_then(|b| b.difficulty),
            episodes: eps,
            traces,
        };
        if let (Some(run), Some(b)) = (own.take(), &batch) {
            cells.push(cell(b.name, run));
        }
        for (c, mine) in controllers.iter().zip(&own_setups) {
            let name = &setup.scenario.spec().name;
            let dir = record.map(|d| d.join(crate::plots::slug(name)).join(crate::plots::slug(c)));
            let setup = &mine[k];
            let run = evaluate_controller(
                setup.clone(),
                || for_setup(c, setup),
                episodes,
                seed,
                threads,
                dir.as_deref(),
                &|_| {},
            )
            .map_err(BenchError::Run)?;
            cells.push(cell(c, run));
            done += 1;
            progress(done, total);
        }
    }
    Ok(SuiteResult { suite: suite.name.clone(), robot: setups[0].0.robot.name.clone(), seed, cells, warnings })
}

/// The mean BARN score of episodes in a world of optimal time `optimal` with lower clip `k`.
fn mean_barn_score(eps: &[EpisodeStats], optimal: f32, k: f32) -> f32 {
    let n = eps.len().max(1) as f32;
    eps.iter().map(|e| barn_score_k(e.outcome == rlnav_sim::Outcome::Success, e.time, optimal, k)).sum::<f32>() / n
}

/// `87% [79–92]`: a rate with its interval, in percent.
pub fn rate_ci(rate: f32, ci: [f32; 2]) -> String {
    format!("{:.0}% [{:.0}–{:.0}]", 100.0 * rate, 100.0 * ci[0], 100.0 * ci[1])
}

/// The distinct items, in the order they first come.
pub(crate) fn first_seen<'a>(items: impl Iterator<Item = &'a str>) -> Vec<&'a str> {
    let mut out: Vec<&str> = Vec::new();
    for i in items {
        if !out.contains(&i) {
            out.push(i);
        }
    }
    out
}

/// A figure with `digits` decimals, `–` when there is none (NaN).
pub(crate) fn num(x: f32, digits: usize) -> String {
    if x.is_finite() { format!("{x:.digits$}") } else { "–".into() }
}

/// Mean and (population) standard deviation.
fn mean_std(v: &[f32]) -> (f32, f32) {
    if v.is_empty() {
        return (f32::NAN, f32::NAN);
    }
    let m = v.iter().sum::<f32>() / v.len() as f32;
    (m, (v.iter().map(|x| (x - m).powi(2)).sum::<f32>() / v.len() as f32).sqrt())
}

impl SuiteResult {
    /// Each controller's summary over every episode of the suite, in the order controllers
    /// were given.
    pub fn pooled(&self) -> Vec<(String, EvalSummary)> {
        first_seen(self.cells.iter().map(|c| c.controller.as_str()))
            .into_iter()
            .map(|name| {
                let eps: Vec<EpisodeStats> = self
                    .cells
                    .iter()
                    .filter(|c| c.controller == name)
                    .flat_map(|c| c.episodes.iter().copied())
                    .collect();
                (name.to_string(), EvalSummary::of(&eps))
            })
            .collect()
    }

    /// The article's table as Markdown: per scenario and controller, success rate, task time,
    /// minimum lidar range, average linear velocity and final distance to the target (mean ±
    /// standard deviation; task time over successful episodes).
    pub fn markdown(&self) -> String {
        let barn = self.cells.iter().any(|c| c.barn_score.is_some());
        let mut s = format!(
            "# {} with {} (seed {})\n\nRates with their 95% Wilson interval; SPL: success weighted by the shortest path's length (Theta* past the static world); ang. acc.: mean absolute angular acceleration (smoothness, lower is smoother).\n\n| scenario | controller | success | collision | timeout | SPL | task time (s) | min lidar range (m) | avg linear velocity (m/s) | ang. acc. (rad/s²) | distance to target (m) |{}\n|---|---|---|---|---|---|---|---|---|---|---|{}\n",
            self.suite,
            self.robot,
            self.seed,
            if barn { " BARN score (k=2) | BARN score (k=4) |" } else { "" },
            if barn { "---|---|" } else { "" },
        );
        for c in &self.cells {
            let pick = |f: &dyn Fn(&EpisodeStats) -> f32, only_wins: bool| {
                let v: Vec<f32> = c
                    .episodes
                    .iter()
                    .filter(|e| !only_wins || e.outcome == rlnav_sim::Outcome::Success)
                    .map(f)
                    .filter(|x| x.is_finite())
                    .collect();
                let (m, sd) = mean_std(&v);
                if m.is_nan() { "–".to_string() } else { format!("{m:.2} ± {sd:.2}") }
            };
            let r = &c.summary;
            s += &format!(
                "| {} | {} | {} | {} | {:.0}% | {} | {} | {} | {} | {} | {} |{}\n",
                c.scenario,
                c.controller,
                rate_ci(r.success_rate, r.success_ci95),
                rate_ci(r.collision_rate, r.collision_ci95),
                100.0 * r.timeout_rate,
                num(r.spl, 2),
                pick(&|e| e.time, true),
                pick(&|e| e.min_range, false),
                pick(&|e| e.mean_speed, false),
                pick(&|e| e.mean_angular_acceleration, false),
                pick(&|e| e.final_distance, false),
                match (c.barn_score, c.barn_score_k4) {
                    (Some(b), Some(b4)) => format!(" {b:.3} | {b4:.3} |"),
                    _ if barn => " – | – |".into(),
                    _ => String::new(),
                },
            );
        }
        for w in &self.warnings {
            s += &format!("\nWarning: {w}.\n");
        }
        // Pooled over the suite: what a suite-level claim ("98% on static rooms") rests on.
        s += "\nOver the whole suite:\n\n| controller | episodes | success | collision | timeout | SPL | task time (s) | min lidar range (m) | ang. acc. (rad/s²) |\n|---|---|---|---|---|---|---|---|---|\n";
        for (controller, r) in self.pooled() {
            s += &format!(
                "| {controller} | {} | {} | {} | {:.1}% | {} | {} | {} | {} |\n",
                r.episodes,
                rate_ci(r.success_rate, r.success_ci95),
                rate_ci(r.collision_rate, r.collision_ci95),
                100.0 * r.timeout_rate,
                num(r.spl, 2),
                num(r.mean_task_time, 2),
                num(r.mean_min_range, 2),
                num(r.mean_angular_acceleration, 2),
            );
        }
        if barn {
            s += &self.barn_markdown();
        }
        s
    }

    /// The BARN part of the report: each controller's mean score under both clips with its
    /// success rate over the worlds, and one row per world (hardest first by characteristic
    /// dimension, the narrowest gap along the path) with its difficulty metrics and each
    /// controller's success and score.
    pub fn barn_markdown(&self) -> String {
        let barn_cells: Vec<&CellResult> = self.cells.iter().filter(|c| c.barn_score.is_some()).collect();
        let controllers = first_seen(barn_cells.iter().map(|c| c.controller.as_str()));
        let mut s = String::from(
            "\nBARN Challenge score over the worlds (k = 2: scored since 2024, best 0.5; k = 4: until 2023, best 0.25):\n\n\
             | controller | worlds | success | collision | timeout | mean time of successes (s) | score (k=2) | score (k=4) |\n\
             |---|---|---|---|---|---|---|---|\n",
        );
        for name in &controllers {
            let mine: Vec<&&CellResult> = barn_cells.iter().filter(|c| c.controller == *name).collect();
            let n = mine.len().max(1) as f32;
            let mean = |f: &dyn Fn(&CellResult) -> f32| mine.iter().map(|c| f(c)).sum::<f32>() / n;
            let wins: Vec<f32> = mine
                .iter()
                .flat_map(|c| c.episodes.iter().filter(|e| e.outcome == rlnav_sim::Outcome::Success).map(|e| e.time))
                .collect();
            s += &format!(
                "| {name} | {} | {:.1}% | {:.1}% | {:.1}% | {} | {:.3} | {:.3} |\n",
                mine.len(),
                100.0 * mean(&|c| c.summary.success_rate),
                100.0 * mean(&|c| c.summary.collision_rate),
                100.0 * mean(&|c| c.summary.timeout_rate),
                if wins.is_empty() {
                    "–".into()
                } else {
                    format!("{:.1}", wins.iter().sum::<f32>() / wins.len() as f32)
                },
                mean(&|c| c.barn_score.unwrap_or(0.0)),
                mean(&|c| c.barn_score_k4.unwrap_or(0.0)),
            );
        }
        let worlds = first_seen(barn_cells.iter().map(|c| c.scenario.as_str()));
        let difficulty = |w: &str| barn_cells.iter().find(|c| c.scenario == w).and_then(|c| c.difficulty);
        if worlds.iter().all(|w| difficulty(w).is_none()) {
            return s;
        }
        let mut order = worlds.clone();
        order.sort_by(|a, b| {
            let key = |w: &str| difficulty(w).map_or(f32::INFINITY, |d| d.characteristic_dimension);
            key(a).total_cmp(&key(b))
        });
        s += "\nPer world, with its difficulty metrics along the reference path (cells of 0.15 m; Perille et al. 2020), \
              narrowest first: success and score (k=2) per controller.\n\n\
              | world | closest wall | visibility | dispersion | char. dimension | tortuosity |";
        for name in &controllers {
            s += &format!(" {name} |");
        }
        s += "\n|---|---|---|---|---|---|";
        s += &"---|".repeat(controllers.len());
        s += "\n";
        for w in order {
            let metrics = match difficulty(w) {
                Some(d) => d.values().iter().map(|v| format!(" {v:.2} |")).collect::<String>(),
                None => " – | – | – | – | – |".into(),
            };
            s += &format!("| {w} |{metrics}");
            for name in &controllers {
                s += &match barn_cells.iter().find(|c| c.scenario == w && c.controller == *name) {
                    Some(c) => format!(" {:.0}% {:.3} |", 100.0 * c.summary.success_rate, c.barn_score.unwrap_or(0.0)),
                    None => " – |".into(),
                };
            }
            s += "\n";
        }
        s
    }
}
