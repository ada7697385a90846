//! A run's policy as an ONNX file carrying its contract: what `rlnav export` writes, and what
//! training writes as `policy.onnx` when it ends.

use crate::config::RunConfig;
use crate::run::{TrainError, load_learner};
use rlnav_policy::RunningMeanStd;
use rlnav_policy::contract::{GraphIo, PolicyContract, RobotEnvelope};
use rlnav_policy::export::{export_onnx, lstm_io};
use rlnav_sim::RobotSpec;
use std::path::Path;

/// The contract of a policy trained with `cfg` on `robot`: the task's observation and
/// action, the robot's scan in `base_link` orientation.
pub fn run_contract(cfg: &RunConfig, robot: &RobotSpec, lstm_units: usize) -> PolicyContract {
    let io = if lstm_units > 0 { lstm_io(lstm_units) } else { GraphIo::default() };
    let envelope = trained_robots(cfg, robot).map(|robots| {
        let r = &cfg.task.randomization;
        RobotEnvelope::of(&robots, [r.wheel_separation_jitter, r.speed_limit_jitter])
    });
    PolicyContract::for_task(&cfg.name, &cfg.task, robot, io, envelope)
}

/// The robots a run trains on (`robots`, or `robot` alone), `robot` given as loaded; `None`
/// when one of them no longer loads (a robot file moved since training): no envelope rather
/// than a wrong one.
fn trained_robots(cfg: &RunConfig, robot: &RobotSpec) -> Option<Vec<RobotSpec>> {
    if cfg.robots.is_empty() {
        return Some(vec![robot.clone()]);
    }
    cfg.robots.iter().map(|r| RobotSpec::load(r).ok()).collect()
}

/// The ONNX bytes of a run folder's checkpoint (`best` or `checkpoint`) and its contract.
pub fn export_run(dir: &Path, which: &str) -> Result<(Vec<u8>, PolicyContract), TrainError> {
    let (cfg, ppo) = load_learner(dir, which)?;
    let robot = RobotSpec::load(&cfg.robot)?;
    let net = ppo.inference_net();
    let contract = run_contract(&cfg, &robot, net.lstm_units());
    let norm = if cfg.train.normalize_input {
        ppo.obs_norm.clone()
    } else {
        // Exactly the identity: scale 1 / sqrt(var + eps) = 1, no clipping.
        let n = ppo.obs_norm.dim();
        RunningMeanStd {
            mean: vec![0.0; n],
            var: vec![1.0 - rlnav_policy::normalizer::EPSILON; n],
            count: 1.0,
            clip: f32::INFINITY,
        }
    };
    let bytes = export_onnx(&net, &norm, &contract)
        .map_err(|e| TrainError::Io { path: dir.join(which).display().to_string(), message: e.to_string() })?;
    Ok((bytes, contract))
}

/// Writes `export_run(dir, best-or-checkpoint)` to `out`; returns which checkpoint it used.
pub fn write_policy(dir: &Path, out: &Path) -> Result<&'static str, TrainError> {
    let which = if dir.join("best").join("state.json").is_file() { "best" } else { "checkpoint" };
    let (bytes, _) = export_run(dir, which)?;
    std::fs::write(out, bytes)
        .map_err(|e| TrainError::Io { path: out.display().to_string(), message: e.to_string() })?;
    Ok(which)
}
