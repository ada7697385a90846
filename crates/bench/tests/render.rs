//! Pictures: what is drawn lands where it is in the world (y up, not down), every format
//! decodes, and an animation has one frame per recorded step up to its cap.

use image::AnimationDecoder;
use rlnav_bench::episode::{Frame, record_episode};
use rlnav_bench::render::{Scene, Style};
use rlnav_sim::geometry::Rect;
use rlnav_sim::task::{EnvSetup, NavEnv};
use rlnav_sim::{GreedyGoal, Vec2};
use std::sync::Arc;

fn tmp(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("rlnav-render-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d.join(name)
}

fn scene_of(env: &NavEnv) -> Scene<'_> {
    Scene::of(env.setup(), env.world())
}

/// Pixel of world point `p` in a picture of `view` drawn `size` pixels on its longer side.
fn pixel(view: Rect, size: u32, p: Vec2) -> (u32, u32) {
    let s = view.size();
    let scale = size as f32 / s.x.max(s.y);
    let h = (s.y * scale).round();
    (((p.x - view.min.x) * scale) as u32, (h - (p.y - view.min.y) * scale) as u32)
}

#[test]
fn png_puts_things_where_they_are() {
    let env = NavEnv::new(Arc::new(EnvSetup::from_scenario_name("static-room").unwrap()), 5).unwrap();
    let scene = scene_of(&env);
    let path = tmp("scene.png");
    let style = Style { size: 600, beam_stride: 0, trail: false };
    scene.write(&path, &[Frame::capture(&env, 0.0)], &style, 1, 1.0).unwrap();
    let img = image::open(&path).unwrap().to_rgb8();
    let at = |p: Vec2| {
        let (x, y) = pixel(scene.view, 600, p);
        img.get_pixel(x, y).0
    };
    // static-room: a 0.25 m cylinder at (-2.2, 1.9) (upper left), a box around (-2.6, -0.3).
    assert_eq!(at(Vec2::new(-2.2, 1.9)), [110, 110, 110], "cylinder, upper half");
    assert_eq!(at(Vec2::new(-2.2, -1.9)), [255, 255, 255], "its mirror image is empty");
    assert_eq!(at(Vec2::new(-2.6, -0.3)), [110, 110, 110], "box");
    assert_eq!(at(env.goal()), [20, 150, 60], "goal dot");
    let robot = at(env.pose().position());
    assert!(robot[2] > robot[0] && robot[2] > 150, "robot drawn in blue at its pose: {robot:?}");
}

#[test]
fn svg_and_gif_of_an_episode() {
    let mut env = NavEnv::new(Arc::new(EnvSetup::from_scenario_name("dynamic-room").unwrap()), 2).unwrap();
    let rec = record_episode(&mut env, &mut GreedyGoal::default());
    assert_eq!(rec.frames.len() as u32, rec.stats.length + 1);
    let scene = scene_of(&env);
    let svg = tmp("episode.svg");
    scene.write(&svg, &rec.frames, &Style::default(), 1, 1.0).unwrap();
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.starts_with("<svg") && text.contains("<polyline"), "trajectory drawn as a path");
    let gif = tmp("episode.gif");
    let style = Style { size: 200, ..Default::default() };
    scene.write(&gif, &rec.frames, &style, 20, 2.0).unwrap();
    let frames = image::codecs::gif::GifDecoder::new(std::io::BufReader::new(std::fs::File::open(&gif).unwrap()))
        .unwrap()
        .into_frames()
        .collect_frames()
        .unwrap();
    let expected = rec.frames.len().div_ceil(rec.frames.len().div_ceil(20));
    assert!(frames.len() == expected || frames.len() == expected + 1, "{} frames", frames.len());
    assert_eq!(frames[0].buffer().dimensions(), (200, 200));
    assert_ne!(frames[0].buffer(), frames[frames.len() - 1].buffer(), "things move");
    if let Ok(dir) = std::env::var("RLNAV_KEEP_FRAMES") {
        frames[frames.len() / 2].buffer().save(format!("{dir}/gif_mid.png")).unwrap();
    }
    assert!(
        scene.write(&tmp("x.bmp"), &rec.frames, &style, 1, 1.0).unwrap_err().to_string().contains(".png, .svg or .gif")
    );
}
