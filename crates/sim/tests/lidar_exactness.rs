//! The fast lidar against a brute-force reference on random scenes: every beam agrees with
//! parry2d's ray casts, no reading passes through an obstacle, none is shorter than the true
//! distance.

use proptest::prelude::*;
use rlnav_sim::geometry::{Obstacle, ObstacleSpec, Pose2, Vec2};
use rlnav_sim::lidar::{Lidar, LidarSpec};
use rlnav_sim::world::World;

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
    #![proptest_config(ProptestConfig { cases: 400, ..ProptestConfig::default() })]

    #[test]
    fn fast_scan_equals_brute_force((specs, spec, pose) in scene()) {
        let world = World::new(specs.into_iter().map(|s| Obstacle::new(s).unwrap()).collect());
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
        let mut reference = vec![0.0; n];
        lidar.scan_reference(&pose, &world, &mut reference);
        let sensor_pose = lidar.sensor_pose(&pose);
        for i in 0..n {
            let (f, r) = (fast[i], reference[i]);
            let both_inf = f.is_infinite() && r.is_infinite();
            // Grazing rays along an edge or tangent to a circle may differ by a hair.
            let tol = 2e-3 * (1.0 + r.min(spec.range_max));
            if !both_inf {
                // A hit parry2d sees within range must be seen, at the same distance...
                prop_assert!(f.is_finite() == r.is_finite() || (f.min(r) >= spec.range_max - tol),
                    "beam {i}: fast {f} reference {r}");
                if f.is_finite() && r.is_finite() {
                    prop_assert!((f - r).abs() <= tol, "beam {i}: fast {f} reference {r}");
                }
            }
            // ...and nothing lies between the sensor and the reading (no reading passes
            // through an obstacle): sample points along the beam short of the reading.
            let angle = sensor_pose.yaw + spec.beam_angle(i);
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
