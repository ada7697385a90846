//! `rlnav.evaluate`'s native part: a Python callable through a benchmark suite beside the
//! named controllers, on the same seeded episodes, giving `rlnav bench`'s tables and files.

use crate::{err, task_file};
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::prelude::*;
use rlnav_bench::batch::BatchPolicy;
use rlnav_bench::suite::{BatchEntry, RunOptions, SuiteSpec, run_suite_with, suite_setups_under};
use std::path::Path;

/// A Python callable as a [`BatchPolicy`]: called with the GIL taken again for each batch.
struct PyPolicy(Py<PyAny>);

impl BatchPolicy for PyPolicy {
    fn act(&mut self, obs: &[f32], obs_dim: usize, actions: &mut [[f32; 2]]) -> Result<(), String> {
        Python::attach(|py| {
            let mut call = || -> PyResult<()> {
                // Ctrl-C in a long evaluation raises KeyboardInterrupt here.
                py.check_signals()?;
                let rows = actions.len();
                let x = PyArray1::from_slice(py, obs).reshape([rows, obs_dim])?;
                let out = self.0.call1(py, (x,))?;
                let a: PyReadonlyArray2<f32> = out.extract(py).map_err(|_| {
                    err(format!(
                        "the policy must return a float32 array of shape ({rows}, 2), got {}",
                        describe(py, &out)
                    ))
                })?;
                if a.shape() != [rows, 2] {
                    return Err(err(format!("the policy must return shape ({rows}, 2), got {:?}", a.shape())));
                }
                for (dst, src) in actions.iter_mut().zip(a.as_array().rows()) {
                    *dst = [src[0], src[1]];
                }
                Ok(())
            };
            call().map_err(|e| format_py_err(py, &e))
        })
    }
}

/// `type(x).__name__` and, for arrays, dtype and shape.
fn describe(py: Python<'_>, x: &Py<PyAny>) -> String {
    let x = x.bind(py);
    let ty = x.get_type().name().map(|n| n.to_string()).unwrap_or_else(|_| "?".into());
    match (x.getattr("dtype"), x.getattr("shape")) {
        (Ok(d), Ok(s)) => format!("{ty} of {d} with shape {s}"),
        _ => ty,
    }
}

/// A Python exception as one line: `KeyError: 'x'`.
fn format_py_err(py: Python<'_>, e: &PyErr) -> String {
    let ty = e.get_type(py).name().map(|n| n.to_string()).unwrap_or_else(|_| "Exception".into());
    format!("{ty}: {}", e.value(py))
}

/// Runs `policy` (observations `float32[n, obs_dim]` → normalised actions `float32[n, 2]`)
/// on the suite `suite` (a shipped name or a file) or on the one-scenario suite `scenario`,
/// then the `baselines` (controller names as `rlnav bench --controller` takes them), each on
/// the same seeded episodes. `task` (a task file) is the policy's observation, action and
/// control period; `baseline_task` (a task file) is the task the baselines run under and the
/// rest of the policy's (time limit, collision range), as `rlnav bench --task` sets them
/// (default: the built-in task). With `out`, writes what `rlnav bench --out` writes (report.md,
/// report.json, report.html, figures). Returns `(markdown, json)`: the suite's cells and
/// episodes (no traces) and `pooled`, each controller's summary over the whole suite.
#[pyfunction]
#[pyo3(signature = (policy, suite=None, scenario=None, robot=None, task=None, episodes=None, seed=7, threads=0, baselines=Vec::new(), name="python".to_string(), out=None, baseline_task=None))]
#[allow(clippy::too_many_arguments)]
pub fn evaluate(
    py: Python<'_>,
    policy: Py<PyAny>,
    suite: Option<&str>,
    scenario: Option<&str>,
    robot: Option<&str>,
    task: Option<&str>,
    episodes: Option<usize>,
    seed: u64,
    threads: usize,
    baselines: Vec<String>,
    name: String,
    out: Option<&str>,
    baseline_task: Option<&str>,
) -> PyResult<(String, String)> {
    let spec = match (suite, scenario) {
        (Some(s), None) => SuiteSpec::load(s).map_err(err)?,
        (None, Some(s)) => SuiteSpec {
            name: s.to_string(),
            description: String::new(),
            scenarios: vec![s.to_string()],
            barn: None,
            episodes: 20,
        },
        _ => return Err(err("give one of `suite` (a suite name or file) and `scenario`")),
    };
    if episodes == Some(0) {
        return Err(err("episodes: expected at least 1"));
    }
    if baselines.contains(&name) {
        return Err(err(format!("name: `{name}` is also a baseline's name; give the policy another")));
    }
    let task = task_file(task)?;
    let base = task_file(baseline_task)?;
    let threads = if threads == 0 { std::thread::available_parallelism().map_or(1, |n| n.get()) } else { threads };
    let opts = RunOptions {
        robot,
        episodes: episodes.unwrap_or(spec.episodes),
        seed,
        threads,
        record: None,
        task: Some(&base),
    };
    let mut callable = PyPolicy(policy);
    let result = py
        .detach(|| {
            let entry = BatchEntry { name: &name, task: &task, policy: &mut callable };
            run_suite_with(&spec, Some(entry), &baselines, &opts, &mut |_, _| {})
        })
        .map_err(err)?;
    let markdown = result.markdown();
    let json = serde_json::json!({ "suites": [&result] });
    // What Python gets back: every figure but the step-by-step traces (report.json keeps them).
    let mut brief = json.clone();
    for cell in brief["suites"][0]["cells"].as_array_mut().into_iter().flatten() {
        cell.as_object_mut().map(|c| c.remove("traces"));
    }
    brief["pooled"] =
        serde_json::to_value(result.pooled().into_iter().collect::<std::collections::BTreeMap<_, _>>()).map_err(err)?;
    if let Some(dir) = out {
        let dir = Path::new(dir);
        let io = |what: &Path, e: &dyn std::fmt::Display| err(format!("writing {}: {e}", what.display()));
        std::fs::create_dir_all(dir).map_err(|e| io(dir, &e))?;
        let setups = suite_setups_under(&spec, robot, &base).map_err(err)?;
        rlnav_bench::plots::write_suite_figures(&result, &setups, dir).map_err(err)?;
        for (file, text) in [("report.md", markdown.clone()), ("report.json", json.to_string())] {
            std::fs::write(dir.join(file), text).map_err(|e| io(&dir.join(file), &e))?;
        }
        rlnav_bench::report::write_html(dir, std::slice::from_ref(&result)).map_err(err)?;
    }
    Ok((markdown, brief.to_string()))
}
