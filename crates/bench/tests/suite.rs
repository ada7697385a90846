//! Suites: every shipped suite loads, controllers run on the same seeded episodes, the table
//! has a row per scenario and controller, and bad input fails before any episode.

use rlnav_bench::suite::{BenchError, SUITE_PRESETS, SuiteSpec, run_suite};

#[test]
fn suites_run_controllers_on_the_same_episodes() {
    for (name, _) in SUITE_PRESETS {
        let s = SuiteSpec::load(name).unwrap();
        for sc in &s.scenarios {
            rlnav_sim::ScenarioSpec::load(sc).unwrap();
        }
    }
    let suite = SuiteSpec::load("paper-static").unwrap();
    let controllers = vec!["greedy".to_string(), "dwa".to_string()];
    let r = run_suite(&suite, &controllers, None, 3, 11, 2).unwrap();
    assert_eq!(r.cells.len(), 4 * 2);
    for pair in r.cells.chunks(2) {
        assert_eq!(pair[0].scenario, pair[1].scenario);
        // Same seed, same scene: the same start-goal distances for both controllers.
        let d = |c: &rlnav_bench::suite::CellResult| c.episodes.iter().map(|e| e.initial_distance).collect::<Vec<_>>();
        assert_eq!(d(&pair[0]), d(&pair[1]));
        assert!(d(&pair[0]).iter().all(|x| (4.5..=5.5).contains(x)), "goal about 4.7 m away: {:?}", d(&pair[0]));
    }
    let md = r.markdown();
    assert_eq!(md.lines().filter(|l| l.starts_with("| paper-static-")).count(), 8, "{md}");
    assert!(md.contains("min lidar range (m)") && md.contains("distance to target (m)"));
}

#[test]
fn bad_benchmarks_fail_before_any_episode() {
    let suite = SuiteSpec::load("paper-static").unwrap();
    let e = run_suite(&suite, &["psychic".into()], None, 1, 0, 1).unwrap_err();
    assert!(matches!(e, BenchError::Controller { .. }) && e.to_string().contains("unknown controller"), "{e}");
    let policy = concat!(env!("CARGO_MANIFEST_DIR"), "/../../policies/jetbot-static-mlp.onnx");
    let e = run_suite(&suite, &[format!("rl:{policy}")], Some("jackal"), 1, 0, 1).unwrap_err().to_string();
    assert!(e.contains("jackal") && e.contains("unseen"), "{e}");
    assert!(matches!(run_suite(&suite, &[], None, 1, 0, 1), Err(BenchError::NoControllers)));
    let empty = rlnav_sim::config::from_yaml_str::<SuiteSpec>("empty.yaml", "name: e\nscenarios: []\n").unwrap_err();
    assert!(empty.to_string().contains("empty.yaml") && empty.to_string().contains("at least one scenario"));
    assert!(SuiteSpec::load("nope").unwrap_err().to_string().contains("paper-static"));
}
