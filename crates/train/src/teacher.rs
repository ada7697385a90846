//! A classical controller as teacher (kickstarting, `train.teacher`): it labels the states
//! the policy visits with the command it would give there, and the update pulls the policy's
//! mean towards it (see [`crate::config::TeacherConfig`]).

use std::sync::Arc;

use rayon::prelude::*;
use rlnav_planners::dwa::{Dwa, DwaConfig};
use rlnav_sim::geometry::Rect;
use rlnav_sim::{Controller, NavEnv, RobotObservation, Vec2, VecEnv, World};

use crate::config::TeacherConfig;

/// One labelled environment's teacher.
struct Slot {
    env: usize,
    dwa: Option<Dwa>,
    /// The world `dwa`'s prior map was built from.
    world: Option<Arc<World>>,
    obs: RobotObservation,
    label: [f32; 2],
}

/// Teachers for a share of a batch's environments.
pub struct Teacher {
    slots: Vec<Slot>,
    /// `slot_of[e]`: environment `e`'s slot, if it is labelled.
    slot_of: Vec<Option<usize>>,
}

impl Teacher {
    /// Teachers for every `1/share`-th environment of a batch of `n`.
    pub fn new(cfg: &TeacherConfig, n: usize) -> Self {
        let stride = (1.0 / cfg.share).round().max(1.0) as usize;
        let mut slot_of = vec![None; n];
        let slots: Vec<Slot> = (0..n)
            .step_by(stride)
            .enumerate()
            .map(|(k, env)| {
                slot_of[env] = Some(k);
                Slot { env, dwa: None, world: None, obs: RobotObservation::default(), label: [0.0; 2] }
            })
            .collect();
        Self { slots, slot_of }
    }

    /// Environments labelled.
    pub fn labelled(&self) -> usize {
        self.slots.len()
    }

    /// Writes the teacher's action (in the policy's [-1, 1] units) for the current state of
    /// every labelled environment into `out` (`[env][act]`), NaN for the others.
    pub fn label(&mut self, env: &VecEnv, out: &mut [f32], act: usize) {
        out.fill(f32::NAN);
        let envs = env.envs();
        self.slots.par_iter_mut().for_each(|s| {
            let e = &envs[s.env];
            e.robot_observation(&mut s.obs);
            let mut obs = std::mem::take(&mut s.obs);
            let cmd = s.teacher_for(e).act(&obs);
            std::mem::swap(&mut s.obs, &mut obs);
            s.label = e.setup().task.action.to_action(cmd);
        });
        for s in &self.slots {
            out[s.env * act..s.env * act + 2].copy_from_slice(&s.label);
        }
    }

    /// Environment `e`'s episode ended: its teacher forgets the episode.
    pub fn episode_ended(&mut self, e: usize) {
        if let Some(k) = self.slot_of.get(e).copied().flatten()
            && let Some(d) = &mut self.slots[k].dwa
        {
            d.reset();
        }
    }
}

impl Slot {
    /// The teacher for `env`'s episode: DWA with the episode's world as its prior map (Nav2 with
    /// the room's map, as the benchmark runs it), rebuilt when the world changes.
    fn teacher_for(&mut self, env: &NavEnv) -> &mut Dwa {
        let world = env.world();
        if self.world.as_ref().is_none_or(|w| !Arc::ptr_eq(w, world)) || self.dwa.is_none() {
            let setup = env.setup();
            let a = setup.scenario.area();
            let bounds = Rect { min: a.min - Vec2::splat(0.5), max: a.max + Vec2::splat(0.5) };
            self.dwa = Some(Dwa::new(DwaConfig::for_setup(setup), bounds, Some(world.clone())));
            self.world = Some(world.clone());
        }
        self.dwa.as_mut().expect("built above")
    }
}
