//! Malformed robot, scenario and task files get errors that name the file, the key and what
//! was expected.

use rlnav_sim::config::{ConfigError, from_yaml_str};
use rlnav_sim::scenario::ScenarioSpec;
use rlnav_sim::task::{EnvSetup, SimError, TaskConfig};
use rlnav_sim::{RobotSpec, TaskConfig as _Task};
use std::io::Write;

fn robot_err(yaml: &str) -> String {
    from_yaml_str::<RobotSpec>("bot.yaml", yaml).unwrap_err().to_string()
}

fn scenario_err(yaml: &str) -> String {
    from_yaml_str::<ScenarioSpec>("scene.yaml", yaml).unwrap_err().to_string()
}

fn task_err(yaml: &str) -> String {
    from_yaml_str::<TaskConfig>("task.yaml", yaml).unwrap_err().to_string()
}

const JETBOT: &str = include_str!("../../../robots/jetbot.yaml");

#[test]
fn robot_files() {
    let e = robot_err(&JETBOT.replace("wheel_radius: 0.0325", "wheel_radius: -1"));
    assert!(e.contains("bot.yaml") && e.contains("wheel_radius") && e.contains("[0.005, 2]"), "{e}");
    let e = robot_err(&JETBOT.replace("wheel_radius:", "wheel_radis:"));
    assert!(e.contains("bot.yaml") && e.contains("unknown field `wheel_radis`"), "{e}");
    let e = robot_err(&JETBOT.replace("  range_max: 3.0", "  range_max: 0.1"));
    assert!(e.contains("lidar.range_max"), "{e}");
    let e = robot_err(&JETBOT.replace("beams: 360", "beams: lots"));
    assert!(e.contains("lidar.beams") && e.contains("line"), "{e}");
    let e = robot_err(&JETBOT.replace("circle: {radius: 0.09}", "polygon: [[0, 0], [1, 1], [2, 2]]"));
    assert!(e.contains("footprint.polygon") && e.contains("convex"), "{e}");
    let e = robot_err(&JETBOT.replace("circle: {radius: 0.09}", "triangle: {side: 0.1}"));
    assert!(e.contains("footprint") && e.contains("triangle"), "{e}");
    let e = robot_err(&JETBOT.replace("max_linear: 0.5\nmin_linear: 0.0", "max_linear: 0.5\nmin_linear: -2"));
    assert!(e.contains("min_linear"), "{e}");
    let e = robot_err("name: x\n");
    assert!(e.contains("missing field"), "{e}");
}

#[test]
fn scenario_files() {
    let e = scenario_err("name: s\narena: {size: [8, 8]}\nobstacles:\n  - circle: {center: [1, 1], radius: 0}\n");
    assert!(e.contains("scene.yaml") && e.contains("obstacles[0].circle.radius") && e.contains("> 0"), "{e}");
    let e = scenario_err(
        "name: s\narena: {size: [8, 8]}\nobstacles:\n  - circle: {center: [1, 1], radius: 1, colour: red}\n",
    );
    assert!(e.contains("unknown field `colour`"), "{e}");
    let e = scenario_err("name: s\narena: {size: [8, 8]}\nobstacles:\n  - blob: {center: [1, 1]}\n");
    assert!(e.contains("obstacles[0]") && e.contains("blob") && e.contains("circle"), "{e}");
    let e = scenario_err(
        "name: s\narena: {size: [8, 8]}\nobstacles:\n  - polygon: {points: [[0, 0], [2, 0], [0.5, 0.5], [0, 2]]}\n",
    );
    assert!(e.contains("obstacles[0].polygon.points") && e.contains("convex"), "{e}");
    let e = scenario_err("name: s\nprocedural: {count: [3, 5]}\nstart: free\n");
    assert!(e.contains("procedural") && e.contains("arena"), "{e}");
    let e = scenario_err("name: s\narena: {size: [8, 8]}\nprocedural: {count: [5, 3]}\n");
    assert!(e.contains("procedural.count"), "{e}");
    let e = scenario_err("name: s\narena: {size: [8, 8]}\nstart_goal_distance: [4, 1]\n");
    assert!(e.contains("start_goal_distance") && e.contains("low <= high"), "{e}");
    let e = scenario_err("name: s\narena: {size: [8, 8]}\nstart: {region: {min: [1, 1], max: [0, 2]}}\n");
    assert!(e.contains("start.region"), "{e}");
    let e = scenario_err(
        "name: s\narena: {size: [8, 8]}\nmovers:\n  - {shape: {box: {size: [0.4, 0.4]}}, waypoints: [[0, 0]], speed: [0.1, 0.2]}\n",
    );
    assert!(e.contains("movers[0].waypoints") && e.contains("at least two"), "{e}");
    let e = scenario_err(
        "name: s\narena: {size: [8, 8]}\nmovers:\n  - {shape: {circle: {radius: 0.2}}, waypoints: [[0, 0], [1, 0]], speed: [0.3, 0.1]}\n",
    );
    assert!(e.contains("movers[0].speed"), "{e}");
    let e = scenario_err(
        "name: s\narena: {size: [8, 8]}\nmovers:\n  - {shape: {blob: {}}, waypoints: [[0, 0], [1, 0]], speed: [0.1, 0.1]}\n",
    );
    assert!(e.contains("movers[0].shape") || e.contains("blob"), "{e}");
    let e = scenario_err("name: s\narena: {size: [8, 8]}\nrobbot: jetbot\n");
    assert!(e.contains("unknown field `robbot`"), "{e}");
    // Unknown presets list the known ones.
    let e = ScenarioSpec::load("static-rooom").unwrap_err().to_string();
    assert!(e.contains("static-room") && e.contains("empty-room"), "{e}");
}

#[test]
fn files_on_disk_are_named_in_errors() {
    let dir = std::env::temp_dir().join(format!("rlnav-bad-input-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("broken.yaml");
    std::fs::File::create(&path).unwrap().write_all(b"name: broken\narena: {size: [8, -1]}\n").unwrap();
    let e = ScenarioSpec::load(path.to_str().unwrap()).unwrap_err().to_string();
    assert!(e.contains("broken.yaml") && e.contains("arena.size[1]"), "{e}");
    let missing = dir.join("missing.yaml");
    let e = ScenarioSpec::load(missing.to_str().unwrap()).unwrap_err();
    assert!(matches!(e, ConfigError::Io { .. }) && e.to_string().contains("missing.yaml"), "{e}");
    let e = TaskConfig::from_file(&missing).unwrap_err().to_string();
    assert!(e.contains("missing.yaml"), "{e}");
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn task_files() {
    let e = task_err("control_period: 0.05\nphysics_dt: 0.03\n");
    assert!(e.contains("task.yaml") && e.contains("control_period") && e.contains("whole multiple"), "{e}");
    let e = task_err("max_steps: -3\n");
    assert!(e.contains("max_steps"), "{e}");
    let e = task_err("reward: {gaol: 30}\n");
    assert!(e.contains("unknown field `gaol`") && e.contains("reward"), "{e}");
    let e = task_err("observation:\n  - lidar: {beams: 0, clip: [0.15, 3]}\n");
    assert!(e.contains("observation[0].lidar.beams"), "{e}");
    let e = task_err("observation:\n  - lidar: {beams: 120, clip: [3, 0.15]}\n");
    assert!(e.contains("observation[0].lidar.clip"), "{e}");
    let e = task_err("observation:\n  - goal_heading\n");
    assert!(e.contains("goal_heading") && e.contains("goal_bearing"), "{e}");
    let e = task_err("goal_tolerance: .nan\n");
    assert!(e.contains("goal_tolerance"), "{e}");
    // A layout that does not fit the robot's lidar.
    let task: _Task = from_yaml_str("t.yaml", "observation:\n  - lidar: {beams: 7, clip: [0.15, 3]}\n").unwrap();
    let e =
        EnvSetup::new(ScenarioSpec::load("empty-room").unwrap(), RobotSpec::load("jetbot").unwrap(), task).unwrap_err();
    assert!(matches!(e, SimError::Incompatible { .. }) && e.to_string().contains("7 beams"), "{e}");
}
