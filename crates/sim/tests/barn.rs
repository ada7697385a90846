//! The BARN worlds shipped in `assets/barn/` (embedded as `barn`): all load, compile for the
//! Jackal and place its start and goal; the Jackal preset matches the challenge's robot; the
//! same file read by path gives the same worlds; bad files are named.

use rlnav_sim::barn::{BarnSet, barn_score};
use rlnav_sim::task::{EnvSetup, TaskConfig};
use rlnav_sim::{NavEnv, RobotSpec, ScenarioSpec};
use std::path::Path;
use std::sync::Arc;

/// The shipped file on disk, read by path as a user's own BARN file would be.
const BARN_FILE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../assets/barn/barn_worlds.json");

/// The challenge's rules as a task: 1 m success radius, 100 s, contact-only collisions.
fn barn_task(set: &BarnSet) -> TaskConfig {
    let mut t = TaskConfig::default();
    t.goal_tolerance = set.success_radius;
    t.max_steps = (set.time_limit / t.control_period).round() as u32;
    t.collision_range = 0.0;
    t
}

#[test]
fn all_worlds_load_and_compile_for_the_jackal() {
    let set = BarnSet::shipped().unwrap();
    assert_eq!(set.worlds.len(), 250);
    assert!(set.worlds.iter().all(|w| w.index % 6 != 0), "the test worlds are held out");
    assert_eq!((set.success_radius, set.time_limit), (1.0, 100.0));
    let jackal = RobotSpec::load("jackal").unwrap();
    let fp = jackal.footprint();
    assert!((fp.radius() - 0.254f32.hypot(0.215)).abs() < 1e-5);
    assert_eq!(jackal.lidar.beams, 720);
    assert!((jackal.lidar.angle_max - jackal.lidar.angle_min - 270f32.to_radians()).abs() < 1e-5);
    assert_eq!((jackal.lidar.range_min, jackal.lidar.range_max), (0.1, 30.0));
    let task = barn_task(&set);
    for w in &set.worlds {
        assert!(w.optimal_time > 0.0 && (w.path_length / 2.0 - w.optimal_time).abs() < 1e-3, "{}", w.name);
        let setup =
            EnvSetup::new(w.spec.clone(), jackal.clone(), task.clone()).unwrap_or_else(|e| panic!("{}: {e}", w.name));
        let env = NavEnv::new(Arc::new(setup), 0).unwrap();
        assert!((env.pose().x + 2.25).abs() < 1e-6 && (env.pose().y - 3.0).abs() < 1e-6);
        assert!((env.goal_polar().0 - 10.0).abs() < 1e-4);
    }
    // One world by reference, as the CLI's --scenario takes it.
    let spec = ScenarioSpec::load("barn#world_1").unwrap();
    assert_eq!(spec.obstacles, set.world("world_1").unwrap().spec.obstacles);
    assert!(spec.obstacles.len() > 100);
    assert!(barn_score(true, 12.0, set.worlds[0].optimal_time) > 0.0);
}

#[test]
fn a_barn_file_by_path_reads_like_the_embedded_worlds() {
    let shipped = BarnSet::shipped().unwrap();
    let by_path = BarnSet::load(Path::new(BARN_FILE)).unwrap();
    let named = BarnSet::load_named(BARN_FILE).unwrap();
    assert_eq!(by_path.worlds.len(), shipped.worlds.len());
    assert_eq!(named.worlds.len(), shipped.worlds.len());
    for (a, b) in by_path.worlds.iter().zip(&shipped.worlds) {
        assert_eq!((&a.name, &a.spec.obstacles, a.optimal_time), (&b.name, &b.spec.obstacles, b.optimal_time));
    }
    let spec = ScenarioSpec::load(&format!("{BARN_FILE}#world_7")).unwrap();
    assert_eq!(spec, ScenarioSpec::load("barn#world_7").unwrap());
}

#[test]
fn bad_barn_references_are_named() {
    let e = ScenarioSpec::load("barn#world_6").unwrap_err().to_string();
    assert!(e.contains("world_6") && e.contains("250 worlds"), "{e}");
    let e = ScenarioSpec::load(&format!("{BARN_FILE}#world_6")).unwrap_err().to_string();
    assert!(e.contains("barn_worlds.json") && e.contains("world_6"), "{e}");
    let e = ScenarioSpec::load("nowhere/barn.json#world_1").unwrap_err().to_string();
    assert!(e.contains("nowhere/barn.json") && e.contains("cannot read"), "{e}");
    let dir = std::env::temp_dir().join(format!("rlnav-barn-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("bad.json");
    std::fs::write(&bad, r#"{"about": {}, "worlds": {}}"#).unwrap();
    let e = BarnSet::load(&bad).unwrap_err().to_string();
    assert!(e.contains("bad.json") && e.contains("missing field"), "{e}");
}
