//! `rlnav list`: what ships in the binary.

use anyhow::Result;
use rlnav_sim::RobotSpec;
use rlnav_sim::scenario::{SCENARIO_PRESETS, ScenarioSpec};

pub fn run() -> Result<()> {
    println!("scenarios:");
    for (name, _) in SCENARIO_PRESETS {
        let s = ScenarioSpec::load(name)?;
        println!("  {name:<16} {}", s.description);
    }
    println!("robots:");
    for (name, _) in rlnav_sim::robot::ROBOT_PRESETS {
        let r = RobotSpec::load(name)?;
        println!("  {name:<18} {}", r.description);
    }
    println!("maps (for a scenario's `map: {{file: NAME}}`):");
    for (name, ..) in rlnav_sim::map::MAP_PRESETS {
        let g = rlnav_sim::map::OccupancyGrid::load(name, Default::default())?;
        let (w, h) = g.size();
        println!("  {name:<16} {w} x {h} cells of {} m", g.resolution());
    }
    println!("BARN worlds (250 shipped, suite `barn`): --scenario barn#world_N --robot jackal");
    Ok(())
}
