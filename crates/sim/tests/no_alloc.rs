//! Stepping allocates nothing: a counting global allocator watches the hot path.

use rlnav_sim::task::{EnvSetup, HistoryFill, HistoryOrder, NavEnv, ObsTerm, ObservationLayout, TaskConfig};
use rlnav_sim::vec_env::VecEnv;
use rlnav_sim::{RobotSpec, ScenarioSpec};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    /// Allocations made by this thread (the harness's own threads may allocate at any time).
    static MINE: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

fn count() {
    ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    // `try_with`: during thread teardown the slot may be gone.
    let _ = MINE.try_with(|c| c.set(c.get() + 1));
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn stepping_does_not_allocate() {
    let setup = Arc::new(EnvSetup::from_scenario_name("static-room").unwrap());
    let d = setup.obs_dim();

    // One environment: steps and resets of a fixed world.
    let mut env = NavEnv::new(setup.clone(), 3).unwrap();
    let mut obs = vec![0.0; d];
    let before = MINE.with(|c| c.get());
    let mut resets = 0;
    for i in 0..5000 {
        let out = env.step([((i % 7) as f32 / 3.0) - 1.0, ((i % 5) as f32 / 2.0) - 1.0]);
        env.write_observation(&mut obs);
        if out.terminated || out.truncated {
            env.reset().unwrap();
            resets += 1;
        }
    }
    assert!(resets > 5);
    assert_eq!(MINE.with(|c| c.get()) - before, 0, "NavEnv step/reset allocated");

    // A layout with history terms (the article's 133 values), the path ahead, a swept scan and
    // past scans moved by the robot's motion and a predicted scan: its past is kept in place,
    // the points, the sweep's table, the moved scan and the predicted scan's objects in
    // preallocated buffers.
    let spec = ScenarioSpec::load("static-room").unwrap();
    let robot = RobotSpec::load(&spec.robot).unwrap();
    let history = |term| ObsTerm::History {
        term: Box::new(term),
        steps: 5,
        stride: 2,
        order: HistoryOrder::OldestFirst,
        fill: HistoryFill::First,
        ego_motion: false,
        predict: 0.0,
    };
    let observation = ObservationLayout(vec![
        ObsTerm::Lidar { beams: 120, clip: [0.15, 2.0], sweep: 0.25 },
        // Past scans moved by the robot's motion, then swept, and the scan predicted.
        ObsTerm::History {
            term: Box::new(ObsTerm::Lidar { beams: 60, clip: [0.15, 3.0], sweep: 0.25 }),
            steps: 3,
            stride: 3,
            order: HistoryOrder::OldestFirst,
            fill: HistoryFill::First,
            ego_motion: true,
            predict: 1.0,
        },
        history(ObsTerm::GoalBearing),
        history(ObsTerm::GoalDistance),
        ObsTerm::Linear,
        ObsTerm::Lateral,
        ObsTerm::Angular,
        ObsTerm::PlanAhead { points: 4, spacing: 0.3 },
    ]);
    let task = TaskConfig { observation, ..Default::default() };
    let mut env = NavEnv::new(Arc::new(EnvSetup::new(spec, robot, task).unwrap()), 3).unwrap();
    let mut obs = vec![0.0; 381];
    let before = MINE.with(|c| c.get());
    for i in 0..2000 {
        // Every other step without a write: the step records its observation itself.
        let out = env.step([((i % 7) as f32 / 3.0) - 1.0, ((i % 5) as f32 / 2.0) - 1.0]);
        if i % 2 == 0 {
            env.write_observation(&mut obs);
        }
        if out.terminated || out.truncated {
            env.reset().unwrap();
        }
    }
    assert_eq!(MINE.with(|c| c.get()) - before, 0, "NavEnv with history terms allocated");

    // The batched environment on its worker threads.
    let mut venv = VecEnv::new(setup, 64, 3, 2).unwrap();
    let actions = vec![[0.5f32, 0.2]; 64];
    venv.step(&actions).unwrap(); // let the pool settle
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    for _ in 0..500 {
        venv.step(&actions).unwrap();
    }
    let per_step = (ALLOCATIONS.load(Ordering::Relaxed) - before) as f64 / 500.0;
    // rayon's job injection may allocate a queue block now and then; environments never do.
    assert!(per_step < 1.0, "{per_step} allocations per VecEnv step");
}
