//! `rlnav render`: a scenario or one episode as a picture or an animation.

use super::EnvArgs;
use anyhow::Result;
use rlnav_bench::episode::{Frame, record_episode};
use rlnav_bench::render::{Scene, Style};
use rlnav_sim::task::NavEnv;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
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
}

pub fn run(a: Args) -> Result<()> {
    let is_gif = a.out.extension().is_some_and(|e| e.eq_ignore_ascii_case("gif"));
    anyhow::ensure!(a.episode || !is_gif, "{}: an animation needs --episode", a.out.display());
    let setup = a.env.setup_for(&a.controller)?;
    let mut env = NavEnv::new(setup.clone(), a.seed)?;
    let (frames, summary) = if a.episode {
        let mut c = rlnav_bench::controllers::for_setup(&a.controller, &setup)?;
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
    super::create_parent(&a.out)?;
    let style = Style { size: a.size, beam_stride: a.beam_stride, trail: a.episode };
    scene.write(&a.out, &frames, &style, 300, a.speedup)?;
    println!("{summary}\nwrote {}", a.out.display());
    Ok(())
}
