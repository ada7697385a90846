//! Lidar speed on the shipped occupancy-grid maps: the batched caster's rays per second from
//! random free poses (one thread), the exact cell walk's ([`OccupancyGrid::cast`]) for the
//! same beams, and the largest difference between the two; then `rlnav sim-speed`'s
//! measurement on the map's scenario.
//!
//! `cargo run --release -p rlnav-sim --example grid_lidar_speed -- [map] [envs] [steps] [threads]`
//! (defaults `turtlebot3-world 64 2000 2`); `ONLY_SCAN=1`: the lidar's speed alone, `ONLY_SIM=1`:
//! the simulator's alone (for `valgrind --tool=callgrind` instruction counts), `DEBUG=1`: the
//! beams that differ from the walk by over 1 cm (cell corners grazed within rounding).

use rand::{RngExt, SeedableRng};
use rlnav_sim::geometry::{Pose2, Vec2};
use rlnav_sim::lidar::{Lidar, LidarSpec};
use rlnav_sim::map::{OccupancyGrid, UnknownCells};
use rlnav_sim::task::EnvSetup;
use rlnav_sim::vec_env::{VecEnv, measure_speed};
use rlnav_sim::world::World;
use std::sync::Arc;
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let map = args.first().map_or("turtlebot3-world", String::as_str);
    let envs: usize = args.get(1).map_or(64, |s| s.parse().unwrap());
    let steps: usize = args.get(2).map_or(2000, |s| s.parse().unwrap());
    let threads: usize = args.get(3).map_or(2, |s| s.parse().unwrap());

    if std::env::var_os("ONLY_SIM").is_none() {
        cast_alone(map);
    }
    let setup = Arc::new(EnvSetup::load(map, None, None).unwrap());
    let mut venv = VecEnv::new(setup, envs, 0, threads).unwrap();
    let r = measure_speed(&mut venv, steps, steps / 10, 0).unwrap();
    println!(
        "{map} sim: {:.0} env steps/s, {:.1} M rays/s, {envs} envs on {} threads",
        r.env_steps_per_s,
        r.rays_per_s / 1e6,
        r.threads
    );
}

/// The lidar alone from random free poses, against the cell walk.
fn cast_alone(map: &str) {
    let grid = Arc::new(OccupancyGrid::load(map, UnknownCells::Occupied).unwrap());
    let world = World::with_grid(Vec::new(), grid.clone());
    let lidar = Lidar::new(LidarSpec { range_max: 3.5, ..Default::default() });
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(1);
    let b = grid.free_bounds();
    let mut poses = Vec::new();
    while poses.len() < 2000 {
        let p = Vec2::new(rng.random_range(b.min.x..b.max.x), rng.random_range(b.min.y..b.max.y));
        if grid.is_known_free(p) {
            poses.push(Pose2::new(p.x, p.y, rng.random_range(-std::f32::consts::PI..std::f32::consts::PI)));
        }
    }
    let n = lidar.beams();
    let (mut dirs, mut out) = (vec![Vec2::ZERO; n], vec![0.0; n]);
    let reps = 5;
    let t = Instant::now();
    for _ in 0..reps {
        for p in &poses {
            lidar.scan(p, world.ray_geometry(), &mut dirs, &mut out);
            std::hint::black_box(&out);
        }
    }
    let fast = (reps * poses.len() * n) as f64 / t.elapsed().as_secs_f64();
    if std::env::var_os("ONLY_SCAN").is_some() {
        println!("{map}: batched caster {:.2} M rays/s", fast / 1e6);
        std::process::exit(0);
    }
    let limit = lidar.spec().range_max;
    let t = Instant::now();
    let mut walk = vec![0.0f32; poses.len() * n];
    for (k, p) in poses.iter().enumerate() {
        for i in 0..n {
            let a = p.yaw + lidar.spec().beam_angle(i);
            walk[k * n + i] = grid.cast(p.position(), Vec2::new(a.cos(), a.sin()), limit);
        }
    }
    let slow = (poses.len() * n) as f64 / t.elapsed().as_secs_f64();
    let (mut worst, mut longer) = (0.0f32, 0.0f32);
    for (k, p) in poses.iter().enumerate() {
        lidar.scan(p, world.ray_geometry(), &mut dirs, &mut out);
        for i in 0..n {
            let f = if out[i].is_finite() { out[i] } else { limit };
            let w = walk[k * n + i].max(lidar.spec().range_min);
            if (f - w).abs() > 1e-2 && std::env::var_os("DEBUG").is_some() {
                let a = p.yaw + lidar.spec().beam_angle(i);
                let d = Vec2::new(a.cos(), a.sin());
                let g = |t: f32| grid.origin().to_local(p.position() + d * t) / grid.resolution();
                println!("pose {p:?} beam {i}: scan {f} ({:?}) walk {w} ({:?})", g(f), g(w));
            }
            worst = worst.max((f - w).abs());
            longer = longer.max(f - w);
        }
    }
    println!(
        "{map}: batched caster {:.2} M rays/s, cell walk {:.2} M rays/s (one thread); max |diff| {worst:.2e} m, max longer {longer:.2e} m",
        fast / 1e6,
        slow / 1e6
    );
}
