//! Any controller through seeded episodes, in parallel: the success, collision and time-out
//! rates and the figures papers report (task time, minimum lidar range, mean speed).

use rayon::prelude::*;
use rlnav_sim::task::{EnvSetup, SimError};
use rlnav_sim::vec_env::env_seed;
use rlnav_sim::{Controller, EpisodeStats, NavEnv};
use serde::Serialize;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

pub use rlnav_sim::EvalSummary;

/// One episode step by step: after each control step, the time, the position, the distance to
/// the goal and the smallest lidar range (step 0 is the start).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct EpisodeTrace {
    /// Seconds since the start.
    pub time: Vec<f32>,
    /// Positions `[x, y]`.
    pub position: Vec<[f32; 2]>,
    /// Distance to the goal (m).
    pub distance: Vec<f32>,
    /// Smallest lidar range in the scan (m).
    pub min_range: Vec<f32>,
}

impl EpisodeTrace {
    pub(crate) fn push(&mut self, env: &NavEnv, time: f32) {
        let p = env.pose().position();
        self.time.push(time);
        self.position.push([p.x, p.y]);
        self.distance.push((env.goal() - p).length());
        self.min_range.push(env.ranges().iter().copied().fold(f32::INFINITY, f32::min));
    }
}

/// A controller's run through a scenario's episodes: the summary, every episode's figures
/// and its trace.
pub type EvalRun = (EvalSummary, Vec<EpisodeStats>, Vec<EpisodeTrace>);

/// Runs the environment's current episode to its end under `c`, tracing it.
pub fn traced_episode(env: &mut NavEnv, c: &mut dyn Controller) -> (EpisodeStats, EpisodeTrace) {
    let period = env.setup().task.control_period;
    let mut trace = EpisodeTrace::default();
    let stats = env.run_to_end(c, |e| trace.push(e, trace.time.len() as f32 * period));
    (stats, trace)
}

/// Runs `episodes` episodes of `setup`, episode `k` seeded with `env_seed(seed, k)` (so the
/// same seed gives the same scenes to every controller, whatever the thread count), each
/// worker with its own controller from `make`; with `record`, episode `k` is also written to
/// `record/episode_KKK.mcap`. `progress` hears the count of finished episodes (from any
/// worker). Returns the summary, every episode's figures and its trace.
pub fn evaluate_controller<E: std::fmt::Display + Send>(
    setup: Arc<EnvSetup>,
    make: impl Fn() -> Result<Box<dyn Controller>, E> + Sync,
    episodes: usize,
    seed: u64,
    threads: usize,
    record: Option<&std::path::Path>,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<EvalRun, String> {
    let finished = AtomicUsize::new(0);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().map_err(|e| format!("thread pool: {e}"))?;
    let runs: Result<Vec<(EpisodeStats, EpisodeTrace)>, String> = pool.install(|| {
        (0..episodes)
            .into_par_iter()
            .map_init(
                || make().map_err(|e| e.to_string()),
                |c, k| {
                    let c = c.as_mut().map_err(|e| e.clone())?;
                    let mut env = NavEnv::new(setup.clone(), env_seed(seed, k)).map_err(|e: SimError| e.to_string())?;
                    let run = match record {
                        Some(dir) => {
                            let file = dir.join(format!("episode_{k:03}.mcap"));
                            crate::record::recorded_episode(&mut env, c.as_mut(), &file).map_err(|e| e.to_string())?
                        }
                        None => traced_episode(&mut env, c.as_mut()),
                    };
                    progress(finished.fetch_add(1, Ordering::Relaxed) + 1);
                    Ok(run)
                },
            )
            .collect()
    });
    let (stats, traces): (Vec<_>, Vec<_>) = runs?.into_iter().unzip();
    Ok((EvalSummary::of(&stats), stats, traces))
}

/// What `rlnav eval --policy` reports (and writes as `eval.json`).
#[derive(Clone, Debug, Serialize)]
pub struct PolicyEvaluation {
    /// The model file.
    pub policy: String,
    /// Its contract.
    pub contract: rlnav_policy::PolicyContract,
    /// Scenario name.
    pub scenario: String,
    /// Robot name.
    pub robot: String,
    /// Seed of the episodes.
    pub seed: u64,
    /// Aggregate figures.
    pub summary: EvalSummary,
    /// Every episode.
    pub episodes: Vec<EpisodeStats>,
}

/// Evaluates an ONNX policy (with its embedded or a side `contract`) on `scenario` with
/// `robot` (default: the contract's robot when it is a preset, else the scenario's). The task
/// is rlnav's default run at the policy's control period and with its action limits, so that
/// the simulator clips nothing the policy may command. The model, the contract and the robot's
/// lidar are checked before any episode. `progress` hears the count of finished episodes.
#[allow(clippy::too_many_arguments)]
pub fn evaluate_policy(
    policy: &std::path::Path,
    contract: Option<&std::path::Path>,
    scenario: &str,
    robot: Option<&str>,
    episodes: usize,
    seed: u64,
    threads: usize,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<PolicyEvaluation, crate::suite::BenchError> {
    use crate::suite::BenchError;
    use rlnav_policy::PolicyRunner;
    use rlnav_sim::task::TaskConfig;
    use rlnav_sim::{RobotSpec, ScenarioSpec};
    let bad = |message: String| BenchError::Controller { name: policy.display().to_string(), message };
    let runner = PolicyRunner::load(policy, contract).map_err(|e| bad(e.to_string()))?;
    let c = runner.contract().clone();
    let scenario = ScenarioSpec::load(scenario)?;
    let robot_name = match robot {
        Some(r) => r.to_string(),
        None if rlnav_sim::robot::ROBOT_PRESETS.iter().any(|(n, _)| *n == c.robot) => c.robot.clone(),
        None => scenario.robot.clone(),
    };
    let robot = RobotSpec::load(&robot_name)?;
    runner
        .check_lidar(&robot.lidar)
        .map_err(|e| bad(format!("the policy's scan contract does not fit {}'s lidar: {e}", robot.name)))?;
    let task = TaskConfig { control_period: c.control_period, action: c.action.ranges(), ..Default::default() };
    let setup = Arc::new(EnvSetup::new(scenario, robot, task)?);
    let (summary, episodes, _) = evaluate_controller(
        setup.clone(),
        || {
            PolicyRunner::load(policy, contract).map(|mut r| {
                r.set_top_speed(setup.robot.max_linear);
                Box::new(r) as Box<dyn Controller>
            })
        },
        episodes,
        seed,
        threads,
        None,
        progress,
    )
    .map_err(BenchError::Run)?;
    Ok(PolicyEvaluation {
        policy: policy.display().to_string(),
        contract: c,
        scenario: setup.scenario.spec().name.clone(),
        robot: setup.robot.name.clone(),
        seed,
        summary,
        episodes,
    })
}
