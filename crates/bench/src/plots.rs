//! The benchmark's figures: distance to the goal over time (mean and standard deviation over
//! episodes, per controller, as the article's figure) and trajectories coloured by the
//! smallest lidar range (the article's "safety spectrum"), as SVG.

use crate::evaluate::EpisodeTrace;
use crate::render::{Figure, Scene, Style, write_figure};
use crate::suite::SuiteResult;
use plotters::coord::Shift;
use plotters::prelude::*;
use rlnav_sim::task::EnvSetup;
use rlnav_sim::{Vec2, World};
use std::path::{Path, PathBuf};

const COLOURS: [RGBColor; 6] = [
    RGBColor(30, 90, 200),
    RGBColor(220, 80, 30),
    RGBColor(40, 150, 60),
    RGBColor(150, 60, 170),
    RGBColor(120, 120, 120),
    RGBColor(200, 160, 0),
];

/// `(time, mean, standard deviation)` per control step.
pub type Band = Vec<(f32, f32, f32)>;

/// Mean and standard deviation of the distance to the goal at each control step; an episode
/// that has ended keeps its final distance.
pub fn distance_band(traces: &[EpisodeTrace]) -> Band {
    let steps = traces.iter().map(|t| t.distance.len()).max().unwrap_or(0);
    let dt = traces.iter().find_map(|t| t.time.get(1).copied()).unwrap_or(0.1);
    (0..steps)
        .map(|k| {
            let v: Vec<f32> =
                traces.iter().filter_map(|t| t.distance.get(k.min(t.distance.len().max(1) - 1)).copied()).collect();
            let m = v.iter().sum::<f32>() / v.len().max(1) as f32;
            let sd = (v.iter().map(|x| (x - m).powi(2)).sum::<f32>() / v.len().max(1) as f32).sqrt();
            (k as f32 * dt, m, sd)
        })
        .collect()
}

/// `distance_vs_time` for one scenario (`.svg` or `.png`): one mean line and ±1 σ band per
/// controller.
pub fn distance_vs_time(out: &Path, title: &str, series: &[(&str, &[EpisodeTrace])]) -> Result<(), String> {
    let bands: Vec<(&str, Band)> = series.iter().map(|(n, t)| (*n, distance_band(t))).collect();
    write_figure(out, (800, 480), &DistanceFigure { title, bands }).map_err(|e| format!("{}: {e}", out.display()))
}

struct DistanceFigure<'a> {
    title: &'a str,
    bands: Vec<(&'a str, Band)>,
}

impl Figure for DistanceFigure<'_> {
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        let bands = &self.bands;
        let t_max = bands.iter().filter_map(|(_, b)| b.last().map(|p| p.0)).fold(1.0f32, f32::max);
        let d_max = bands.iter().flat_map(|(_, b)| b.iter().map(|p| p.1 + p.2)).fold(1.0f32, f32::max);
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(root)
            .caption(self.title, ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(50)
            .build_cartesian_2d(0f32..t_max, 0f32..d_max * 1.05)?;
        chart.configure_mesh().x_desc("time (s)").y_desc("distance to goal (m)").draw()?;
        for (i, (name, band)) in bands.iter().enumerate() {
            let c = COLOURS[i % COLOURS.len()];
            let mut poly: Vec<(f32, f32)> = band.iter().map(|(t, m, s)| (*t, m + s)).collect();
            poly.extend(band.iter().rev().map(|(t, m, s)| (*t, (m - s).max(0.0))));
            chart.draw_series(std::iter::once(Polygon::new(poly, c.mix(0.2).filled())))?;
            chart
                .draw_series(LineSeries::new(band.iter().map(|(t, m, _)| (*t, *m)), c.stroke_width(2)))?
                .label(*name)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
        }
        chart.configure_series_labels().background_style(WHITE.mix(0.8)).border_style(BLACK).draw()?;
        Ok(())
    }
}

/// `barn_score_vs_difficulty` (`.svg` or `.png`): one panel per difficulty metric of
/// Perille et al. with each BARN world's score (k = 2) per controller against it, and each
/// controller's mean score over the worlds in five bins of the metric as a line. `None` when
/// `result` has no BARN world with difficulty metrics.
pub fn barn_score_vs_difficulty(out: &Path, result: &SuiteResult) -> Result<Option<()>, String> {
    let controllers = crate::suite::first_seen(result.cells.iter().map(|c| c.controller.as_str()));
    let series: Vec<(&str, Vec<WorldPoint>)> = controllers
        .iter()
        .map(|name| {
            let points = result
                .cells
                .iter()
                .filter(|c| c.controller == *name)
                .filter_map(|c| Some((c.difficulty?.values(), c.barn_score?)))
                .collect();
            (*name, points)
        })
        .filter(|(_, p): &(&str, Vec<WorldPoint>)| !p.is_empty())
        .collect();
    if series.is_empty() {
        return Ok(None);
    }
    let figure = DifficultyFigure { title: &result.suite, series };
    write_figure(out, (1500, 330), &figure).map_err(|e| format!("{}: {e}", out.display()))?;
    Ok(Some(()))
}

/// A BARN world's five difficulty metrics and a controller's score there.
type WorldPoint = ([f32; 5], f32);

struct DifficultyFigure<'a> {
    title: &'a str,
    series: Vec<(&'a str, Vec<WorldPoint>)>,
}

impl Figure for DifficultyFigure<'_> {
    fn draw<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        root.fill(&WHITE)?;
        let root =
            root.titled(&format!("{}: BARN score (k = 2) against world difficulty", self.title), ("sans-serif", 18))?;
        let panels = root.split_evenly((1, 5));
        let labels = [
            "closest wall (cells)",
            "average visibility (cells)",
            "dispersion",
            "characteristic dimension",
            "tortuosity",
        ];
        for (m, (panel, label)) in panels.iter().zip(labels).enumerate() {
            let xs = self.series.iter().flat_map(|(_, p)| p.iter().map(|(d, _)| d[m]));
            let (lo, hi) = xs.fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), x| (a.min(x), b.max(x)));
            let pad = ((hi - lo) * 0.05).max(0.05);
            let mut chart = ChartBuilder::on(panel)
                .margin(8)
                .x_label_area_size(35)
                .y_label_area_size(if m == 0 { 45 } else { 30 })
                .build_cartesian_2d(lo - pad..hi + pad, 0f32..0.52)?;
            chart
                .configure_mesh()
                .x_desc(label)
                .y_desc(if m == 0 { "score (k = 2)" } else { "" })
                .x_labels(5)
                .draw()?;
            for (i, (name, points)) in self.series.iter().enumerate() {
                let c = COLOURS[i % COLOURS.len()];
                chart.draw_series(points.iter().map(|(d, s)| Circle::new((d[m], *s), 3, c.mix(0.5).filled())))?;
                let bins = binned_means(points.iter().map(|(d, s)| (d[m], *s)), lo, hi, 5);
                let line = chart.draw_series(LineSeries::new(bins, c.stroke_width(2)))?;
                if m == 0 {
                    let name = name.to_string();
                    line.label(name)
                        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
                }
            }
            if m == 0 {
                chart.configure_series_labels().background_style(WHITE.mix(0.8)).border_style(BLACK).draw()?;
            }
        }
        Ok(())
    }
}

/// The mean of `y` in `bins` equal bins of `x` over `[lo, hi]`, at each non-empty bin's centre.
fn binned_means(points: impl Iterator<Item = (f32, f32)>, lo: f32, hi: f32, bins: usize) -> Vec<(f32, f32)> {
    let width = ((hi - lo) / bins as f32).max(f32::EPSILON);
    let mut sums = vec![(0.0f32, 0usize); bins];
    for (x, y) in points {
        let b = (((x - lo) / width) as usize).min(bins - 1);
        sums[b].0 += y;
        sums[b].1 += 1;
    }
    sums.iter()
        .enumerate()
        .filter(|(_, (_, n))| *n > 0)
        .map(|(b, (sum, n))| (lo + (b as f32 + 0.5) * width, sum / *n as f32))
        .collect()
}

/// A file-name-safe form of a controller spec.
pub fn slug(s: &str) -> String {
    let spec = s.strip_prefix("rl:").unwrap_or(s);
    let model = spec.split(".onnx").next().unwrap_or(spec);
    let name = model.rsplit('/').next().unwrap_or(model);
    name.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' { c } else { '_' }).collect()
}

/// Writes, for every scenario of `result`, `distance_vs_time_<scenario>.svg` and
/// `trajectories_<scenario>_<controller>.svg`, and for BARN worlds with difficulty metrics
/// `barn_score_vs_difficulty.svg`, each also as PNG, into `dir`; `setups` are the suite's
/// scenarios in order. Returns the files written.
pub fn write_suite_figures(
    result: &SuiteResult,
    setups: &[std::sync::Arc<EnvSetup>],
    dir: &Path,
) -> Result<Vec<PathBuf>, String> {
    let mut files = Vec::new();
    for ext in ["svg", "png"] {
        let f = dir.join(format!("barn_score_vs_difficulty.{ext}"));
        if barn_score_vs_difficulty(&f, result)?.is_some() {
            files.push(f);
        }
    }
    for setup in setups {
        let name = &setup.scenario.spec().name;
        let cells: Vec<_> = result.cells.iter().filter(|c| &c.scenario == name).collect();
        let series: Vec<(&str, &[EpisodeTrace])> =
            cells.iter().map(|c| (c.controller.as_str(), c.traces.as_slice())).collect();
        for ext in ["svg", "png"] {
            let f = dir.join(format!("distance_vs_time_{name}.{ext}"));
            distance_vs_time(&f, &format!("{name}: distance to goal (mean ± 1 sd)"), &series)?;
            files.push(f);
        }
        // A scenario whose world changes every episode is drawn without obstacles.
        let empty = std::sync::Arc::new(World::new(Vec::new()));
        let world = setup.scenario.fixed_world().unwrap_or(&empty);
        let scene = Scene::of(setup, world);
        for c in &cells {
            let paths: Vec<Vec<(Vec2, f32)>> = c
                .traces
                .iter()
                .map(|t| t.position.iter().zip(&t.min_range).map(|(p, r)| (Vec2::new(p[0], p[1]), *r)).collect())
                .collect();
            for ext in ["svg", "png"] {
                let f = dir.join(format!("trajectories_{name}_{}.{ext}", slug(&c.controller)));
                let style = Style { size: 700, ..Default::default() };
                scene.write_paths(&f, &paths, setup.task.collision_range, 1.0, &style).map_err(|e| e.to_string())?;
                files.push(f);
            }
        }
    }
    Ok(files)
}
