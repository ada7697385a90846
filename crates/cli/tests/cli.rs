//! The binary end to end: the README's main command, sim-speed's JSON line, and clean errors.

use std::process::Command;

fn rlnav(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_rlnav")).args(args).output().expect("rlnav runs")
}

#[test]
fn demo_prints_episodes_and_a_summary() {
    let out = rlnav(&["demo", "--episodes", "3", "--scenario", "empty-room"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("scenario empty-room | robot jetbot | controller greedy"), "{text}");
    assert_eq!(text.lines().filter(|l| l.trim_start().starts_with(char::is_numeric)).count(), 3, "{text}");
    assert!(text.lines().last().unwrap().starts_with("success "), "{text}");
}

#[test]
fn sim_speed_ends_with_a_json_line() {
    let out = rlnav(&["sim-speed", "--envs", "4", "--steps", "20", "--threads", "1"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8(out.stdout).unwrap();
    let v: serde_json::Value = serde_json::from_str(text.lines().last().unwrap()).unwrap();
    for key in ["env_steps_per_s", "rays_per_s", "envs", "threads", "beams", "obstacles"] {
        assert!(v.get(key).is_some(), "{key} missing in {v}");
    }
    assert_eq!((v["envs"].as_u64(), v["threads"].as_u64(), v["beams"].as_u64()), (Some(4), Some(1), Some(360)));
    // static-room: 4 arena walls and 10 obstacles.
    assert_eq!(v["obstacles"].as_u64(), Some(14));
    assert!(v["env_steps_per_s"].as_f64().unwrap() > 0.0);
}

#[test]
fn bad_input_is_a_clean_error() {
    let dir = std::env::temp_dir().join(format!("rlnav-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("bad-scene.yaml");
    std::fs::write(&bad, "name: bad\narena: {size: [8, 8]}\nobstacles:\n  - circle: {center: [1, 1], radius: -2}\n")
        .unwrap();
    for args in [
        vec!["demo", "--scenario", bad.to_str().unwrap()],
        vec!["demo", "--scenario", "no-such-scene"],
        vec!["demo", "--robot", "no-such-robot"],
        vec!["sim-speed", "--envs", "0"],
    ] {
        let out = rlnav(&args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        assert!(err.starts_with("error: ") && !err.contains("panicked"), "{args:?}: {err}");
    }
    let err = String::from_utf8_lossy(&rlnav(&["demo", "--scenario", bad.to_str().unwrap()]).stderr).into_owned();
    assert!(err.contains("bad-scene.yaml") && err.contains("obstacles[0].circle.radius"), "{err}");
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn train_smoke_run_and_errors() {
    let dir = std::env::temp_dir().join(format!("rlnav-cli-train-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let out = rlnav(&["train", "--config", "smoke", "--out", dir.to_str().unwrap(), "--set", "train.max_epochs=2"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("2 epochs, 1024 env steps"), "{text}");
    // The evaluation's line reaches a log that is not a terminal (the progress bar is hidden).
    assert!(text.contains("|      1024 steps |") && text.contains("eval on empty-room: success"), "{text}");
    assert!(text.contains("policy on empty-room (20 episodes"), "{text}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["iterations"], 2);
    // Evaluate the run on another scenario.
    let out = rlnav(&["eval", "--run", dir.to_str().unwrap(), "--scenario", "static-room", "--episodes", "10"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(dir.join("eval.json").is_file());
    // Mistakes are clean errors.
    for (args, needle) in [
        (vec!["train", "--set", "train.max_epohs=3"], "max_epohs"),
        (vec!["train", "--config", "nope"], "static-mlp"),
        (vec!["train", "--config", "smoke", "--out", dir.to_str().unwrap()], "already holds a run"),
        (vec!["train", "--resume", "/nonexistent/run"], "not a run folder"),
    ] {
        let out = rlnav(&args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        assert!(err.contains(needle) && !err.contains("panicked"), "{args:?}: {err}");
    }
    std::fs::remove_dir_all(&dir).ok();
    // A policy whose speed is a share of the robot's top speed says so in its contract, and
    // the ROS 2 node will not drive it without the robot's top speed.
    let out = rlnav(&[
        "train",
        "--config",
        "smoke",
        "--out",
        dir.to_str().unwrap(),
        "--set",
        "train.max_epochs=1",
        "--set",
        "task.action.linear=[0.2, 1.0]",
        "--set",
        "task.action.linear_relative=true",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let policy = dir.join("policy.onnx");
    let out = rlnav(&["inspect", policy.to_str().unwrap()]);
    assert!(String::from_utf8_lossy(&out.stdout).contains("linear_relative: true"));
    let out = rlnav(&["ros2", "node", "--policy", policy.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("max_linear") && err.contains("top speed") && !err.contains("panicked"), "{err}");
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn render_writes_pictures_and_refuses_what_it_cannot() {
    let dir = std::env::temp_dir().join(format!("rlnav-cli-render-{}", std::process::id()));
    let png = dir.join("scene.png");
    let out = rlnav(&["render", "--scenario", "warehouse", "-o", png.to_str().unwrap(), "--size", "300"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(image_size(&png), (300, 229), "the 12 x 9 m known part of the 13 x 10 m map plus 0.3 m margins");
    // A map_saver map: the 5.65 x 5.2 m mapped arena of a 19.2 m square, not the square.
    let out = rlnav(&["render", "--scenario", "turtlebot3-world", "-o", png.to_str().unwrap(), "--size", "400"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(image_size(&png), (400, 371), "6.25 x 5.8 m at 64 px/m");
    let gif = dir.join("run.gif");
    let out =
        rlnav(&["render", "--scenario", "people-room", "--episode", "-o", gif.to_str().unwrap(), "--size", "160"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stdout).contains("greedy on people-room"));
    assert!(std::fs::read(&gif).unwrap().starts_with(b"GIF89a"));
    let out = rlnav(&["render", "-o", gif.to_str().unwrap()]);
    assert!(!out.status.success() && String::from_utf8_lossy(&out.stderr).contains("needs --episode"));
    let out = rlnav(&["render", "--episode", "--controller", "psychic", "-o", png.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("unknown controller `psychic`") && err.contains("greedy"), "{err}");
}

fn image_size(png: &std::path::Path) -> (u32, u32) {
    // PNG: the IHDR chunk's width and height follow the 8-byte signature and 8-byte chunk header.
    let b = std::fs::read(png).unwrap();
    assert_eq!(&b[..8], b"\x89PNG\r\n\x1a\n");
    let be = |i: usize| u32::from_be_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
    (be(16), be(20))
}

#[test]
fn robot_import_writes_a_robot_that_runs() {
    let dir = std::env::temp_dir().join(format!("rlnav-cli-urdf-{}", std::process::id()));
    let yaml = dir.join("robots/burger.yaml");
    let urdf = concat!(env!("CARGO_MANIFEST_DIR"), "/../sim/tests/urdf/burger_like.urdf");
    let out = rlnav(&["robot", "import", urdf, "-o", yaml.to_str().unwrap(), "--name", "burger"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("found: drive wheels") && err.contains("DEFAULT (check it): accelerations"), "{err}");
    let out = rlnav(&["demo", "--robot", yaml.to_str().unwrap(), "--episodes", "2", "--scenario", "empty-room"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stdout).contains("robot burger"));
    let bad = concat!(env!("CARGO_MANIFEST_DIR"), "/../sim/tests/urdf/no_wheels.urdf");
    let out = rlnav(&["robot", "import", bad]);
    assert!(!out.status.success() && String::from_utf8_lossy(&out.stderr).contains("no pair of drive wheels"));
}

#[test]
fn robot_import_expands_xacro_with_a_package_path_and_arguments() {
    let tb4 = concat!(env!("CARGO_MANIFEST_DIR"), "/../sim/tests/urdf/turtlebot4");
    let file = format!("{tb4}/turtlebot4_description/urdf/lite/turtlebot4.urdf.xacro");
    let import = |args: &[&str]| {
        // The tests must not see a ROS installation's packages.
        Command::new(env!("CARGO_BIN_EXE_rlnav"))
            .args(["robot", "import", &file])
            .args(args)
            .env_remove("ROS_PACKAGE_PATH")
            .env_remove("AMENT_PREFIX_PATH")
            .output()
            .expect("rlnav runs")
    };
    let out = import(&["--package-path", tb4, "gazebo:=ignition", "--name", "tb4lite"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(err.contains("found: xacro expanded (") && err.contains("gazebo:=ignition"), "{err}");
    let yaml = String::from_utf8_lossy(&out.stdout);
    assert!(yaml.contains("name: tb4lite") && yaml.contains("wheel_separation: 0.233"), "{yaml}");
    let out = import(&[]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("package `irobot_create_description` not found"), "{err}");
    let out = import(&["--package-path", tb4, "gazebo=ignition"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("not a xacro argument NAME:=VALUE"), "{err}");
}

#[test]
fn policies_inspect_and_evaluate_with_clear_errors() {
    let article = concat!(env!("CARGO_MANIFEST_DIR"), "/../../policies/article");
    let contracts = concat!(env!("CARGO_MANIFEST_DIR"), "/../../contracts");
    let model = format!("{article}/static_120_new.onnx");
    let contract = format!("{contracts}/static_120_new.yaml");
    let out = rlnav(&["inspect", &model, "--contract", &contract]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && text.contains("input  obs [1, 124]") && text.contains("fits its contract"),
        "{text}"
    );
    let out = rlnav(&["inspect", &model]);
    assert!(String::from_utf8_lossy(&out.stdout).contains("no contract in metadata_props"));
    let dir = std::env::temp_dir().join(format!("rlnav-cli-eval-{}", std::process::id()));
    let ev = eval_in_empty_room(&model, &contract, 4, &dir);
    for key in ["success_rate", "collision_rate", "timeout_rate", "mean_task_time", "mean_min_range", "mean_speed"] {
        assert!(ev["summary"].get(key).is_some(), "{key}");
    }
    // A 270° Jackal cannot feed a 360° policy: refused before any episode.
    let out = rlnav(&["eval", "--policy", &model, "--contract", &contract, "--robot", "jackal"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("does not fit jackal's lidar") && err.contains("unseen"), "{err}");
    let out = rlnav(&["eval", "--policy", &model]);
    assert!(!out.status.success() && String::from_utf8_lossy(&out.stderr).contains("--contract"));
}

/// A foreign model of the reference article's 133-input layout, evaluated through its side
/// contract. The model echoes the current goal distance and bearing as (v, ω), so it heads for
/// the goal: it proves the values sit where contracts/article-mlp-133.yaml says.
#[test]
fn a_133_input_model_runs_through_its_side_contract() {
    use prost::Message;
    let dir = std::env::temp_dir().join(format!("rlnav-cli-133-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let contract = concat!(env!("CARGO_MANIFEST_DIR"), "/../../contracts/article-mlp-133.yaml");
    let c = rlnav_policy::PolicyContract::from_file(std::path::Path::new(contract)).unwrap();
    // Values 124 and 129: the newest of the five bearings and of the five distances.
    let proto = rlnav_policy::export::echo_model(133, [129, 124], &c.io).unwrap();
    let model = dir.join("mlp-133.onnx");
    std::fs::write(&model, proto.encode_to_vec()).unwrap();
    let model = model.to_str().unwrap();
    let out = rlnav(&["inspect", model, "--contract", contract]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success() && text.contains("input  obs [batch, 133]"), "{text}");
    assert!(text.contains("120-124  goal_bearing × 5, oldest first") && text.contains("131  lateral"), "{text}");
    let ev = eval_in_empty_room(model, contract, 6, &dir);
    // Steering by the goal bearing reaches goals in an empty room; misplaced values would not.
    assert!(ev["summary"]["success_rate"].as_f64().unwrap() >= 0.5, "{}", ev["summary"]);
    // Without the side contract: refused, pointing at --contract.
    let out = rlnav(&["eval", "--policy", model]);
    assert!(!out.status.success() && String::from_utf8_lossy(&out.stderr).contains("--contract"));
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn dwa_runs_from_the_command_line() {
    let out = rlnav(&["demo", "--controller", "dwa", "--episodes", "3", "--scenario", "static-room"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("controller dwa") && text.lines().last().unwrap().starts_with("success "), "{text}");
    let out = rlnav(&["latency", "--controller", "dwa", "--cycles", "50"]);
    assert!(out.status.success() && String::from_utf8_lossy(&out.stdout).contains("\"controller\":\"dwa\""));
}

/// The user's report: `rlnav bench` on a suite of a real map_saver map (small known area in a
/// large unknown square, starts and goals 1-3 m apart) runs DWA and a shipped policy.
#[test]
fn bench_runs_on_a_real_map() {
    let dir = std::env::temp_dir().join(format!("rlnav-cli-bench-map-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let suite = dir.join("tb3.yaml");
    std::fs::write(&suite, "name: tb3\nscenarios: [turtlebot3-world]\n").unwrap();
    let policy = concat!(env!("CARGO_MANIFEST_DIR"), "/../../policies/jetbot-static-mlp.onnx");
    let rl = format!("rl:{policy}");
    let out = rlnav(&[
        "bench",
        "--suite",
        suite.to_str().unwrap(),
        "--controller",
        "dwa",
        "--controller",
        &rl,
        "--episodes",
        "2",
        "--timing-cycles",
        "10",
        "--out",
        dir.join("out").to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out/report.json")).unwrap()).unwrap();
    let cells = json["suites"][0]["cells"].as_array().unwrap();
    assert_eq!(cells.len(), 2);
    for c in cells {
        assert_eq!(c["scenario"], "turtlebot3-world");
        assert_eq!(c["episodes"].as_array().unwrap().len(), 2, "{c}");
    }
    std::fs::remove_dir_all(dir).ok();
}

/// `report.html` is one self-contained page: tables, and per scene the distance figure and one
/// trajectory figure per controller, all inline. With `RLNAV_CHROMIUM` (set by `.ci/run`),
/// headless Chromium parses it into the same DOM and draws a screenshot that is not blank.
fn check_html_report(path: &std::path::Path, scenes: usize, controllers: usize) {
    let html = std::fs::read_to_string(path).unwrap();
    let figures = scenes * (1 + controllers);
    assert_eq!(html.matches("<svg").count(), figures, "{html}");
    assert!(html.contains("Over the whole suite") && html.contains("<table"));
    assert!(!html.contains("src=\"") && !html.contains("href=\""), "refers to files beside it");
    let Ok(chromium) = std::env::var("RLNAV_CHROMIUM") else {
        eprintln!("RLNAV_CHROMIUM not set: report.html is not rendered in a browser");
        return;
    };
    let dir = path.parent().unwrap();
    let run = |extra: &[String]| {
        let mut args: Vec<String> = [
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
        ]
        .map(String::from)
        .to_vec();
        args.push(format!("--user-data-dir={}", dir.join("chromium-profile").display()));
        args.extend_from_slice(extra);
        args.push(format!("file://{}", path.display()));
        let out = std::process::Command::new(&chromium).args(&args).output().unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        out.stdout
    };
    let dom = String::from_utf8(run(&["--dump-dom".into()])).unwrap();
    assert_eq!(dom.matches("<svg").count(), figures, "Chromium's DOM");
    assert!(dom.contains("<table"));
    let shot = dir.join("report.png");
    run(&[format!("--screenshot={}", shot.display()), "--window-size=1400,2400".into()]);
    // A blank 1400 x 2400 page compresses to a few kB; tables and figures do not.
    let size = std::fs::metadata(&shot).unwrap().len();
    assert!(size > 40_000, "screenshot of {} bytes: blank?", size);
}

#[test]
fn bench_writes_the_report() {
    let dir = std::env::temp_dir().join(format!("rlnav-cli-bench-{}", std::process::id()));
    let out = rlnav(&[
        "bench",
        "--suite",
        "paper-dynamic",
        "--controller",
        "greedy",
        "--controller",
        "dwa",
        "--episodes",
        "1",
        "--timing-cycles",
        "100",
        "--record",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
    assert_eq!(md.lines().filter(|l| l.starts_with("| paper-dynamic-")).count(), 8, "{md}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap()).unwrap();
    assert_eq!(json["suites"][0]["cells"].as_array().unwrap().len(), 8);
    let timing = json["per_cycle_compute"].as_array().unwrap();
    assert_eq!(timing.len(), 2);
    assert!(timing.iter().all(|t| t["p50_us"].as_f64().unwrap() > 0.0));
    assert!(md.contains("Per-cycle compute"), "{md}");
    // Rates carry their 95% interval; the suite is pooled per controller.
    assert!(md.contains("% [") && md.contains("Over the whole suite") && md.contains("| SPL |"), "{md}");
    check_html_report(&dir.join("report.html"), 4, 2);
    let mcap = dir.join("mcap/paper-dynamic/paper-dynamic-box01/dwa/episode_000.mcap");
    assert!(std::fs::read(&mcap).unwrap().starts_with(b"\x89MCAP0\r\n"), "{}", mcap.display());
    // An independent reader (PyPI mcap + mcap-ros2-support) decodes every message from the
    // schemas in the file.
    if let Ok(python) = std::env::var("RLNAV_ROS_PYTHON") {
        let tool = concat!(env!("CARGO_MANIFEST_DIR"), "/../../tools/mcap_check.py");
        let out = std::process::Command::new(python).arg(tool).arg(&mcap).output().unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        let f = &v[mcap.to_str().unwrap()];
        assert_eq!(f["profile"], "ros2");
        let t = &f["topics"];
        let n = t["/scan"]["count"].as_u64().unwrap();
        assert!(n > 1);
        for (topic, schema) in [
            ("/scan", "sensor_msgs/msg/LaserScan"),
            ("/odom", "nav_msgs/msg/Odometry"),
            ("/tf", "tf2_msgs/msg/TFMessage"),
            ("/cmd_vel", "geometry_msgs/msg/Twist"),
            ("/goal_pose", "geometry_msgs/msg/PoseStamped"),
            ("/clock", "rosgraph_msgs/msg/Clock"),
        ] {
            assert_eq!(t[topic]["schema"], schema, "{topic}");
            assert_eq!(t[topic]["count"].as_u64(), Some(n), "{topic}");
        }
        assert_eq!(t["/scan"]["beams"], 360);
        assert_eq!(t["/odom"]["covariance_len"], 36);
        assert_eq!(t["/tf"]["frames"], serde_json::json!([["odom", "base_link"], ["base_link", "laser"]]));
    } else {
        eprintln!("RLNAV_ROS_PYTHON not set: the MCAP file is not checked with an independent reader");
    }
    let out = rlnav(&["bench", "--suite", "no-such-suite", "--controller", "greedy"]);
    assert!(!out.status.success() && String::from_utf8_lossy(&out.stderr).contains("unknown suite `no-such-suite`"));
}

#[test]
fn barn_worlds_run_from_any_folder() {
    // An empty folder: nothing of the repository is beside it.
    let dir = std::env::temp_dir().join(format!("rlnav-cli-barn-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let run = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_rlnav")).args(args).current_dir(&dir).output().expect("rlnav runs")
    };
    let out = run(&["demo", "--scenario", "barn#world_1", "--robot", "jackal", "--episodes", "1"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stdout).contains("scenario barn-world_1 | robot jackal"));
    let out = run(&[
        "bench",
        "--suite",
        "barn",
        "--controller",
        "greedy",
        "--episodes",
        "1",
        "--timing-cycles",
        "0",
        "--out",
        "report",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let md = std::fs::read_to_string(dir.join("report/report.md")).unwrap();
    // One row per world in the results table and again in the per-world difficulty table.
    assert_eq!(md.lines().filter(|l| l.starts_with("| barn-world_")).count(), 50, "{md}");
    assert!(md.contains("BARN Challenge score over the worlds"), "{md}");
    assert!(md.contains("| world | closest wall | visibility |"), "{md}");
    // The score-against-difficulty figure is written and inlined in the page.
    let svg = std::fs::read_to_string(dir.join("report/barn_score_vs_difficulty.svg")).unwrap();
    assert!(svg.contains("characteristic dimension") && svg.contains("greedy"), "{svg}");
    let html = std::fs::read_to_string(dir.join("report/report.html")).unwrap();
    assert!(html.contains("BARN score against world difficulty") && html.contains("(k=4)"));
    let out = run(&["list"]);
    assert!(String::from_utf8_lossy(&out.stdout).contains("barn#world_N"));
}

#[test]
fn help_lists_every_shipped_config_and_suite() {
    let out = rlnav(&["train", "--help"]);
    let text = String::from_utf8_lossy(&out.stdout);
    for name in rlnav_train::config::TRAIN_PRESETS.iter().map(|p| p.0) {
        assert!(text.contains(name), "{name} missing in\n{text}");
    }
    let out = rlnav(&["bench", "--help"]);
    let text = String::from_utf8_lossy(&out.stdout);
    for name in rlnav_bench::suite::SUITE_PRESETS.iter().map(|p| p.0) {
        assert!(text.contains(name), "{name} missing in\n{text}");
    }
    assert!(text.contains("barn"));
}

/// `rlnav eval --policy MODEL --contract CONTRACT` on the empty room: the eval.json it wrote,
/// checked to hold `episodes` episodes.
fn eval_in_empty_room(model: &str, contract: &str, episodes: usize, dir: &std::path::Path) -> serde_json::Value {
    let n = episodes.to_string();
    let args = ["eval", "--policy", model, "--contract", contract, "--scenario", "empty-room", "--episodes", &n];
    let out = rlnav(&[&args[..], &["--out", dir.to_str().unwrap()]].concat());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let ev: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("eval.json")).unwrap()).unwrap();
    assert_eq!(ev["episodes"].as_array().unwrap().len(), episodes);
    ev
}

/// `rlnav barn import` on a folder laid out as the challenge's (world files, path_files/):
/// the data file and suites are written, the test suite runs under `bench`; a folder with a
/// broken file writes nothing.
#[test]
fn barn_import_writes_suites_that_bench_runs_and_nothing_on_error() {
    let dir = std::env::temp_dir().join(format!("rlnav-cli-barn-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let src = dir.join("BARN");
    std::fs::create_dir_all(src.join("path_files")).unwrap();
    // Two cylinders in the field, off the path; the path runs straight up row 15.
    let model = |i: usize, x: f32, y: f32| {
        format!(
            "<model name='c{i}'><pose>{x} {y} 0 0 0 0</pose><link name='l'><collision name='c'><geometry>\
             <cylinder><radius>0.075</radius><length>1</length></cylinder></geometry></collision></link></model>"
        )
    };
    let world = format!(
        "<sdf version='1.6'><world name='default'>{}{}</world></sdf>",
        model(0, -4.425, 6.0),
        model(1, -0.075, 8.0)
    );
    let mut path = b"\x93NUMPY\x01\x00".to_vec();
    let header = "{'descr': '<i8', 'fortran_order': False, 'shape': (2, 2), }\n";
    path.extend((header.len() as u16).to_le_bytes());
    path.extend(header.as_bytes());
    for v in [15i64, 0, 15, 29] {
        path.extend(v.to_le_bytes());
    }
    for index in [0, 6] {
        std::fs::write(src.join(format!("world_{index}.world")), &world).unwrap();
        std::fs::write(src.join(format!("path_files/path_{index}.npy")), &path).unwrap();
    }
    let out_dir = dir.join("out");
    let out = rlnav(&["barn", "import", src.to_str().unwrap(), "--out", out_dir.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("read 2 worlds") && text.contains("2 of them test worlds"), "{text}");
    let bench_dir = dir.join("bench");
    let suite = out_dir.join("barn-test.yaml");
    let out = rlnav(&[
        "bench",
        "--suite",
        suite.to_str().unwrap(),
        "--controller",
        "dwa",
        "--robot",
        "jackal",
        "--seed",
        "1",
        "--out",
        bench_dir.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(bench_dir.join("report.json")).unwrap()).unwrap();
    let cells = report["suites"][0]["cells"].as_array().unwrap();
    assert_eq!(cells.len(), 2, "two test worlds: {report}");
    assert!(cells.iter().all(|c| c["barn_score"].as_f64().is_some()), "{report}");

    // One malformed world: an error naming it, and no file written.
    std::fs::write(src.join("world_6.world"), "<sdf><world>").unwrap();
    let fresh = dir.join("fresh");
    let out = rlnav(&["barn", "import", src.to_str().unwrap(), "--out", fresh.to_str().unwrap()]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("world_6.world"), "{err}");
    assert!(!fresh.exists() || std::fs::read_dir(&fresh).unwrap().next().is_none(), "something was written");
    std::fs::remove_dir_all(dir).ok();
}
