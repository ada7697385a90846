//! Per-cycle compute time of a controller: what one control step costs on this machine (for an
//! RL policy: the observation built from the scan, inference, the command), as percentiles.

use rlnav_sim::task::{EnvSetup, SimError};
use rlnav_sim::{Controller, NavEnv, RobotObservation};
use serde::Serialize;
use std::sync::Arc;
use std::time::Instant;

/// Latency percentiles over many control cycles (microseconds).
#[derive(Clone, Debug, Serialize)]
pub struct LatencyReport {
    /// Controller name.
    pub controller: String,
    /// Cycles timed.
    pub cycles: usize,
    /// Beams of the scans it was given.
    pub beams: usize,
    /// Median (µs).
    pub p50_us: f64,
    /// 99th percentile (µs).
    pub p99_us: f64,
    /// Mean (µs).
    pub mean_us: f64,
    /// Slowest (µs).
    pub max_us: f64,
}

/// Times `controller.act` on `cycles` observations from episodes of `setup` (the simulation
/// step between cycles is not timed), after `warmup` untimed cycles.
pub fn measure_latency(
    controller: &mut dyn Controller,
    setup: Arc<EnvSetup>,
    cycles: usize,
    warmup: usize,
    seed: u64,
) -> Result<LatencyReport, SimError> {
    let mut env = NavEnv::new(setup.clone(), seed)?;
    let mut obs = RobotObservation::default();
    let mut times = Vec::with_capacity(cycles);
    controller.reset();
    for i in 0..warmup + cycles {
        env.robot_observation(&mut obs);
        let t = Instant::now();
        let cmd = controller.act(&obs);
        let dt = t.elapsed().as_secs_f64() * 1e6;
        if i >= warmup {
            times.push(dt);
        }
        let s = env.step_twist(cmd);
        if s.terminated || s.truncated {
            env.reset()?;
            controller.reset();
        }
    }
    times.sort_by(f64::total_cmp);
    let pct = |p: f64| times[((times.len() - 1) as f64 * p).round() as usize];
    Ok(LatencyReport {
        controller: controller.name().to_string(),
        cycles,
        beams: setup.lidar.beams(),
        p50_us: pct(0.5),
        p99_us: pct(0.99),
        mean_us: times.iter().sum::<f64>() / times.len().max(1) as f64,
        max_us: *times.last().unwrap_or(&0.0),
    })
}

/// Times each controller spec (`dwa`, `rl:FILE`, ...) on `setup`, one after another on this
/// thread, for the benchmark's per-cycle compute table.
pub fn measure_controllers(
    specs: &[String],
    setup: &Arc<EnvSetup>,
    cycles: usize,
    seed: u64,
) -> Result<Vec<LatencyReport>, crate::suite::BenchError> {
    let mut out = Vec::new();
    for spec in specs {
        let bad = |message: String| crate::suite::BenchError::Controller { name: spec.clone(), message };
        let mut c = crate::controllers::for_setup(spec, setup).map_err(|e| bad(e.to_string()))?;
        let mut r = measure_latency(c.as_mut(), setup.clone(), cycles, (cycles / 10).min(200), seed)
            .map_err(|e| bad(e.to_string()))?;
        r.controller = spec.clone();
        out.push(r);
    }
    Ok(out)
}

/// The per-cycle compute table (Markdown) for `reports` measured on `scenario`.
pub fn markdown(reports: &[LatencyReport], scenario: &str) -> String {
    let mut s = format!(
        "## Per-cycle compute ({scenario}, one thread)\n\n| controller | beams | p50 (µs) | p99 (µs) | mean (µs) | max (µs) |\n|---|---|---|---|---|---|\n"
    );
    for r in reports {
        s += &format!(
            "| {} | {} | {:.1} | {:.1} | {:.1} | {:.1} |\n",
            r.controller, r.beams, r.p50_us, r.p99_us, r.mean_us, r.max_us
        );
    }
    s
}
