//! Scenario suites: named lists of scenarios run together (`suites/`, embedded), and running
//! several controllers through all of them on the same seeded episodes.

use crate::controllers::{check, for_setup};
use crate::evaluate::{EvalSummary, evaluate_controller};
use rlnav_sim::config::{ConfigError, Invalid, Validate, preset_or_file};
use rlnav_sim::task::{EnvSetup, SimError, TaskConfig};
use rlnav_sim::{EpisodeStats, RobotSpec, ScenarioSpec};
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// The suites shipped in `suites/`: `(name, yaml)`.
pub const SUITE_PRESETS: &[(&str, &str)] = &[
    ("paper-static", include_str!("../../../suites/paper-static.yaml")),
    ("paper-dynamic", include_str!("../../../suites/paper-dynamic.yaml")),
    ("random-static", include_str!("../../../suites/random-static.yaml")),
    ("random-dynamic", include_str!("../../../suites/random-dynamic.yaml")),
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
    pub scenarios: Vec<String>,
    /// Episodes per scenario and controller (default 20).
    #[serde(default = "default_episodes")]
    pub episodes: usize,
}

fn default_episodes() -> usize {
    20
}

impl Validate for SuiteSpec {
    fn validate(&self) -> Result<(), Invalid> {
        if self.scenarios.is_empty() {
            return Err(Invalid::new("scenarios", "at least one scenario"));
        }
        if self.episodes == 0 {
            return Err(Invalid::new("episodes", "at least 1"));
        }
        Ok(())
    }
}

impl SuiteSpec {
    /// A shipped suite by name, or a YAML file.
    pub fn load(name_or_path: &str) -> Result<Self, ConfigError> {
        preset_or_file("suite", SUITE_PRESETS, name_or_path)
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
}

/// The suite's scenarios compiled for `robot` (default: each scenario's) and the default task.
pub fn suite_setups(suite: &SuiteSpec, robot: Option<&str>) -> Result<Vec<Arc<EnvSetup>>, BenchError> {
    let mut setups = Vec::new();
    for name in &suite.scenarios {
        let spec = ScenarioSpec::load(name)?;
        let robot = RobotSpec::load(robot.unwrap_or(&spec.robot))?;
        setups.push(Arc::new(EnvSetup::new(spec, robot, TaskConfig::default())?));
    }
    Ok(setups)
}

/// Runs every controller on every scenario of `suite` with the same `episodes` seeded
/// episodes each; `robot` replaces the scenarios' robot. Controllers, scenarios and policy
/// contracts are all checked before the first episode.
pub fn run_suite(
    suite: &SuiteSpec,
    controllers: &[String],
    robot: Option<&str>,
    episodes: usize,
    seed: u64,
    threads: usize,
) -> Result<SuiteResult, BenchError> {
    if controllers.is_empty() {
        return Err(BenchError::NoControllers);
    }
    let setups = suite_setups(suite, robot)?;
    let bad = |name: &str, message: &str| BenchError::Controller { name: name.into(), message: message.into() };
    for c in controllers {
        for setup in &setups {
            check(c, setup)
                .map_err(|e| bad(c, &format!("{} on {}: {e}", setup.robot.name, setup.scenario.spec().name)))?;
        }
    }
    let mut cells = Vec::new();
    for setup in &setups {
        for c in controllers {
            let (summary, eps, traces) =
                evaluate_controller(setup.clone(), || for_setup(c, setup), episodes, seed, threads)
                    .map_err(BenchError::Run)?;
            cells.push(CellResult {
                scenario: setup.scenario.spec().name.clone(),
                controller: c.clone(),
                summary,
                episodes: eps,
                traces,
            });
        }
    }
    Ok(SuiteResult { suite: suite.name.clone(), robot: setups[0].robot.name.clone(), seed, cells })
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
    /// The article's table as Markdown: per scenario and controller, success rate, task time,
    /// minimum lidar range, average linear velocity and final distance to the target (mean ±
    /// standard deviation; task time over successful episodes).
    pub fn markdown(&self) -> String {
        let mut s = format!(
            "# {} with {} (seed {})\n\n| scenario | controller | success | collision | timeout | task time (s) | min lidar range (m) | avg linear velocity (m/s) | distance to target (m) |\n|---|---|---|---|---|---|---|---|---|\n",
            self.suite, self.robot, self.seed
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
                "| {} | {} | {:.0}% | {:.0}% | {:.0}% | {} | {} | {} | {} |\n",
                c.scenario,
                c.controller,
                100.0 * r.success_rate,
                100.0 * r.collision_rate,
                100.0 * r.timeout_rate,
                pick(&|e| e.time, true),
                pick(&|e| e.min_range, false),
                pick(&|e| e.mean_speed, false),
                pick(&|e| e.final_distance, false),
            );
        }
        s
    }
}
