//! [`VecEnv`]: N navigation environments stepped in parallel, with automatic reset and
//! structure-of-arrays buffers ready for a learner.
//!
//! Every environment owns its random stream, seeded from the run seed and its index, so the
//! results are the same whatever the thread count. Stepping allocates nothing (only drawing a
//! procedurally generated world at reset does, and planning a path at reset for a task with a
//! `plan`).

use crate::task::{EnvSetup, EpisodeStats, NavEnv, SimError, privileged_len};
use rand::{RngExt, SeedableRng};
use rayon::prelude::*;
use std::sync::Arc;
use std::time::Instant;

/// Seed of environment `index` in a run seeded with `seed` (SplitMix64 finaliser, so that
/// neighbouring indices get unrelated streams).
pub fn env_seed(seed: u64, index: usize) -> u64 {
    let mut z = seed ^ (index as u64).wrapping_add(1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// N environments with shared setup, stepped together.
pub struct VecEnv {
    envs: Vec<NavEnv>,
    pool: rayon::ThreadPool,
    obs_dim: usize,
    /// Observations after the last step (after reset for environments that finished), `[n, obs_dim]`.
    pub obs: Vec<f32>,
    /// Rewards of the last step, `[n]`.
    pub rewards: Vec<f32>,
    /// Episode ended by success or collision in the last step, `[n]`.
    pub terminated: Vec<bool>,
    /// Episode cut by the time limit in the last step, `[n]`.
    pub truncated: Vec<bool>,
    /// Final observation of environments that finished in the last step (for bootstrapping
    /// time-outs), `[n, obs_dim]`; rows of running environments are stale.
    pub final_obs: Vec<f32>,
    /// Statistics of the episodes that finished in the last step, per environment.
    pub finished: Vec<Option<EpisodeStats>>,
    /// Privileged state per environment (`[env][privileged_len]`, empty unless
    /// [`VecEnv::set_privileged`] asked for it): what a training critic reads beside `obs`.
    pub privileged: Vec<f32>,
    /// The privileged state at the end of an episode, where `terminated` or `truncated`.
    pub final_privileged: Vec<f32>,
    /// Movers in the privileged state (0: none kept).
    privileged_movers: usize,
    /// One `true` per environment: [`Self::step`]'s flags, kept so that a step allocates nothing.
    all_active: Vec<bool>,
}

/// Environments per rayon task: enough work to amortise scheduling.
const CHUNK: usize = 16;

impl VecEnv {
    /// Builds `n` environments on `threads` worker threads (0: rayon's default).
    pub fn new(setup: Arc<EnvSetup>, n: usize, seed: u64, threads: usize) -> Result<Self, SimError> {
        Self::new_mixed(std::slice::from_ref(&setup), n, seed, threads)
    }

    /// Builds `n` environments, environment `i` with `setups[i % setups.len()]` (several
    /// robots, say, in one batch), on `threads` worker threads (0: rayon's default). The
    /// setups must give observations of one length.
    pub fn new_mixed(setups: &[Arc<EnvSetup>], n: usize, seed: u64, threads: usize) -> Result<Self, SimError> {
        assert!(!setups.is_empty(), "at least one setup");
        let d = setups[0].obs_dim();
        if let Some(other) = setups.iter().find(|s| s.obs_dim() != d) {
            return Err(SimError::Incompatible {
                robot: other.robot.name.clone(),
                message: format!(
                    "its observation has {} values, {}'s in the same batch {d}",
                    other.obs_dim(),
                    setups[0].robot.name
                ),
            });
        }
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .thread_name(|i| format!("rlnav-sim-{i}"))
            .build()
            .expect("a thread pool can be built");
        let envs = pool.install(|| {
            (0..n)
                .into_par_iter()
                .map(|i| NavEnv::new(setups[i % setups.len()].clone(), env_seed(seed, i)))
                .collect::<Result<Vec<_>, _>>()
        })?;
        let mut v = Self {
            envs,
            pool,
            obs_dim: d,
            obs: vec![0.0; n * d],
            rewards: vec![0.0; n],
            terminated: vec![false; n],
            truncated: vec![false; n],
            final_obs: vec![0.0; n * d],
            finished: vec![None; n],
            privileged: Vec::new(),
            final_privileged: Vec::new(),
            privileged_movers: 0,
            all_active: vec![true; n],
        };
        for (env, o) in v.envs.iter_mut().zip(v.obs.chunks_mut(d)) {
            env.write_observation(o);
        }
        Ok(v)
    }

    /// Number of environments.
    pub fn len(&self) -> usize {
        self.envs.len()
    }

    /// Whether there are no environments.
    pub fn is_empty(&self) -> bool {
        self.envs.is_empty()
    }

    /// Length of one observation.
    pub fn obs_dim(&self) -> usize {
        self.obs_dim
    }

    /// Worker threads.
    pub fn threads(&self) -> usize {
        self.pool.current_num_threads()
    }

    /// The environments (for inspection: poses, worlds, scans).
    pub fn envs(&self) -> &[NavEnv] {
        &self.envs
    }

    /// Starts an automatic curriculum: every environment goes to a level drawn uniformly from
    /// `0..=start_max` of its setup's [`EnvSetup::levels`] (which must be built) and starts a
    /// new episode there; from then on each episode's outcome moves its environment's level
    /// ([`NavEnv::advance_level`]).
    pub fn start_levels(&mut self, start_max: usize, seed: u64) -> Result<(), SimError> {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
        for env in &mut self.envs {
            assert!(!env.setup().levels.is_empty(), "difficulty levels are built for every setup");
            env.set_level(Some(rng.random_range(0..=start_max)));
        }
        self.reset_all()
    }

    /// Starts a new episode in every environment (each from its own random stream, which
    /// goes on where it was) and writes the observations.
    pub fn reset_all(&mut self) -> Result<(), SimError> {
        let d = self.obs_dim;
        let Self { envs, pool, obs, finished, .. } = self;
        finished.iter_mut().for_each(|f| *f = None);
        pool.install(|| {
            envs.par_iter_mut().zip(obs.par_chunks_mut(d)).try_for_each(|(env, o)| {
                env.reset()?;
                env.write_observation(o);
                Ok::<(), SimError>(())
            })
        })?;
        self.write_privileged(false);
        Ok(())
    }

    /// Mean difficulty of the environments' levels in [0, 1] (`None` without levels).
    pub fn mean_difficulty(&self) -> Option<f32> {
        let (sum, n) = self
            .envs
            .iter()
            .filter_map(|e| e.level().map(|l| l as f32 / (e.setup().levels.len() - 1).max(1) as f32))
            .fold((0.0, 0usize), |(s, n), d| (s + d, n + 1));
        (n > 0).then(|| sum / n as f32)
    }

    /// Steps every environment with its normalised action (`actions.len() == len()`),
    /// resetting those whose episode ended.
    pub fn step(&mut self, actions: &[[f32; 2]]) -> Result<(), SimError> {
        self.step_some(actions, None)
    }

    /// As [`Self::step`], but with `active` (one flag per environment) only the flagged
    /// environments step; the others keep their state and observation and report a zero
    /// reward and no episode end. Evaluation uses it to stop environments that have run their
    /// quota of episodes while the slowest finish theirs.
    pub fn step_some(&mut self, actions: &[[f32; 2]], active: Option<&[bool]>) -> Result<(), SimError> {
        assert_eq!(actions.len(), self.envs.len(), "one action per environment");
        if let Some(a) = active {
            assert_eq!(a.len(), self.envs.len(), "one flag per environment");
        }
        let d = self.obs_dim;
        let Self { envs, pool, obs, rewards, terminated, truncated, final_obs, finished, all_active, .. } = self;
        let active = active.unwrap_or(all_active);
        pool.install(|| {
            envs.par_chunks_mut(CHUNK)
                .zip(actions.par_chunks(CHUNK))
                .zip(obs.par_chunks_mut(CHUNK * d))
                .zip(final_obs.par_chunks_mut(CHUNK * d))
                .zip(rewards.par_chunks_mut(CHUNK))
                .zip(terminated.par_chunks_mut(CHUNK))
                .zip(truncated.par_chunks_mut(CHUNK))
                .zip(finished.par_chunks_mut(CHUNK))
                .zip(active.par_chunks(CHUNK))
                .try_for_each(|((((((((envs, acts), obs), fobs), rew), term), trunc), fin), on)| {
                    for i in 0..envs.len() {
                        if !on[i] {
                            (rew[i], term[i], trunc[i], fin[i]) = (0.0, false, false, None);
                            continue;
                        }
                        let env = &mut envs[i];
                        let out = env.step(acts[i]);
                        rew[i] = out.reward;
                        term[i] = out.terminated;
                        trunc[i] = out.truncated;
                        let o = &mut obs[i * d..(i + 1) * d];
                        if out.terminated || out.truncated {
                            env.write_observation(&mut fobs[i * d..(i + 1) * d]);
                            fin[i] = env.last_episode();
                            if let Some(e) = &fin[i] {
                                env.advance_level(e.outcome == crate::task::Outcome::Success);
                            }
                            env.keep_final_privileged();
                            env.reset()?;
                        } else {
                            fin[i] = None;
                        }
                        env.write_observation(o);
                    }
                    Ok::<(), SimError>(())
                })
        })?;
        self.write_privileged(true);
        Ok(())
    }

    /// Keeps the privileged state of `movers` movers per environment from now on
    /// (`privileged` and `final_privileged`, [`crate::task::privileged_len`] values each; 0
    /// keeps none).
    pub fn set_privileged(&mut self, movers: usize) {
        self.privileged_movers = movers;
        let p = privileged_len(movers);
        self.privileged = vec![0.0; self.envs.len() * p];
        self.final_privileged = vec![0.0; self.envs.len() * p];
        for env in &mut self.envs {
            env.set_privileged_movers(movers);
        }
        self.write_privileged(false);
    }

    /// Length of one environment's privileged state (0 when none is kept).
    pub fn privileged_dim(&self) -> usize {
        privileged_len(self.privileged_movers)
    }

    /// Writes the current privileged state and, with `finals`, the final one of the
    /// environments whose episode just ended.
    fn write_privileged(&mut self, finals: bool) {
        let (k, p) = (self.privileged_movers, self.privileged_dim());
        if k == 0 {
            return;
        }
        for (i, env) in self.envs.iter().enumerate() {
            env.write_privileged(k, &mut self.privileged[i * p..(i + 1) * p]);
            if finals && (self.terminated[i] || self.truncated[i]) {
                self.final_privileged[i * p..(i + 1) * p].copy_from_slice(env.final_privileged());
            }
        }
    }
}

/// What `rlnav sim-speed` measures.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SpeedReport {
    /// Environment (control) steps per second, resets included.
    pub env_steps_per_s: f64,
    /// Lidar beams cast per second.
    pub rays_per_s: f64,
    /// Environments.
    pub envs: usize,
    /// Worker threads.
    pub threads: usize,
    /// Beams per scan.
    pub beams: usize,
    /// Obstacles in the first environment's world (walls count one each).
    pub obstacles: usize,
    /// Episodes that ended during the measurement.
    pub episodes: usize,
    /// Steps measured.
    pub steps: usize,
}

/// Steps `env` with uniformly random actions for `steps` rounds (after `warmup` rounds) and
/// reports the throughput.
pub fn measure_speed(env: &mut VecEnv, steps: usize, warmup: usize, seed: u64) -> Result<SpeedReport, SimError> {
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
    let mut actions = vec![[0.0f32; 2]; env.len()];
    let mut episodes = 0;
    let mut elapsed = 0.0;
    for round in 0..warmup + steps {
        for a in actions.iter_mut() {
            *a = [rng.random_range(-1.0..=1.0), rng.random_range(-1.0..=1.0)];
        }
        let t = Instant::now();
        env.step(&actions)?;
        if round >= warmup {
            elapsed += t.elapsed().as_secs_f64();
            episodes += env.finished.iter().filter(|f| f.is_some()).count();
        }
    }
    let env_steps = (steps * env.len()) as f64;
    let beams = env.envs.first().map_or(0, |e| e.setup().lidar.beams());
    Ok(SpeedReport {
        env_steps_per_s: env_steps / elapsed,
        rays_per_s: env_steps * beams as f64 / elapsed,
        envs: env.len(),
        threads: env.threads(),
        beams,
        obstacles: env.envs.first().map_or(0, |e| e.world().obstacles().len()),
        episodes,
        steps: steps * env.len(),
    })
}

/// Times the culled caster and the parry2d brute-force reference on the scene and pose of
/// `env`, `scans` scans each, on the calling thread. Returns scans per second `(fast, reference)`.
pub fn compare_casters(env: &NavEnv, scans: usize) -> (f64, f64) {
    let lidar = &env.setup().lidar;
    let world = env.world();
    let n = lidar.beams();
    let (mut dirs, mut out) = (vec![crate::geometry::Vec2::ZERO; n], vec![0.0; n]);
    let mut pose = env.pose();
    let t = std::time::Instant::now();
    for i in 0..scans {
        pose.yaw = crate::geometry::wrap_angle(pose.yaw + 0.001 * i as f32);
        lidar.scan(&pose, world.ray_geometry(), &mut dirs, &mut out);
        std::hint::black_box(&out);
    }
    let fast = scans as f64 / t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    let ref_scans = (scans / 10).max(1);
    for i in 0..ref_scans {
        pose.yaw = crate::geometry::wrap_angle(pose.yaw + 0.001 * i as f32);
        lidar.scan_reference(&pose, world, &mut out);
        std::hint::black_box(&out);
    }
    (fast, ref_scans as f64 / t.elapsed().as_secs_f64())
}
