//! The observation vector: its layout as data ([`ObservationLayout`], a list of [`ObsTerm`]s)
//! and the one builder that turns what a robot measures into that vector
//! ([`ObservationBuilder`]). The simulator's training observation and the deployed policy's
//! observation (`rlnav-policy`'s runner, hence the ROS 2 node) are both written by it, so they
//! cannot drift apart.
//!
//! A [`ObsTerm::History`] stacks a term's values of the last control steps. The builder keeps
//! them: every [`ObservationBuilder::write`] shows the stored past values and the current one,
//! [`ObservationBuilder::commit`] (once per control step, when the step is taken) stores what
//! was written last as the newest past value, and [`ObservationBuilder::reset`] forgets the
//! past at the start of an episode.

use crate::config::{Invalid, Validate, check_interval};
use crate::controller::Twist;
use crate::geometry::{Pose2, Vec2};
use crate::lidar::{LidarSpec, min_pool};
use serde::{Deserialize, Serialize};

/// Largest history a term may ask for (steps).
pub const MAX_HISTORY_STEPS: usize = 1000;
/// Most points a `plan_ahead` term may show.
pub const MAX_PLAN_POINTS: usize = 64;

/// One term of the observation vector.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum ObsTerm {
    /// Lidar ranges, min-pooled from the scan's beams down to `beams` (which must divide the
    /// scan's beam count), clipped to `clip`; a beam with no return reads `clip[1]`.
    ///
    /// With `sweep` > 0 each bin reads instead how far a disc of radius `sweep` round the
    /// scanner could travel straight along the bin's bearing before a return of the (pooled,
    /// clipped) scan falls inside it: the free travel per bearing, in `[0, clip[1]]`. A thin
    /// post then blocks every bearing the disc would brush it on (±30° at 0.5 m for 0.25 m),
    /// where its plain range fills one bin against a wall's dozens.
    Lidar {
        /// Values after pooling.
        beams: usize,
        /// `[min, max]` (m).
        clip: [f32; 2],
        /// Radius of the swept disc (m; default 0: the plain ranges).
        #[serde(default, skip_serializing_if = "is_zero")]
        sweep: f32,
    },
    /// Distance to the goal (m).
    GoalDistance,
    /// Bearing of the goal in the robot frame (rad, (-π, π]).
    GoalBearing,
    /// The previous command's linear velocity (m/s).
    LastLinear,
    /// The previous command's angular velocity (rad/s).
    LastAngular,
    /// Measured forward velocity (m/s, `base_link` x), as odometry reports it
    /// (`twist.linear.x`).
    Linear,
    /// Measured lateral velocity (m/s, `base_link` y, left positive), as odometry reports it
    /// (`twist.linear.y`). Always 0 for a differential drive; there for layouts that expect it.
    Lateral,
    /// Measured angular velocity (rad/s).
    Angular,
    /// Points `spacing`, 2·`spacing`, ... ahead along the path being followed (the global
    /// plan, or the straight line to the goal without one), in the robot frame: `x, y` (m,
    /// forward, left) per point, `2 × points` values. It shows the path's shape ahead (a sharp
    /// turn after a door, round a wall's end) where the goal terms show one point.
    PlanAhead {
        /// Points shown.
        points: usize,
        /// Path length between them (m).
        spacing: f32,
    },
    /// The values of `term` at `steps` control steps, the current one included, `stride`
    /// steps apart (`steps × term.len()` values).
    History {
        /// The term whose past is stacked (any term but a history).
        term: Box<ObsTerm>,
        /// Values shown, the current one included (1 is the current value only).
        steps: usize,
        /// Control steps between two values shown (default 1: consecutive steps). A stride
        /// spans a longer past with the same inputs: an obstacle walking at 0.3 m/s moves 6 cm
        /// in the 0.2 s of three consecutive 10 Hz scans, 18 cm with a stride of 3.
        #[serde(default = "one", skip_serializing_if = "is_one")]
        stride: usize,
        /// Where the newest value goes.
        order: HistoryOrder,
        /// What the steps before the episode's first read (default: its first value).
        #[serde(default)]
        fill: HistoryFill,
        /// For a lidar term: show each past scan as seen from where the scanner is now
        /// ([`ObservationInputs::pose`]), its returns moved by the robot's motion since
        /// (default false: as it was seen then). Still obstacles then read the same at every
        /// step shown and only what moves changes, where otherwise the robot's own turn
        /// shifts every bin and its drive changes every range.
        #[serde(default, skip_serializing_if = "is_false")]
        ego_motion: bool,
        /// For a lidar history with `ego_motion`: show one more scan, the current one with
        /// each moving object carried on at the motion per step it made since the oldest step
        /// shown, `predict` times the history's span ahead ((steps − 1) × stride control
        /// steps; default 0: none). Early in an episode, with fewer steps stored, the motion
        /// is measured from the oldest stored (`fill: first`) or not at all (`fill: zero`,
        /// until the oldest step shown is stored: the current scan). It goes beyond the
        /// current step in the history's order (last when oldest first). See
        /// [`predict_scan`].
        #[serde(default, skip_serializing_if = "is_zero")]
        predict: f32,
    },
}

fn is_false(b: &bool) -> bool {
    !*b
}

fn is_zero(x: &f32) -> bool {
    *x == 0.0
}

fn one() -> usize {
    1
}

fn is_one(n: &usize) -> bool {
    *n == 1
}

/// Order of the steps in a history stack.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HistoryOrder {
    /// Chronological: the oldest step first, the current value last.
    OldestFirst,
    /// The current value first, then older and older steps.
    NewestFirst,
}

/// What a history shows for the steps before the episode started.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum HistoryFill {
    /// The episode's first value (as if the robot had stood there).
    #[default]
    First,
    /// Zeros.
    Zero,
}

impl ObsTerm {
    /// Number of values this term contributes.
    pub fn len(&self) -> usize {
        match self {
            ObsTerm::Lidar { beams, .. } => *beams,
            ObsTerm::History { term, .. } => self.slots() * term.len(),
            ObsTerm::PlanAhead { points, .. } => 2 * points,
            _ => 1,
        }
    }

    /// How many sets of its inner term's values the term shows: a history's steps, and one
    /// more for its predicted scan (`predict`); 1 for a term that is not a history.
    pub fn slots(&self) -> usize {
        match self {
            ObsTerm::History { steps, predict, .. } => steps + usize::from(*predict > 0.0),
            _ => 1,
        }
    }

    /// Whether the term contributes nothing (never for a valid term: kept for the `len`
    /// convention).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The lidar term's `(beams, clip)`, also when it is the term of a history.
    pub fn lidar(&self) -> Option<(usize, [f32; 2])> {
        match self {
            ObsTerm::Lidar { beams, clip, .. } => Some((*beams, *clip)),
            ObsTerm::History { term, .. } => term.lidar(),
            _ => None,
        }
    }

    /// The term's YAML name (`goal_bearing`, `history`...).
    pub fn name(&self) -> &'static str {
        match self {
            ObsTerm::Lidar { .. } => "lidar",
            ObsTerm::GoalDistance => "goal_distance",
            ObsTerm::GoalBearing => "goal_bearing",
            ObsTerm::LastLinear => "last_linear",
            ObsTerm::LastAngular => "last_angular",
            ObsTerm::Linear => "linear",
            ObsTerm::Lateral => "lateral",
            ObsTerm::Angular => "angular",
            ObsTerm::PlanAhead { .. } => "plan_ahead",
            ObsTerm::History { .. } => "history",
        }
    }

    /// A short description for listings (`lidar 120 beams, clip [0.15, 2]`, `goal_bearing × 5,
    /// oldest first`).
    pub fn describe(&self) -> String {
        match self {
            ObsTerm::Lidar { beams, clip, sweep } if *sweep > 0.0 => {
                format!("lidar {beams} beams, clip [{}, {}], free travel of a {sweep} m disc", clip[0], clip[1])
            }
            ObsTerm::Lidar { beams, clip, .. } => format!("lidar {beams} beams, clip [{}, {}]", clip[0], clip[1]),
            ObsTerm::PlanAhead { points, spacing } => format!("plan_ahead {points} points, {spacing} m apart"),
            ObsTerm::History { term, steps, stride, order, fill, ego_motion, predict } => format!(
                "{} × {steps}{}{}{}, {}, before the episode: {}",
                term.describe(),
                if *stride > 1 { format!(" every {stride} steps") } else { String::new() },
                if *ego_motion { ", seen from the current pose" } else { "" },
                if *predict > 0.0 {
                    format!(", and predicted {predict}× the history's span ahead")
                } else {
                    String::new()
                },
                match order {
                    HistoryOrder::OldestFirst => "oldest first",
                    HistoryOrder::NewestFirst => "newest first",
                },
                match fill {
                    HistoryFill::First => "its first value",
                    HistoryFill::Zero => "zeros",
                }
            ),
            other => other.name().to_string(),
        }
    }

    /// Checks the term; `key` names it in errors (`observation[3]`).
    fn check(&self, key: &str) -> Result<(), Invalid> {
        match self {
            ObsTerm::Lidar { beams, clip, sweep } => {
                if *beams == 0 {
                    return Err(Invalid::new(format!("{key}.lidar.beams"), "at least 1"));
                }
                if !(sweep.is_finite() && (0.0..=10.0).contains(sweep)) {
                    return Err(Invalid::new(
                        format!("{key}.lidar.sweep"),
                        format!("a radius in [0, 10] m (0: plain ranges), got {sweep}"),
                    ));
                }
                check_interval(&format!("{key}.lidar.clip"), *clip, 0.0, 1000.0)
            }
            ObsTerm::PlanAhead { points, spacing } => {
                if !(1..=MAX_PLAN_POINTS).contains(points) {
                    return Err(Invalid::new(
                        format!("{key}.plan_ahead.points"),
                        format!("1 to {MAX_PLAN_POINTS}, got {points}"),
                    ));
                }
                if !(spacing.is_finite() && *spacing > 0.0 && *spacing <= 100.0) {
                    return Err(Invalid::new(format!("{key}.plan_ahead.spacing"), "a length in (0, 100] m"));
                }
                Ok(())
            }
            ObsTerm::History { term, steps, stride, ego_motion, predict, .. } => {
                if !(predict.is_finite() && (0.0..=10.0).contains(predict)) {
                    return Err(Invalid::new(
                        format!("{key}.history.predict"),
                        format!("a multiple of the history's span in [0, 10] (0: no predicted scan), got {predict}"),
                    ));
                }
                if *predict > 0.0 && !(*ego_motion && *steps >= 2) {
                    return Err(Invalid::new(
                        format!("{key}.history.predict"),
                        "0 unless the history moves its past scans (ego_motion: true) and shows at least 2 steps",
                    ));
                }
                if *ego_motion && !matches!(**term, ObsTerm::Lidar { .. }) {
                    return Err(Invalid::new(
                        format!("{key}.history.ego_motion"),
                        format!(
                            "false for a {} term (only past scans can be moved by the robot's motion)",
                            term.name()
                        ),
                    ));
                }
                if !(1..=MAX_HISTORY_STEPS).contains(steps) {
                    return Err(Invalid::new(
                        format!("{key}.history.steps"),
                        format!("1 to {MAX_HISTORY_STEPS} control steps, got {steps}"),
                    ));
                }
                if *stride == 0 || (steps - 1) * stride > MAX_HISTORY_STEPS {
                    return Err(Invalid::new(
                        format!("{key}.history.stride"),
                        format!(
                            "at least 1, with (steps - 1) × stride at most {MAX_HISTORY_STEPS} control steps, got {stride}"
                        ),
                    ));
                }
                if matches!(**term, ObsTerm::History { .. }) {
                    return Err(Invalid::new(format!("{key}.history.term"), "a term that is not itself a history"));
                }
                term.check(&format!("{key}.history.term"))
            }
            _ => Ok(()),
        }
    }
}

/// The observation vector's layout: an ordered list of terms. Data, not code, so that other
/// layouts (the seed policies', stacked frames...) are configuration.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct ObservationLayout(pub Vec<ObsTerm>);

impl Default for ObservationLayout {
    /// The article's `[L_t (120 ranges, 0.15-3 m), d_t, θ_t, v_{t-1}, ω_{t-1}]`: 124 values.
    fn default() -> Self {
        ObservationLayout(vec![
            ObsTerm::Lidar { beams: 120, clip: [0.15, 3.0], sweep: 0.0 },
            ObsTerm::GoalDistance,
            ObsTerm::GoalBearing,
            ObsTerm::LastLinear,
            ObsTerm::LastAngular,
        ])
    }
}

impl ObservationLayout {
    /// Length of the observation vector.
    pub fn len(&self) -> usize {
        self.0.iter().map(ObsTerm::len).sum()
    }

    /// Whether the layout is empty.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Checks every term (lidar beams and clip, history steps and nesting) and that there is
    /// at least one; keys read `observation[i]...`.
    pub fn check(&self) -> Result<(), Invalid> {
        if self.0.is_empty() {
            return Err(Invalid::new("observation", "at least one term"));
        }
        for (i, t) in self.0.iter().enumerate() {
            t.check(&format!("observation[{i}]"))?;
        }
        Ok(())
    }

    /// The lidar terms (also those inside histories) with their keys: `(key, beams)`.
    pub fn lidar_terms(&self) -> impl Iterator<Item = (String, usize)> + '_ {
        self.0.iter().enumerate().filter_map(|(i, t)| {
            let key = match t {
                ObsTerm::History { .. } => format!("observation[{i}].history.term.lidar.beams"),
                _ => format!("observation[{i}].lidar.beams"),
            };
            t.lidar().map(|(beams, _)| (key, beams))
        })
    }

    /// Where each term's values lie: `(first index, term)` in layout order.
    pub fn spans(&self) -> impl Iterator<Item = (usize, &ObsTerm)> + '_ {
        self.0.iter().scan(0, |k, t| {
            let start = *k;
            *k += t.len();
            Some((start, t))
        })
    }

    /// The `plan_ahead` term's `(points, spacing)` (the first, also inside a history): what
    /// [`ObservationInputs::plan_ahead`] must hold.
    pub fn plan_ahead(&self) -> Option<(usize, f32)> {
        self.0.iter().find_map(|t| match t {
            ObsTerm::PlanAhead { points, spacing } => Some((*points, *spacing)),
            ObsTerm::History { term, .. } => match **term {
                ObsTerm::PlanAhead { points, spacing } => Some((points, spacing)),
                _ => None,
            },
            _ => None,
        })
    }

    fn max_lidar_beams(&self) -> usize {
        self.0.iter().filter_map(|t| t.lidar().map(|(b, _)| b)).max().unwrap_or(0)
    }
}

/// The left-right mirror image of an observation: what the robot would observe in the world
/// reflected about its own x axis (forward stays forward, left becomes right). Lidar bins are
/// exchanged with the bins at the opposite bearing, bearings, plan points' `y`, lateral and
/// angular velocities change sign, distances and forward speeds stay.
///
/// Why: the navigation task is symmetric, but a policy trained on it need not be. Training
/// with mirrored copies of its experience (`train.mirror`) teaches both sides of every lesson
/// (the RSL-RL symmetry augmentation of Isaac Lab). Built by [`ObservationLayout::mirror`].
#[derive(Clone, Debug, PartialEq)]
pub struct ObservationMirror {
    /// Value `i` of the mirrored observation is `sign[i] · obs[source[i]]`.
    source: Vec<usize>,
    sign: Vec<f32>,
    /// Largest angle between a lidar bin's mirrored bearing and the bin it is exchanged with
    /// (rad).
    max_bin_error: f32,
}

impl ObservationMirror {
    /// Length of the observations it mirrors.
    pub fn len(&self) -> usize {
        self.source.len()
    }

    /// Whether it mirrors empty observations.
    pub fn is_empty(&self) -> bool {
        self.source.is_empty()
    }

    /// Largest angle between a lidar bin's mirrored bearing and the centre of the bin that
    /// takes its value (rad): 0 where the bins lie symmetrically about the robot's x axis; a
    /// 360-beam scan from -π pooled by 3 is 1° off (its groups of three beams start at -π, so
    /// a group's mirror image straddles two groups).
    pub fn max_bin_error(&self) -> f32 {
        self.max_bin_error
    }

    /// Writes the mirror image of each row of `obs` (`[rows][len]`) to `out` (same shape).
    pub fn apply(&self, obs: &[f32], out: &mut [f32]) {
        let n = self.source.len();
        assert_eq!(obs.len(), out.len(), "mirror: input and output of one shape");
        assert_eq!(obs.len() % n.max(1), 0, "mirror: rows of {n} values");
        for (row, dst) in obs.chunks_exact(n).zip(out.chunks_exact_mut(n)) {
            for ((d, &s), &g) in dst.iter_mut().zip(&self.source).zip(&self.sign) {
                *d = g * row[s];
            }
        }
    }

    /// The mirror image of `obs` (rows of [`Self::len`]).
    pub fn mirrored(&self, obs: &[f32]) -> Vec<f32> {
        let mut out = vec![0.0; obs.len()];
        self.apply(obs, &mut out);
        out
    }
}

impl ObservationLayout {
    /// The mirror of this layout's observations when the scan is `lidar`'s, or why there is
    /// none: the scanner must sit on the robot's x axis facing forward, and each lidar term's
    /// bins must pair up with bins at the opposite bearing (a full turn, or a field of view
    /// symmetric about the x axis), each pair within half a bin of exact.
    pub fn mirror(&self, lidar: &LidarSpec) -> Result<ObservationMirror, Invalid> {
        if lidar.mount.y.abs() > 1e-6 || lidar.mount.yaw.abs() > 1e-6 {
            return Err(Invalid::new(
                "lidar.mount",
                format!(
                    "a scanner on the robot's x axis facing forward (y = 0, yaw = 0) for a mirrored observation, got y {} and yaw {}",
                    lidar.mount.y, lidar.mount.yaw
                ),
            ));
        }
        let mut source = Vec::with_capacity(self.len());
        let mut sign = Vec::with_capacity(self.len());
        let mut max_bin_error = 0.0f32;
        for (start, term) in self.spans() {
            // A predicted scan mirrors as the scans do.
            let (inner, steps) = match term {
                ObsTerm::History { term: inner, .. } => (&**inner, term.slots()),
                t => (t, 1),
            };
            // The map of one value of `inner`, relative to its first index.
            let (map, signs): (Vec<usize>, Vec<f32>) = match inner {
                ObsTerm::Lidar { beams, .. } => {
                    let (map, err) = lidar_bin_mirror(lidar, *beams)?;
                    max_bin_error = max_bin_error.max(err);
                    (map, vec![1.0; *beams])
                }
                ObsTerm::PlanAhead { points, .. } => {
                    ((0..2 * points).collect(), (0..2 * points).map(|i| if i % 2 == 1 { -1.0 } else { 1.0 }).collect())
                }
                ObsTerm::GoalBearing | ObsTerm::LastAngular | ObsTerm::Lateral | ObsTerm::Angular => {
                    (vec![0], vec![-1.0])
                }
                ObsTerm::GoalDistance | ObsTerm::LastLinear | ObsTerm::Linear => (vec![0], vec![1.0]),
                ObsTerm::History { .. } => {
                    unreachable!("histories of histories are refused by ObservationLayout::check")
                }
            };
            let w = map.len();
            for s in 0..steps {
                source.extend(map.iter().map(|m| start + s * w + m));
                sign.extend_from_slice(&signs);
            }
        }
        Ok(ObservationMirror { source, sign, max_bin_error })
    }
}

/// Which pooled bin of `lidar`'s scan (min-pooled to `beams`) lies at the opposite bearing of
/// each bin, and the largest angle between a mirrored bearing and its partner's (rad).
fn lidar_bin_mirror(lidar: &LidarSpec, beams: usize) -> Result<(Vec<usize>, f32), Invalid> {
    if beams == 0 || lidar.beams % beams != 0 {
        return Err(Invalid::new(
            "lidar.beams",
            format!("a multiple of the lidar term's {beams} bins for a mirrored observation, got {}", lidar.beams),
        ));
    }
    let group = lidar.beams / beams;
    let inc = lidar.angle_increment();
    let width = group as f32 * inc;
    // A bin's bearing: the middle of its beams.
    let centre = |k: usize| lidar.angle_min + (k * group) as f32 * inc + (group - 1) as f32 * 0.5 * inc;
    let full = lidar.is_full_circle();
    let gap = |a: f32, b: f32| {
        if full {
            let d = (a - b).rem_euclid(std::f32::consts::TAU);
            d.min(std::f32::consts::TAU - d)
        } else {
            (a - b).abs()
        }
    };
    let mut map = Vec::with_capacity(beams);
    let mut worst = 0.0f32;
    for k in 0..beams {
        let want = -centre(k);
        let (best, err) =
            (0..beams).map(|j| (j, gap(centre(j), want))).min_by(|a, b| a.1.total_cmp(&b.1)).expect("at least one bin");
        worst = worst.max(err);
        map.push(best);
    }
    let paired = map.iter().enumerate().all(|(k, &j)| map[j] == k);
    if worst > 0.5 * width + 1e-4 || !paired {
        return Err(Invalid::new(
            "lidar",
            format!(
                "a scan whose {beams} pooled bins pair up at opposite bearings for a mirrored observation (a full turn, or angle_min = -angle_max), got angle_min {} and angle_max {}",
                lidar.angle_min, lidar.angle_max
            ),
        ));
    }
    Ok((map, worst))
}

impl Validate for ObservationLayout {
    fn validate(&self) -> Result<(), Invalid> {
        self.check()
    }
}

/// What the observation is built from at one control step.
#[derive(Clone, Copy, Debug)]
pub struct ObservationInputs<'a> {
    /// The scan, counter-clockwise from the layout's first beam; its length must be a
    /// multiple of every lidar term's beams. `+inf` is no return.
    pub ranges: &'a [f32],
    /// Angle between two beams (rad, `LaserScan.angle_increment`; its sign does not matter):
    /// a swept lidar term (`sweep` > 0) needs it.
    pub angle_increment: f32,
    /// Goal distance (m).
    pub goal_distance: f32,
    /// Goal bearing in the robot frame (rad).
    pub goal_bearing: f32,
    /// The command given at the previous control step.
    pub last_command: Twist,
    /// Measured forward and angular velocity.
    pub velocity: Twist,
    /// Measured lateral velocity (m/s, `base_link` y).
    pub lateral_velocity: f32,
    /// Angle of the first beam of `ranges` (rad, in the frame of [`pose`](Self::pose)): a
    /// history with `ego_motion` needs it.
    pub angle_min: f32,
    /// Where the scan is taken from, in a fixed frame (odometry): the scanner's position,
    /// with the heading of the frame `angle_min` is measured in. A history with `ego_motion`
    /// moves past scans by the change of this pose; others ignore it.
    pub pose: Pose2,
    /// The points a `plan_ahead` term shows, in the robot frame
    /// ([`crate::plan::points_ahead`]); empty when the layout has none. Missing points read as
    /// the last one given (zeros when none is).
    pub plan_ahead: &'a [crate::geometry::Vec2],
}

/// The past of one history term.
#[derive(Clone, Debug)]
struct Stack {
    /// Values per step.
    width: usize,
    /// Steps shown, the current one included.
    steps: usize,
    /// Control steps between two shown.
    stride: usize,
    order: HistoryOrder,
    fill: HistoryFill,
    /// Up to `(steps - 1) × stride` past steps, oldest first, `width` values each. For a
    /// lidar history with `ego_motion`, the pooled, clipped ranges (as `newest`): the term's
    /// values are made at write, from these moved by the robot's motion since.
    past: Vec<f32>,
    /// Where each past step was taken (`ego_motion` only; empty otherwise).
    poses: Vec<Pose2>,
    /// Past steps stored.
    stored: usize,
    /// The current values written last (stored by the next commit).
    newest: Vec<f32>,
    /// The current pose written last (`ego_motion` only).
    newest_pose: Pose2,
    /// How far ahead a predicted scan is shown, in multiples of the span (0: none).
    predict: f32,
    /// Sets of values shown: `steps`, and the predicted scan ([`ObsTerm::slots`]).
    slots: usize,
}

/// Where a shown step's values are kept.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Slot {
    /// The current step's.
    Newest,
    /// Past step `p` (0 the oldest stored).
    Past(usize),
    /// None: the step reads zeros.
    Zero,
}

impl Stack {
    /// Where the values of chronological step `s` (`steps - 1` is the current one) are.
    fn slot(&self, s: usize) -> Slot {
        // Control steps back from the current one.
        let back = (self.steps - 1 - s) * self.stride;
        if back == 0 {
            Slot::Newest
        } else if back <= self.stored {
            Slot::Past(self.stored - back)
        } else {
            match self.fill {
                HistoryFill::First if self.stored > 0 => Slot::Past(0),
                HistoryFill::First => Slot::Newest,
                HistoryFill::Zero => Slot::Zero,
            }
        }
    }

    /// The stored values of a slot.
    fn values(&self, slot: Slot) -> Option<&[f32]> {
        let w = self.width;
        match slot {
            Slot::Newest => Some(self.newest.as_slice()),
            Slot::Past(p) => Some(&self.past[p * w..(p + 1) * w]),
            Slot::Zero => None,
        }
    }

    /// Where chronological step `s` goes among the steps shown (the history's order); the
    /// predicted scan, if any, is step `steps`, beyond the current one.
    fn shown_at(&self, s: usize) -> usize {
        match self.order {
            HistoryOrder::OldestFirst => s,
            HistoryOrder::NewestFirst => self.slots - 1 - s,
        }
    }

    fn push(&mut self) {
        let w = self.width;
        let cap = (self.steps - 1) * self.stride;
        if cap == 0 {
            return;
        }
        if self.stored == cap {
            self.past.copy_within(w.., 0);
            if !self.poses.is_empty() {
                self.poses.copy_within(1.., 0);
            }
            self.stored -= 1;
        }
        self.past[self.stored * w..(self.stored + 1) * w].copy_from_slice(&self.newest);
        if !self.poses.is_empty() {
            self.poses[self.stored] = self.newest_pose;
        }
        self.stored += 1;
    }
}

/// Builds observation vectors of one layout, keeping the past its history terms need.
/// Writing and committing allocate nothing.
#[derive(Clone, Debug)]
pub struct ObservationBuilder {
    layout: ObservationLayout,
    pooled: Vec<f32>,
    /// A past scan moved into the current pose (`ego_motion`).
    moved: Vec<f32>,
    /// The bins' directions for moving past scans.
    moves: MoveTable,
    /// The buffers of a predicted scan and the scan (`predict`).
    predictor: Predictor,
    predicted: Vec<f32>,
    sweep: SweepTable,
    /// One per history term, in layout order.
    stacks: Vec<Stack>,
    /// Whether the current step's observation was written since the last commit or reset.
    written: bool,
}

impl ObservationBuilder {
    /// A builder for `layout` (checked beforehand: see [`ObservationLayout::check`]).
    pub fn new(layout: &ObservationLayout) -> Self {
        let stacks = layout
            .0
            .iter()
            .filter_map(|t| match t {
                ObsTerm::History { term, steps, stride, order, fill, ego_motion, predict } => Some(Stack {
                    width: term.len(),
                    steps: *steps,
                    stride: *stride,
                    order: *order,
                    fill: *fill,
                    past: vec![0.0; steps.saturating_sub(1) * stride * term.len()],
                    poses: if *ego_motion {
                        vec![Pose2::default(); steps.saturating_sub(1) * stride]
                    } else {
                        Vec::new()
                    },
                    stored: 0,
                    newest: vec![0.0; term.len()],
                    newest_pose: Pose2::default(),
                    predict: *predict,
                    slots: t.slots(),
                }),
                _ => None,
            })
            .collect();
        let beams = layout.max_lidar_beams();
        Self {
            layout: layout.clone(),
            pooled: vec![0.0; beams],
            moved: vec![0.0; beams],
            moves: MoveTable::with_capacity(beams),
            predictor: Predictor::with_capacity(beams),
            predicted: vec![0.0; beams],
            sweep: SweepTable { bin_width: f32::NAN, cos_sin: Vec::with_capacity(beams) },
            stacks,
            written: false,
        }
    }

    /// The layout.
    pub fn layout(&self) -> &ObservationLayout {
        &self.layout
    }

    /// Whether the layout has history terms (and [`commit`](Self::commit) matters).
    pub fn has_history(&self) -> bool {
        !self.stacks.is_empty()
    }

    /// Whether an observation was written since the last commit or reset.
    pub fn is_written(&self) -> bool {
        self.written
    }

    /// Forgets the past (a new episode).
    pub fn reset(&mut self) {
        for s in &mut self.stacks {
            s.stored = 0;
        }
        self.written = false;
    }

    /// Stores the history terms' values written last as their newest past step: call it once
    /// per control step, when the step is taken. Without a write since the last commit it
    /// stores nothing.
    pub fn commit(&mut self) {
        if self.written {
            for s in &mut self.stacks {
                s.push();
            }
        }
        self.written = false;
    }

    /// Writes the observation for `inputs` into `out` (length [`ObservationLayout::len`]);
    /// `lidar_noise()` is added to every lidar value before clipping (the simulator's
    /// randomisation; `|| 0.0` for none). Writing again before a commit replaces the current
    /// step's values.
    pub fn write(&mut self, inputs: &ObservationInputs, out: &mut [f32], mut lidar_noise: impl FnMut() -> f32) {
        let Self { layout, pooled, moved, moves, predictor, predicted, sweep, stacks, written } = self;
        let mut k = 0;
        let mut h = 0;
        for term in &layout.0 {
            let n = term.len();
            let dst = &mut out[k..k + n];
            if let ObsTerm::History { term, ego_motion, .. } = term {
                let s = &mut stacks[h];
                h += 1;
                match (&**term, *ego_motion) {
                    (&ObsTerm::Lidar { beams, clip, sweep: radius }, true) => {
                        // The stack keeps pooled ranges and poses; each step shown is the scan
                        // then, moved into the pose now, then swept (or not) as a plain term.
                        pool_lidar(inputs, clip, &mut s.newest, &mut lidar_noise);
                        s.newest_pose = inputs.pose;
                        let bins = ScanBins::of(inputs, beams);
                        let w = s.width;
                        let predicted = &mut predicted[..beams];
                        if s.predict > 0.0 {
                            // Nothing past to tell motion from (the episode's first step, or the
                            // oldest step shown not yet stored with `fill: zero`): the current
                            // scan; replaced below from the oldest step shown.
                            predicted.copy_from_slice(&s.newest);
                        }
                        for step in 0..s.steps {
                            let d = &mut dst[s.shown_at(step) * w..][..w];
                            match s.slot(step) {
                                Slot::Zero => d.fill(0.0),
                                Slot::Newest => finish_lidar(&s.newest, clip, radius, &bins, sweep, d),
                                Slot::Past(p) => {
                                    let then = inputs.pose.inverse().compose(&s.poses[p]);
                                    let moved = &mut moved[..beams];
                                    move_scan(&s.past[p * w..(p + 1) * w], &then, clip, &bins, moves, moved);
                                    if step == 0 && s.predict > 0.0 {
                                        // From the oldest step shown, as far back as it lies.
                                        let elapsed = s.stored - p;
                                        let ahead = s.predict * ((s.steps - 1) * s.stride) as f32;
                                        predict_scan(
                                            &s.newest, moved, elapsed, ahead, clip, &bins, moves, predictor, predicted,
                                        );
                                    }
                                    finish_lidar(moved, clip, radius, &bins, sweep, d);
                                }
                            }
                        }
                        if s.predict > 0.0 {
                            let d = &mut dst[s.shown_at(s.steps) * w..][..w];
                            finish_lidar(predicted, clip, radius, &bins, sweep, d);
                        }
                    }
                    _ => {
                        write_term(term, inputs, pooled, sweep, &mut s.newest, &mut lidar_noise);
                        let w = s.width;
                        for step in 0..s.steps {
                            let d = &mut dst[s.shown_at(step) * w..][..w];
                            match s.values(s.slot(step)) {
                                Some(v) => d.copy_from_slice(v),
                                None => d.fill(0.0),
                            }
                        }
                    }
                }
            } else {
                write_term(term, inputs, pooled, sweep, dst, &mut lidar_noise);
            }
            k += n;
        }
        *written = true;
    }
}

/// Writes a term that is not a history.
fn write_term(
    term: &ObsTerm,
    inputs: &ObservationInputs,
    pooled: &mut [f32],
    sweep_table: &mut SweepTable,
    out: &mut [f32],
    lidar_noise: &mut impl FnMut() -> f32,
) {
    match term {
        ObsTerm::Lidar { beams, clip, sweep } => {
            let pooled = &mut pooled[..*beams];
            pool_lidar(inputs, *clip, pooled, lidar_noise);
            finish_lidar(pooled, *clip, *sweep, &ScanBins::of(inputs, *beams), sweep_table, out);
        }
        ObsTerm::GoalDistance => out[0] = inputs.goal_distance,
        ObsTerm::GoalBearing => out[0] = inputs.goal_bearing,
        ObsTerm::LastLinear => out[0] = inputs.last_command.linear,
        ObsTerm::LastAngular => out[0] = inputs.last_command.angular,
        ObsTerm::Linear => out[0] = inputs.velocity.linear,
        ObsTerm::Lateral => out[0] = inputs.lateral_velocity,
        ObsTerm::Angular => out[0] = inputs.velocity.angular,
        ObsTerm::PlanAhead { points, .. } => {
            let last = inputs.plan_ahead.last().copied().unwrap_or_default();
            for k in 0..*points {
                let p = inputs.plan_ahead.get(k).copied().unwrap_or(last);
                out[2 * k] = p.x;
                out[2 * k + 1] = p.y;
            }
        }
        ObsTerm::History { .. } => unreachable!("histories of histories are refused by ObservationLayout::check"),
    }
}

/// Min-pools the scan into `pooled` (its length the term's bins), adds noise and clips.
fn pool_lidar(inputs: &ObservationInputs, clip: [f32; 2], pooled: &mut [f32], lidar_noise: &mut impl FnMut() -> f32) {
    min_pool(inputs.ranges, pooled);
    for r in pooled.iter_mut() {
        // +inf (no return) clips to the far end.
        *r = (r.min(clip[1]) + lidar_noise()).clamp(clip[0], clip[1]);
    }
}

/// A lidar term's values from its pooled, clipped ranges: the ranges, or their free travel
/// for a disc of `radius` > 0.
fn finish_lidar(pooled: &[f32], clip: [f32; 2], radius: f32, bins: &ScanBins, table: &mut SweepTable, out: &mut [f32]) {
    if radius > 0.0 {
        table.fit(bins.width, pooled.len());
        free_travel(pooled, clip[1], radius, bins.full, &table.cos_sin, out);
    } else {
        out.copy_from_slice(pooled);
    }
}

/// The bearings of a lidar term's bins.
#[derive(Clone, Copy, Debug, PartialEq)]
struct ScanBins {
    /// Bins.
    n: usize,
    /// Bearing of bin 0's centre (rad).
    first: f32,
    /// Angle between two bins (rad).
    width: f32,
    /// The bins go round the whole turn.
    full: bool,
}

impl ScanBins {
    fn of(inputs: &ObservationInputs, beams: usize) -> Self {
        let group = inputs.ranges.len() / beams.max(1);
        let inc = inputs.angle_increment.abs();
        // Beams spread evenly round the whole turn, also a ROS scan that ends one increment
        // short of it (`angle_max = π - inc`), which `is_full_circle` on its angles would call
        // partial: the bins wrap round the back.
        let full = (inputs.ranges.len() as f32 * inc - std::f32::consts::TAU).abs() < 0.5 * inc;
        let first = inputs.angle_min + 0.5 * (group as f32 - 1.0) * inc;
        Self { n: beams, first, width: group as f32 * inc, full }
    }

    /// The bin (fractional) whose centre lies at `bearing`, counted from bin 0 counter-clockwise
    /// round the turn, in `[0, 2π / width)`.
    fn index(&self, bearing: f32) -> f32 {
        (bearing - self.first).rem_euclid(std::f32::consts::TAU) / self.width
    }
}

/// Neighbouring returns of a scan closer in range than this (m) are taken for one surface
/// when a scan is moved ([`move_scan`]): a wall seen at a slant steps by up to 0.3 m from one
/// 3° bin to the next at 2 m, while a cart or a post stands a metre or more off the wall behind.
const SURFACE_STEP: f32 = 0.3;

/// A past scan's pooled ranges `then_ranges`, taken at pose `then` (given in the current
/// scanner frame), as the current scanner would see its returns. Each bin's return is an arc
/// of the bin's width at its range, joined to the next bin's return by a straight segment when
/// the two are one surface ([`SURFACE_STEP`]), so that a wall stays whole when the robot's
/// motion spreads its returns over more bins. Moved into the current frame, every current bin
/// whose bearing crosses an arc or segment reads the distance to it along that bearing (the
/// nearest one). Bins none crosses read `clip[1]` (nothing there then, or out of view then).
/// Values clipped to `clip`.
fn move_scan(
    then_ranges: &[f32],
    then: &Pose2,
    clip: [f32; 2],
    bins: &ScanBins,
    table: &mut MoveTable,
    out: &mut [f32],
) {
    out.fill(clip[1]);
    // Directions then are the table's turned by the pose's yaw: one `sin_cos` per scan, not
    // one per point.
    let (sy, cy) = then.yaw.sin_cos();
    let origin = Vec2::new(then.x, then.y);
    draw_returns(then_ranges, (cy, sy), |_| Some(origin), clip, bins, table, out);
}

/// Draws the returns of a scan `ranges` (pooled, clipped: `clip[1]` is no return) into `out`
/// as the current scanner sees them, keeping the nearest: return k lies at `shift(k)` plus its
/// range along its bin's direction turned by `rot` (`(cos, sin)`); `shift(k)` `None` leaves it
/// out. Each return is an arc of its bin's width at its range, joined to the next bin's return
/// by a straight segment when the two are one surface ([`SURFACE_STEP`]) and both are drawn;
/// every bin whose bearing crosses an arc or segment reads the distance to it along that
/// bearing. Values clipped to `clip`.
fn draw_returns(
    ranges: &[f32],
    rot: (f32, f32),
    shift: impl Fn(usize) -> Option<Vec2>,
    clip: [f32; 2],
    bins: &ScanBins,
    table: &mut MoveTable,
    out: &mut [f32],
) {
    let n = bins.n;
    table.fit(bins);
    // Bins round the whole turn, the wrap included (a partial scan has fewer); `turn`, the
    // same as [`ScanBins::index`] counts it, for bearings (not whole where bins do not divide
    // the turn).
    let round = (std::f32::consts::TAU / bins.width).round() as usize;
    let turn = if bins.full { round as f32 } else { std::f32::consts::TAU / bins.width };
    let (c, s) = rot;
    let at = |r: f32, u: Vec2, o: Vec2| Vec2::new(o.x + r * (u.x * c - u.y * s), o.y + r * (u.x * s + u.y * c));
    let bearing_index = |p: Vec2| bins.index(p.y.atan2(p.x));
    let is_return = |d: f32| d < clip[1];
    let MoveTable { centre, edge, points, .. } = table;
    // Each return's centre point now and its bin: both ends of the segments to its neighbours.
    for (k, ((point, &d), &u)) in points.iter_mut().zip(ranges).zip(centre.iter()).enumerate() {
        if let (true, Some(o)) = (is_return(d), shift(k)) {
            let p = at(d, u, o);
            *point = (p, bearing_index(p));
        }
    }
    // Draws the segment p–q (`ip`, `iq`: their bins): the bins whose bearings it crosses read
    // their distance to it.
    let mut draw = |(p, ip): (Vec2, f32), (q, iq): (Vec2, f32)| {
        // A pose that is not finite (bad odometry) moves nothing anywhere: the robot's
        // controller reports the bad input, not a panic here.
        if !(p.is_finite() && q.is_finite()) {
            return;
        }
        // The shorter way round from one end's bearing to the other's.
        let span = (iq - ip).rem_euclid(turn);
        let (lo, span) = if span <= 0.5 * turn { (ip, span) } else { (iq, turn - span) };
        let (np, nq) = (p.length(), q.length());
        let (near, far) = (np.min(nq), np.max(nq));
        let e = q - p;
        // The bins whose bearings lie within index range [a, a + width] (a thousandth of a bin
        // of slack for ends on a bin's bearing; one lying between two bins' bearings, the
        // nearer bin) read their distance along their bearing to the line p–q.
        let mut cover = |a: f32, width: f32| {
            let (mut first, mut last) = ((a - 1e-3).ceil().max(0.0) as usize, (a + width + 1e-3).floor() as usize);
            if last < first {
                first = (a + 0.5 * width).round() as usize;
                last = first;
            }
            for i in first..=last {
                // Round a full turn the bins wrap; a partial scan's past its last are out of view.
                let j = if bins.full { i % round } else { i };
                if j >= n {
                    continue;
                }
                let u = centre[j];
                let den = u.x * e.y - u.y * e.x;
                let t = if den.abs() > 1e-6 { (p.x * e.y - p.y * e.x) / den } else { near };
                out[j] = out[j].min(t.clamp(near, far).clamp(clip[0], clip[1]));
            }
        };
        if bins.full || lo + span < turn {
            cover(lo, span);
        } else {
            // Across the bearing where a partial scan's index wraps (not a whole bin).
            cover(lo, turn - lo);
            cover(0.0, lo + span - turn);
        }
    };
    for (k, &d) in ranges.iter().enumerate() {
        let Some(o) = shift(k).filter(|_| is_return(d)) else {
            continue;
        };
        let (l, r) = (at(d, edge[k], o), at(d, edge[k + 1], o));
        draw((l, bearing_index(l)), (r, bearing_index(r)));
        let next = if k + 1 < n { Some(k + 1) } else { bins.full.then_some(0) };
        if let Some(m) = next {
            let dm = ranges[m];
            // One surface, moved alike (a predicted scan's object split at the wrap is not).
            if is_return(dm) && (dm - d).abs() <= SURFACE_STEP && shift(m) == Some(o) {
                draw(points[k], points[m]);
            }
        }
    }
}

/// Objects in a scan longer than this (m, from end to end) are taken to stand still
/// ([`predict_scan`]): walls, whose visible stretch changes as the robot drives; a cart or a
/// person is shorter.
const MOVER_EXTENT: f32 = 1.0;

/// An object is matched to the one in the older scan whose centre lies nearest, within this
/// (m, over the span between the two scans; [`predict_scan`]).
const MATCH_RADIUS: f32 = 0.5;

/// An object whose centre moved less than this (m) between the two scans stands still
/// ([`predict_scan`]): a centre shifts a little as the robot sees the object from elsewhere.
const STILL: f32 = 0.05;

/// One object of a scan: a run of returns on one surface ([`SURFACE_STEP`]).
#[derive(Clone, Copy, Debug, Default)]
struct Segment {
    /// Its first and last bin.
    first: usize,
    last: usize,
    /// Mean of its returns' points (scanner frame).
    centre: Vec2,
    /// Distance between its end points (m).
    extent: f32,
}

/// Buffers of [`predict_scan`], kept with the builder.
#[derive(Clone, Debug)]
struct Predictor {
    now: Vec<Segment>,
    then: Vec<Segment>,
    /// Where each current return will be, less where it is (`None`: it stands still).
    shift: Vec<Option<Vec2>>,
}

impl Predictor {
    fn with_capacity(beams: usize) -> Self {
        Self { now: Vec::with_capacity(beams), then: Vec::with_capacity(beams), shift: Vec::with_capacity(beams) }
    }
}

/// Splits the returns of `ranges` (`clip_far`: no return) into [`Segment`]s.
fn segments(ranges: &[f32], clip_far: f32, centre: &[Vec2], out: &mut Vec<Segment>) {
    out.clear();
    let point = |k: usize| centre[k] * ranges[k];
    let mut k = 0;
    while k < ranges.len() {
        if ranges[k] >= clip_far {
            k += 1;
            continue;
        }
        let first = k;
        let mut sum = point(k);
        while k + 1 < ranges.len() && ranges[k + 1] < clip_far && (ranges[k + 1] - ranges[k]).abs() <= SURFACE_STEP {
            k += 1;
            sum += point(k);
        }
        let centre = sum / (k - first + 1) as f32;
        out.push(Segment { first, last: k, centre, extent: (point(k) - point(first)).length() });
        k += 1;
    }
}

/// The current scan `now` with its moving objects carried on (pooled, clipped ranges; `then`:
/// the scan `elapsed` control steps ago, moved into the current pose by [`move_scan`]),
/// `ahead` control steps ahead, written to `out`.
///
/// A lidar sees no velocities; this finds them the way a scan-based obstacle tracker does,
/// from two scans: each scan is split into objects (runs of returns on one surface), each
/// object now no longer than [`MOVER_EXTENT`] is matched to the object then whose centre lies
/// nearest within [`MATCH_RADIUS`], and one whose centre moved by [`STILL`] or more is taken
/// to keep that motion. Its returns are drawn where they will be ([`draw_returns`]); bins it
/// leaves read `clip[1]` (what stands behind it is not seen), every other bin reads `now`.
/// Walls, posts and furniture stand still once the past scan is moved by the robot's own
/// motion, so only movers move; a mover seen only now (it came round a corner) stands still.
#[allow(clippy::too_many_arguments)]
fn predict_scan(
    now: &[f32],
    then: &[f32],
    elapsed: usize,
    ahead: f32,
    clip: [f32; 2],
    bins: &ScanBins,
    table: &mut MoveTable,
    buffers: &mut Predictor,
    out: &mut [f32],
) {
    table.fit(bins);
    let Predictor { now: segs_now, then: segs_then, shift } = buffers;
    segments(now, clip[1], &table.centre, segs_now);
    segments(then, clip[1], &table.centre, segs_then);
    shift.clear();
    shift.resize(now.len(), None);
    let scale = if elapsed > 0 { ahead / elapsed as f32 } else { 0.0 };
    // Whether an object now may be one that moves: short, not cut by the end of the range or
    // hidden in part behind something nearer (its visible stretch changes as the robot moves,
    // and its centre with it), and not where the scan then saw it (on most of its bins the past
    // scan, moved, reads what the current one does).
    let may_move = |seg: &Segment| {
        let (a, b) = (now[seg.first], now[seg.last]);
        let hidden = |k: Option<usize>, r: f32| k.is_some_and(|k| now[k] < r - SURFACE_STEP);
        let before = if seg.first > 0 { Some(seg.first - 1) } else { bins.full.then_some(now.len() - 1) };
        let after = if seg.last + 1 < now.len() { Some(seg.last + 1) } else { bins.full.then_some(0) };
        let same = (seg.first..=seg.last).filter(|&k| (now[k] - then[k]).abs() < STILL).count();
        seg.extent <= MOVER_EXTENT
            && a.max(b) < clip[1] - SURFACE_STEP
            && !hidden(before, a)
            && !hidden(after, b)
            && 2 * same < seg.last - seg.first + 1
    };
    for seg in segs_now.iter().filter(|s| may_move(s)) {
        let nearest = segs_then
            .iter()
            .filter(|t| t.extent <= MOVER_EXTENT + SURFACE_STEP)
            .map(|t| seg.centre - t.centre)
            .min_by(|a, b| a.length().total_cmp(&b.length()));
        if let Some(moved) = nearest.filter(|d| (STILL..=MATCH_RADIUS).contains(&d.length())) {
            shift[seg.first..=seg.last].fill(Some(moved * scale));
        }
    }
    for (o, (&r, s)) in out.iter_mut().zip(now.iter().zip(shift.iter())) {
        *o = if s.is_some() { clip[1] } else { r };
    }
    let shift = &*shift;
    draw_returns(now, (1.0, 0.0), |k| shift[k], clip, bins, table, out);
}

/// The directions of a lidar term's bins, kept between writes for [`draw_returns`] (a moved or
/// predicted scan; they change only with the scanner), and its buffer of a scan's points.
#[derive(Clone, Debug)]
struct MoveTable {
    /// The bins the table is for (`None` before the first move).
    bins: Option<ScanBins>,
    /// `(cos, sin)` of bin k's centre bearing.
    centre: Vec<Vec2>,
    /// `(cos, sin)` of the bearing half a bin clockwise of bin k's centre, for k up to the
    /// number of bins (the last: half a bin counter-clockwise of the last bin's centre).
    edge: Vec<Vec2>,
    /// A past scan's centre points in the current scanner frame and their bins (fractional).
    points: Vec<(Vec2, f32)>,
}

impl MoveTable {
    /// An empty table with room for `beams` bins.
    fn with_capacity(beams: usize) -> Self {
        Self {
            bins: None,
            centre: Vec::with_capacity(beams),
            edge: Vec::with_capacity(beams + 1),
            points: Vec::with_capacity(beams),
        }
    }

    /// Makes the table hold `bins`' directions (allocates nothing once its capacity holds
    /// them).
    fn fit(&mut self, bins: &ScanBins) {
        if self.bins == Some(*bins) {
            return;
        }
        let dir = |a: f32| {
            let (s, c) = a.sin_cos();
            Vec2::new(c, s)
        };
        self.bins = Some(*bins);
        self.centre.clear();
        self.centre.extend((0..bins.n).map(|k| dir(bins.first + k as f32 * bins.width)));
        self.edge.clear();
        self.edge.extend((0..=bins.n).map(|k| dir(bins.first + (k as f32 - 0.5) * bins.width)));
        self.points.clear();
        self.points.resize(bins.n, (Vec2::default(), 0.0));
    }
}

/// `cos` and `sin` of whole multiples of a swept lidar term's bin width, kept between writes
/// (the width changes only with the scanner).
#[derive(Clone, Debug)]
struct SweepTable {
    /// The bin width the table is for (rad; NaN before the first swept write).
    bin_width: f32,
    /// `(cos mw, sin mw)` for `m = 0, 1, ...`.
    cos_sin: Vec<(f32, f32)>,
}

impl SweepTable {
    /// Makes the table hold `beams` multiples of `bin_width` (allocates nothing once the
    /// builder's capacity holds them).
    fn fit(&mut self, bin_width: f32, beams: usize) {
        if self.bin_width == bin_width && self.cos_sin.len() >= beams {
            return;
        }
        self.bin_width = bin_width;
        self.cos_sin.clear();
        self.cos_sin.extend((0..beams).map(|m| {
            let (s, c) = (m as f32 * bin_width).sin_cos();
            (c, s)
        }));
    }
}

/// The free travel per bin of a scan `ranges` (equal bins, `cos_sin` holding their angular
/// offsets; `full`: the bins go round the whole turn) for a disc of `radius` round the
/// scanner, written to `out`: for bearing `θ`, the distance the disc moves along `θ` before a
/// return falls inside it, capped at `far`. Ranges at `far` or beyond are no return.
///
/// A return at range `d` and angle `Δ` off the bearing is met when the disc's centre has
/// travelled `d cos Δ − sqrt(r² − d² sin² Δ)`, if `d |sin Δ| < r` and it lies ahead.
fn free_travel(ranges: &[f32], far: f32, radius: f32, full: bool, cos_sin: &[(f32, f32)], out: &mut [f32]) {
    let n = ranges.len();
    out.fill(far);
    let r2 = radius * radius;
    // Largest offset in bins: half a turn each way round a full turn, the whole scan otherwise.
    let reach = if full { n / 2 } else { n - 1 };
    for (k, &d) in ranges.iter().enumerate() {
        if d >= far {
            continue;
        }
        if d <= radius {
            // A return inside the disc already: no bearing is free.
            out.fill(0.0);
            return;
        }
        for (m, &(c, s)) in cos_sin.iter().enumerate().take(reach + 1) {
            let lateral = d * s;
            // Past a right angle, or wide enough to clear it: so are all larger offsets.
            if c <= 0.0 || lateral >= radius {
                break;
            }
            let t = (d * c - (r2 - lateral * lateral).sqrt()).max(0.0);
            let mut meet = |j: usize| out[j] = out[j].min(t);
            if full {
                meet((k + m) % n);
                meet((k + n - m) % n);
            } else {
                if k + m < n {
                    meet(k + m);
                }
                if m <= k {
                    meet(k - m);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{ConfigError, from_yaml_str, to_yaml_string};
    use crate::geometry::{Pose2, Vec2};

    fn inputs(ranges: &[f32], d: f32, b: f32) -> ObservationInputs<'_> {
        ObservationInputs {
            ranges,
            angle_increment: std::f32::consts::TAU / ranges.len() as f32,
            angle_min: -std::f32::consts::PI,
            pose: Pose2::default(),
            goal_distance: d,
            goal_bearing: b,
            last_command: Twist::new(0.3, -0.2),
            velocity: Twist::new(0.25, 0.1),
            lateral_velocity: -0.05,
            plan_ahead: &[],
        }
    }

    fn history(term: ObsTerm, steps: usize, order: HistoryOrder, fill: HistoryFill) -> ObsTerm {
        ObsTerm::History { term: Box::new(term), steps, stride: 1, order, fill, ego_motion: false, predict: 0.0 }
    }

    /// The observation of a scan `f(bearing)` mirrored equals the observation of the mirrored
    /// scan `f(-bearing)` with mirrored goal, plan and velocities, on the shipped robots' scan
    /// geometries and a layout with every kind of term.
    #[test]
    fn mirror_is_the_observation_of_the_mirrored_world() {
        let layout: ObservationLayout = from_yaml_str(
            "t.yaml",
            "- history: {term: {lidar: {beams: 120, clip: [0.15, 3.0]}}, steps: 3, stride: 2, order: oldest_first}\n\
             - goal_distance\n- goal_bearing\n- plan_ahead: {points: 3, spacing: 0.3}\n\
             - last_linear\n- last_angular\n- linear\n- lateral\n- angular\n\
             - history: {term: goal_bearing, steps: 2, order: newest_first}\n",
        )
        .unwrap();
        // A scene with nothing symmetric about it, changing with time.
        let range = |a: f32, t: f32| 1.4 + 0.5 * (a + 0.3 * t).sin() + 0.2 * (3.0 * a).cos();
        let jackal = LidarSpec { beams: 720, angle_min: -2.356_194_5, angle_max: 2.356_194_5, ..Default::default() };
        for (spec, tol) in [(LidarSpec::default(), 0.05), (jackal, 1e-3)] {
            let mirror = layout.mirror(&spec).unwrap();
            assert_eq!(mirror.len(), layout.len());
            let bin_width = (spec.beams / 120) as f32 * spec.angle_increment();
            assert!(mirror.max_bin_error() <= 0.5 * bin_width);
            let (mut a, mut b) = (ObservationBuilder::new(&layout), ObservationBuilder::new(&layout));
            let (mut oa, mut ob) = (vec![0.0; layout.len()], vec![0.0; layout.len()]);
            for t in 0..5 {
                let t = t as f32;
                let ra: Vec<f32> = (0..spec.beams).map(|i| range(spec.beam_angle(i), t)).collect();
                let rb: Vec<f32> = (0..spec.beams).map(|i| range(-spec.beam_angle(i), t)).collect();
                let plan = [Vec2::new(0.3, 0.1 * t), Vec2::new(0.6, -0.2), Vec2::new(0.8, 0.5)];
                let plan_m: Vec<Vec2> = plan.iter().map(|p| Vec2::new(p.x, -p.y)).collect();
                let ia = ObservationInputs {
                    ranges: &ra,
                    angle_increment: spec.angle_increment(),
                    angle_min: spec.angle_min,
                    pose: Pose2::default(),
                    goal_distance: 2.0 + t,
                    goal_bearing: 0.4 - 0.2 * t,
                    last_command: Twist::new(0.3, 0.1 * t - 0.2),
                    velocity: Twist::new(0.25, 0.3 - 0.1 * t),
                    lateral_velocity: 0.05 * t,
                    plan_ahead: &plan,
                };
                let ib = ObservationInputs {
                    ranges: &rb,
                    goal_bearing: -ia.goal_bearing,
                    last_command: Twist::new(0.3, -ia.last_command.angular),
                    velocity: Twist::new(0.25, -ia.velocity.angular),
                    lateral_velocity: -ia.lateral_velocity,
                    plan_ahead: &plan_m,
                    ..ia
                };
                a.write(&ia, &mut oa, || 0.0);
                b.write(&ib, &mut ob, || 0.0);
                a.commit();
                b.commit();
                let m = mirror.mirrored(&oa);
                // Away from the scan, exact; a bin may read its partner's neighbourhood (the
                // bins are up to 1° off symmetric), so a smooth scene differs a little.
                let scan = 3 * 120;
                for (i, (x, y)) in m.iter().zip(&ob).enumerate() {
                    let tol = if i < scan { tol } else { 1e-6 };
                    assert!((x - y).abs() <= tol, "value {i}: mirrored {x}, mirrored world {y} (t {t})");
                }
                assert_eq!(mirror.mirrored(&m), oa, "mirroring twice gives the observation back");
            }
        }
    }

    #[test]
    fn scans_that_cannot_be_mirrored_are_named() {
        let layout = ObservationLayout::default();
        let off_axis = LidarSpec { mount: Pose2::new(0.0, 0.05, 0.0), ..Default::default() };
        let e = layout.mirror(&off_axis).unwrap_err();
        assert_eq!(e.key, "lidar.mount");
        assert!(e.expected.contains("got y 0.05"), "{}", e.expected);
        let lopsided = LidarSpec { beams: 240, angle_min: -2.0, angle_max: 1.0, ..Default::default() };
        let e = layout.mirror(&lopsided).unwrap_err();
        assert_eq!(e.key, "lidar");
        assert!(e.expected.contains("angle_min -2") && e.expected.contains("angle_max 1"), "{}", e.expected);
        let coarse = LidarSpec { beams: 60, ..Default::default() };
        assert_eq!(layout.mirror(&coarse).unwrap_err().key, "lidar.beams");
        // A 270° scan symmetric about the x axis pairs exactly.
        let jackal = LidarSpec { beams: 720, angle_min: -2.356_194_5, angle_max: 2.356_194_5, ..Default::default() };
        assert!(layout.mirror(&jackal).unwrap().max_bin_error() < 1e-4);
    }

    #[test]
    fn histories_read_and_write_as_yaml() {
        let text = "- lidar: {beams: 4, clip: [0.1, 2.0]}\n\
                    - history: {term: goal_bearing, steps: 5, order: oldest_first}\n\
                    - history: {term: goal_distance, steps: 3, order: newest_first, fill: zero}\n\
                    - history: {term: {lidar: {beams: 2, clip: [0.1, 2.0]}}, steps: 2, order: oldest_first}\n\
                    - linear\n- lateral\n- angular\n\
                    - history: {term: linear, steps: 3, stride: 4, order: oldest_first}\n";
        let l: ObservationLayout = from_yaml_str("t.yaml", text).unwrap();
        assert_eq!(l.len(), 4 + 5 + 3 + 4 + 3 + 3);
        assert_eq!(l.0[1], history(ObsTerm::GoalBearing, 5, HistoryOrder::OldestFirst, HistoryFill::First));
        assert_eq!(l.0[2], history(ObsTerm::GoalDistance, 3, HistoryOrder::NewestFirst, HistoryFill::Zero));
        assert_eq!(l.lidar_terms().map(|(_, b)| b).collect::<Vec<_>>(), vec![4, 2]);
        let back: ObservationLayout = from_yaml_str("back.yaml", &to_yaml_string(&l)).unwrap();
        assert_eq!(back, l);
        assert_eq!(l.spans().map(|(k, _)| k).collect::<Vec<_>>(), vec![0, 4, 9, 12, 16, 17, 18, 19]);
        assert!(matches!(l.0[7], ObsTerm::History { stride: 4, .. }));
        // A stride of 1 is the default and is not written: contracts without one read as before.
        let yaml = to_yaml_string(&l);
        assert_eq!(yaml.matches("stride").count(), 1, "{yaml}");
    }

    #[test]
    fn bad_histories_are_refused_with_their_key() {
        for (text, key) in [
            ("- history: {term: goal_bearing, steps: 0, order: oldest_first}", "observation[0].history.steps"),
            (
                "- linear\n- history: {term: {history: {term: linear, steps: 2, order: oldest_first}}, steps: 2, \
                 order: oldest_first}",
                "observation[1].history.term",
            ),
            (
                "- history: {term: {lidar: {beams: 0, clip: [0.1, 2.0]}}, steps: 2, order: oldest_first}",
                "observation[0].history.term.lidar.beams",
            ),
            ("- history: {term: linear, steps: 2, stride: 0, order: oldest_first}", "observation[0].history.stride"),
            ("- history: {term: linear, steps: 3, stride: 600, order: oldest_first}", "observation[0].history.stride"),
        ] {
            let e = from_yaml_str::<ObservationLayout>("bad.yaml", text).unwrap_err().to_string();
            assert!(e.contains("bad.yaml") && e.contains(key), "{e}");
        }
        // The order is part of the contract: never guessed.
        let e = from_yaml_str::<ObservationLayout>("o.yaml", "- history: {term: goal_bearing, steps: 5}")
            .unwrap_err()
            .to_string();
        assert!(e.contains("order"), "{e}");
    }

    #[test]
    fn plain_terms_are_written_in_layout_order() {
        let layout = ObservationLayout(vec![
            ObsTerm::Lidar { beams: 2, clip: [0.2, 1.5], sweep: 0.0 },
            ObsTerm::GoalDistance,
            ObsTerm::GoalBearing,
            ObsTerm::LastLinear,
            ObsTerm::LastAngular,
            ObsTerm::Linear,
            ObsTerm::Lateral,
            ObsTerm::Angular,
        ]);
        let mut b = ObservationBuilder::new(&layout);
        let mut out = vec![0.0; layout.len()];
        b.write(&inputs(&[0.1, 0.9, f32::INFINITY, 1.0], 2.0, 0.5), &mut out, || 0.0);
        assert_eq!(out, vec![0.2, 1.0, 2.0, 0.5, 0.3, -0.2, 0.25, -0.05, 0.1]);
    }

    #[test]
    fn histories_keep_the_last_steps_in_their_order() {
        let layout = ObservationLayout(vec![
            history(ObsTerm::GoalBearing, 4, HistoryOrder::OldestFirst, HistoryFill::First),
            history(ObsTerm::GoalDistance, 3, HistoryOrder::NewestFirst, HistoryFill::Zero),
            history(
                ObsTerm::Lidar { beams: 2, clip: [0.0, 10.0], sweep: 0.0 },
                2,
                HistoryOrder::OldestFirst,
                HistoryFill::First,
            ),
        ]);
        let mut b = ObservationBuilder::new(&layout);
        assert!(b.has_history());
        let mut out = vec![0.0; layout.len()];
        let step = |b: &mut ObservationBuilder, out: &mut [f32], i: f32| {
            let ranges = [i, 50.0, 6.0, 10.0 + i];
            b.write(&inputs(&ranges, 10.0 + i, i), out, || 0.0);
        };
        step(&mut b, &mut out, 1.0);
        // Before the episode: the first value (bearing, lidar) or zeros (distance).
        assert_eq!(out, vec![1.0, 1.0, 1.0, 1.0, 11.0, 0.0, 0.0, 1.0, 6.0, 1.0, 6.0]);
        // Writing again without a commit replaces the current step.
        step(&mut b, &mut out, 2.0);
        assert_eq!(&out[..4], &[2.0; 4]);
        b.commit();
        step(&mut b, &mut out, 3.0);
        assert_eq!(out, vec![2.0, 2.0, 2.0, 3.0, 13.0, 12.0, 0.0, 2.0, 6.0, 3.0, 6.0]);
        b.commit();
        b.commit(); // nothing written since: stores nothing
        for i in 4..=6 {
            step(&mut b, &mut out, i as f32);
            b.commit();
        }
        step(&mut b, &mut out, 7.0);
        assert_eq!(out, vec![4.0, 5.0, 6.0, 7.0, 17.0, 16.0, 15.0, 6.0, 6.0, 7.0, 6.0]);
        // A new episode forgets the past.
        b.reset();
        step(&mut b, &mut out, 9.0);
        assert_eq!(out, vec![9.0, 9.0, 9.0, 9.0, 19.0, 0.0, 0.0, 9.0, 6.0, 9.0, 6.0]);
    }

    #[test]
    fn a_stride_shows_every_nth_past_step() {
        let strided = |order, fill| {
            ObservationLayout(vec![ObsTerm::History {
                term: Box::new(ObsTerm::GoalDistance),
                steps: 3,
                stride: 2,
                order,
                fill,
                ego_motion: false,
                predict: 0.0,
            }])
        };
        let layout = strided(HistoryOrder::OldestFirst, HistoryFill::First);
        let mut b = ObservationBuilder::new(&layout);
        let mut z = ObservationBuilder::new(&strided(HistoryOrder::NewestFirst, HistoryFill::Zero));
        let (mut out, mut zout) = (vec![0.0; 3], vec![0.0; 3]);
        // Step i reads distance i; shown: steps t-4, t-2 and t.
        let mut seen = Vec::new();
        for i in 1..=7 {
            b.write(&inputs(&[1.0], i as f32, 0.0), &mut out, || 0.0);
            z.write(&inputs(&[1.0], i as f32, 0.0), &mut zout, || 0.0);
            seen.push((out.clone(), zout.clone()));
            b.commit();
            z.commit();
        }
        let expect = |i: i32| -> (Vec<f32>, Vec<f32>) {
            let at = |k: i32| if k >= 1 { k as f32 } else { 1.0 };
            let atz = |k: i32| if k >= 1 { k as f32 } else { 0.0 };
            (vec![at(i - 4), at(i - 2), at(i)], vec![atz(i), atz(i - 2), atz(i - 4)])
        };
        for (i, s) in (1..=7).zip(&seen) {
            assert_eq!(*s, expect(i), "step {i}");
        }
        // A new episode forgets the past.
        b.reset();
        b.write(&inputs(&[1.0], 9.0, 0.0), &mut out, || 0.0);
        assert_eq!(out, vec![9.0; 3]);
    }

    #[test]
    fn lidar_noise_is_added_before_clipping() {
        let layout = ObservationLayout(vec![ObsTerm::Lidar { beams: 3, clip: [0.5, 2.0], sweep: 0.0 }]);
        let mut b = ObservationBuilder::new(&layout);
        let mut out = vec![0.0; 3];
        let mut noise = [0.25, -1.0, 1.0].into_iter();
        b.write(&inputs(&[1.0, 1.0, 1.0], 0.0, 0.0), &mut out, || noise.next().unwrap());
        assert_eq!(out, vec![1.25, 0.5, 2.0]);
    }

    /// Free travel by brute force: every return a point, every bearing a direction, the
    /// disc's centre moved along it until the point is within the radius.
    fn free_travel_brute(ranges: &[f32], bearing: impl Fn(usize) -> f32, far: f32, radius: f32) -> Vec<f32> {
        let points: Vec<Vec2> = ranges
            .iter()
            .enumerate()
            .filter(|(_, d)| **d < far)
            .map(|(k, d)| Vec2::new(d * bearing(k).cos(), d * bearing(k).sin()))
            .collect();
        (0..ranges.len())
            .map(|j| {
                let u = Vec2::new(bearing(j).cos(), bearing(j).sin());
                points.iter().fold(far, |best, p| {
                    let along = p.x * u.x + p.y * u.y;
                    let lateral = (p.x * u.y - p.y * u.x).abs();
                    if p.x.hypot(p.y) <= radius {
                        0.0
                    } else if along > 0.0 && lateral < radius {
                        best.min((along - (radius * radius - lateral * lateral).sqrt()).max(0.0))
                    } else {
                        best
                    }
                })
            })
            .collect()
    }

    #[test]
    fn a_swept_scan_is_the_free_travel_of_the_disc() {
        let term = |sweep: f32| ObservationLayout(vec![ObsTerm::Lidar { beams: 120, clip: [0.15, 3.0], sweep }]);
        // A 360-beam full turn: one post 0.52 m ahead (beams 180-182 of -π + k·1°: bin 60).
        let mut ranges = vec![f32::INFINITY; 360];
        ranges[180..183].fill(0.52);
        let mut b = ObservationBuilder::new(&term(0.25));
        let mut out = vec![0.0; 120];
        b.write(&inputs(&ranges, 1.0, 0.0), &mut out, || 0.0);
        // The disc touches it after 0.27 m.
        assert!((out[60] - 0.27).abs() < 1e-5, "{}", out[60]);
        // It blocks the bearings within asin(0.25 / 0.52) = 28.7° (9 bins of 3°), none beyond.
        assert!(out[51..=69].iter().all(|&t| t < 0.52), "{:?}", &out[48..73]);
        assert!(out[..51].iter().chain(&out[70..]).all(|&t| t == 3.0), "{:?}", &out[48..73]);
        // Plain, the post fills one bin.
        let mut plain = ObservationBuilder::new(&term(0.0));
        plain.write(&inputs(&ranges, 1.0, 0.0), &mut out, || 0.0);
        assert_eq!(out.iter().filter(|&&r| r < 3.0).count(), 1);

        // A random room on a full turn and on the Jackal's 270° (no wrapping round the back),
        // against the brute force on the pooled bins' centres.
        use rand::{RngExt, SeedableRng};
        use std::f32::consts::{PI, TAU};
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(3);
        for (beams, angle_min, inc) in [(360, -PI, TAU / 360.0), (720, -2.356_194_5, 4.712_389 / 719.0)] {
            let group = beams / 120;
            let ranges: Vec<f32> = (0..beams)
                .map(|i| {
                    let u: f32 = rng.random();
                    if u < 0.3 { f32::INFINITY } else { 0.3 + 2.5 * (i as f32 * 0.05).sin().abs() + 0.2 * u }
                })
                .collect();
            let centre = |k: usize| angle_min + (k * group) as f32 * inc + (group - 1) as f32 * 0.5 * inc;
            let mut pooled = vec![0.0; 120];
            min_pool(&ranges, &mut pooled);
            let pooled: Vec<f32> = pooled.iter().map(|r| r.clamp(0.15, 3.0)).collect();
            let want = free_travel_brute(&pooled, centre, 3.0, 0.25);
            let input = ObservationInputs { angle_increment: inc, ..inputs(&ranges, 1.0, 0.0) };
            b.write(&input, &mut out, || 0.0);
            for (j, (got, want)) in out.iter().zip(&want).enumerate() {
                assert!((got - want).abs() < 1e-4, "{beams} beams, bin {j}: {got} against {want}");
            }
            assert!(out.iter().any(|&t| t > 0.0 && t < 3.0));
        }

        // A return inside the disc: nowhere to go.
        ranges[100] = 0.2;
        b.write(&inputs(&ranges, 1.0, 0.0), &mut out, || 0.0);
        assert!(out.iter().all(|&t| t == 0.0));
    }

    #[test]
    fn sweep_reads_and_writes_as_yaml_and_is_checked() {
        let t: ObservationLayout =
            from_yaml_str("t.yaml", "- lidar: {beams: 120, clip: [0.15, 3.0], sweep: 0.25}").unwrap();
        assert_eq!(t.0, vec![ObsTerm::Lidar { beams: 120, clip: [0.15, 3.0], sweep: 0.25 }]);
        // A plain term writes no sweep, so contracts read by older builds stay readable.
        let plain = to_yaml_string(&ObsTerm::Lidar { beams: 120, clip: [0.15, 3.0], sweep: 0.0 });
        assert!(!plain.contains("sweep"), "{plain}");
        let bad = ObservationLayout(vec![ObsTerm::Lidar { beams: 120, clip: [0.15, 3.0], sweep: -0.1 }]);
        let err = bad.check().unwrap_err();
        assert_eq!(err.key, "observation[0].lidar.sweep");
        assert!(err.expected.contains("got -0.1"), "{}", err.expected);
    }

    /// Ranges of a 360-beam full turn from `pose` inside the rectangle `[0, 4] × [0, 3]`
    /// (every wall seen from everywhere inside), plus a post of radius 0.1 at (2.5, 1.2).
    fn room_scan(pose: &Pose2) -> Vec<f32> {
        room_scan_with(pose, Vec2::new(2.5, 1.2), 0.1)
    }

    /// [`room_scan`] with the post at `post`, of radius `radius`.
    fn room_scan_with(pose: &Pose2, post: Vec2, radius: f32) -> Vec<f32> {
        let spec = LidarSpec::default();
        (0..spec.beams)
            .map(|i| {
                let a = pose.yaw + spec.beam_angle(i);
                let (s, c) = a.sin_cos();
                let mut t = f32::INFINITY;
                for (wall, d, pos) in [(0.0, c, pose.x), (4.0, c, pose.x), (0.0, s, pose.y), (3.0, s, pose.y)] {
                    let hit = (wall - pos) / d;
                    if hit > 0.0 {
                        t = t.min(hit);
                    }
                }
                // The post: the ray's nearer crossing of the circle, if any.
                let (ox, oy) = (post.x - pose.x, post.y - pose.y);
                let along = ox * c + oy * s;
                let off2 = ox * ox + oy * oy - along * along;
                if along > 0.0 && off2 < radius * radius {
                    t = t.min(along - (radius * radius - off2).sqrt());
                }
                t
            })
            .collect()
    }

    /// Bin `k` of 120 of a 360-beam scan, min-pooled.
    fn b_pooled(ranges: &[f32], k: usize) -> f32 {
        ranges[3 * k..3 * k + 3].iter().copied().fold(f32::INFINITY, f32::min)
    }

    fn scan_inputs<'a>(ranges: &'a [f32], pose: Pose2) -> ObservationInputs<'a> {
        let spec = LidarSpec::default();
        ObservationInputs {
            angle_min: spec.angle_min,
            angle_increment: spec.angle_increment(),
            pose,
            ..inputs(ranges, 1.0, 0.0)
        }
    }

    /// Past scans moved into the current pose read what the current scan reads wherever the
    /// past scan saw the same surface (a room with a post, the robot driven 0.3 m and turned
    /// 0.5 rad), and a plain history does not.
    #[test]
    fn ego_motion_shows_still_obstacles_where_they_are_now() {
        let layout = |ego_motion, sweep| {
            ObservationLayout(vec![ObsTerm::History {
                term: Box::new(ObsTerm::Lidar { beams: 120, clip: [0.15, 3.0], sweep }),
                steps: 2,
                stride: 1,
                order: HistoryOrder::OldestFirst,
                fill: HistoryFill::First,
                ego_motion,
                predict: 0.0,
            }])
        };
        let then = Pose2::new(1.2, 1.0, 0.3);
        let now = Pose2::new(1.45, 1.15, 0.8);
        let (a, b) = (room_scan(&then), room_scan(&now));
        for sweep in [0.0, 0.25] {
            let mut moved = ObservationBuilder::new(&layout(true, sweep));
            let mut plain = ObservationBuilder::new(&layout(false, sweep));
            let (mut om, mut op) = (vec![0.0; 240], vec![0.0; 240]);
            for (builder, out) in [(&mut moved, &mut om), (&mut plain, &mut op)] {
                builder.write(&scan_inputs(&a, then), out, || 0.0);
                builder.commit();
                builder.write(&scan_inputs(&b, now), out, || 0.0);
            }
            // The current step is the plain term's in both.
            assert_eq!(om[120..], op[120..]);
            // Among the bins that see a surface within 2.5 m now (one the scan then reached
            // too), those that agree within 0.1 m: all but the wall the post hid then.
            let seen: Vec<usize> = (0..120).filter(|&k| b_pooled(&b, k) < 2.5).collect();
            let close = |past: &[f32]| seen.iter().filter(|&&k| (past[k] - om[120 + k]).abs() < 0.1).count();
            let (m, p) = (close(&om[..120]), close(&op[..120]));
            assert!(seen.len() > 80, "{}", seen.len());
            assert!(m + 2 >= seen.len(), "sweep {sweep}: {m} of {} moved bins agree with the current scan", seen.len());
            assert!(2 * p < seen.len(), "sweep {sweep}: {p} of {} unmoved bins agree", seen.len());
        }
    }

    /// A history with `predict` and its last slot.
    fn predicting(predict: f32, order: HistoryOrder) -> ObservationLayout {
        ObservationLayout(vec![ObsTerm::History {
            term: Box::new(ObsTerm::Lidar { beams: 120, clip: [0.15, 3.0], sweep: 0.0 }),
            steps: 2,
            stride: 1,
            order,
            fill: HistoryFill::First,
            ego_motion: true,
            predict,
        }])
    }

    /// A cart 0.2 m in radius crossing the room (0.4 m between the two scans) while the robot
    /// drives and turns: the predicted scan shows it 0.4 m further on, where a scan with the
    /// cart there reads it, and every bin away from the cart reads the current scan; with the
    /// cart standing still, the robot's own motion predicts nothing.
    #[test]
    fn a_predicted_scan_carries_a_moving_cart_on_and_keeps_walls_still() {
        let (then, now) = (Pose2::new(1.0, 1.5, 0.0), Pose2::new(1.25, 1.45, 0.2));
        let cart = [Vec2::new(2.8, 0.6), Vec2::new(2.8, 1.0), Vec2::new(2.8, 1.4)];
        let mut builder = ObservationBuilder::new(&predicting(1.0, HistoryOrder::OldestFirst));
        assert_eq!(builder.layout().len(), 360);
        let mut out = vec![0.0; 360];
        let (a, b) = (room_scan_with(&then, cart[0], 0.2), room_scan_with(&now, cart[1], 0.2));
        // The first step has no past to tell motion from: the prediction is the current scan.
        builder.write(&scan_inputs(&a, then), &mut out, || 0.0);
        assert_eq!(out[240..], out[120..240]);
        builder.commit();
        builder.write(&scan_inputs(&b, now), &mut out, || 0.0);
        let future = room_scan_with(&now, cart[2], 0.2);
        let (current, predicted) = (&out[120..240], &out[240..]);
        let pooled = |k: usize| b_pooled(&b, k).min(3.0);
        for (k, c) in current.iter().enumerate() {
            assert!((c - pooled(k)).abs() < 1e-6);
        }
        // The bins that see the cart now and where it will be (nearer than the empty room).
        let empty = room_scan_with(&now, Vec2::new(-10.0, -10.0), 0.1);
        let sees = |scan: &[f32]| -> Vec<usize> {
            (0..120).filter(|&k| b_pooled(scan, k) < b_pooled(&empty, k).min(3.0) - 0.05).collect()
        };
        let (cart_now, cart_then) = (sees(&b), sees(&future));
        assert!(cart_now.len() >= 3 && cart_then.len() >= 3, "{cart_now:?} {cart_then:?}");
        assert!(cart_then.iter().any(|k| !cart_now.contains(k)), "the cart moves to other bins");
        // All but an edge bin read the cart where it will be: its centre is estimated from the
        // side it shows, so its motion a little short.
        let hit = cart_then.iter().filter(|&&k| (predicted[k] - b_pooled(&future, k)).abs() < 0.1).count();
        assert!(hit + 1 >= cart_then.len(), "{hit} of {} bins read the cart where it will be", cart_then.len());
        // The bins it leaves (all but an edge bin, as above) are not read as blocked; the rest
        // read the current scan exactly.
        let left: Vec<usize> = cart_now.iter().copied().filter(|k| !cart_then.contains(k)).collect();
        let freed = left.iter().filter(|&&k| predicted[k] > current[k] + 0.1).count();
        assert!(!left.is_empty() && freed + 1 >= left.len(), "{freed} of the {} bins it leaves are free", left.len());
        for k in (0..120).filter(|k| !cart_now.contains(k) && !cart_then.contains(k)) {
            assert_eq!(predicted[k], current[k], "bin {k}");
        }
        // The cart standing still at its current place: nothing is predicted to move.
        let mut still = ObservationBuilder::new(&predicting(1.0, HistoryOrder::OldestFirst));
        still.write(&scan_inputs(&room_scan_with(&then, cart[1], 0.2), then), &mut out, || 0.0);
        still.commit();
        still.write(&scan_inputs(&b, now), &mut out, || 0.0);
        assert_eq!(out[240..], out[120..240]);
        // Newest first, the predicted scan goes first.
        let mut newest = ObservationBuilder::new(&predicting(1.0, HistoryOrder::NewestFirst));
        let mut other = vec![0.0; 360];
        newest.write(&scan_inputs(&a, then), &mut other, || 0.0);
        newest.commit();
        newest.write(&scan_inputs(&b, now), &mut other, || 0.0);
        builder.reset();
        builder.write(&scan_inputs(&a, then), &mut out, || 0.0);
        builder.commit();
        builder.write(&scan_inputs(&b, now), &mut out, || 0.0);
        assert_eq!(other[..120], out[240..]);
        assert_eq!(other[120..240], out[120..240]);
        assert_eq!(other[240..], out[..120]);
    }

    #[test]
    fn predict_reads_and_writes_as_yaml_and_is_checked() {
        let yaml = "- history: {term: {lidar: {beams: 120, clip: [0.15, 3.0]}}, steps: 3, stride: 3, order: oldest_first, ego_motion: true, predict: 2.0}";
        let t: ObservationLayout = from_yaml_str("t.yaml", yaml).unwrap();
        assert!(matches!(t.0[0], ObsTerm::History { predict: 2.0, .. }));
        assert_eq!(t.len(), 480);
        // The predicted scan mirrors as the scans do (a map of every value).
        let m = t.mirror(&LidarSpec::default()).unwrap();
        assert_eq!(m.source.len(), 480);
        assert_eq!(m.source[360..].iter().map(|i| i - 360).collect::<Vec<_>>(), m.source[..120]);
        assert!(t.0[0].describe().contains("predicted 2× the history's span ahead"), "{}", t.0[0].describe());
        let back: ObservationLayout = from_yaml_str("t.yaml", &to_yaml_string(&t)).unwrap();
        assert_eq!(back, t);
        // Without it nothing is written.
        assert!(!to_yaml_string(&predicting(0.0, HistoryOrder::OldestFirst)).contains("predict"));
        for (bad, why) in [
            (yaml.replace("ego_motion: true", "ego_motion: false"), "ego_motion: true"),
            (yaml.replace("steps: 3", "steps: 1"), "at least 2 steps"),
            (yaml.replace("predict: 2.0", "predict: -1.0"), "[0, 10]"),
            (yaml.replace("predict: 2.0", "predict: .nan"), "[0, 10]"),
        ] {
            match from_yaml_str::<ObservationLayout>("t.yaml", &bad) {
                Err(ConfigError::Invalid { key, expected, .. }) => {
                    assert_eq!(key, "observation[0].history.predict");
                    assert!(expected.contains(why), "{expected}");
                }
                other => panic!("{bad}: {other:?}"),
            }
        }
    }

    /// Moving a scan by a turn of whole bins is a shift of its bins; by no motion, nothing.
    #[test]
    fn a_scan_moved_by_a_turn_is_shifted() {
        let ranges: Vec<f32> = (0..120).map(|k| 0.5 + 0.02 * k as f32).collect();
        let full: Vec<f32> = vec![1.0; 360];
        let bins = ScanBins::of(&scan_inputs(&full, Pose2::default()), 120);
        let mut out = vec![0.0; 120];
        let mut table = MoveTable::with_capacity(120);
        move_scan(&ranges, &Pose2::default(), [0.15, 3.0], &bins, &mut table, &mut out);
        for (o, r) in out.iter().zip(&ranges) {
            assert!((o - r).abs() < 1e-4, "{o} against {r}");
        }
        // The scan then was taken facing 5 bins further left: its bin k is bin k + 5 now.
        move_scan(&ranges, &Pose2::new(0.0, 0.0, 5.0 * bins.width), [0.15, 3.0], &bins, &mut table, &mut out);
        for k in 0..120 {
            assert!((out[(k + 5) % 120] - ranges[k]).abs() < 1e-3, "bin {k}");
        }
        // A 270° scan: what turned out of view then reads nothing, the rest is shifted.
        let spec = LidarSpec { beams: 720, angle_min: -2.356_194_5, angle_max: 2.356_194_5, ..Default::default() };
        let scan = vec![1.0; 720];
        let partial = ObservationInputs {
            angle_min: spec.angle_min,
            angle_increment: spec.angle_increment(),
            ..inputs(&scan, 1.0, 0.0)
        };
        let bins = ScanBins::of(&partial, 120);
        assert!(!bins.full);
        move_scan(&ranges, &Pose2::new(0.0, 0.0, 5.0 * bins.width), [0.15, 3.0], &bins, &mut table, &mut out);
        assert!(out[..5].iter().all(|&r| r == 3.0), "{:?}", &out[..5]);
        for k in 0..115 {
            assert!((out[k + 5] - ranges[k]).abs() < 1e-3, "bin {k}");
        }
        // A pose that is not finite moves nothing anywhere (and does not panic).
        move_scan(&ranges, &Pose2::new(f32::NAN, 0.0, 0.0), [0.15, 3.0], &bins, &mut table, &mut out);
        assert!(out.iter().all(|&r| r == 3.0));
    }

    #[test]
    fn ego_motion_reads_and_writes_as_yaml_and_is_checked() {
        let yaml = "- history: {term: {lidar: {beams: 120, clip: [0.15, 3.0]}}, steps: 3, stride: 3, order: oldest_first, ego_motion: true}";
        let t: ObservationLayout = from_yaml_str("t.yaml", yaml).unwrap();
        assert!(matches!(t.0[0], ObsTerm::History { ego_motion: true, .. }));
        assert!(t.0[0].describe().contains("seen from the current pose"));
        // Without it nothing is written, so older contracts read the same.
        let plain = to_yaml_string(&history(ObsTerm::GoalDistance, 2, HistoryOrder::OldestFirst, HistoryFill::First));
        assert!(!plain.contains("ego_motion"), "{plain}");
        let bad = ObservationLayout(vec![ObsTerm::History {
            term: Box::new(ObsTerm::GoalBearing),
            steps: 2,
            stride: 1,
            order: HistoryOrder::OldestFirst,
            fill: HistoryFill::First,
            ego_motion: true,
            predict: 0.0,
        }]);
        let err = bad.check().unwrap_err();
        assert_eq!(err.key, "observation[0].history.ego_motion");
        assert!(err.expected.contains("goal_bearing"), "{}", err.expected);
    }
}
