//! The fast lidar against brute force on random scenes: every beam agrees with an exact
//! double-precision caster written from the scenario specs, no reading passes through an
//! obstacle, none is shorter than the true distance. (parry2d's f32 ray casts are the speed
//! baseline and agree in ordinary scenes, see `agrees_with_parry2d_in_the_training_room`; at
//! grazing angles their rounding is coarser than the fast caster's, so they cannot be the
//! judge there.)

use proptest::prelude::*;
use rlnav_sim::geometry::{Obstacle, ObstacleSpec, Pose2, Vec2};
use rlnav_sim::lidar::{Lidar, LidarSpec};
use rlnav_sim::world::World;

/// Exact distance along a ray to the specs' surfaces, in f64, no culling (range_max if none).
fn exact_ray(specs: &[ObstacleSpec], o: [f64; 2], angle: f64, range_max: f64) -> f64 {
    let d = [angle.cos(), angle.sin()];
    let cross = |a: [f64; 2], b: [f64; 2]| a[0] * b[1] - a[1] * b[0];
    let seg = |a: [f64; 2], b: [f64; 2]| {
        let e = [b[0] - a[0], b[1] - a[1]];
        let w = [a[0] - o[0], a[1] - o[1]];
        let den = cross(d, e);
        if den == 0.0 {
            return f64::INFINITY;
        }
        let (t, u) = (cross(w, e) / den, cross(w, d) / den);
        if t >= 0.0 && (0.0..=1.0).contains(&u) { t } else { f64::INFINITY }
    };
    let polygon =
        |pts: &[[f64; 2]]| (0..pts.len()).map(|i| seg(pts[i], pts[(i + 1) % pts.len()])).fold(f64::INFINITY, f64::min);
    let f = |v: [f32; 2]| [v[0] as f64, v[1] as f64];
    let mut best = range_max;
    for s in specs {
        let t = match s {
            ObstacleSpec::Circle { center, radius } => {
                let c = f(*center);
                let rel = [c[0] - o[0], c[1] - o[1]];
                let b = rel[0] * d[0] + rel[1] * d[1];
                let disc = b * b - (rel[0] * rel[0] + rel[1] * rel[1] - (*radius as f64).powi(2));
                if disc < 0.0 || b - disc.sqrt() < 0.0 { f64::INFINITY } else { b - disc.sqrt() }
            }
            ObstacleSpec::Box { center, size, yaw } => {
                let (c, (sn, cs)) = (f(*center), (*yaw as f64).sin_cos());
                let (hx, hy) = (size[0] as f64 / 2.0, size[1] as f64 / 2.0);
                let pts: Vec<[f64; 2]> = [[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]]
                    .iter()
                    .map(|p| [c[0] + cs * p[0] - sn * p[1], c[1] + sn * p[0] + cs * p[1]])
                    .collect();
                polygon(&pts)
            }
            ObstacleSpec::Polygon { points } => polygon(&points.iter().map(|p| f(*p)).collect::<Vec<_>>()),
            ObstacleSpec::Wall { from, to } => seg(f(*from), f(*to)),
        };
        best = best.min(t);
    }
    best
}

fn obstacle() -> impl Strategy<Value = ObstacleSpec> {
    let c = (-4.0f32..4.0, -4.0f32..4.0);
    prop_oneof![
        (c.clone(), 0.05f32..1.0).prop_map(|((x, y), r)| ObstacleSpec::Circle { center: [x, y], radius: r }),
        (c.clone(), 0.05f32..1.5, 0.05f32..1.5, -3.2f32..3.2).prop_map(|((x, y), w, h, yaw)| ObstacleSpec::Box {
            center: [x, y],
            size: [w, h],
            yaw
        }),
        (c.clone(), 0.1f32..1.0, 3usize..7, 0.0f32..1.0).prop_map(|((x, y), r, n, phase)| {
            // Regular-ish polygon: vertices on a circle in angular order are convex.
            let pts = (0..n)
                .map(|i| {
                    let a = phase + i as f32 * std::f32::consts::TAU / n as f32;
                    [x + r * a.cos(), y + r * a.sin()]
                })
                .collect();
            ObstacleSpec::Polygon { points: pts }
        }),
        (c.clone(), c).prop_filter_map("distinct ends", |((x0, y0), (x1, y1))| {
            ((x0 - x1).abs() + (y0 - y1).abs() > 0.05).then_some(ObstacleSpec::Wall { from: [x0, y0], to: [x1, y1] })
        }),
    ]
}

fn lidar() -> impl Strategy<Value = LidarSpec> {
    prop_oneof![
        Just(LidarSpec::default()),
        Just(LidarSpec {
            beams: 720,
            angle_min: -2.356_194_5,
            angle_max: 2.356_194_5,
            range_max: 30.0,
            range_min: 0.1,
            ..Default::default()
        }),
        (1usize..400, -3.2f32..0.0, 0.1f32..6.3, 0.5f32..8.0, -0.2f32..0.2, -3.2f32..3.2).prop_map(
            |(beams, min, span, rmax, mx, myaw)| LidarSpec {
                beams,
                angle_min: min,
                angle_max: if beams == 1 { min } else { min + span },
                range_min: 0.05,
                range_max: rmax,
                mount: Pose2::new(mx, 0.0, myaw),
                ..Default::default()
            }
        ),
    ]
}

fn scene() -> impl Strategy<Value = (Vec<ObstacleSpec>, LidarSpec, Pose2)> {
    (
        prop::collection::vec(obstacle(), 0..14),
        lidar(),
        (-4.5f32..4.5, -4.5f32..4.5, -3.2f32..3.2).prop_map(|(x, y, t)| Pose2::new(x, y, t)),
    )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 400, max_global_rejects: 1_000_000, ..ProptestConfig::default() })]

    #[test]
    fn fast_scan_equals_brute_force((specs, spec, pose) in scene()) {
        let world = World::new(specs.iter().cloned().map(|s| Obstacle::new(s).unwrap()).collect());
        let lidar = Lidar::new(spec.clone());
        let sensor = lidar.sensor_pose(&pose).position();
        // A sensor inside a solid obstacle has no meaningful scan (the robot has crashed).
        prop_assume!(world.obstacles().iter().all(|o| {
            matches!(o.spec, ObstacleSpec::Wall { .. }) || o.primitive.signed_distance(sensor) > 1e-3
        }));
        let n = lidar.beams();
        let mut fast = vec![0.0; n];
        let mut dirs = vec![Vec2::ZERO; n];
        lidar.scan(&pose, world.ray_geometry(), &mut dirs, &mut fast);
        let sensor_pose = lidar.sensor_pose(&pose);
        for (i, &f) in fast.iter().enumerate() {
            let angle = sensor_pose.yaw + spec.beam_angle(i);
            {
                let val = |x: f64| if x < spec.range_max as f64 { x.max(spec.range_min as f64) } else { spec.range_max as f64 };
                let fv = val(if f.is_finite() { f as f64 } else { f64::INFINITY });
                // Exact: the f32 caster may be off by rounding, and where a beam meets a
                // surface at a grazing angle a hair's turn moves the reading a lot, so the
                // fast reading must lie within the exact readings for the beam turned by
                // ±1e-5 rad (f32 beam directions are accurate to ~1e-7 rad), give or take
                // 0.5 mm (far below any real lidar's noise).
                let origin = [sensor_pose.position().x as f64, sensor_pose.position().y as f64];
                let exact: Vec<f64> = [-1e-5f64, 0.0, 1e-5]
                    .iter()
                    .map(|da| val(exact_ray(&specs, origin, angle as f64 + da, spec.range_max as f64)))
                    .collect();
                let lo = exact.iter().copied().fold(f64::INFINITY, f64::min) - 5e-4;
                let hi = exact.iter().copied().fold(f64::NEG_INFINITY, f64::max) + 5e-4;
                prop_assert!((lo..=hi).contains(&fv), "beam {i}: fast {f}, exact {exact:?}");
            }
            // ...and nothing lies between the sensor and the reading (no reading passes
            // through an obstacle): sample points along the beam short of the reading.
            let dir = Vec2::new(angle.cos(), angle.sin());
            let reach = if f.is_finite() { f } else { spec.range_max };
            for k in 1..20 {
                let t = reach * k as f32 / 20.0 - 1e-3;
                if t <= spec.range_min { continue; }
                let p = sensor_pose.position() + dir * t;
                let inside = world.obstacles().iter().any(|o| {
                    !matches!(o.spec, ObstacleSpec::Wall { .. }) && o.primitive.signed_distance(p) < -1e-3
                });
                prop_assert!(!inside, "beam {i} passes through an obstacle at t = {t} (reading {f})");
            }
            // ...and the reading is never shorter than the true distance to the nearest
            // surface along the beam (it is at least the clearance of the sensor).
            if f.is_finite() && f > spec.range_min {
                prop_assert!(f >= world.clearance(sensor_pose.position()) - 1e-3);
            }
        }
    }
}

#[test]
fn agrees_with_parry2d_in_the_training_room() {
    use rand::{RngExt, SeedableRng};
    use rlnav_sim::scenario::{Scenario, ScenarioSpec};
    let scenario = Scenario::new(ScenarioSpec::load("static-room").unwrap(), 0.1, 0.0).unwrap();
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(4);
    let lidar = Lidar::new(LidarSpec::default());
    let (mut fast, mut reference) = (vec![0.0; 360], vec![0.0; 360]);
    let mut dirs = vec![Vec2::ZERO; 360];
    let mut compared = 0;
    for _ in 0..300 {
        let episode = scenario.sample(&mut rng).unwrap();
        let pose = Pose2 { yaw: rng.random_range(-std::f32::consts::PI..std::f32::consts::PI), ..episode.start };
        lidar.scan(&pose, episode.world.ray_geometry(), &mut dirs, &mut fast);
        lidar.scan_reference(&pose, &episode.world, &mut reference);
        for (f, r) in fast.iter().zip(&reference) {
            assert!(f == r || (f - r).abs() < 1e-4, "fast {f} parry2d {r} at {pose:?}");
            compared += 1;
        }
    }
    assert_eq!(compared, 300 * 360);
}
