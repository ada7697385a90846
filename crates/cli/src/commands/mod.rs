//! One module per `rlnav` command (its arguments and its code), and what several share.

pub mod barn;
pub mod bench;
pub mod demo;
pub mod eval;
pub mod export;
pub mod inspect;
pub mod latency;
pub mod list;
pub mod render;
pub mod robot;
pub mod ros2;
pub mod sim_speed;
pub mod train;

use anyhow::{Context, Result};
use rlnav_sim::task::EnvSetup;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// The scenario, robot and task a command runs (`--scenario`, `--robot`, `--task`).
#[derive(clap::Args)]
pub struct EnvArgs {
    /// Scenario: a shipped name (see `rlnav list`) or a YAML file.
    #[arg(long, default_value = "static-room")]
    pub scenario: String,
    /// Robot: a shipped name or a YAML file (default: the scenario's).
    #[arg(long)]
    pub robot: Option<String>,
    /// Task file (default: configs/task.yaml's values, built in).
    #[arg(long)]
    pub task: Option<PathBuf>,
}

impl EnvArgs {
    /// Loads the three and checks that they fit together.
    pub fn setup(&self) -> Result<Arc<EnvSetup>> {
        Ok(Arc::new(EnvSetup::load(&self.scenario, self.robot.as_deref(), self.task.as_deref())?))
    }

    /// [`Self::setup`] for `controller`: a policy runs under its own action ranges, control
    /// period and plan (`rlnav_bench::controllers::task_for`) on top of `--task`, as in
    /// `rlnav bench`, so that a command shows the robot the policy was trained to drive.
    pub fn setup_for(&self, controller: &str) -> Result<Arc<EnvSetup>> {
        let setup = self.setup()?;
        let task = rlnav_bench::controllers::task_for(controller, &setup.task)?;
        if task == setup.task {
            return Ok(setup);
        }
        Ok(Arc::new(EnvSetup::new(setup.scenario.spec().clone(), setup.robot.clone(), task)?))
    }
}

/// Writes `value` as pretty JSON to `path` (creating its folder) and says so.
pub fn write_json(path: &Path, value: &impl serde::Serialize) -> Result<()> {
    create_parent(path)?;
    std::fs::write(path, serde_json::to_string_pretty(value)?)
        .with_context(|| format!("writing {}", path.display()))?;
    println!("wrote {}", path.display());
    Ok(())
}

/// Creates the folder `path` will be written in, if it has one.
pub fn create_parent(path: &Path) -> Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    Ok(())
}

/// A flag set by Ctrl-C (and SIGTERM), for loops that must end by leaving the robot stopped.
pub fn stop_flag() -> Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    let s = stop.clone();
    ctrlc::set_handler(move || s.store(true, Ordering::SeqCst)).context("installing the Ctrl-C handler")?;
    Ok(stop)
}

/// A progress bar of `len` steps with `what` after the count (`episodes`, `epochs`).
pub fn progress_bar(len: u64, what: &str) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(len);
    let template = format!("{{bar:30}} {{pos}}/{{len}} {what} [{{elapsed_precise}} eta {{eta}}] {{msg}}");
    bar.set_style(indicatif::ProgressStyle::with_template(&template).expect("a valid template"));
    bar
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `--task` sets what a policy's contract does not (here the time limit); the policy keeps
    /// its contract's action ranges, and a classical controller takes the file's.
    #[test]
    fn a_policy_keeps_its_action_ranges_under_task() {
        let dir = std::env::temp_dir().join(format!("rlnav-setup-for-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("task.yaml");
        std::fs::write(&file, "max_steps: 321\naction:\n  linear: [0.0, 0.3]\n").unwrap();
        let policy = concat!(env!("CARGO_MANIFEST_DIR"), "/../../policies/default.onnx");
        let args = EnvArgs { scenario: "static-room".into(), robot: Some("jetbot".into()), task: Some(file) };
        let rl = args.setup_for(&format!("rl:{policy}")).unwrap();
        assert_eq!(rl.task.max_steps, 321);
        assert_eq!(rl.task.action.linear, [0.1, 0.5], "the contract's ranges");
        let dwa = args.setup_for("dwa").unwrap();
        assert_eq!((dwa.task.max_steps, dwa.task.action.linear), (321, [0.0, 0.3]));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
