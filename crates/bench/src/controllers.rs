//! Controllers by name, as the command line names them: `greedy`, `straight`, `dwa` (the
//! classical baseline, set up for the scenario, robot and task), and `rl:POLICY.onnx` (or
//! `rl:POLICY.onnx:CONTRACT.yaml` for a model with a side contract).

use rlnav_planners::Dwa;
use rlnav_policy::PolicyRunner;
use rlnav_sim::task::{EnvSetup, TaskConfig};
use rlnav_sim::{Controller, GreedyGoal, StraightAhead};
use std::path::Path;

/// The built-in controller names [`by_name`] knows (besides `rl:FILE`).
pub const CONTROLLER_NAMES: &[&str] = &["greedy", "straight", "dwa", "rl:POLICY.onnx[:CONTRACT.yaml]"];

/// A controller that cannot be made.
#[derive(Debug, thiserror::Error)]
pub enum ControllerError {
    /// Not a known name.
    #[error("unknown controller `{0}`: expected one of {names}", names = CONTROLLER_NAMES.join(", "))]
    Unknown(String),
    /// A policy that does not load.
    #[error(transparent)]
    Policy(#[from] rlnav_policy::runner::PolicyError),
}

/// A controller by name: `greedy` (turn towards the goal and drive, blind), `straight`, or an
/// ONNX policy `rl:FILE[:CONTRACT]` (one whose speed is a share of the robot's top speed
/// needs the robot: [`for_setup`]).
pub fn by_name(name: &str) -> Result<Box<dyn Controller>, ControllerError> {
    match name {
        "greedy" => Ok(Box::new(GreedyGoal::default())),
        "straight" => Ok(Box::new(StraightAhead { speed: 0.3 })),
        "dwa" => Err(ControllerError::Unknown("dwa (it needs the scenario: use `for_setup`)".into())),
        other => match rl_spec(other) {
            Some((model, contract)) => {
                Ok(Box::new(PolicyRunner::load(Path::new(&model), contract.as_deref().map(Path::new))?))
            }
            None => Err(ControllerError::Unknown(other.to_string())),
        },
    }
}

/// The task the controller `name` runs under: a policy's own action ranges, control period and
/// plan from its contract (as it was trained: the simulator clamps every command to the task's
/// ranges, so a 2 m/s policy under the default 0.5 m/s task would crawl), the rest `base`'s;
/// `base` itself for the other controllers. A policy trained on plans gets the global plan of
/// a world known in advance, as a Nav2 controller gets the planner's.
pub fn task_for(name: &str, base: &TaskConfig) -> Result<TaskConfig, ControllerError> {
    let Some((model, contract)) = rl_spec(name) else {
        return Ok(base.clone());
    };
    let runner = PolicyRunner::load(Path::new(&model), contract.as_deref().map(Path::new))?;
    let c = runner.contract();
    let substeps = (c.control_period / base.physics_dt).round().max(1.0);
    Ok(TaskConfig {
        control_period: c.control_period,
        physics_dt: c.control_period / substeps,
        action: c.action.ranges(),
        plan: c.plan.clone(),
        ..base.clone()
    })
}

/// `rl:MODEL.onnx[:CONTRACT.yaml]` as (model, contract).
fn rl_spec(name: &str) -> Option<(String, Option<String>)> {
    let spec = name.strip_prefix("rl:")?;
    Some(match spec.split_once(".onnx:") {
        Some((m, c)) => (format!("{m}.onnx"), Some(c.to_string())),
        None => (spec.to_string(), None),
    })
}

/// Checks, before any episode, that the controller `name` can be made and, for a policy, that
/// the robot's lidar can feed its scan contract. Returns warnings: a robot outside the
/// envelope of the robots the policy was trained on.
pub fn check(name: &str, setup: &EnvSetup) -> Result<Vec<String>, ControllerError> {
    if let Some((model, contract)) = rl_spec(name) {
        let runner = PolicyRunner::load(Path::new(&model), contract.as_deref().map(Path::new))?;
        runner.check_lidar(&setup.robot.lidar)?;
        let mut warnings: Vec<String> = match &runner.contract().envelope {
            Some(e) => e
                .outside(&setup.robot)
                .into_iter()
                .map(|w| format!("{name} was trained on {}; {}'s {w}", e.robots.join(", "), setup.robot.name))
                .collect(),
            None => Vec::new(),
        };
        // Plans are given only in rooms known in advance (as DWA gets the map).
        if runner.contract().plan.is_some() && setup.scenario.fixed_world().is_none() {
            warnings.push(format!(
                "{name} was trained to follow a plan, but {} has no room known in advance to plan in: it steers to the goal",
                setup.scenario.spec().name
            ));
        }
        return Ok(warnings);
    }
    for_setup(name, setup).map(|_| Vec::new())
}

/// A controller by name for episodes of `setup`: as [`by_name`], and `dwa` set up for the
/// scenario, robot and task ([`Dwa::for_setup`]).
pub fn for_setup(name: &str, setup: &EnvSetup) -> Result<Box<dyn Controller>, ControllerError> {
    match name {
        "dwa" => Ok(Box::new(Dwa::for_setup(setup))),
        other => match rl_spec(other) {
            // The robot is known here: a policy whose speed is a share of its top speed gets it.
            Some((model, contract)) => {
                let mut runner = PolicyRunner::load(Path::new(&model), contract.as_deref().map(Path::new))?;
                runner.set_top_speed(setup.robot.max_linear);
                Ok(Box::new(runner))
            }
            None => by_name(other),
        },
    }
}
