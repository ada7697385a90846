//! The BARN-like generator against the dataset it imitates.

use rand::SeedableRng;
use rlnav_sim::barn::generate::try_world;
use rlnav_sim::barn::{BarnSet, Difficulty};
use rlnav_sim::scenario::{Scenario, ScenarioSpec};

/// Mean of each metric.
fn means(d: &[Difficulty]) -> [f32; 5] {
    let mut m = [0.0; 5];
    for x in d {
        for (k, v) in x.values().iter().enumerate() {
            m[k] += v / d.len() as f32;
        }
    }
    m
}

/// With the dataset's schedule (fill 0.15 to 0.30 in steps of 0.05, 2 to 4 smoothing passes,
/// 25 worlds each), the drawn worlds are about as hard as BARN's own by every metric.
#[test]
fn drawn_worlds_are_as_hard_as_the_dataset() {
    let shipped = BarnSet::shipped().unwrap();
    let barn: Vec<Difficulty> = shipped.worlds.iter().map(|w| w.difficulty.unwrap()).collect();
    let mut drawn = Vec::new();
    let mut draws = [0; 12];
    let mut rng = rand_pcg::Pcg64::seed_from_u64(2020);
    for i in 0..300 {
        let (fill, smoothing) = (0.15 + 0.05 * (i / 75) as f32, 2 + ((i % 75) / 25) as u32);
        loop {
            draws[i / 25] += 1;
            if let Some(w) = try_world(&mut rng, fill, smoothing) {
                drawn.push(w.difficulty);
                break;
            }
        }
    }
    let (b, d) = (means(&barn), means(&drawn));
    eprintln!("mean metrics, BARN {b:?}\ndrawn {d:?}\ndraws per 25 worlds {draws:?}");
    // Seed 2020 gives 0.4, 1.4, 2.0, 1.5 and 2.4% off; a sample of 300 worlds wanders by a
    // few percent on its own.
    for k in 0..5 {
        let off = (d[k] - b[k]).abs() / b[k];
        assert!(off < 0.08, "{}: drawn {} against BARN {} ({:.1}% off)", Difficulty::NAMES[k], d[k], b[k], 100.0 * off);
    }
    // Denser fills are the ones thrown away (the dataset's own generator kept 1 in ~1800 at
    // 0.30 with 2 passes).
    assert!(draws[0] < draws[9], "{draws:?}");
}

/// The training scenario draws a new BARN-like world every episode, in the challenge's frame,
/// with the start and the goal clear; at difficulty 0 its clutter is the sparsest.
#[test]
fn the_training_scenario_draws_a_new_world_every_episode() {
    let spec = ScenarioSpec::load("barn-generated").unwrap();
    let scenario = Scenario::new(spec.clone(), 0.35, 0.0).unwrap();
    let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
    let a = scenario.sample(&mut rng).unwrap();
    let b = scenario.sample(&mut rng).unwrap();
    assert_ne!(a.world.obstacles().len(), 0);
    let specs = |w: &rlnav_sim::World| w.obstacles().iter().map(|o| o.spec.clone()).collect::<Vec<_>>();
    assert_ne!(specs(&a.world), specs(&b.world), "a new world per episode");
    assert_eq!((a.start.x, a.start.y, a.goal.x, a.goal.y), (-2.25, 3.0, -2.25, 13.0));
    let count = |s: &ScenarioSpec| {
        let sc = Scenario::new(s.clone(), 0.35, 0.0).unwrap();
        let mut rng = rand_pcg::Pcg64::seed_from_u64(4);
        (0..20).map(|_| sc.sample(&mut rng).unwrap().world.obstacles().len()).sum::<usize>()
    };
    assert!(count(&spec.at_difficulty(0.0)) < count(&spec), "sparser clutter at difficulty 0");
    // A fill the automaton cannot get through is refused up front.
    let mut bad = spec.clone();
    bad.procedural.as_mut().unwrap().barn.as_mut().unwrap().fill = [0.3, 0.6];
    let Err(err) = Scenario::new(bad, 0.35, 0.0) else { panic!("a fill of 0.6 is refused") };
    let err = err.to_string();
    assert!(err.contains("procedural.barn.fill"), "{err}");
}
