//! A policy that acts for many episodes at once (a network in Python, a batched model) through
//! the same seeded episodes as [`evaluate_controller`](crate::evaluate::evaluate_controller):
//! every episode of every scenario runs in lockstep, one call of the policy per control step
//! for the whole batch, the simulation stepped in parallel between calls.

use crate::evaluate::{EpisodeTrace, EvalRun};
use rayon::prelude::*;
use rlnav_sim::task::EnvSetup;
use rlnav_sim::vec_env::env_seed;
use rlnav_sim::{EpisodeStats, EvalSummary, NavEnv};
use std::sync::Arc;

/// A policy that maps a batch of observations to normalised actions.
pub trait BatchPolicy {
    /// Writes one action per row of `obs` (`actions.len()` rows of `obs_dim` values,
    /// row-major), each `[linear, angular]` in `[-1, 1]` as the task's action maps it. Row `i`
    /// is the same episode from its first step to its last; rows whose episode has ended are
    /// still given (their last observation) and their actions ignored. An error stops the
    /// evaluation.
    fn act(&mut self, obs: &[f32], obs_dim: usize, actions: &mut [[f32; 2]]) -> Result<(), String>;
}

/// One episode in the batch.
struct Row {
    env: NavEnv,
    optimal: f32,
    trace: EpisodeTrace,
    stats: Option<EpisodeStats>,
}

/// Runs `episodes` episodes of each setup under `policy`, episode `k` of a setup seeded with
/// `env_seed(seed, k)` (the scenes [`evaluate_controller`](crate::evaluate::evaluate_controller)
/// gives every controller), stepping the simulation on `threads` threads. The setups must
/// share one observation length. Returns, per setup, the summary, every episode's figures
/// (with the shortest path's length, for SPL) and its trace.
pub fn evaluate_batch(
    setups: &[Arc<EnvSetup>],
    episodes: usize,
    seed: u64,
    threads: usize,
    policy: &mut dyn BatchPolicy,
) -> Result<Vec<EvalRun>, String> {
    let Some(first) = setups.first() else {
        return Ok(Vec::new());
    };
    let obs_dim = first.obs_dim();
    if let Some(s) = setups.iter().find(|s| s.obs_dim() != obs_dim) {
        return Err(format!(
            "{} gives {} observation values and {} gives {obs_dim}: one policy cannot take both",
            s.scenario.spec().name,
            s.obs_dim(),
            first.scenario.spec().name
        ));
    }
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().map_err(|e| format!("thread pool: {e}"))?;
    let mut rows: Vec<Row> = pool.install(|| {
        setups
            .par_iter()
            .flat_map_iter(|s| (0..episodes).map(move |k| (s, k)))
            .map(|(s, k)| {
                let env = NavEnv::new(s.clone(), env_seed(seed, k)).map_err(|e| e.to_string())?;
                let mut trace = EpisodeTrace::default();
                trace.push(&env, 0.0);
                Ok(Row { optimal: env.shortest_path_length().unwrap_or(f32::NAN), env, trace, stats: None })
            })
            .collect::<Result<_, String>>()
    })?;
    let mut obs = vec![0.0; rows.len() * obs_dim];
    let mut actions = vec![[0.0f32; 2]; rows.len()];
    while rows.iter().any(|r| r.stats.is_none()) {
        pool.install(|| {
            rows.par_iter_mut().zip(obs.par_chunks_mut(obs_dim)).for_each(|(r, o)| {
                if r.stats.is_none() {
                    r.env.write_observation(o);
                }
            })
        });
        policy.act(&obs, obs_dim, &mut actions)?;
        if let Some((i, a)) =
            actions.iter().enumerate().find(|(i, a)| rows[*i].stats.is_none() && !a.iter().all(|x| x.is_finite()))
        {
            return Err(format!("the policy's action for row {i} is not finite: {a:?}"));
        }
        pool.install(|| {
            rows.par_iter_mut().zip(&actions).for_each(|(r, a)| {
                if r.stats.is_some() {
                    return;
                }
                let out = r.env.step(*a);
                let period = r.env.setup().task.control_period;
                r.trace.push(&r.env, r.trace.time.len() as f32 * period);
                if out.terminated || out.truncated {
                    let mut stats = r.env.last_episode().expect("set when an episode ends");
                    stats.optimal_path_length = r.optimal;
                    r.stats = Some(stats);
                }
            })
        });
    }
    let mut out = Vec::with_capacity(setups.len());
    let mut rows = rows.into_iter();
    for _ in setups {
        let (stats, traces): (Vec<_>, Vec<_>) =
            rows.by_ref().take(episodes).map(|r| (r.stats.expect("every episode ended"), r.trace)).unzip();
        out.push((EvalSummary::of(&stats), stats, traces));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::evaluate::evaluate_controller;
    use rlnav_policy::PolicyRunner;
    use rlnav_sim::Controller;
    use rlnav_sim::task::TaskConfig;
    use std::path::Path;

    const POLICY: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../policies/jetbot-static-mlp.onnx");

    /// The shipped policy row by row on the simulator's own observations.
    struct Rows(PolicyRunner);

    impl BatchPolicy for Rows {
        fn act(&mut self, obs: &[f32], d: usize, actions: &mut [[f32; 2]]) -> Result<(), String> {
            for (o, a) in obs.chunks(d).zip(actions.iter_mut()) {
                *a = self.0.infer(o).map_err(|e| e.to_string())?.mu.map(|m| m.clamp(-1.0, 1.0));
            }
            Ok(())
        }
    }

    #[test]
    fn same_episodes_as_the_policy_run_as_a_controller() {
        // In a batch on the simulator's observations, or one episode at a time as a
        // Controller building its observation from scan and odometry: the same scenes and
        // the same drive.
        let runner = PolicyRunner::load(Path::new(POLICY), None).unwrap();
        let c = runner.contract().clone();
        let task = TaskConfig { control_period: c.control_period, action: c.action.ranges(), ..Default::default() };
        let setup = |name: &str| {
            let s = EnvSetup::from_scenario_name(name).unwrap();
            Arc::new(EnvSetup::new(s.scenario.spec().clone(), s.robot.clone(), task.clone()).unwrap())
        };
        let setups = vec![setup("random-static"), setup("empty-room")];
        let batch = evaluate_batch(&setups, 6, 3, 2, &mut Rows(runner)).unwrap();
        assert_eq!(batch.len(), 2);
        for (s, (summary, eps, traces)) in setups.iter().zip(&batch) {
            assert_eq!((eps.len(), summary.episodes), (6, 6));
            let make = || PolicyRunner::load(Path::new(POLICY), None).map(|r| Box::new(r) as Box<dyn Controller>);
            let (_, ctrl, _) = evaluate_controller(s.clone(), make, 6, 3, 1, None, &|_| {}).unwrap();
            for (a, b) in eps.iter().zip(&ctrl) {
                assert_eq!(a.initial_distance, b.initial_distance, "the same scene");
                assert_eq!(a.optimal_path_length.to_bits(), b.optimal_path_length.to_bits());
                assert_eq!((a.outcome, a.length), (b.outcome, b.length), "the same drive");
                assert!((a.path_length - b.path_length).abs() < 1e-3 * b.path_length.max(1.0));
            }
            for (e, t) in eps.iter().zip(traces) {
                assert_eq!(t.time.len(), e.length as usize + 1, "a trace point per step and the start");
            }
        }
    }

    #[test]
    fn a_policy_error_or_a_bad_action_stops_the_run() {
        struct Fails;
        impl BatchPolicy for Fails {
            fn act(&mut self, _: &[f32], _: usize, _: &mut [[f32; 2]]) -> Result<(), String> {
                Err("the callable raised".into())
            }
        }
        struct Nan;
        impl BatchPolicy for Nan {
            fn act(&mut self, _: &[f32], _: usize, a: &mut [[f32; 2]]) -> Result<(), String> {
                a[1] = [f32::NAN, 0.0];
                Ok(())
            }
        }
        let setups = vec![Arc::new(EnvSetup::from_scenario_name("empty-room").unwrap())];
        assert_eq!(evaluate_batch(&setups, 2, 0, 1, &mut Fails).unwrap_err(), "the callable raised");
        let e = evaluate_batch(&setups, 2, 0, 1, &mut Nan).unwrap_err();
        assert!(e.contains("row 1") && e.contains("not finite"), "{e}");
    }
}
