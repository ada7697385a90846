//! How long building a planning costmap from a map and one A* plan across it take, on maps of
//! the sizes the ROS node plans on (its cap is 2^20 cells): a warehouse-like grid of shelves
//! (rows of 0.6 m x 4 m blocks with 2 m aisles) at 5 cm cells, planned corner to corner.
//!
//! `cargo run --release -p rlnav-planners --example astar_speed [SIDE_CELLS...]`

use rlnav_planners::astar;
use rlnav_planners::costmap::{Costmap, CostmapConfig};
use rlnav_sim::Vec2;
use std::time::Instant;

fn main() {
    let sides: Vec<usize> = std::env::args().skip(1).filter_map(|a| a.parse().ok()).collect();
    let sides = if sides.is_empty() { vec![160, 400, 512, 1024] } else { sides };
    let r = 0.05f32;
    for n in sides {
        let side = n as f32 * r;
        // Shelves: 0.6 m wide, 4 m long, every 2.6 m across and 6 m along, 1 m off the edges.
        let lethal: Vec<bool> = (0..n * n)
            .map(|k| {
                let (x, y) = ((k % n) as f32 * r, (k / n) as f32 * r);
                let (sx, sy) = (x % 2.6, y % 6.0);
                let inside = x > 1.0 && y > 1.0 && x < side - 1.0 && y < side - 1.0;
                inside && sx > 2.0 && sy < 4.0
            })
            .collect();
        let t = Instant::now();
        let map = Costmap::from_cells(n, n, CostmapConfig::default(), 0.2, lethal).expect("sizes agree");
        let build = t.elapsed();
        let (a, b) = (Vec2::new(0.5, 0.5), Vec2::new(side - 0.5, side - 0.5));
        let t = Instant::now();
        let mut cells = 0;
        let runs = 5;
        for _ in 0..runs {
            cells = astar::plan(&map, a, b, 3.0).map_or(0, |p| p.len());
        }
        let plan = t.elapsed() / runs;
        println!(
            "{n} x {n} cells ({side:.0} m square): costmap {:.1} ms, A* corner to corner {:.1} ms ({cells} cells of path)",
            build.as_secs_f64() * 1e3,
            plan.as_secs_f64() * 1e3
        );
    }
}
