//! `rlnav`: train, evaluate and deploy RL local planners for wheeled robots with a 2D lidar.
//! This binary parses arguments, shows progress and wires the library crates together; each
//! command lives in its own module under `commands/`, with its arguments beside its code.

mod commands;

use anyhow::Result;
use clap::{Parser, Subcommand};
use commands::{barn, bench, demo, eval, export, inspect, latency, list, render, robot, ros2, sim_speed, train};

#[derive(Parser)]
#[command(name = "rlnav", version, about = "End-to-end RL local planners for wheeled robots with a 2D lidar")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a simple controller on a scenario and print what happened.
    Demo(demo::Args),
    /// Measure simulator throughput with random actions; the last line is a JSON object.
    SimSpeed(sim_speed::Args),
    /// Train a policy with PPO (default: the built-in static-obstacle Jetbot run) and report
    /// how well it navigates scenes it never saw.
    Train(train::Args),
    /// Evaluate a trained run (`--run`, on its evaluation scenario by default) or any ONNX
    /// policy with a contract (`--policy`, on static-room by default) and write eval.json.
    Eval(eval::Args),
    /// Export a run's policy as ONNX with its contract (training does it too: policy.onnx).
    Export(export::Args),
    /// Time one control cycle of a controller (for a policy: observation from the scan,
    /// inference, command) on scenario observations; prints p50/p99 and a JSON line.
    Latency(latency::Args),
    /// Run controllers on scenario suites with the same seeded episodes and write the
    /// article's table (report.md, report.json). With no arguments: the shipped policies and
    /// DWA on paper-static and paper-dynamic.
    Bench(bench::Args),
    /// Print an ONNX policy's contract and its graph's inputs and outputs.
    Inspect(inspect::Args),
    /// Draw a scenario (PNG or SVG): the world, the robot at its start, the goal, the lidar's
    /// rays; with `--episode`, one episode under `--controller` with its whole path, or
    /// animated when the output is a GIF.
    Render(render::Args),
    /// List the shipped scenarios and robots.
    List,
    /// BARN Challenge worlds.
    Barn {
        #[command(subcommand)]
        command: barn::Command,
    },
    /// Robot files.
    Robot {
        #[command(subcommand)]
        command: robot::Command,
    },
    /// ROS 2 (pure Rust, no ROS installation): the policy node and the simulator bridge.
    Ros2 {
        #[command(subcommand)]
        command: ros2::Command,
    },
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
        Command::Demo(a) => demo::run(a),
        Command::SimSpeed(a) => sim_speed::run(a),
        Command::Train(a) => train::run(a),
        Command::Eval(a) => eval::run(a),
        Command::Export(a) => export::run(a),
        Command::Latency(a) => latency::run(a),
        Command::Bench(a) => bench::run(a),
        Command::Inspect(a) => inspect::run(a),
        Command::Render(a) => render::run(a),
        Command::List => list::run(),
        Command::Barn { command } => barn::run(command),
        Command::Robot { command } => robot::run(command),
        Command::Ros2 { command } => ros2::run(command),
    }
}
