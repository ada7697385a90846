//! `rlnav latency`: the compute of one control cycle of a controller.

use super::EnvArgs;
use anyhow::Result;

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    env: EnvArgs,
    /// Controller: greedy, straight, dwa or rl:POLICY.onnx[:CONTRACT.yaml].
    #[arg(long)]
    controller: String,
    /// Cycles to time.
    #[arg(long, default_value_t = 20000)]
    cycles: usize,
}

pub fn run(a: Args) -> Result<()> {
    anyhow::ensure!(a.cycles > 0, "--cycles must be at least 1");
    let setup = a.env.setup_for(&a.controller)?;
    let mut c = rlnav_bench::controllers::for_setup(&a.controller, &setup)?;
    let r = rlnav_bench::latency::measure_latency(c.as_mut(), setup, a.cycles, a.cycles / 10, 0)?;
    println!(
        "{}: {} cycles on {}-beam scans: p50 {:.1} µs, p99 {:.1} µs, mean {:.1} µs, max {:.1} µs",
        r.controller, r.cycles, r.beams, r.p50_us, r.p99_us, r.mean_us, r.max_us
    );
    println!("{}", serde_json::to_string(&r)?);
    Ok(())
}
