//! A network trained in Python as an rlnav policy file, and any rlnav policy file run from
//! Python: `rlnav.export`'s native part and [`OnnxPolicy`].

use crate::{err, json_to_py, task_file};
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use rlnav_policy::contract::{GraphIo, PolicyContract, RobotEnvelope};
use rlnav_policy::export::{DenseLayer, ObsAffine, export_mlp_onnx};
use rlnav_policy::{ActivationKind, PolicyRunner};
use std::path::Path;

/// One layer as Python gives it: weight `[inputs, outputs]`, bias, activation name or None.
type PyLayer<'py> = (PyReadonlyArray2<'py, f32>, PyReadonlyArray1<'py, f32>, Option<String>);

/// Writes a feed-forward actor as an ONNX policy carrying rlnav's contract for `task` (a
/// task file; default: the built-in task) and `robot`: `layers` are `(weight[in, out],
/// bias[out], activation)` with activation `"tanh"`, `"relu"`, `"elu"` or None (the last
/// layer: the normalised action mean); `obs_scale`, `obs_shift` and `obs_clip` the
/// observation normalisation in front (`clip(obs * scale + shift)`). The file is written
/// whole or not at all, then loaded back as `rlnav ros2 node` loads it and checked against
/// the robot's lidar. Returns the contract as a dict.
#[pyfunction]
#[pyo3(signature = (path, layers, obs_scale, obs_shift, obs_clip, robot, task=None, name="python"))]
#[allow(clippy::too_many_arguments)]
pub fn export_mlp<'py>(
    py: Python<'py>,
    path: &str,
    layers: Vec<PyLayer<'py>>,
    obs_scale: Vec<f32>,
    obs_shift: Vec<f32>,
    obs_clip: f32,
    robot: &str,
    task: Option<&str>,
    name: &str,
) -> PyResult<Bound<'py, PyAny>> {
    let robot = rlnav_sim::RobotSpec::load(robot).map_err(err)?;
    let task = task_file(task)?;
    let mut dense = Vec::with_capacity(layers.len());
    for (i, (w, b, act)) in layers.iter().enumerate() {
        let [inputs, outputs] =
            <[usize; 2]>::try_from(w.shape()).map_err(|_| err(format!("layers[{i}]: a 2-D weight")))?;
        let activation = match act.as_deref() {
            None => None,
            Some("tanh") => Some(ActivationKind::Tanh),
            Some("relu") => Some(ActivationKind::Relu),
            Some("elu") => Some(ActivationKind::Elu),
            Some(other) => return Err(err(format!("layers[{i}]: activation tanh, relu, elu or None, got `{other}`"))),
        };
        dense.push(DenseLayer {
            weight: w.as_array().iter().copied().collect(),
            inputs,
            outputs,
            bias: b.as_array().to_vec(),
            activation,
        });
    }
    let r = &task.randomization;
    let envelope = RobotEnvelope::of(std::slice::from_ref(&robot), [r.wheel_separation_jitter, r.speed_limit_jitter]);
    let contract = PolicyContract::for_task(name, &task, &robot, GraphIo::default(), Some(envelope));
    let norm = ObsAffine { scale: obs_scale, shift: obs_shift, clip: obs_clip };
    let bytes = export_mlp_onnx(&dense, &norm, &contract).map_err(|e| err(format!("{path}: {e}")))?;
    let path = Path::new(path);
    let io = |e: std::io::Error| err(format!("writing {}: {e}", path.display()));
    // Written beside the target and renamed: a crash leaves no half-written policy.
    let part = path.with_extension("onnx.part");
    std::fs::write(&part, bytes).map_err(io)?;
    let checked = PolicyRunner::load(&part, None).and_then(|r| r.check_lidar(&robot.lidar));
    if let Err(e) = checked {
        let _ = std::fs::remove_file(&part);
        return Err(err(format!("{}: the exported policy does not load: {e}", path.display())));
    }
    std::fs::rename(&part, path).map_err(io)?;
    json_to_py(py, &serde_json::to_string(&contract).map_err(err)?)
}

/// An rlnav policy file (ONNX with its contract inside, or with a side contract) run by the
/// same runtime `rlnav bench` and `rlnav ros2 node` use.
#[pyclass(module = "rlnav._rlnav", unsendable)]
pub struct OnnxPolicy {
    runner: PolicyRunner,
}

#[pymethods]
impl OnnxPolicy {
    /// Loads `path` (and its side `contract` YAML, for a model without one inside).
    #[new]
    #[pyo3(signature = (path, contract=None))]
    fn new(path: &str, contract: Option<&str>) -> PyResult<Self> {
        let runner = PolicyRunner::load(Path::new(path), contract.map(Path::new)).map_err(err)?;
        Ok(Self { runner })
    }

    /// The contract as a dict.
    #[getter]
    fn contract<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        json_to_py(py, &serde_json::to_string(self.runner.contract()).map_err(err)?)
    }

    /// The action mean `mu` (`float32[n, 2]`, before the contract's scaling) for a batch of raw
    /// observations (`float32[n, obs_dim]`), one row at a time. A recurrent policy takes one
    /// row per call and carries its state; `reset()` clears it.
    fn __call__<'py>(&mut self, py: Python<'py>, obs: PyReadonlyArray2<'py, f32>) -> PyResult<Bound<'py, PyAny>> {
        let d = self.runner.contract().obs_dim();
        let shape = obs.shape().to_vec();
        if shape.len() != 2 || shape[1] != d {
            return Err(err(format!("obs: expected shape (n, {d}), got {shape:?}")));
        }
        if !self.runner.contract().io.recurrent.is_empty() && shape[0] != 1 {
            return Err(err("obs: a recurrent policy takes one row per call (its state is one episode's)"));
        }
        let mut mu = Vec::with_capacity(shape[0] * 2);
        for row in obs.as_array().rows() {
            let row: Vec<f32> = row.to_vec();
            mu.extend(self.runner.infer(&row).map_err(err)?.mu);
        }
        Ok(PyArray1::from_vec(py, mu).reshape([shape[0], 2])?.into_any())
    }

    /// Starts a new episode: clears a recurrent state.
    fn reset(&mut self) {
        use rlnav_sim::Controller;
        self.runner.reset();
    }
}
