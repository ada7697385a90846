//! `rlnav export`: a run's policy as ONNX with its contract.

use anyhow::{Context, Result};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Run folder written by `rlnav train`.
    #[arg(long)]
    run: PathBuf,
    /// Output file (default: RUN/policy.onnx).
    #[arg(short, long)]
    out: Option<PathBuf>,
    /// Checkpoint: `best` (default when there is one) or `checkpoint` (the last).
    #[arg(long)]
    checkpoint: Option<String>,
}

pub fn run(a: Args) -> Result<()> {
    let out = a.out.unwrap_or_else(|| a.run.join("policy.onnx"));
    let which = match a.checkpoint.as_deref() {
        None => None,
        Some(c @ ("best" | "checkpoint")) => Some(c),
        Some(other) => anyhow::bail!("--checkpoint `{other}`: expected `best` or `checkpoint`"),
    };
    let used = match which {
        Some(w) => {
            let (bytes, _) = rlnav_train::export::export_run(&a.run, w)?;
            std::fs::write(&out, bytes).with_context(|| format!("writing {}", out.display()))?;
            w
        }
        None => rlnav_train::export::write_policy(&a.run, &out)?,
    };
    println!("exported {}/{used} to {}", a.run.display(), out.display());
    Ok(())
}
