//! `report.html`: one self-contained page for a benchmark (the tables, the distance-to-goal
//! figures and each scene's trajectories side by side per controller) that a person opens in a
//! browser. Figures are inlined as SVG, so the file needs nothing beside it.

use crate::evaluate::EvalSummary;
use crate::plots::slug;
use crate::suite::{SuiteResult, first_seen, num, rate_ci};
use std::fmt::Write as _;
use std::path::Path;

/// Escapes text for HTML.
fn esc(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

/// An SVG file written by [`crate::plots::write_suite_figures`], ready to inline (without its
/// XML declaration), or a note that it is missing.
fn inline_svg(path: &Path) -> String {
    match std::fs::read_to_string(path) {
        Ok(s) => match s.find("<svg") {
            Some(i) => s[i..].to_string(),
            None => format!("<p class=\"missing\">{} is not an SVG</p>", esc(&path.display().to_string())),
        },
        Err(e) => format!("<p class=\"missing\">{}: {}</p>", esc(&path.display().to_string()), esc(&e.to_string())),
    }
}

/// One table row.
fn row(cells: impl IntoIterator<Item = String>) -> String {
    let mut r = String::from("<tr>");
    for c in cells {
        r += "<td>";
        r += &c;
        r += "</td>";
    }
    r + "</tr>\n"
}

/// A summary's rates (with intervals), SPL, task time and lidar minimum, as table cells.
fn figures(s: &EvalSummary) -> [String; 6] {
    [
        rate_ci(s.success_rate, s.success_ci95),
        rate_ci(s.collision_rate, s.collision_ci95),
        format!("{:.1}%", 100.0 * s.timeout_rate),
        num(s.spl, 2),
        num(s.mean_task_time, 1),
        num(s.mean_min_range, 2),
    ]
}

const STYLE: &str = "body{font-family:sans-serif;margin:2em;color:#222}\
table{border-collapse:collapse;margin:1em 0}th,td{border:1px solid #bbb;padding:3px 8px;text-align:right}\
th{background:#eee}td:first-child,td:nth-child(2){text-align:left}\
.row{display:flex;flex-wrap:wrap;gap:12px;align-items:flex-start}.fig{flex:0 0 auto}\
.fig svg{width:420px;height:auto}.fig h4{margin:4px 0;font-weight:normal}.missing{color:#a00}.wide svg{width:100%;max-width:1500px;height:auto}";

/// Writes `dir/report.html` for `suites`, whose figures [`crate::plots::write_suite_figures`]
/// already wrote into `dir`; returns its path.
pub fn write_html(dir: &Path, suites: &[SuiteResult]) -> Result<std::path::PathBuf, String> {
    let mut h = String::new();
    let title = suites.iter().map(|s| s.suite.as_str()).collect::<Vec<_>>().join(", ");
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>rlnav bench: {}</title>\
         <style>{STYLE}</style></head><body>\n<h1>rlnav bench: {}</h1>\n<p>Rates with their 95% Wilson \
         interval. SPL: success weighted by the length of the shortest path that keeps the robot's \
         clearance. ang. acc.: mean absolute angular acceleration (lower is smoother).</p>\n",
        esc(&title),
        esc(&title)
    );
    for r in suites {
        let _ = writeln!(
            h,
            "<h2 id=\"{}\">{} with {} (seed {})</h2>",
            slug(&r.suite),
            esc(&r.suite),
            esc(&r.robot),
            r.seed
        );
        for w in &r.warnings {
            let _ = writeln!(h, "<p class=\"missing\">Warning: {}.</p>", esc(w));
        }
        h += "<h3>Over the whole suite</h3>\n<table><tr><th>controller</th><th>episodes</th><th>success</th>\
              <th>collision</th><th>timeout</th><th>SPL</th><th>task time (s)</th><th>min lidar range (m)</th>\
              <th>ang. acc. (rad/s²)</th></tr>\n";
        for (c, s) in r.pooled() {
            let cells = [esc(&c), s.episodes.to_string()].into_iter();
            h += &row(cells.chain(figures(&s)).chain([num(s.mean_angular_acceleration, 2)]));
        }
        h += "</table>\n<h3>Per scene</h3>\n<table><tr><th>scenario</th><th>controller</th><th>success</th>\
              <th>collision</th><th>timeout</th><th>SPL</th><th>task time (s)</th><th>min lidar range (m)</th>\
              <th>avg speed (m/s)</th><th>ang. acc. (rad/s²)</th><th>BARN score (k=2)</th><th>(k=4)</th></tr>\n";
        for c in &r.cells {
            let s = &c.summary;
            let score = |b: Option<f32>| b.map_or("–".into(), |b| format!("{b:.3}"));
            let rest = [
                num(s.mean_speed, 2),
                num(s.mean_angular_acceleration, 2),
                score(c.barn_score),
                score(c.barn_score_k4),
            ];
            h += &row([esc(&c.scenario), esc(&c.controller)].into_iter().chain(figures(s)).chain(rest));
        }
        h += "</table>\n";
        if dir.join("barn_score_vs_difficulty.svg").exists() {
            let _ = writeln!(
                h,
                "<h3>BARN score against world difficulty</h3>\n<div class=\"wide\">{}</div>",
                inline_svg(&dir.join("barn_score_vs_difficulty.svg"))
            );
        }
        for scene in first_seen(r.cells.iter().map(|c| c.scenario.as_str())) {
            let _ = writeln!(h, "<h3>{}</h3>\n<div class=\"row\">", esc(scene));
            let _ = writeln!(
                h,
                "<div class=\"fig\"><h4>distance to goal</h4>{}</div>",
                inline_svg(&dir.join(format!("distance_vs_time_{scene}.svg")))
            );
            for c in r.cells.iter().filter(|c| c.scenario == scene) {
                let _ = writeln!(
                    h,
                    "<div class=\"fig\"><h4>{}: {}</h4>{}</div>",
                    esc(&c.controller),
                    rate_ci(c.summary.success_rate, c.summary.success_ci95),
                    inline_svg(&dir.join(format!("trajectories_{scene}_{}.svg", slug(&c.controller))))
                );
            }
            h += "</div>\n";
        }
    }
    h += "</body></html>\n";
    let path = dir.join("report.html");
    std::fs::write(&path, h).map_err(|e| format!("writing {}: {e}", path.display()))?;
    Ok(path)
}
