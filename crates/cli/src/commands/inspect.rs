//! `rlnav inspect`: an ONNX policy's graph and contract, checked against each other.

use anyhow::Result;
use rlnav_policy::runner::{PolicyRunner, embedded_contract, graph_io, input_dims, read_model};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// The ONNX file.
    policy: PathBuf,
    /// Side contract to check the model against instead of the embedded one.
    #[arg(long)]
    contract: Option<PathBuf>,
}

pub fn run(a: Args) -> Result<()> {
    let file = a.policy.display().to_string();
    let proto = read_model(&a.policy)?;
    println!(
        "{file}: producer {} {}, opset {:?}",
        proto.producer_name,
        proto.producer_version,
        proto.opset_import.iter().map(|o| o.version).collect::<Vec<_>>()
    );
    let (inputs, outputs) = graph_io(&proto);
    for i in &inputs {
        let dims = input_dims(&proto, i).unwrap_or_default();
        let dims: Vec<String> = dims.iter().map(|d| d.map_or("batch".to_string(), |v| v.to_string())).collect();
        println!("  input  {i} [{}]", dims.join(", "));
    }
    for o in &outputs {
        println!("  output {o}");
    }
    let c = match &a.contract {
        Some(p) => Some(rlnav_policy::PolicyContract::from_file(p)?),
        None => embedded_contract(&proto, &file)?,
    };
    let Some(c) = c else {
        println!("no contract in metadata_props (give --contract FILE)");
        return Ok(());
    };
    println!("contract ({}):", if a.contract.is_some() { "side file" } else { "embedded" });
    for line in c.to_yaml().lines() {
        println!("  {line}");
    }
    println!("observation ({} values):", c.obs_dim());
    for (start, term) in c.observation.spans() {
        let end = start + term.len() - 1;
        let at = if end > start { format!("{start}-{end}") } else { start.to_string() };
        println!("  {at:>9}  {}", term.describe());
    }
    // Load it for real: the contract must fit the graph.
    PolicyRunner::from_proto(&file, &proto, c)?;
    let n = input_dims(&proto, &inputs[0]).map_or(0, |d| d.last().copied().flatten().unwrap_or(0));
    println!("the model fits its contract ({n} observation values)");
    Ok(())
}
