//! `training.svg`: mean episode return and success rate (training episodes and evaluations)
//! against environment steps, drawn from `metrics.csv`.

use plotters::prelude::*;
use std::path::Path;

/// One row of `metrics.csv` as plotted.
struct Point {
    steps: f64,
    ret: f64,
    success: f64,
    eval: Option<f64>,
}

fn read(csv: &Path) -> std::io::Result<Vec<Point>> {
    let text = std::fs::read_to_string(csv)?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap_or_default().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name);
    let (Some(s), Some(r), Some(k), Some(e)) =
        (col("env_steps"), col("mean_return"), col("success_rate"), col("eval_success_rate"))
    else {
        return Ok(Vec::new());
    };
    Ok(lines
        .filter_map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            let num = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok());
            Some(Point { steps: num(s)?, ret: num(r)?, success: num(k)?, eval: num(e) })
        })
        .collect())
}

fn millions(x: &f64) -> String {
    format!("{:.1}M", x / 1e6)
}

/// Draws `out` (SVG) from the run's `metrics.csv`.
pub fn training_svg(csv: &Path, out: &Path) -> Result<(), String> {
    let pts = read(csv).map_err(|e| format!("{}: {e}", csv.display()))?;
    if pts.is_empty() {
        return Ok(());
    }
    let err = |e: &dyn std::fmt::Display| format!("{}: {e}", out.display());
    register_font();
    let root = SVGBackend::new(out, (900, 640)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let (top, bottom) = root.split_vertically(320);
    let max_steps = pts.last().map_or(1.0, |p| p.steps).max(1.0);
    // A moving average makes the noisy per-epoch means readable.
    let smooth = |f: &dyn Fn(&Point) -> f64| -> Vec<(f64, f64)> {
        let k = (pts.len() / 50).max(1);
        (0..pts.len())
            .map(|i| {
                let lo = i.saturating_sub(k);
                let w = &pts[lo..=i];
                (pts[i].steps, w.iter().map(f).sum::<f64>() / w.len() as f64)
            })
            .collect()
    };
    let returns = smooth(&|p| p.ret);
    let (rmin, rmax) = returns.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), (_, r)| (a.min(*r), b.max(*r)));
    let pad = ((rmax - rmin) * 0.1).max(1.0);
    let mut chart = ChartBuilder::on(&top)
        .caption("mean episode return", ("sans-serif", 18))
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..max_steps, (rmin - pad)..(rmax + pad))
        .map_err(|e| err(&e))?;
    chart.configure_mesh().x_desc("env steps").x_label_formatter(&millions).draw().map_err(|e| err(&e))?;
    chart.draw_series(LineSeries::new(returns, &BLUE)).map_err(|e| err(&e))?;

    let mut chart = ChartBuilder::on(&bottom)
        .caption("success rate", ("sans-serif", 18))
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..max_steps, 0.0..1.0)
        .map_err(|e| err(&e))?;
    chart.configure_mesh().x_desc("env steps").x_label_formatter(&millions).draw().map_err(|e| err(&e))?;
    chart
        .draw_series(LineSeries::new(smooth(&|p| p.success), &BLUE))
        .map_err(|e| err(&e))?
        .label("training episodes")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE));
    let evals: Vec<(f64, f64)> = pts.iter().filter_map(|p| p.eval.map(|e| (p.steps, e))).collect();
    chart
        .draw_series(LineSeries::new(evals.clone(), &RED))
        .map_err(|e| err(&e))?
        .label("evaluation (unseen scenes)")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED));
    chart.draw_series(evals.iter().map(|p| Circle::new(*p, 3, RED.filled()))).map_err(|e| err(&e))?;
    chart.configure_series_labels().background_style(WHITE.mix(0.8)).border_style(BLACK).draw().map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))
}

/// Registers the embedded font (DejaVu Sans) for plot text once per process. plotters lays
/// text out with ab_glyph (the feature the benchmark's PNG figures need), which has no font
/// unless one is registered; rlnav-bench registers the same file for its figures.
fn register_font() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let font: &'static [u8] = include_bytes!("../../../assets/fonts/DejaVuSans.ttf");
        // The font is ours and known good; a failure would only drop the text.
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, font);
    });
}
