//! One episode under a controller, recorded frame by frame for pictures and animations.

use rlnav_sim::movers::Mover;
use rlnav_sim::{Controller, EpisodeStats, NavEnv, Pose2, Vec2};

/// What the world looked like after one control step.
#[derive(Clone, Debug)]
pub struct Frame {
    /// Seconds since the episode started.
    pub time: f32,
    /// Robot pose.
    pub pose: Pose2,
    /// Goal position.
    pub goal: Vec2,
    /// The full scan (LaserScan conventions).
    pub ranges: Vec<f32>,
    /// Moving obstacles.
    pub movers: Vec<Mover>,
    /// People: position and radius.
    pub people: Vec<(Vec2, f32)>,
    /// Smallest lidar range in this scan (m).
    pub min_range: f32,
}

impl Frame {
    /// The environment as it is now.
    pub fn capture(env: &NavEnv, time: f32) -> Self {
        let ranges = env.ranges().to_vec();
        Self {
            time,
            pose: env.pose(),
            goal: env.goal(),
            min_range: ranges.iter().copied().fold(f32::INFINITY, f32::min),
            ranges,
            movers: env.movers().to_vec(),
            people: env.people().iter().map(|p| (p.position, p.radius)).collect(),
        }
    }
}

/// A recorded episode.
#[derive(Clone, Debug)]
pub struct Recording {
    /// Frame 0 is the start; then one per control step.
    pub frames: Vec<Frame>,
    /// How it ended.
    pub stats: EpisodeStats,
}

/// Runs the environment's current episode to its end under `controller`, recording every
/// control step. The environment is left at the end state (not reset), so that the world the
/// episode ran in can still be drawn.
pub fn record_episode(env: &mut NavEnv, controller: &mut dyn Controller) -> Recording {
    let period = env.setup().task.control_period;
    let mut frames = Vec::new();
    let stats = env.run_to_end(controller, |e| frames.push(Frame::capture(e, frames.len() as f32 * period)));
    Recording { frames, stats }
}
