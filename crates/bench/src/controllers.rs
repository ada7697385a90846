//! Controllers by name, as the command line names them: `greedy`, `straight`, `dwa` (the
//! classical baseline, set up for the scenario, robot and task), and `rl:POLICY.onnx` (or
//! `rl:POLICY.onnx:CONTRACT.yaml` for a model with a side contract).

use rlnav_planners::{Dwa, DwaConfig};
use rlnav_policy::PolicyRunner;
use rlnav_sim::geometry::Rect;
use rlnav_sim::task::EnvSetup;
use rlnav_sim::{Controller, GreedyGoal, StraightAhead, Vec2};
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
/// ONNX policy `rl:FILE[:CONTRACT]`.
pub fn by_name(name: &str) -> Result<Box<dyn Controller>, ControllerError> {
    match name {
        "greedy" => Ok(Box::new(GreedyGoal::default())),
        "straight" => Ok(Box::new(StraightAhead { speed: 0.3 })),
        "dwa" => Err(ControllerError::Unknown("dwa (it needs the scenario: use `for_setup`)".into())),
        other => match other.strip_prefix("rl:") {
            Some(spec) => {
                let (model, contract) = match spec.split_once(".onnx:") {
                    Some((m, c)) => (format!("{m}.onnx"), Some(c.to_string())),
                    None => (spec.to_string(), None),
                };
                Ok(Box::new(PolicyRunner::load(Path::new(&model), contract.as_deref().map(Path::new))?))
            }
            None => Err(ControllerError::Unknown(other.to_string())),
        },
    }
}

/// A controller by name for episodes of `setup`: as [`by_name`], and `dwa` configured from
/// the robot and the task (speed limits, accelerations, control period; its centre keeps the
/// footprint radius or the collision range, whichever is larger, plus 3 cm), with the
/// scenario's static world as its prior map when every episode shares it.
pub fn for_setup(name: &str, setup: &EnvSetup) -> Result<Box<dyn Controller>, ControllerError> {
    if name != "dwa" {
        return by_name(name);
    }
    let cfg = DwaConfig {
        robot_radius: setup.footprint.radius().max(setup.task.collision_range) + 0.03,
        linear: setup.task.action.linear,
        max_angular: setup.task.action.angular[0].abs().min(setup.task.action.angular[1].abs()),
        linear_accel: setup.robot.max_linear_accel,
        angular_accel: setup.robot.max_angular_accel,
        control_period: setup.task.control_period,
        ..Default::default()
    };
    let a = setup.scenario.area();
    let bounds = Rect { min: a.min - Vec2::splat(0.5), max: a.max + Vec2::splat(0.5) };
    Ok(Box::new(Dwa::new(cfg, bounds, setup.scenario.fixed_world().cloned())))
}
