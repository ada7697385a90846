//! The BARN Challenge worlds (Benchmark for Autonomous Robot Navigation) as scenarios.
//!
//! The data file (`barn_worlds.json`, converted from the public challenge repository) holds
//! every world's cylinders, the reference path length and the "optimal time" the challenge's
//! score uses. Each world becomes a [`ScenarioSpec`] for the `jackal` preset: the fixed start
//! pose, the fixed goal, the cylinders. The 250 worlds of `assets/barn/` are embedded
//! ([`SHIPPED_BARN`], named `barn`); a scenario name `barn#world_N` loads one of them, and
//! `FILE.json#world_N` one world of another file in the same format.

use crate::config::{ConfigError, Invalid, Validate};
use crate::geometry::{ObstacleSpec, Pose2};
use crate::scenario::{Placement, ScenarioSpec};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// The name of the embedded BARN worlds, wherever a BARN data file is asked for.
pub const SHIPPED_NAME: &str = "barn";

/// The BARN worlds shipped in `assets/barn/barn_worlds.json` (MIT, the BARN Challenge; see the
/// README and LICENSE there), embedded so that they work from any folder.
pub const SHIPPED_BARN: &str = include_str!("../../../../assets/barn/barn_worlds.json");

pub mod difficulty;
pub mod generate;
pub mod import;

pub use difficulty::{BarnGrid, Difficulty, GRID_SIZE};
pub use import::{Split, import_dir};

/// How the challenge scores a run (written into imported files' `about`).
const SCORE_NOTE: &str = "success * optimal_time / clip(actual_time, k*optimal_time, 8*optimal_time), optimal_time = \
     reference path length / 2 m/s; k = 2 since 2024, k = 4 before";
/// The challenge's robot (written into imported files' `about`).
const ROBOT_NOTE: &str = "Clearpath Jackal: 0.508 x 0.430 m footprint, max 2.0 m/s (baselines run at 0.5 m/s); lidar \
     Hokuyo UST-10: 720 beams over 270 deg, 0.1-30 m";

/// What errors call the embedded file.
const SHIPPED_LABEL: &str = "<embedded BARN worlds `barn`>";

#[derive(Serialize, Deserialize)]
struct BarnFile {
    about: About,
    worlds: BTreeMap<String, Entry>,
}

#[derive(Serialize, Deserialize)]
struct About {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    source: Option<String>,
    cylinder_radius_m: f32,
    start: StartPose,
    goal: GoalPoint,
    success_radius_m: f32,
    time_limit_s: f32,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    score: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    robot: Option<String>,
}

#[derive(Serialize, Deserialize)]
struct StartPose {
    x: f32,
    y: f32,
    yaw: f32,
}

#[derive(Serialize, Deserialize)]
struct GoalPoint {
    x: f32,
    y: f32,
}

#[derive(Serialize, Deserialize)]
struct Entry {
    cylinders: Vec<[f32; 2]>,
    optimal_time_s: f32,
    reference_path_length_m: f32,
    /// The dataset's difficulty metrics along the reference path (files made before rlnav
    /// measured them have none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    difficulty: Option<Difficulty>,
}

/// One BARN world as a scenario, with what the challenge's score needs.
#[derive(Clone, Debug)]
pub struct BarnWorld {
    /// `world_N`.
    pub name: String,
    /// `N`.
    pub index: u32,
    /// The scenario (robot `jackal`, fixed start and goal, the cylinders).
    pub spec: ScenarioSpec,
    /// Reference path length / 2 m/s (s).
    pub optimal_time: f32,
    /// Reference path length (m).
    pub path_length: f32,
    /// The dataset's difficulty metrics, when the file has them.
    pub difficulty: Option<Difficulty>,
}

/// The worlds of a BARN data file and the challenge's rules.
#[derive(Clone, Debug)]
pub struct BarnSet {
    /// Worlds in index order.
    pub worlds: Vec<BarnWorld>,
    /// A run succeeds within this distance of the goal (m).
    pub success_radius: f32,
    /// Time limit per run (s).
    pub time_limit: f32,
}

impl BarnSet {
    /// Reads a BARN data file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|error| ConfigError::Io { file: file.clone(), error })?;
        Self::parse(&file, &text)
    }

    /// The embedded worlds ([`SHIPPED_BARN`]).
    pub fn shipped() -> Result<Self, ConfigError> {
        Self::parse(SHIPPED_LABEL, SHIPPED_BARN)
    }

    /// The embedded worlds for `barn` ([`SHIPPED_NAME`]), otherwise the file at that path.
    pub fn load_named(name_or_path: &str) -> Result<Self, ConfigError> {
        if name_or_path == SHIPPED_NAME { Self::shipped() } else { Self::load(Path::new(name_or_path)) }
    }

    /// Reads BARN data from `text`; `file` names it in errors.
    pub fn parse(file: &str, text: &str) -> Result<Self, ConfigError> {
        let file = file.to_string();
        let data: BarnFile = serde_json::from_str(text)
            .map_err(|e| ConfigError::Parse { file: file.clone(), message: e.to_string() })?;
        let a = &data.about;
        let invalid = |key: &str, expected: &str| Invalid::new(key, expected).in_file(&file);
        if !(a.cylinder_radius_m > 0.0 && a.success_radius_m > 0.0 && a.time_limit_s > 0.0) {
            return Err(invalid("about", "positive cylinder_radius_m, success_radius_m and time_limit_s"));
        }
        if data.worlds.is_empty() {
            return Err(invalid("worlds", "at least one world"));
        }
        let start = Pose2::new(a.start.x, a.start.y, a.start.yaw);
        let goal = [a.goal.x, a.goal.y];
        let straight = (goal[0] - start.x).hypot(goal[1] - start.y);
        let mut worlds = Vec::with_capacity(data.worlds.len());
        for (name, e) in &data.worlds {
            let index = name
                .strip_prefix("world_")
                .and_then(|n| n.parse().ok())
                .ok_or_else(|| invalid(&format!("worlds.{name}"), "world names `world_N`"))?;
            let spec = ScenarioSpec {
                name: format!("barn-{name}"),
                description: format!("BARN Challenge {name}: {} cylinders", e.cylinders.len()),
                robot: "jackal".into(),
                arena: None,
                obstacles: e
                    .cylinders
                    .iter()
                    .map(|c| ObstacleSpec::Circle { center: *c, radius: a.cylinder_radius_m })
                    .collect(),
                procedural: None,
                start: Placement::Poses(vec![start]),
                goal: Placement::Points(vec![goal]),
                start_goal_distance: [0.0, straight + 1.0],
                margin: 0.0,
                goal_motion: None,
                movers: Vec::new(),
                people: Vec::new(),
                map: None,
                // BARN guarantees a path for the Jackal's rectangle, through gaps its
                // circumscribed circle would not pass.
                require_path: false,
                base_dir: None,
            };
            spec.validate().map_err(|err| err.under(&format!("worlds.{name}")).in_file(&file))?;
            if !(e.optimal_time_s > 0.0 && e.reference_path_length_m > 0.0) {
                return Err(invalid(&format!("worlds.{name}"), "positive optimal_time_s and reference_path_length_m"));
            }
            worlds.push(BarnWorld {
                name: name.clone(),
                index,
                spec,
                optimal_time: e.optimal_time_s,
                path_length: e.reference_path_length_m,
                difficulty: e.difficulty,
            });
        }
        worlds.sort_by_key(|w| w.index);
        Ok(Self { worlds, success_radius: a.success_radius_m, time_limit: a.time_limit_s })
    }

    /// One world by name (`world_N`).
    pub fn world(&self, name: &str) -> Option<&BarnWorld> {
        self.worlds.iter().find(|w| w.name == name)
    }
}

/// The BARN Challenge score of one run as scored since 2024:
/// `success * optimal / clip(time, 2 optimal, 8 optimal)` ([`barn_score_k`] with k = 2).
pub fn barn_score(success: bool, time: f32, optimal_time: f32) -> f32 {
    barn_score_k(success, time, optimal_time, 2.0)
}

/// The BARN Challenge score with lower clip `k`: `success * optimal / clip(time, k optimal,
/// 8 optimal)`. The challenge used k = 4 until 2023 (best score 0.25) and k = 2 since 2024
/// (best 0.5); published results are quoted under one or the other.
pub fn barn_score_k(success: bool, time: f32, optimal_time: f32, k: f32) -> f32 {
    if !success {
        return 0.0;
    }
    optimal_time / time.clamp(k * optimal_time, 8.0 * optimal_time)
}

/// Whether a scenario name refers to one BARN world: `barn#world_N` (the embedded worlds) or
/// a name containing `.json` (`FILE.json#world_N`).
pub fn is_world_reference(name: &str) -> bool {
    name.contains(".json") || name.split_once('#').is_some_and(|(set, _)| set == SHIPPED_NAME)
}

/// The scenarios `name` stands for: every world of a BARN set, in index order, for `SET#*`
/// (`barn#*`, `FILE.json#*`; the set is read once), otherwise the one [`ScenarioSpec::load`]
/// gives.
pub fn load_scenarios(name: &str) -> Result<Vec<ScenarioSpec>, ConfigError> {
    match name.strip_suffix("#*") {
        Some(set) if is_world_reference(name) => {
            Ok(BarnSet::load_named(set)?.worlds.into_iter().map(|w| w.spec).collect())
        }
        _ => Ok(vec![ScenarioSpec::load(name)?]),
    }
}

/// Loads `barn#world_N` (the embedded worlds) or `FILE.json#world_N` as a scenario.
pub fn load_world_spec(reference: &str) -> Result<ScenarioSpec, ConfigError> {
    let (path, world) = reference.split_once('#').unwrap_or((reference, ""));
    let set = BarnSet::load_named(path)?;
    match set.world(world) {
        Some(w) => Ok(w.spec.clone()),
        None => Err(ConfigError::Invalid {
            file: path.to_string(),
            key: "worlds".into(),
            expected: format!(
                "a world named after `#` (`{path}#world_1`); `{world}` is not one of its {} worlds",
                set.worlds.len()
            ),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn score_clips_like_the_challenge() {
        assert_eq!(barn_score(false, 10.0, 5.0), 0.0);
        assert_eq!(barn_score(true, 5.0, 5.0), 0.5, "faster than 2x optimal counts as 2x");
        assert_eq!(barn_score(true, 20.0, 5.0), 0.25);
        assert_eq!(barn_score(true, 100.0, 5.0), 0.125, "slower than 8x optimal counts as 8x");
        assert_eq!(barn_score_k(true, 5.0, 5.0, 4.0), 0.25, "k = 4: the older ceiling");
        assert_eq!(barn_score_k(true, 30.0, 5.0, 4.0), 5.0 / 30.0);
    }

    #[test]
    fn a_star_stands_for_every_world_of_a_set() {
        let all = load_scenarios("barn#*").unwrap();
        assert_eq!(all.len(), 250);
        assert_eq!(all[0].name, load_world_spec("barn#world_1").unwrap().name, "world 0 is a test world, not shipped");
        assert_eq!(all[249].obstacles, load_world_spec("barn#world_299").unwrap().obstacles);
        assert_eq!(load_scenarios("barn#world_3").unwrap()[0].name, load_world_spec("barn#world_3").unwrap().name);
        assert_eq!(load_scenarios("random-static").unwrap()[0].name, "random-static");
        let err = load_scenarios("/nonexistent/worlds.json#*").unwrap_err().to_string();
        assert!(err.contains("/nonexistent/worlds.json"), "{err}");
    }
}
