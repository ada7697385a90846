//! `rlnav robot import`: a robot file from a URDF or xacro description.

use anyhow::{Context, Result};
use clap::Subcommand;
use rlnav_sim::xacro::{PackagePath, XacroOptions};
use std::path::PathBuf;

#[derive(Subcommand)]
pub enum Command {
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

/// Reads `NAME:=VALUE`.
fn xacro_arg(s: &str) -> Result<(String, String), String> {
    rlnav_sim::xacro::parse_arg(s).ok_or_else(|| format!("`{s}` is not a xacro argument NAME:=VALUE"))
}

pub fn run(command: Command) -> Result<()> {
    let Command::Import { urdf, xacro_args, package_path, out, name } = command;
    let options = XacroOptions { args: xacro_args, packages: PackagePath::new(package_path).with_environment() };
    let mut imp = rlnav_sim::urdf::import_description_file(&urdf, &options)?;
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
            super::create_parent(&path)?;
            std::fs::write(&path, yaml).with_context(|| format!("writing {}", path.display()))?;
            eprintln!("wrote {} (use it with --robot {})", path.display(), path.display());
        }
        None => print!("{yaml}"),
    }
    Ok(())
}
