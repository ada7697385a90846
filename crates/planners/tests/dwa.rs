//! The classical baseline: the costmap marks and clears what the lidar sees, A* finds paths
//! around obstacles, and DWA drives a Jetbot to its goals in the static scenes.

use rlnav_planners::astar;
use rlnav_planners::costmap::{Costmap, CostmapConfig, INSCRIBED, LETHAL};
use rlnav_planners::dwa::Dwa;
use rlnav_sim::geometry::{Obstacle, ObstacleSpec, Rect};
use rlnav_sim::task::{EnvSetup, NavEnv};
use rlnav_sim::{LaserScan, LidarSpec, Outcome, Pose2, Vec2, World};
use std::sync::Arc;

fn room() -> Rect {
    Rect { min: Vec2::splat(-2.0), max: Vec2::splat(2.0) }
}

#[test]
fn costmap_marks_inflates_and_clears() {
    let mut m = Costmap::new(room(), CostmapConfig::default(), 0.2, None);
    let spec = LidarSpec { beams: 360, ..Default::default() };
    // Something 1 m ahead, then nothing: marked, then cleared by the beam that passes through.
    let mut scan = LaserScan { ranges: vec![f32::INFINITY; 360], ..LaserScan::for_spec(&spec) };
    scan.ranges[180] = 1.0;
    m.update(&Pose2::default(), &Pose2::default(), &scan);
    assert_eq!(m.cost_at(Vec2::new(1.0, 0.0)), LETHAL);
    assert_eq!(m.cost_at(Vec2::new(0.85, 0.0)), INSCRIBED, "within the inscribed radius");
    let c = m.cost_at(Vec2::new(0.6, 0.0));
    assert!(c > 0 && c < INSCRIBED, "inflated: {c}");
    assert_eq!(m.cost_at(Vec2::new(0.0, 0.0)), 0);
    scan.ranges[180] = f32::INFINITY;
    m.update(&Pose2::default(), &Pose2::default(), &scan);
    assert_eq!(m.cost_at(Vec2::new(1.0, 0.0)), 0, "the moving obstacle left no ghost");
    // The static layer stays.
    let w = World::new(vec![Obstacle::new(ObstacleSpec::Circle { center: [1.0, 1.0], radius: 0.2 }).unwrap()]);
    let mut m = Costmap::new(room(), CostmapConfig::default(), 0.2, Some(&w));
    assert_eq!(m.cost_at(Vec2::new(1.0, 1.0)), LETHAL);
    m.update(&Pose2::default(), &Pose2::default(), &scan);
    assert_eq!(m.cost_at(Vec2::new(1.0, 1.0)), LETHAL);
    assert_eq!(m.cost_at(Vec2::new(5.0, 0.0)), LETHAL, "outside the map");
}

#[test]
fn a_thin_wall_on_cell_boundaries_is_lethal_all_along() {
    // x = 0 and y = 0.3 are cell boundaries of a 5 cm grid from -2: centres are exactly half a
    // cell from these walls, and every cell they touch must be lethal (a missed door jamb is
    // a collision).
    let w = World::new(vec![
        Obstacle::new(ObstacleSpec::Wall { from: [0.0, -2.0], to: [0.0, 1.0] }).unwrap(),
        Obstacle::new(ObstacleSpec::Wall { from: [-1.5, 0.3], to: [-0.5, 0.3] }).unwrap(),
    ]);
    let m = Costmap::new(room(), CostmapConfig::default(), 0.2, Some(&w));
    for k in 0..58 {
        let y = -1.95 + 0.05 * k as f32;
        assert_eq!(m.cost_at(Vec2::new(-0.01, y)), LETHAL, "left of the wall at y = {y}");
        assert_eq!(m.cost_at(Vec2::new(0.01, y)), LETHAL, "right of the wall at y = {y}");
    }
    for k in 0..20 {
        let x = -1.48 + 0.05 * k as f32;
        assert_eq!(m.cost_at(Vec2::new(x, 0.29)), LETHAL, "below the wall at x = {x}");
        assert_eq!(m.cost_at(Vec2::new(x, 0.31)), LETHAL, "above the wall at x = {x}");
    }
}

#[test]
fn astar_goes_around_a_wall() {
    let w = World::new(vec![Obstacle::new(ObstacleSpec::Wall { from: [0.0, -2.0], to: [0.0, 1.0] }).unwrap()]);
    let m = Costmap::new(room(), CostmapConfig::default(), 0.2, Some(&w));
    let path = astar::plan(&m, Vec2::new(-1.0, -1.0), Vec2::new(1.0, -1.0), 3.0).unwrap();
    assert!(path.iter().any(|p| p.y > 1.2), "through the gap above the wall");
    assert!(path.iter().all(|p| m.cost_at(*p) < INSCRIBED));
    assert!(
        (path[0] - Vec2::new(-1.0, -1.0)).length() < 0.05
            && (*path.last().unwrap() - Vec2::new(1.0, -1.0)).length() < 0.05
    );
    // Walled off completely: no path.
    let sealed = World::new(vec![Obstacle::new(ObstacleSpec::Wall { from: [0.0, -2.0], to: [0.0, 2.0] }).unwrap()]);
    let m = Costmap::new(room(), CostmapConfig::default(), 0.2, Some(&sealed));
    assert!(astar::plan(&m, Vec2::new(-1.0, -1.0), Vec2::new(1.0, -1.0), 3.0).is_none());
}

#[test]
fn a_costmap_from_map_cells_inflates_as_one_from_the_world() {
    // The same wall as obstacle cells of a 4 x 4 m grid (origin at its corner) and as a world
    // shape: the inflated costs agree cell for cell, and A* goes round it on either.
    let w = World::new(vec![Obstacle::new(ObstacleSpec::Wall { from: [0.0, -2.0], to: [0.0, 1.0] }).unwrap()]);
    let from_world = Costmap::new(room(), CostmapConfig::default(), 0.2, Some(&w));
    let (width, height) = from_world.size();
    let lethal: Vec<bool> = (0..width * height).map(|k| from_world.cost(k % width, k / width) == LETHAL).collect();
    assert!(lethal.iter().filter(|l| **l).count() >= 120, "the wall is 3 m of 5 cm cells, two wide");
    let from_cells = Costmap::from_cells(width, height, CostmapConfig::default(), 0.2, lethal.clone()).unwrap();
    for iy in 0..height {
        for ix in 0..width {
            assert_eq!(from_cells.cost(ix, iy), from_world.cost(ix, iy), "cell ({ix}, {iy})");
        }
    }
    // The grid frame has its origin at cell (0, 0)'s corner: the room's (-1, -1) is (1, 1).
    let path = astar::plan(&from_cells, Vec2::new(1.0, 1.0), Vec2::new(3.0, 1.0), 3.0).unwrap();
    assert!(path.iter().any(|p| p.y > 3.2), "through the gap above the wall");
    assert!(Costmap::from_cells(width, height + 1, CostmapConfig::default(), 0.2, lethal).is_none());
}

#[test]
fn dwa_reaches_goals_in_the_static_room() {
    let setup = Arc::new(EnvSetup::from_scenario_name("static-room").unwrap());
    let (mut wins, n) = (0, 30);
    for k in 0..n {
        let mut env = NavEnv::new(setup.clone(), 4000 + k).unwrap();
        let mut dwa = Dwa::for_setup(env.setup());
        let s = env.run_episode(&mut dwa).unwrap();
        wins += (s.outcome == Outcome::Success) as u32;
    }
    let rate = wins as f32 / n as f32;
    eprintln!("DWA success in static-room: {rate:.2}");
    assert!(rate >= 0.8, "DWA reaches {rate:.2} of static-room goals, expected >= 0.80");
}
