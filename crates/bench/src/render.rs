//! Pictures of a scene or an episode: the world (obstacles, map cells, moving obstacles,
//! people), the goal and its tolerance, the robot's footprint and heading, the lidar's rays,
//! and the trajectory so far. SVG and PNG for one instant (with the whole path), animated GIF
//! for an episode.
//!
//! Drawing is plotters' (one drawing routine for its SVG and bitmap backends); PNG and GIF
//! encoding is the `image` crate's. Pictures carry no text, so that no font is needed.

use crate::episode::Frame;
use image::codecs::gif::{GifEncoder, Repeat};
use image::{Delay, RgbImage, RgbaImage};
use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf32;
use plotters::prelude::*;
use rlnav_sim::geometry::{Primitive, Rect};
use rlnav_sim::map::Cell;
use rlnav_sim::movers::MoverShape;
use rlnav_sim::robot::FootprintSpec;
use rlnav_sim::{LidarSpec, Pose2, Vec2, World};
use std::path::Path;

/// Why a picture could not be made.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// The output name has no extension rlnav can write.
    #[error("{0}: expected a .png, .svg or .gif file name")]
    Format(String),
    /// Drawing or writing failed.
    #[error("{file}: {message}")]
    Write {
        /// The output file.
        file: String,
        /// What went wrong.
        message: String,
    },
    /// Nothing to draw.
    #[error("nothing to draw: no frames")]
    Empty,
}

/// What stays the same through an episode: the world and the robot.
pub struct Scene<'a> {
    /// The static world (obstacles and any map).
    pub world: &'a World,
    /// The region to show (m).
    pub view: Rect,
    /// The robot's outline.
    pub footprint: &'a FootprintSpec,
    /// The robot's lidar.
    pub lidar: &'a LidarSpec,
    /// Goal tolerance (m), drawn as a ring around the goal.
    pub goal_tolerance: f32,
}

/// Drawing options.
#[derive(Clone, Debug)]
pub struct Style {
    /// Pixels along the longer side of the picture.
    pub size: u32,
    /// Draw every `beam_stride`-th lidar beam (0: none).
    pub beam_stride: usize,
    /// Draw the path driven so far.
    pub trail: bool,
}

impl Default for Style {
    fn default() -> Self {
        Self { size: 800, beam_stride: 4, trail: true }
    }
}

const OBSTACLE: RGBColor = RGBColor(110, 110, 110);
const OCCUPIED: RGBColor = RGBColor(40, 40, 40);
const UNKNOWN: RGBColor = RGBColor(205, 205, 205);
const MOVER: RGBColor = RGBColor(230, 140, 20);
const PERSON: RGBColor = RGBColor(150, 60, 170);
const ROBOT: RGBColor = RGBColor(30, 90, 200);
const GOAL: RGBColor = RGBColor(20, 150, 60);
const RAY: RGBColor = RGBColor(220, 40, 40);

impl<'a> Scene<'a> {
    /// The scene of episodes of `setup` in `world` (an episode's, or the scenario's fixed one):
    /// the scenario's area and the world, 0.3 m of margin.
    pub fn of(setup: &'a rlnav_sim::task::EnvSetup, world: &'a World) -> Self {
        Self {
            world,
            view: view_of(world, setup.scenario.area(), 0.3),
            footprint: &setup.robot.footprint,
            lidar: &setup.robot.lidar,
            goal_tolerance: setup.task.goal_tolerance,
        }
    }

    fn pixels(&self, style: &Style) -> (u32, u32) {
        let s = self.view.size();
        let scale = style.size as f32 / s.x.max(s.y);
        (((s.x * scale).round() as u32).max(16), ((s.y * scale).round() as u32).max(16))
    }

    /// Pixels per metre.
    fn scale(&self, style: &Style) -> f32 {
        let s = self.view.size();
        style.size as f32 / s.x.max(s.y)
    }

    /// Draws `frame` (and the trail of `history` before it) onto any plotters backend.
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
        frame: &Frame,
        history: &[Frame],
        style: &Style,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        root.fill(&WHITE)?;
        let area = self.world_area(root);
        let px = |r: f32| ((r * self.scale(style)).round() as i32).max(1);
        let pt = |p: Vec2| (p.x, p.y);

        self.draw_world(&area, style)?;

        // The goal and its tolerance.
        area.draw(&Circle::new(pt(frame.goal), px(self.goal_tolerance), GOAL.stroke_width(2)))?;
        area.draw(&Circle::new(pt(frame.goal), 4, GOAL.filled()))?;

        for m in &frame.movers {
            match (&m.shape, m.corners()) {
                (MoverShape::Circle { radius }, _) => {
                    area.draw(&Circle::new(pt(m.pose.position()), px(*radius), MOVER.filled()))?
                }
                (_, Some(c)) => {
                    area.draw(&Polygon::new(c.iter().map(|p| pt(*p)).collect::<Vec<_>>(), MOVER.filled()))?
                }
                _ => {}
            }
        }
        for (p, r) in &frame.people {
            area.draw(&Circle::new(pt(*p), px(*r), PERSON.mix(0.8).filled()))?;
        }

        if style.trail && !history.is_empty() {
            let path: Vec<(f32, f32)> =
                history.iter().chain(std::iter::once(frame)).map(|f| pt(f.pose.position())).collect();
            area.draw(&Circle::new(path[0], 5, ROBOT.stroke_width(2)))?;
            area.draw(&PathElement::new(path, ROBOT.stroke_width(2)))?;
        }

        if style.beam_stride > 0 {
            let sensor = frame.pose.compose(&self.lidar.mount);
            let from = pt(sensor.position());
            for (i, r) in frame.ranges.iter().enumerate().step_by(style.beam_stride) {
                if !r.is_finite() {
                    continue;
                }
                let a = sensor.yaw + self.lidar.beam_angle(i);
                let hit = sensor.position() + Vec2::new(a.cos(), a.sin()) * *r;
                area.draw(&PathElement::new(vec![from, pt(hit)], RAY.mix(0.35).stroke_width(1)))?;
                area.draw(&Circle::new(pt(hit), 2, RAY.filled()))?;
            }
        }

        self.draw_robot(&area, &frame.pose, style)?;
        Ok(())
    }

    /// The world-coordinate drawing area of a root area.
    fn world_area<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
    ) -> DrawingArea<DB, Cartesian2d<RangedCoordf32, RangedCoordf32>> {
        let (w, h) = root.dim_in_pixel();
        let v = self.view;
        // Pixel rows grow downwards; y grows upwards.
        root.apply_coord_spec(Cartesian2d::<RangedCoordf32, RangedCoordf32>::new(
            v.min.x..v.max.x,
            v.min.y..v.max.y,
            (0..w as i32, h as i32..0),
        ))
    }

    /// Map cells and static obstacles.
    fn draw_world<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Cartesian2d<RangedCoordf32, RangedCoordf32>>,
        style: &Style,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        let px = |r: f32| ((r * self.scale(style)).round() as i32).max(1);
        let pt = |p: Vec2| (p.x, p.y);
        if let Some(grid) = self.world.grid() {
            // Horizontal runs of equal cells, one polygon each.
            let (gw, gh) = grid.size();
            let r = grid.resolution();
            for iy in 0..gh {
                let mut ix = 0;
                while ix < gw {
                    let c = grid.cell(ix, iy);
                    let start = ix;
                    while ix < gw && grid.cell(ix, iy) == c {
                        ix += 1;
                    }
                    let colour = match c {
                        Cell::Free => continue,
                        Cell::Occupied => OCCUPIED,
                        Cell::Unknown => UNKNOWN,
                    };
                    let (x0, x1, y0, y1) = (start as f32 * r, ix as f32 * r, iy as f32 * r, (iy + 1) as f32 * r);
                    let corners = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
                        .map(|(x, y)| pt(grid.origin().to_parent(Vec2::new(x, y))));
                    area.draw(&Polygon::new(corners.to_vec(), colour.filled()))?;
                }
            }
        }
        for o in self.world.obstacles() {
            match &o.primitive {
                Primitive::Circle { center, radius } => {
                    area.draw(&Circle::new(pt(*center), px(*radius), OBSTACLE.filled()))?
                }
                Primitive::Polygon { vertices } => {
                    area.draw(&Polygon::new(vertices.iter().map(|p| pt(*p)).collect::<Vec<_>>(), OBSTACLE.filled()))?
                }
                Primitive::Segment { a, b } => {
                    area.draw(&PathElement::new(vec![pt(*a), pt(*b)], OBSTACLE.stroke_width(3)))?
                }
            }
        }

        Ok(())
    }

    /// Writes the world with paths drawn over it (`.svg` or `.png`, by extension), each point
    /// coloured by the smallest lidar range at that moment (the article's "safety spectrum":
    /// red at `red` m or closer, green at `green` m or farther), each path starting at a hollow
    /// circle.
    pub fn write_paths(
        &self,
        path: &Path,
        paths: &[Vec<(Vec2, f32)>],
        red: f32,
        green: f32,
        style: &Style,
    ) -> Result<(), RenderError> {
        let figure = PathsFigure { scene: self, paths, red, green, style };
        write_figure(path, self.pixels(style), &figure)
            .map_err(|message| RenderError::Write { file: path.display().to_string(), message })
    }
}

/// A scene with coloured paths over it.
struct PathsFigure<'a> {
    scene: &'a Scene<'a>,
    paths: &'a [Vec<(Vec2, f32)>],
    red: f32,
    green: f32,
    style: &'a Style,
}

impl Figure for PathsFigure<'_> {
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        let Self { scene, paths, red, green, style } = *self;
        root.fill(&WHITE)?;
        let area = scene.world_area(root);
        scene.draw_world(&area, style)?;
        for p in paths {
            if let Some(first) = p.first() {
                area.draw(&Circle::new((first.0.x, first.0.y), 4, ROBOT.stroke_width(1)))?;
            }
            for w in p.windows(2) {
                let t = ((w[1].1 - red) / (green - red)).clamp(0.0, 1.0) as f64;
                // Red through yellow to green.
                let colour = RGBColor((255.0 * (2.0 - 2.0 * t).min(1.0)) as u8, (200.0 * (2.0 * t).min(1.0)) as u8, 40);
                area.draw(&PathElement::new(vec![(w[0].0.x, w[0].0.y), (w[1].0.x, w[1].0.y)], colour.stroke_width(2)))?;
            }
        }
        Ok(())
    }
}

impl Scene<'_> {
    fn draw_robot<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Cartesian2d<RangedCoordf32, RangedCoordf32>>,
        pose: &Pose2,
        style: &Style,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        let pt = |p: Vec2| (p.x, p.y);
        let reach = match self.footprint {
            FootprintSpec::Circle { radius } => {
                let r = ((radius * self.scale(style)).round() as i32).max(3);
                area.draw(&Circle::new(pt(pose.position()), r, ROBOT.mix(0.6).filled()))?;
                *radius
            }
            FootprintSpec::Polygon(points) => {
                let pts: Vec<(f32, f32)> = points.iter().map(|p| pt(pose.to_parent(Vec2::new(p[0], p[1])))).collect();
                area.draw(&Polygon::new(pts, ROBOT.mix(0.6).filled()))?;
                points.iter().map(|p| p[0].hypot(p[1])).fold(0.0, f32::max)
            }
        };
        // Heading: a line from the centre to a little beyond the outline.
        let tip = pose.to_parent(Vec2::new(reach.max(0.05) * 1.4, 0.0));
        area.draw(&PathElement::new(vec![pt(pose.position()), pt(tip)], BLACK.stroke_width(2)))
    }

    /// Draws one frame (with the trail of `history`) into an RGB buffer (what `.png` files
    /// hold, and the Python API's `render()` returns).
    pub fn raster(&self, frame: &Frame, history: &[Frame], style: &Style) -> Result<RgbImage, String> {
        let (w, h) = self.pixels(style);
        let mut buf = vec![0u8; (w * h * 3) as usize];
        {
            let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
            self.draw(&root, frame, history, style).map_err(|e| e.to_string())?;
            root.present().map_err(|e| e.to_string())?;
        }
        RgbImage::from_raw(w, h, buf).ok_or_else(|| "buffer size".to_string())
    }

    /// Writes the last frame with the whole trail before it: `.svg` or `.png`; or every frame
    /// as an animated `.gif` (at most `max_frames`, evenly picked, played at `speedup` times
    /// real time).
    pub fn write(
        &self,
        path: &Path,
        frames: &[Frame],
        style: &Style,
        max_frames: usize,
        speedup: f32,
    ) -> Result<(), RenderError> {
        let file = path.display().to_string();
        let err = |message: String| RenderError::Write { file: file.clone(), message };
        let last = frames.last().ok_or(RenderError::Empty)?;
        let history = &frames[..frames.len() - 1];
        let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("svg") => {
                let root = SVGBackend::new(path, self.pixels(style)).into_drawing_area();
                self.draw(&root, last, history, style).map_err(|e| err(e.to_string()))?;
                root.present().map_err(|e| err(e.to_string()))
            }
            Some("png") => {
                let img = self.raster(last, history, style).map_err(err)?;
                img.save_with_format(path, image::ImageFormat::Png).map_err(|e| err(e.to_string()))
            }
            Some("gif") => {
                let stride = frames.len().div_ceil(max_frames.max(1));
                let dt = if frames.len() > 1 { frames[1].time - frames[0].time } else { 0.1 };
                let delay_ms = ((dt * stride as f32 * 1000.0 / speedup.max(0.01)).round() as u32).max(20);
                let out = std::fs::File::create(path).map_err(|e| err(e.to_string()))?;
                let mut enc = GifEncoder::new_with_speed(std::io::BufWriter::new(out), 10);
                enc.set_repeat(Repeat::Infinite).map_err(|e| err(e.to_string()))?;
                let mut picks: Vec<usize> = (0..frames.len()).step_by(stride).collect();
                if picks.last() != Some(&(frames.len() - 1)) {
                    picks.push(frames.len() - 1);
                }
                for (k, &i) in picks.iter().enumerate() {
                    let rgb = self.raster(&frames[i], &frames[..i], style).map_err(err)?;
                    let rgba: RgbaImage = image::DynamicImage::ImageRgb8(rgb).to_rgba8();
                    // Hold the last frame so the ending can be seen.
                    let ms = if k + 1 == picks.len() { 1500 } else { delay_ms };
                    let frame = image::Frame::from_parts(rgba, 0, 0, Delay::from_numer_denom_ms(ms, 1));
                    enc.encode_frame(frame).map_err(|e| err(e.to_string()))?;
                }
                Ok(())
            }
            _ => Err(RenderError::Format(file)),
        }
    }
}

/// A view around `area` and everything in the world (tight: vertices, not bounding circles),
/// with a margin. Of a map, only the known cells count: a `map_saver` map is mostly unknown
/// space around the part that was mapped.
pub fn view_of(world: &World, area: Rect, margin: f32) -> Rect {
    let (mut min, mut max) = (area.min, area.max);
    let mut grow = |p: Vec2, r: f32| {
        min = min.min(p - Vec2::splat(r));
        max = max.max(p + Vec2::splat(r));
    };
    for o in world.obstacles() {
        match &o.primitive {
            Primitive::Circle { center, radius } => grow(*center, *radius),
            Primitive::Segment { a, b } => {
                grow(*a, 0.0);
                grow(*b, 0.0);
            }
            Primitive::Polygon { vertices } => vertices.iter().for_each(|v| grow(*v, 0.0)),
        }
    }
    if let Some(g) = world.grid() {
        let b = g.known_bounds();
        grow(b.min, 0.0);
        grow(b.max, 0.0);
    }
    Rect { min: min - Vec2::splat(margin), max: max + Vec2::splat(margin) }
}

/// Registers the embedded font (DejaVu Sans) for plot text once per process, so that labels
/// render the same on every machine, with or without system fonts.
pub(crate) fn register_font() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let font: &'static [u8] = include_bytes!("../../../assets/fonts/DejaVuSans.ttf");
        // The font is ours and known good; a failure would only drop the text.
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, font);
    });
}

/// Something drawn the same way on any plotters backend.
pub trait Figure {
    /// Draws onto `root`.
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>>;
}

/// Draws `figure` at `size` pixels and writes it as SVG or PNG, by `path`'s extension.
pub fn write_figure(path: &Path, size: (u32, u32), figure: &impl Figure) -> Result<(), String> {
    register_font();
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("svg") => {
            let root = SVGBackend::new(path, size).into_drawing_area();
            figure.draw(&root).map_err(|e| e.to_string())?;
            root.present().map_err(|e| e.to_string())
        }
        Some("png") => {
            let (w, h) = size;
            let mut buf = vec![0u8; (w * h * 3) as usize];
            {
                let root = BitMapBackend::with_buffer(&mut buf, size).into_drawing_area();
                figure.draw(&root).map_err(|e| e.to_string())?;
                root.present().map_err(|e| e.to_string())?;
            }
            let img = RgbImage::from_raw(w, h, buf).ok_or("buffer size")?;
            img.save_with_format(path, image::ImageFormat::Png).map_err(|e| e.to_string())
        }
        _ => Err("unknown picture format (use .svg or .png)".into()),
    }
}
