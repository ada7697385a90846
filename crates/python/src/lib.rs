//! `rlnav._rlnav`: the simulator for Python. The `rlnav` Python package (python/) builds the
//! Gymnasium environments on top of [`VecSim`]; this module keeps to what must be native:
//! stepping the batch with the GIL released, writing observations straight into the caller's
//! numpy arrays, rendering, and the loaders with the CLI's errors.

use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray2, PyReadwriteArray1, PyReadwriteArray2, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rlnav_bench::episode::Frame;
use rlnav_bench::render::{Scene, Style};
use rlnav_sim::observation::ObsTerm;
use rlnav_sim::task::{EnvSetup, EpisodeStats, Outcome};
use rlnav_sim::vec_env::VecEnv;
use std::path::Path;
use std::sync::Arc;

mod evaluate;
mod export;

pyo3::create_exception!(
    _rlnav,
    RlnavError,
    PyValueError,
    "A scenario, robot or task that cannot be loaded or does not fit (the message names the file and field), or input of the wrong shape."
);

fn err(e: impl std::fmt::Display) -> PyErr {
    RlnavError::new_err(e.to_string())
}

/// A task file, or the built-in task without one; a bad file raises `RlnavError` naming it.
fn task_file(path: Option<&str>) -> PyResult<rlnav_sim::TaskConfig> {
    match path {
        Some(p) => rlnav_sim::TaskConfig::from_file(Path::new(p)).map_err(err),
        None => Ok(rlnav_sim::TaskConfig::default()),
    }
}

/// Parses JSON text into Python objects (dicts, lists, floats...).
fn json_to_py<'py>(py: Python<'py>, text: &str) -> PyResult<Bound<'py, PyAny>> {
    py.import("json")?.call_method1("loads", (text,))
}

/// N navigation environments stepped together (autoreset in the same step), the batch under
/// `rlnav.make_vec`.
#[pyclass(module = "rlnav._rlnav")]
pub struct VecSim {
    setup: Arc<EnvSetup>,
    venv: VecEnv,
    actions: Vec<[f32; 2]>,
}

impl VecSim {
    fn check_rows(&self, what: &str, shape: &[usize], cols: usize) -> PyResult<()> {
        let n = self.venv.len();
        if shape != [n, cols] {
            return Err(err(format!("{what}: expected shape ({n}, {cols}), got {shape:?}")));
        }
        Ok(())
    }

    fn check_len(&self, what: &str, len: usize) -> PyResult<()> {
        if len != self.venv.len() {
            return Err(err(format!("{what}: expected {} values, got {len}", self.venv.len())));
        }
        Ok(())
    }

    fn write_obs(&self, obs: &mut PyReadwriteArray2<f32>) -> PyResult<()> {
        self.check_rows("obs", obs.shape(), self.venv.obs_dim())?;
        obs.as_slice_mut()
            .map_err(|_| err("obs: expected a C-contiguous float32 array"))?
            .copy_from_slice(&self.venv.obs);
        Ok(())
    }
}

#[pymethods]
impl VecSim {
    /// Builds `num_envs` environments of `scenario` (a shipped name or a YAML file) with
    /// `robot` (name or file; default: the scenario's) and `task` (a task YAML file; default:
    /// configs/task.yaml's values), environment i seeded from `seed` and i, stepped on
    /// `threads` worker threads (0: one per core).
    #[new]
    #[pyo3(signature = (scenario, robot=None, task=None, num_envs=1, seed=0, threads=0))]
    fn new(
        py: Python<'_>,
        scenario: &str,
        robot: Option<&str>,
        task: Option<&str>,
        num_envs: usize,
        seed: u64,
        threads: usize,
    ) -> PyResult<Self> {
        if num_envs == 0 {
            return Err(err("num_envs: expected at least 1"));
        }
        let setup = Arc::new(EnvSetup::load(scenario, robot, task.map(Path::new)).map_err(err)?);
        let s = setup.clone();
        let venv = py.detach(move || VecEnv::new(s, num_envs, seed, threads)).map_err(err)?;
        Ok(Self { setup, venv, actions: vec![[0.0; 2]; num_envs] })
    }

    /// Number of environments.
    #[getter]
    fn num_envs(&self) -> usize {
        self.venv.len()
    }

    /// Length of one observation.
    #[getter]
    fn obs_dim(&self) -> usize {
        self.venv.obs_dim()
    }

    /// The environments' description as a dict: scenario, robot, task (every key), the
    /// observation's terms with their spans, the lidar, the control period and how the
    /// normalised action maps to a velocity command.
    fn describe<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let s = &self.setup;
        let terms: Vec<serde_json::Value> = s
            .task
            .observation
            .spans()
            .map(|(start, t)| {
                serde_json::json!({"start": start, "len": t.len(), "name": t.name(), "describe": t.describe()})
            })
            .collect();
        let v = serde_json::json!({
            "scenario": s.scenario.spec().name,
            "robot": s.robot,
            "task": s.task,
            "observation": terms,
            "obs_dim": s.obs_dim(),
            "control_period": s.task.control_period,
            "max_steps": s.task.max_steps,
            "action": {"linear": s.task.action.linear, "angular": s.task.action.angular},
        });
        json_to_py(py, &v.to_string())
    }

    /// Per-value bounds of the observation `(low, high)` (infinite where the task leaves a
    /// value open), for the observation space.
    fn obs_bounds(&self) -> (Vec<f32>, Vec<f32>) {
        let (mut low, mut high) = (Vec::new(), Vec::new());
        for term in &self.setup.task.observation.0 {
            term_bounds(term, &self.setup.task, &mut low, &mut high);
        }
        (low, high)
    }

    /// Starts a new episode in every environment and writes the observations into `obs`
    /// (`float32[num_envs, obs_dim]`). With a `seed`, the environments are built again from
    /// it (the same seed gives the same episodes); without, each goes on with its stream.
    #[pyo3(signature = (obs, seed=None))]
    fn reset(&mut self, py: Python<'_>, mut obs: PyReadwriteArray2<f32>, seed: Option<u64>) -> PyResult<()> {
        let (setup, n, threads) = (self.setup.clone(), self.venv.len(), self.venv.threads());
        let venv = &mut self.venv;
        py.detach(move || match seed {
            Some(seed) => VecEnv::new(setup, n, seed, threads).map(|v| *venv = v),
            None => venv.reset_all(),
        })
        .map_err(err)?;
        self.write_obs(&mut obs)
    }

    /// Steps every environment with its normalised action (`float32[num_envs, 2]` in
    /// [-1, 1]: linear, angular) and writes the results into the caller's arrays; an
    /// environment whose episode ended starts the next one in the same step: `obs` holds the
    /// new episode's first observation and `final_obs` the last one of the episode that ended.
    /// Returns `[(index, stats)]` for the episodes that ended (stats: a dict of the episode's
    /// figures, as `rlnav bench` reports them).
    #[allow(clippy::too_many_arguments)]
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        actions: PyReadonlyArray2<'py, f32>,
        mut obs: PyReadwriteArray2<'py, f32>,
        mut rewards: PyReadwriteArray1<'py, f32>,
        mut terminated: PyReadwriteArray1<'py, bool>,
        mut truncated: PyReadwriteArray1<'py, bool>,
        mut final_obs: PyReadwriteArray2<'py, f32>,
    ) -> PyResult<Vec<(usize, Bound<'py, PyAny>)>> {
        self.check_rows("actions", actions.shape(), 2)?;
        self.check_rows("final_obs", final_obs.shape(), self.venv.obs_dim())?;
        self.check_rows("obs", obs.shape(), self.venv.obs_dim())?;
        for (what, len) in
            [("rewards", rewards.len()), ("terminated", terminated.len()), ("truncated", truncated.len())]
        {
            self.check_len(what, len)?;
        }
        let a = actions.as_slice().map_err(|_| err("actions: expected a C-contiguous float32 array"))?;
        for (i, (dst, src)) in self.actions.iter_mut().zip(a.chunks_exact(2)).enumerate() {
            if !src.iter().all(|x| x.is_finite()) {
                return Err(err(format!("actions[{i}]: expected finite values, got {src:?}")));
            }
            *dst = [src[0], src[1]];
        }
        let (venv, acts) = (&mut self.venv, &self.actions);
        py.detach(move || venv.step(acts)).map_err(err)?;
        let contiguous = |what: &str| err(format!("{what}: expected a C-contiguous array"));
        obs.as_slice_mut().map_err(|_| contiguous("obs"))?.copy_from_slice(&self.venv.obs);
        rewards.as_slice_mut().map_err(|_| contiguous("rewards"))?.copy_from_slice(&self.venv.rewards);
        terminated.as_slice_mut().map_err(|_| contiguous("terminated"))?.copy_from_slice(&self.venv.terminated);
        truncated.as_slice_mut().map_err(|_| contiguous("truncated"))?.copy_from_slice(&self.venv.truncated);
        let d = self.venv.obs_dim();
        let fobs = final_obs.as_slice_mut().map_err(|_| contiguous("final_obs"))?;
        let mut done = Vec::new();
        for (i, f) in self.venv.finished.iter().enumerate() {
            if let Some(stats) = f {
                fobs[i * d..(i + 1) * d].copy_from_slice(&self.venv.final_obs[i * d..(i + 1) * d]);
                done.push((i, stats_to_py(py, stats)?));
            }
        }
        Ok(done)
    }

    /// Environment `index` as a picture: `uint8[height, width, 3]`, `size` pixels along the
    /// longer side (world, movers, people, robot, goal and every `beam_stride`-th beam).
    #[pyo3(signature = (index=0, size=400, beam_stride=4))]
    fn render<'py>(&self, py: Python<'py>, index: usize, size: u32, beam_stride: usize) -> PyResult<Bound<'py, PyAny>> {
        let env = self
            .venv
            .envs()
            .get(index)
            .ok_or_else(|| err(format!("index: expected 0..{}, got {index}", self.venv.len())))?;
        let frame = Frame::capture(env, 0.0);
        let scene = Scene::of(&self.setup, env.world());
        let style = Style { size: size.clamp(16, 4096), beam_stride, trail: false };
        let img = scene.raster(&frame, &[], &style).map_err(err)?;
        let (w, h) = (img.width() as usize, img.height() as usize);
        Ok(PyArray1::from_vec(py, img.into_raw()).reshape([h, w, 3])?.into_any())
    }
}

/// Bounds of one term's values where the task fixes them (lidar clip, bearing, the clipped
/// command); measured velocities, distances and plan points are left open.
fn term_bounds(term: &ObsTerm, task: &rlnav_sim::TaskConfig, low: &mut Vec<f32>, high: &mut Vec<f32>) {
    let mut push = |lo: f32, hi: f32, n: usize| {
        low.extend(std::iter::repeat_n(lo, n));
        high.extend(std::iter::repeat_n(hi, n));
    };
    match term {
        // Free travel reads 0 with a return inside the swept disc.
        ObsTerm::Lidar { beams, clip, sweep } => push(if *sweep > 0.0 { 0.0 } else { clip[0] }, clip[1], *beams),
        ObsTerm::GoalBearing => push(-std::f32::consts::PI, std::f32::consts::PI, 1),
        ObsTerm::GoalDistance => push(0.0, f32::INFINITY, 1),
        // An episode starts with the zero command, which may lie outside the action's range.
        ObsTerm::LastLinear => push(task.action.linear[0].min(0.0), task.action.linear[1].max(0.0), 1),
        ObsTerm::LastAngular => push(task.action.angular[0].min(0.0), task.action.angular[1].max(0.0), 1),
        // Each step shown, and a predicted scan, reads as the term does.
        ObsTerm::History { term: inner, .. } => {
            for _ in 0..term.slots() {
                term_bounds(inner, task, low, high);
            }
        }
        other => push(f32::NEG_INFINITY, f32::INFINITY, other.len()),
    }
}

/// An episode's figures as a dict (`outcome` as a string; infinities and NaNs kept, which
/// JSON would lose).
fn stats_to_py<'py>(py: Python<'py>, s: &EpisodeStats) -> PyResult<Bound<'py, PyAny>> {
    let d = PyDict::new(py);
    let outcome = match s.outcome {
        Outcome::Success => "success",
        Outcome::Collision => "collision",
        Outcome::Timeout => "timeout",
    };
    d.set_item("outcome", outcome)?;
    d.set_item("length", s.length)?;
    for (k, v) in [
        ("episode_return", s.episode_return),
        ("time", s.time),
        ("min_range", s.min_range),
        ("mean_speed", s.mean_speed),
        ("path_length", s.path_length),
        ("initial_distance", s.initial_distance),
        ("final_distance", s.final_distance),
        ("wheel_radius", s.wheel_radius),
        ("wheel_separation", s.wheel_separation),
        ("speed_scale", s.speed_scale),
        ("min_person_gap", s.min_person_gap),
        ("mean_angular_acceleration", s.mean_angular_acceleration),
        ("optimal_path_length", s.optimal_path_length),
    ] {
        d.set_item(k, f64::from(v))?;
    }
    Ok(d.into_any())
}

/// Loads a scenario (shipped name or YAML file) and returns it as a dict, every key filled
/// in; a bad file raises `RlnavError` naming the file and the field.
#[pyfunction]
fn load_scenario<'py>(py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyAny>> {
    let spec = rlnav_sim::ScenarioSpec::load(name).map_err(err)?;
    json_to_py(py, &serde_json::to_string(&spec).map_err(err)?)
}

/// Loads a robot (shipped name or YAML file) and returns it as a dict.
#[pyfunction]
fn load_robot<'py>(py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyAny>> {
    let spec = rlnav_sim::RobotSpec::load(name).map_err(err)?;
    json_to_py(py, &serde_json::to_string(&spec).map_err(err)?)
}

/// Loads a task file (default: the built-in task) and returns it as a dict.
#[pyfunction]
#[pyo3(signature = (path=None))]
fn load_task<'py>(py: Python<'py>, path: Option<&str>) -> PyResult<Bound<'py, PyAny>> {
    let task = task_file(path)?;
    json_to_py(py, &serde_json::to_string(&task).map_err(err)?)
}

/// The shipped scenarios' names.
#[pyfunction]
fn scenarios() -> Vec<&'static str> {
    rlnav_sim::scenario::SCENARIO_PRESETS.iter().map(|(n, _)| *n).collect()
}

/// The shipped robots' names.
#[pyfunction]
fn robots() -> Vec<&'static str> {
    rlnav_sim::robot::ROBOT_PRESETS.iter().map(|(n, _)| *n).collect()
}

/// The extension module.
#[pymodule]
fn _rlnav(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<VecSim>()?;
    m.add_class::<export::OnnxPolicy>()?;
    m.add_function(wrap_pyfunction!(evaluate::evaluate, m)?)?;
    m.add_function(wrap_pyfunction!(export::export_mlp, m)?)?;
    m.add_function(wrap_pyfunction!(load_scenario, m)?)?;
    m.add_function(wrap_pyfunction!(load_robot, m)?)?;
    m.add_function(wrap_pyfunction!(load_task, m)?)?;
    m.add_function(wrap_pyfunction!(scenarios, m)?)?;
    m.add_function(wrap_pyfunction!(robots, m)?)?;
    m.add("RlnavError", m.py().get_type::<RlnavError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
