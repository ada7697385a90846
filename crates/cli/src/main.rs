//! `rlnav`: train, evaluate and deploy RL local planners for wheeled robots with a 2D lidar.
//! This binary parses arguments, shows progress and wires the library crates together.

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use rlnav_sim::scenario::{SCENARIO_PRESETS, ScenarioSpec};
use rlnav_sim::task::{EnvSetup, NavEnv, TaskConfig};
use rlnav_sim::vec_env::{VecEnv, measure_speed};
use rlnav_sim::{Outcome, RobotSpec};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

#[derive(Parser)]
#[command(name = "rlnav", version, about = "End-to-end RL local planners for wheeled robots with a 2D lidar")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a simple controller on a scenario and print what happened.
    Demo {
        #[command(flatten)]
        env: EnvArgs,
        /// Controller: `greedy` (turn to the goal and drive), `straight`, `dwa` or
        /// `rl:POLICY.onnx[:CONTRACT.yaml]`.
        #[arg(long, default_value = "greedy")]
        controller: String,
        /// Episodes to run.
        #[arg(long, default_value_t = 20)]
        episodes: usize,
        /// Run seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
    },
    /// Measure simulator throughput with random actions; the last line is a JSON object.
    SimSpeed {
        #[command(flatten)]
        env: EnvArgs,
        /// Environments stepped together.
        #[arg(long, default_value_t = 256)]
        envs: usize,
        /// Worker threads (0: one per core).
        #[arg(long, default_value_t = 2)]
        threads: usize,
        /// Steps per environment to measure.
        #[arg(long, default_value_t = 2000)]
        steps: usize,
        /// Run seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Also time parry2d's brute-force ray casts for the same scans (one thread).
        #[arg(long)]
        reference_lidar: bool,
    },
    /// Train a policy with PPO (default: the built-in static-obstacle Jetbot run) and report
    /// how well it navigates scenes it never saw.
    Train {
        /// Training configuration: a shipped name (static-mlp, smoke) or a YAML file.
        #[arg(long)]
        config: Option<String>,
        /// Run folder (default: runs/<config name>-<seed>, or the first free -2, -3... after it).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Run seed (overrides the config's).
        #[arg(long)]
        seed: Option<u64>,
        /// Override a config value by its dotted path, e.g. `--set train.max_epochs=3`.
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        /// Continue the run in this folder from its last checkpoint.
        #[arg(long, conflicts_with_all = ["config", "out", "seed"])]
        resume: Option<PathBuf>,
    },
    /// Evaluate a trained run (`--run`, on its evaluation scenario by default) or any ONNX
    /// policy with a contract (`--policy`, on static-room by default) and write eval.json.
    Eval {
        /// Run folder written by `rlnav train`.
        #[arg(long, required_unless_present = "policy", conflicts_with = "policy")]
        run: Option<PathBuf>,
        /// ONNX policy (its contract inside, or given with --contract).
        #[arg(long)]
        policy: Option<PathBuf>,
        /// Side contract for a policy rlnav did not export (see contracts/).
        #[arg(long, requires = "policy")]
        contract: Option<PathBuf>,
        /// Robot for --policy (default: the contract's robot when it is a preset, else the
        /// scenario's).
        #[arg(long, requires = "policy")]
        robot: Option<String>,
        /// Scenario: a shipped name or a YAML file.
        #[arg(long)]
        scenario: Option<String>,
        /// Worker threads for --policy.
        #[arg(long, default_value_t = 2)]
        threads: usize,
        /// Episodes.
        #[arg(long, default_value_t = 200)]
        episodes: usize,
        /// Seed of the evaluation episodes.
        #[arg(long, default_value_t = 12345)]
        seed: u64,
        /// Folder for eval.json (default: the run folder, or the current folder for --policy).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Export a run's policy as ONNX with its contract (training does it too: policy.onnx).
    Export {
        /// Run folder written by `rlnav train`.
        #[arg(long)]
        run: PathBuf,
        /// Output file (default: RUN/policy.onnx).
        #[arg(short, long)]
        out: Option<PathBuf>,
        /// Checkpoint: `best` (default when there is one) or `checkpoint` (the last).
        #[arg(long)]
        checkpoint: Option<String>,
    },
    /// Time one control cycle of a controller (for a policy: observation from the scan,
    /// inference, command) on scenario observations; prints p50/p99 and a JSON line.
    Latency {
        #[command(flatten)]
        env: EnvArgs,
        /// Controller: greedy, straight, dwa or rl:POLICY.onnx[:CONTRACT.yaml].
        #[arg(long)]
        controller: String,
        /// Cycles to time.
        #[arg(long, default_value_t = 20000)]
        cycles: usize,
    },
    /// Run controllers on scenario suites with the same seeded episodes and write the
    /// article's table (report.md, report.json). With no arguments: the shipped policies and
    /// DWA on paper-static and paper-dynamic.
    Bench {
        /// Suite: paper-static, paper-dynamic, random-static, random-dynamic, or a YAML file
        /// (repeat for several; default paper-static and paper-dynamic).
        #[arg(long)]
        suite: Vec<String>,
        /// Controller: dwa, greedy, straight or rl:POLICY.onnx[:CONTRACT.yaml] (repeat;
        /// default the shipped policies and dwa).
        #[arg(long)]
        controller: Vec<String>,
        /// Robot for every scenario (default: each scenario's).
        #[arg(long)]
        robot: Option<String>,
        /// Episodes per scenario and controller (default: the suite's).
        #[arg(long)]
        episodes: Option<usize>,
        /// Seed of the episodes.
        #[arg(long, default_value_t = 7)]
        seed: u64,
        /// Worker threads.
        #[arg(long, default_value_t = 2)]
        threads: usize,
        /// Output folder.
        #[arg(long, default_value = "bench-out")]
        out: PathBuf,
        /// Also record every episode as MCAP (ROS 2 CDR: /scan, /odom, /tf, /cmd_vel,
        /// /goal_pose, /clock) under OUT/mcap/SUITE/SCENARIO/CONTROLLER/.
        #[arg(long)]
        record: bool,
        /// Control cycles timed per controller for the per-cycle compute table (0: none).
        #[arg(long, default_value_t = 3000)]
        timing_cycles: usize,
    },
    /// Print an ONNX policy's contract and its graph's inputs and outputs.
    Inspect {
        /// The ONNX file.
        policy: PathBuf,
        /// Side contract to check the model against instead of the embedded one.
        #[arg(long)]
        contract: Option<PathBuf>,
    },
    /// Draw a scenario (PNG or SVG): the world, the robot at its start, the goal, the lidar's
    /// rays; with `--episode`, one episode under `--controller` with its whole path, or
    /// animated when the output is a GIF.
    Render {
        #[command(flatten)]
        env: EnvArgs,
        /// Output picture: .png, .svg or .gif.
        #[arg(short, long)]
        out: PathBuf,
        /// Run one episode under `--controller` and draw it.
        #[arg(long)]
        episode: bool,
        /// Controller for `--episode`: greedy, straight, dwa or rl:POLICY.onnx[:CONTRACT.yaml].
        #[arg(long, default_value = "greedy")]
        controller: String,
        /// Episode seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Pixels along the longer side.
        #[arg(long, default_value_t = 800)]
        size: u32,
        /// Draw every N-th lidar beam (0: none).
        #[arg(long, default_value_t = 4)]
        beam_stride: usize,
        /// GIF playback speed relative to real time.
        #[arg(long, default_value_t = 2.0)]
        speedup: f32,
    },
    /// List the shipped scenarios and robots.
    List,
    /// Robot files.
    Robot {
        #[command(subcommand)]
        command: RobotCommand,
    },
    /// ROS 2 (pure Rust, no ROS installation): the policy node and the simulator bridge.
    Ros2 {
        #[command(subcommand)]
        command: Ros2Command,
    },
}

#[derive(clap::Args)]
struct DdsArgs {
    /// DDS domain (default: ROS_DOMAIN_ID, else 0).
    #[arg(long)]
    domain: Option<u16>,
    /// Talk over loopback only (also set by ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST).
    #[arg(long)]
    localhost: bool,
}

impl DdsArgs {
    fn resolve(&self) -> Result<(u16, rlnav_ros2::bus::Reach)> {
        use rlnav_ros2::bus::{Reach, domain_from_env};
        let domain = match self.domain {
            Some(d) => d,
            None => domain_from_env()?,
        };
        let reach = if self.localhost { Reach::Localhost } else { Reach::from_env() };
        Ok((domain, reach))
    }
}

#[derive(Subcommand)]
enum Ros2Command {
    /// Drive a robot with a policy: /scan and /odom (or a pose topic) in, /cmd_vel out, the
    /// goal from --goal, the parameters or /goal_pose; state on /rlnav/status.
    Node {
        /// The policy (ONNX with its contract, e.g. policies/jetbot-static-mlp.onnx).
        #[arg(long)]
        policy: PathBuf,
        /// A side contract for a policy file without one.
        #[arg(long)]
        contract: Option<PathBuf>,
        /// Parameter YAML (topics, frames, limits, timeouts; flat or ROS 2's
        /// `node: {ros__parameters: ...}`).
        #[arg(long)]
        params: Option<PathBuf>,
        /// Goal X Y in the pose frame (overrides the parameters' goal).
        #[arg(long, num_args = 2, value_names = ["X", "Y"], allow_negative_numbers = true)]
        goal: Option<Vec<f64>>,
        #[command(flatten)]
        dds: DdsArgs,
    },
    /// Run a scenario as a ROS 2 robot: /scan, /odom, /tf, /tf_static, /clock and /goal_pose
    /// out, /cmd_vel in. Prints each episode's figures as a JSON line.
    Sim {
        /// Scenario: a shipped name or a YAML file.
        #[arg(long, default_value = "static-room")]
        scenario: String,
        /// Robot (default: the scenario's).
        #[arg(long)]
        robot: Option<String>,
        /// Seed of the episodes.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Episodes to run, then exit (0: until Ctrl-C).
        #[arg(long, default_value_t = 0)]
        episodes: usize,
        /// Simulated seconds per second (1: real time).
        #[arg(long, default_value_t = 1.0)]
        rate: f64,
        /// /cmd_vel carries geometry_msgs/TwistStamped.
        #[arg(long)]
        cmd_vel_stamped: bool,
        #[command(flatten)]
        dds: DdsArgs,
    },
}

#[derive(Subcommand)]
enum RobotCommand {
    /// Make a robot file from a URDF or xacro description: drive wheels, footprint, lidar
    /// mount (and the lidar's beams and ranges from a Gazebo ray sensor); prints what it found
    /// and what it defaulted.
    Import {
        /// The description: URDF, or xacro (`.urdf.xacro`, or a URDF that uses xacro), which
        /// is expanded first.
        urdf: PathBuf,
        /// xacro arguments, as `xacro` takes them (e.g. `namespace:=tb3_ gazebo:=ignition`).
        #[arg(value_name = "NAME:=VALUE", value_parser = xacro_arg)]
        xacro_args: Vec<(String, String)>,
        /// A folder holding ROS packages (at any depth), for `$(find PKG)` and `package://PKG`;
        /// searched before ROS_PACKAGE_PATH and AMENT_PREFIX_PATH. Repeatable.
        #[arg(long = "package-path", value_name = "DIR")]
        package_path: Vec<PathBuf>,
        /// Robot YAML to write (default: print it).
        #[arg(short, long)]
        out: Option<PathBuf>,
        /// Robot name (default: the URDF's).
        #[arg(long)]
        name: Option<String>,
    },
}

#[derive(clap::Args)]
struct EnvArgs {
    /// Scenario: a shipped name (see `rlnav list`) or a YAML file.
    #[arg(long, default_value = "static-room")]
    scenario: String,
    /// Robot: a shipped name or a YAML file (default: the scenario's).
    #[arg(long)]
    robot: Option<String>,
    /// Task file (default: configs/task.yaml's values, built in).
    #[arg(long)]
    task: Option<PathBuf>,
}

impl EnvArgs {
    fn setup(&self) -> Result<Arc<EnvSetup>> {
        let scenario = ScenarioSpec::load(&self.scenario)?;
        let robot = RobotSpec::load(self.robot.as_deref().unwrap_or(&scenario.robot))?;
        let task = match &self.task {
            Some(p) => TaskConfig::from_file(p)?,
            None => TaskConfig::default(),
        };
        Ok(Arc::new(EnvSetup::new(scenario, robot, task)?))
    }
}

fn main() {
    // A closed pipe (`rlnav list | head`) ends the program quietly, as for other command-line
    // tools, instead of panicking in println!.
    #[cfg(unix)]
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    if let Err(e) = run(Cli::parse()) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Demo { env, controller, episodes, seed } => demo(&env, &controller, episodes, seed),
        Command::SimSpeed { env, envs, threads, steps, seed, reference_lidar } => {
            sim_speed(&env, envs, threads, steps, seed, reference_lidar)
        }
        Command::Train { config, out, seed, set, resume } => train(config, out, seed, set, resume),
        Command::Eval { run: Some(run), policy: None, scenario, episodes, seed, out, .. } => {
            anyhow::ensure!(episodes > 0, "--episodes must be at least 1");
            let ev = rlnav_train::run::evaluate_run(&run, scenario.as_deref(), episodes, 50, seed)?;
            let r = &ev.summary;
            println!("{} on {} ({} episodes, seed {seed})", run.display(), ev.scenario, r.episodes);
            println!(
                "success {:.1}% | collision {:.1}% | timeout {:.1}% | mean return {:.1} | mean time to goal {:.1} s",
                100.0 * r.success_rate,
                100.0 * r.collision_rate,
                100.0 * r.timeout_rate,
                r.mean_return,
                r.mean_success_time
            );
            write_json(&out.unwrap_or(run).join("eval.json"), &ev)
        }
        Command::Eval { policy: Some(policy), contract, robot, scenario, episodes, seed, out, threads, .. } => {
            eval_policy(&policy, contract.as_deref(), robot, scenario, episodes, seed, out, threads)
        }
        Command::Eval { .. } => anyhow::bail!("give --run DIR or --policy FILE"),
        Command::Export { run, out, checkpoint } => {
            let out = out.unwrap_or_else(|| run.join("policy.onnx"));
            let which = match checkpoint.as_deref() {
                None => None,
                Some(c @ ("best" | "checkpoint")) => Some(c),
                Some(other) => anyhow::bail!("--checkpoint `{other}`: expected `best` or `checkpoint`"),
            };
            let used = match which {
                Some(w) => {
                    let (bytes, _) = rlnav_train::export::export_run(&run, w)?;
                    std::fs::write(&out, bytes).with_context(|| format!("writing {}", out.display()))?;
                    w
                }
                None => rlnav_train::export::write_policy(&run, &out)?,
            };
            println!("exported {}/{used} to {}", run.display(), out.display());
            Ok(())
        }
        Command::Inspect { policy, contract } => inspect(&policy, contract.as_deref()),
        Command::Bench { suite, controller, robot, episodes, seed, threads, out, record, timing_cycles } => {
            let opts = BenchArgs { robot, episodes, seed, threads, record, timing_cycles };
            bench(suite, controller, &opts, &out)
        }
        Command::Latency { env, controller, cycles } => {
            anyhow::ensure!(cycles > 0, "--cycles must be at least 1");
            let setup = env.setup()?;
            let mut c = rlnav_bench::controllers::for_setup(&controller, &setup)?;
            let r = rlnav_bench::latency::measure_latency(c.as_mut(), setup, cycles, cycles / 10, 0)?;
            println!(
                "{}: {} cycles on {}-beam scans: p50 {:.1} µs, p99 {:.1} µs, mean {:.1} µs, max {:.1} µs",
                r.controller, r.cycles, r.beams, r.p50_us, r.p99_us, r.mean_us, r.max_us
            );
            println!("{}", serde_json::to_string(&r)?);
            Ok(())
        }
        Command::Robot { command: RobotCommand::Import { urdf, xacro_args, package_path, out, name } } => {
            let options = rlnav_sim::xacro::XacroOptions {
                args: xacro_args,
                packages: rlnav_sim::xacro::PackagePath::new(package_path).with_environment(),
            };
            robot_import(&urdf, &options, out, name)
        }
        Command::Ros2 { command } => ros2(command),
        Command::Render { env, out, episode, controller, seed, size, beam_stride, speedup } => {
            render(&env, &out, episode, &controller, seed, size, beam_stride, speedup)
        }
        Command::List => {
            println!("scenarios:");
            for (name, _) in SCENARIO_PRESETS {
                let s = ScenarioSpec::load(name)?;
                println!("  {name:<16} {}", s.description);
            }
            println!("robots:");
            for (name, _) in rlnav_sim::robot::ROBOT_PRESETS {
                let r = RobotSpec::load(name)?;
                println!("  {name:<18} {}", r.description);
            }
            println!("maps (for a scenario's `map: {{file: NAME}}`):");
            for (name, ..) in rlnav_sim::map::MAP_PRESETS {
                let g = rlnav_sim::map::OccupancyGrid::load(name, Default::default())?;
                let (w, h) = g.size();
                println!("  {name:<16} {w} x {h} cells of {} m", g.resolution());
            }
            println!("BARN worlds: --scenario PATH/barn_worlds.json#world_N --robot jackal");
            Ok(())
        }
    }
}

fn demo(args: &EnvArgs, controller: &str, episodes: usize, seed: u64) -> Result<()> {
    let setup = args.setup()?;
    let mut c = rlnav_bench::controllers::for_setup(controller, &setup)?;
    println!(
        "scenario {} | robot {} | controller {} | {} episodes, seed {seed}",
        setup.scenario.spec().name,
        setup.robot.name,
        c.name(),
        episodes
    );
    let mut env = NavEnv::new(setup.clone(), seed)?;
    println!(
        "{:>4} {:>9} {:>7} {:>7} {:>8} {:>8} {:>8}",
        "ep", "outcome", "time_s", "return", "min_lidar", "speed", "start_d"
    );
    let mut all = Vec::new();
    for ep in 0..episodes {
        let s = env.run_episode(c.as_mut()).context("running an episode")?;
        println!(
            "{ep:>4} {:>9} {:>7.1} {:>7.1} {:>8.2} {:>8.2} {:>8.2}",
            format!("{:?}", s.outcome).to_lowercase(),
            s.time,
            s.episode_return,
            s.min_range,
            s.mean_speed,
            s.initial_distance
        );
        all.push(s);
    }
    let rate = |o: Outcome| 100.0 * all.iter().filter(|s| s.outcome == o).count() as f32 / all.len().max(1) as f32;
    println!(
        "success {:.0}% | collision {:.0}% | timeout {:.0}%",
        rate(Outcome::Success),
        rate(Outcome::Collision),
        rate(Outcome::Timeout)
    );
    Ok(())
}

fn sim_speed(args: &EnvArgs, envs: usize, threads: usize, steps: usize, seed: u64, reference: bool) -> Result<()> {
    anyhow::ensure!(envs > 0 && steps > 0, "--envs and --steps must be at least 1");
    let setup = args.setup()?;
    let mut venv = VecEnv::new(setup.clone(), envs, seed, threads)?;
    eprintln!(
        "scenario {} | robot {} | {} beams | {} envs on {} threads | {} steps each",
        setup.scenario.spec().name,
        setup.robot.name,
        setup.lidar.beams(),
        envs,
        venv.threads(),
        steps
    );
    let report = measure_speed(&mut venv, steps, steps / 10, seed)?;
    if reference {
        let (fast, slow) = rlnav_sim::vec_env::compare_casters(&venv.envs()[0], 2000);
        eprintln!(
            "lidar, one thread: culled caster {:.0} scans/s, parry2d brute force {:.0} scans/s ({:.1}x)",
            fast,
            slow,
            fast / slow
        );
    }
    eprintln!(
        "{:.0} env steps/s, {:.1} M rays/s, {} episodes finished",
        report.env_steps_per_s,
        report.rays_per_s / 1e6,
        report.episodes
    );
    println!("{}", serde_json::to_string(&report)?);
    Ok(())
}

fn train(
    config: Option<String>,
    out: Option<PathBuf>,
    seed: Option<u64>,
    mut set: Vec<String>,
    resume: Option<PathBuf>,
) -> Result<()> {
    use rlnav_train::{TrainOptions, load_run_config};
    let (cfg, out, resuming) = match resume {
        Some(dir) => {
            let cfg = rlnav_train::run::read_run_config(&dir)?;
            if !set.is_empty() {
                anyhow::bail!("--set cannot change a run being resumed");
            }
            (cfg, dir, true)
        }
        None => {
            if let Some(s) = seed {
                set.push(format!("seed={s}"));
            }
            let cfg = load_run_config(config.as_deref(), &set)?;
            let out = out.unwrap_or_else(|| {
                rlnav_train::run::fresh_run_dir(&PathBuf::from(format!("runs/{}-{}", cfg.name, cfg.seed)))
            });
            (cfg, out, false)
        }
    };
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        ctrlc::set_handler(move || {
            if stop.swap(true, Ordering::SeqCst) {
                std::process::exit(130);
            }
            eprintln!("\nstopping after this epoch (a checkpoint will be written); Ctrl-C again to abort");
        })
        .context("installing the Ctrl-C handler")?;
    }
    println!(
        "training {} | robot {} | scenario {} | network {:?}{} | {} envs x {} steps | {} epochs -> {}",
        cfg.name,
        cfg.robot,
        if cfg.curriculum.is_empty() {
            cfg.scenario.clone()
        } else {
            format!("curriculum of {}", cfg.curriculum.len())
        },
        cfg.network.hidden,
        if cfg.network.lstm_units > 0 { format!(" + LSTM {}", cfg.network.lstm_units) } else { String::new() },
        cfg.train.num_actors,
        cfg.train.horizon_length,
        cfg.train.max_epochs,
        out.display()
    );
    let bar = indicatif::ProgressBar::new(cfg.train.max_epochs as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{bar:30} {pos}/{len} epochs [{elapsed_precise} eta {eta}] {msg}")
            .expect("a valid template"),
    );
    let opts = TrainOptions { out: out.clone(), resume: resuming, stop };
    let summary = rlnav_train::train(&cfg, &opts, &mut |r| {
        bar.set_position(r.epoch as u64);
        bar.set_message(format!(
            "{:.0} steps/s | return {:.1} | success {:.0}% | stage {}",
            r.steps_per_s,
            r.mean_return,
            100.0 * r.success_rate,
            r.stage_name
        ));
        if let Some(e) = &r.eval {
            bar.println(format!(
                "epoch {:>5} | {:>9} steps | {:>6.1} s | eval on {}: success {:.1}% collision {:.1}% timeout {:.1}%",
                r.epoch,
                r.env_steps,
                r.wall_s,
                cfg.eval.scenario,
                100.0 * e.success_rate,
                100.0 * e.collision_rate,
                100.0 * e.timeout_rate
            ));
        }
    })?;
    bar.finish_and_clear();
    println!(
        "{} epochs, {} env steps in {:.1} s ({:.0} steps/s){}",
        summary.iterations,
        summary.env_steps,
        summary.wall_s,
        summary.steps_per_s,
        if summary.interrupted {
            ", stopped early: resume with --resume"
        } else if summary.reached_stop_target {
            ", stopped at eval.stop_at_success"
        } else {
            ""
        }
    );
    for (target, m) in [("90%", summary.first_90), ("95%", summary.first_95)] {
        match m {
            Some(m) => println!(
                "evaluation first reached {target} after epoch {} ({} env steps, {:.1} s): {:.1}%",
                m.epoch,
                m.env_steps,
                m.wall_s,
                100.0 * m.success_rate
            ),
            None => println!("evaluation never reached {target}"),
        }
    }
    if let Some(e) = summary.final_eval {
        println!(
            "evaluation of the epoch-{} policy on {} ({} episodes in scenes not seen in training): success {:.1}%, collision {:.1}%, timeout {:.1}%",
            summary.final_epoch,
            summary.eval_scenario,
            e.episodes,
            100.0 * e.success_rate,
            100.0 * e.collision_rate,
            100.0 * e.timeout_rate
        );
    }
    println!("run folder: {}", out.display());
    Ok(())
}

/// Reads `NAME:=VALUE`.
fn xacro_arg(s: &str) -> Result<(String, String), String> {
    rlnav_sim::xacro::parse_arg(s).ok_or_else(|| format!("`{s}` is not a xacro argument NAME:=VALUE"))
}

fn robot_import(
    urdf: &std::path::Path,
    options: &rlnav_sim::xacro::XacroOptions,
    out: Option<PathBuf>,
    name: Option<String>,
) -> Result<()> {
    let mut imp = rlnav_sim::urdf::import_description_file(urdf, options)?;
    if let Some(n) = name {
        imp.robot.name = n;
    }
    for f in &imp.found {
        eprintln!("found: {f}");
    }
    for d in &imp.defaults {
        eprintln!("DEFAULT (check it): {d}");
    }
    let yaml = imp.to_yaml(&urdf.display().to_string());
    match out {
        Some(path) => {
            if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
                std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
            }
            std::fs::write(&path, yaml).with_context(|| format!("writing {}", path.display()))?;
            eprintln!("wrote {} (use it with --robot {})", path.display(), path.display());
        }
        None => print!("{yaml}"),
    }
    Ok(())
}

#[allow(clippy::too_many_arguments)]
fn render(
    args: &EnvArgs,
    out: &std::path::Path,
    episode: bool,
    controller: &str,
    seed: u64,
    size: u32,
    beam_stride: usize,
    speedup: f32,
) -> Result<()> {
    use rlnav_bench::episode::{Frame, record_episode};
    use rlnav_bench::render::{Scene, Style};
    let is_gif = out.extension().is_some_and(|e| e.eq_ignore_ascii_case("gif"));
    anyhow::ensure!(episode || !is_gif, "{}: an animation needs --episode", out.display());
    let setup = args.setup()?;
    let mut env = NavEnv::new(setup.clone(), seed)?;
    let (frames, summary) = if episode {
        let mut c = rlnav_bench::controllers::for_setup(controller, &setup)?;
        let rec = record_episode(&mut env, c.as_mut());
        let s = rec.stats;
        let summary = format!(
            "{} on {}: {:?} after {:.1} s, min lidar {:.2} m, mean speed {:.2} m/s",
            c.name(),
            setup.scenario.spec().name,
            s.outcome,
            s.time,
            s.min_range,
            s.mean_speed
        );
        (rec.frames, summary)
    } else {
        (vec![Frame::capture(&env, 0.0)], format!("{} at the start of an episode", setup.scenario.spec().name))
    };
    let scene = Scene::of(&setup, env.world());
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let style = Style { size, beam_stride, trail: episode };
    scene.write(out, &frames, &style, 300, speedup)?;
    println!("{summary}\nwrote {}", out.display());
    Ok(())
}

fn write_json(path: &std::path::Path, value: &impl serde::Serialize) -> Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    std::fs::write(path, serde_json::to_string_pretty(value)?)
        .with_context(|| format!("writing {}", path.display()))?;
    println!("wrote {}", path.display());
    Ok(())
}

#[allow(clippy::too_many_arguments)]
fn eval_policy(
    policy: &std::path::Path,
    contract: Option<&std::path::Path>,
    robot: Option<String>,
    scenario: Option<String>,
    episodes: usize,
    seed: u64,
    out: Option<PathBuf>,
    threads: usize,
) -> Result<()> {
    anyhow::ensure!(episodes > 0, "--episodes must be at least 1");
    let scenario = scenario.as_deref().unwrap_or("static-room");
    let ev = rlnav_bench::evaluate::evaluate_policy(
        policy,
        contract,
        scenario,
        robot.as_deref(),
        episodes,
        seed,
        threads.max(1),
    )?;
    let r = &ev.summary;
    println!(
        "{} ({}) on {} with {} ({episodes} episodes, seed {seed})",
        ev.policy, ev.contract.task, ev.scenario, ev.robot
    );
    println!(
        "{:<10} {:>8} {:>9} {:>8} {:>10} {:>10} {:>10}",
        "", "success", "collision", "timeout", "task_time", "min_lidar", "speed"
    );
    println!(
        "{:<10} {:>7.1}% {:>8.1}% {:>7.1}% {:>9.1}s {:>9.2}m {:>7.2}m/s",
        "",
        100.0 * r.success_rate,
        100.0 * r.collision_rate,
        100.0 * r.timeout_rate,
        r.mean_task_time,
        r.mean_min_range,
        r.mean_speed
    );
    write_json(&out.unwrap_or_else(|| PathBuf::from(".")).join("eval.json"), &ev)
}

fn inspect(policy: &std::path::Path, contract: Option<&std::path::Path>) -> Result<()> {
    use rlnav_policy::runner::{embedded_contract, graph_io, read_model};
    let file = policy.display().to_string();
    let proto = read_model(policy)?;
    println!(
        "{file}: producer {} {}, opset {:?}",
        proto.producer_name,
        proto.producer_version,
        proto.opset_import.iter().map(|o| o.version).collect::<Vec<_>>()
    );
    let (inputs, outputs) = graph_io(&proto);
    for i in &inputs {
        let dims = rlnav_policy::runner::input_dims(&proto, i).unwrap_or_default();
        let dims: Vec<String> = dims.iter().map(|d| d.map_or("batch".to_string(), |v| v.to_string())).collect();
        println!("  input  {i} [{}]", dims.join(", "));
    }
    for o in &outputs {
        println!("  output {o}");
    }
    let c = match contract {
        Some(p) => Some(rlnav_policy::PolicyContract::from_file(p)?),
        None => embedded_contract(&proto, &file)?,
    };
    match c {
        Some(c) => {
            println!("contract ({}):", if contract.is_some() { "side file" } else { "embedded" });
            for line in c.to_yaml().lines() {
                println!("  {line}");
            }
            // Load it for real: the contract must fit the graph.
            rlnav_policy::runner::PolicyRunner::from_proto(&file, &proto, c)?;
            println!(
                "the model fits its contract ({} observation values)",
                rlnav_policy::runner::input_dims(&proto, &inputs[0]).map_or(0, |d| d
                    .last()
                    .copied()
                    .flatten()
                    .unwrap_or(0))
            );
        }
        None => println!("no contract in metadata_props (give --contract FILE)"),
    }
    Ok(())
}

/// The shipped policies `rlnav bench` runs by default (with DWA).
const SHIPPED_POLICIES: [&str; 2] = ["policies/jetbot-static-mlp.onnx", "policies/jetbot-dynamic-lstm.onnx"];

/// `rlnav bench`'s options besides the suites and controllers.
struct BenchArgs {
    robot: Option<String>,
    episodes: Option<usize>,
    seed: u64,
    threads: usize,
    record: bool,
    timing_cycles: usize,
}

fn bench(suites: Vec<String>, controllers: Vec<String>, a: &BenchArgs, out: &std::path::Path) -> Result<()> {
    use rlnav_bench::suite::{RunOptions, SuiteSpec, run_suite};
    let suites = if suites.is_empty() { vec!["paper-static".into(), "paper-dynamic".into()] } else { suites };
    let controllers = if controllers.is_empty() {
        SHIPPED_POLICIES.iter().map(|p| format!("rl:{p}")).chain(["dwa".to_string()]).collect()
    } else {
        controllers
    };
    anyhow::ensure!(a.episodes != Some(0), "--episodes must be at least 1");
    // Load every suite first: a bad name fails before any episode runs.
    let specs = suites.iter().map(|s| SuiteSpec::load(s)).collect::<Result<Vec<_>, _>>()?;
    let mut md = String::new();
    let mut all = Vec::new();
    for spec in &specs {
        let n = a.episodes.unwrap_or(spec.episodes);
        eprintln!(
            "{}: {} scenarios x {} controllers x {n} episodes...",
            spec.name,
            spec.scenarios.len(),
            controllers.len()
        );
        let bar = indicatif::ProgressBar::new(1);
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{bar:30} {pos}/{len} scenario x controller [{elapsed_precise}] {msg}",
            )
            .expect("a valid template"),
        );
        bar.set_message(spec.name.clone());
        let record = a.record.then(|| out.join("mcap").join(rlnav_bench::plots::slug(&spec.name)));
        let opts = RunOptions {
            robot: a.robot.as_deref(),
            episodes: n,
            seed: a.seed,
            threads: a.threads.max(1),
            record: record.as_deref(),
        };
        let r = run_suite(spec, &controllers, &opts, &mut |done, total| {
            bar.set_length(total as u64);
            bar.set_position(done as u64);
        })?;
        bar.finish_and_clear();
        std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
        let setups = rlnav_bench::suite::suite_setups(spec, a.robot.as_deref())?;
        let figures = rlnav_bench::plots::write_suite_figures(&r, &setups, out).map_err(|e| anyhow::anyhow!(e))?;
        eprintln!("{}: {} figures in {}", spec.name, figures.len(), out.display());
        if let Some(dir) = &record {
            eprintln!("{}: MCAP recordings in {}", spec.name, dir.display());
        }
        let table = r.markdown();
        println!("{table}");
        md += &table;
        md += "\n";
        all.push(r);
    }
    // Per-cycle compute, one controller at a time on one thread, on the first suite's first
    // scenario: what each costs per control step on this machine.
    let mut timing = Vec::new();
    if a.timing_cycles > 0 {
        let setup = rlnav_bench::suite::suite_setups(&specs[0], a.robot.as_deref())?.remove(0);
        timing = rlnav_bench::latency::measure_controllers(&controllers, &setup, a.timing_cycles, a.seed)?;
        let t = rlnav_bench::latency::markdown(&timing, &setup.scenario.spec().name);
        println!("{t}");
        md += &t;
    }
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    std::fs::write(out.join("report.md"), md).with_context(|| format!("writing {}/report.md", out.display()))?;
    write_json(&out.join("report.json"), &serde_json::json!({ "suites": all, "per_cycle_compute": timing }))
}

/// A flag set by Ctrl-C (and SIGTERM), for loops that must end by leaving the robot stopped.
fn stop_flag() -> Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    let s = stop.clone();
    ctrlc::set_handler(move || s.store(true, Ordering::SeqCst)).context("installing the Ctrl-C handler")?;
    Ok(stop)
}

fn ros2(command: Ros2Command) -> Result<()> {
    use rlnav_ros2::bridge::{BridgeOptions, SimBridge, bridge_setup, run_bridge};
    use rlnav_ros2::node::{NodeParams, PolicyNode, run_node};
    match command {
        Ros2Command::Node { policy, contract, params, goal, dds } => {
            let (domain, reach) = dds.resolve()?;
            let mut p = match &params {
                Some(f) => NodeParams::from_file(f)?,
                None => NodeParams::default(),
            };
            if let Some(g) = goal {
                p.goal = Some([g[0], g[1]]);
            }
            let runner = rlnav_policy::PolicyRunner::load(&policy, contract.as_deref())?;
            let c = runner.contract();
            eprintln!(
                "rlnav_policy: {} ({} beams over [{:.2}, {:.2}] rad, every {:.3} s) on domain {domain}; {} -> {}",
                policy.display(),
                c.scan.beams,
                c.scan.angle_min,
                c.scan.angle_max,
                c.control_period,
                p.scan_topic,
                p.cmd_vel_topic
            );
            let node = PolicyNode::new(runner, p);
            run_node(node, domain, reach, stop_flag()?, |_, _| {})?;
            Ok(())
        }
        Ros2Command::Sim { scenario, robot, seed, episodes, rate, cmd_vel_stamped, dds } => {
            let (domain, reach) = dds.resolve()?;
            anyhow::ensure!(rate.is_finite() && rate > 0.0, "--rate must be positive");
            let setup = bridge_setup(&scenario, robot.as_deref())?;
            let opts = BridgeOptions { seed, episodes, rate, cmd_vel_stamped, ..Default::default() };
            eprintln!(
                "rlnav_sim: {} with {} on domain {domain}, {rate}x real time",
                setup.scenario.spec().name,
                setup.robot.name
            );
            let bridge = SimBridge::new(setup, &opts)?;
            run_bridge(bridge, &opts, domain, reach, stop_flag()?, |stats| {
                println!("{}", serde_json::to_string(stats).unwrap_or_default());
            })?;
            Ok(())
        }
    }
}
