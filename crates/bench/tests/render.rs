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

/// A map_saver map is mostly unknown space: the picture shows the mapped part (its known
/// cells plus the margin), not the whole 19.2 m square.
#[test]
fn a_real_map_is_cropped_to_its_known_part() {
    let env = NavEnv::new(Arc::new(EnvSetup::from_scenario_name("turtlebot3-world").unwrap()), 1).unwrap();
    let scene = scene_of(&env);
    let grid = env.world().grid().unwrap();
    let known = grid.known_bounds();
    let (min, max) = (known.min - Vec2::splat(0.3), known.max + Vec2::splat(0.3));
    assert!((scene.view.min - min).abs().max_element() < 1e-4, "{:?} vs known {known:?}", scene.view);
    assert!((scene.view.max - max).abs().max_element() < 1e-4, "{:?} vs known {known:?}", scene.view);
    assert!(scene.view.size().x < 6.5 && grid.bounds().size().x > 19.0);
    let path = tmp("turtlebot3-world.png");
    let style = Style { size: 400, beam_stride: 0, trail: false };
    scene.write(&path, &[Frame::capture(&env, 0.0)], &style, 1, 1.0).unwrap();
    let img = image::open(&path).unwrap().to_rgb8();
    // 5.65 x 5.2 m known plus 0.3 m a side: 400 x 371 pixels, about 64 px/m.
    assert_eq!(img.dimensions(), (400, 371));
    let grey = img.pixels().filter(|p| p.0 == [205, 205, 205]).count() as f32 / (400.0 * 371.0);
    let white = img.pixels().filter(|p| p.0 == [255, 255, 255]).count() as f32 / (400.0 * 371.0);
    // The arena (free, white: 19.8 m² of 36.3) fills over half the picture, unknown (grey)
    // only the corners and the margin (40%). The whole map would be 94% grey, 5% white.
    assert!(white > 0.45 && grey < 0.45, "white {white}, grey {grey}");
    // A wall lands where it is: the arena's south wall fills y = -2.6..-2.5 near x = 0.
    let (x, y) = pixel(scene.view, 400, Vec2::new(0.02, -2.55));
    assert_eq!(img.get_pixel(x, y).0, [40, 40, 40], "south wall at pixel ({x}, {y})");
}
