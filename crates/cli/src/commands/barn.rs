//! `rlnav barn import`: a user's own copy of the BARN worlds as a BARN data file and suites.

use anyhow::{Context, Result};
use clap::Subcommand;
use rlnav_sim::barn::{Split, import_dir};
use std::path::{Path, PathBuf};

#[derive(Subcommand)]
pub enum Command {
    /// Read the BARN worlds as the challenge or the dataset distributes them (world_N.world
    /// files, or grid_N.npy grids, with path_files/path_N.npy) into OUT/barn_worlds.json, with
    /// each world's reference path length and difficulty metrics, and write the suites
    /// OUT/barn-all.yaml and OUT/barn-test.yaml (the challenge's 50 test worlds, indices
    /// 0, 6, ..., 294) for `rlnav bench --suite`. Nothing is written unless every file reads.
    Import {
        /// The folder: the challenge's jackal_helper/worlds/BARN (or the repository holding
        /// it), or the dataset's folder with world_files/ or grid_files/ and path_files/.
        dir: PathBuf,
        /// Output folder (created if needed).
        #[arg(short, long, default_value = "barn")]
        out: PathBuf,
        /// Which worlds: all, test (indices that are multiples of 6) or train (the others).
        #[arg(long, default_value = "all", value_parser = split)]
        split: Split,
    },
}

fn split(s: &str) -> Result<Split, String> {
    match s {
        "all" => Ok(Split::All),
        "test" => Ok(Split::Test),
        "train" => Ok(Split::Train),
        _ => Err(format!("`{s}`: expected all, test or train")),
    }
}

pub fn run(command: Command) -> Result<()> {
    let Command::Import { dir, out, split } = command;
    let imported = import_dir(&dir, split)?;
    let n = imported.indices.len();
    let tests = imported.indices.iter().filter(|i| Split::Test.contains(**i)).count();
    let suite = |name: &str, split: &str, what: &str| {
        format!(
            "# Written by `rlnav barn import {}`.\nname: {name}\ndescription: {what}, Jackal, 1 m success radius, 100 s\n\
             barn: {{file: barn_worlds.json, split: {split}}}\nepisodes: 1\n",
            dir.display()
        )
    };
    let mut files = vec![
        ("barn_worlds.json", imported.json.clone()),
        ("barn-all.yaml", suite("barn-all", "all", &format!("{n} imported BARN worlds"))),
    ];
    if tests > 0 {
        files.push(("barn-test.yaml", suite("barn-test", "test", &format!("the challenge's {tests} test worlds"))));
    }
    write_all(&out, &files)?;
    println!(
        "read {n} worlds ({} files in {}), {tests} of them test worlds; wrote {} in {}",
        imported.obstacles_from,
        imported.world_dir.display(),
        files.iter().map(|f| f.0).collect::<Vec<_>>().join(", "),
        out.display()
    );
    let test_suite = out.join("barn-test.yaml");
    if tests > 0 {
        println!("run the test split: rlnav bench --suite {} --controller dwa --robot jackal", test_suite.display());
    }
    Ok(())
}

/// Writes every file under a temporary name first and renames them into place only when all
/// are written, so that a failure leaves nothing half-written.
fn write_all(dir: &Path, files: &[(&str, String)]) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let tmp = |name: &str| dir.join(format!(".{name}.partial"));
    let written: Result<()> = files.iter().try_for_each(|(name, text)| {
        std::fs::write(tmp(name), text).with_context(|| format!("writing {}", tmp(name).display()))
    });
    if let Err(e) = written {
        for (name, _) in files {
            let _ = std::fs::remove_file(tmp(name));
        }
        return Err(e);
    }
    for (name, _) in files {
        std::fs::rename(tmp(name), dir.join(name)).with_context(|| format!("writing {}", dir.join(name).display()))?;
    }
    Ok(())
}
