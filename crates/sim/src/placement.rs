//! Start and goal placement on a fixed world, from lists of candidate cells made once per
//! scenario, so that drawing an episode never misses, however little of the map is free.
//!
//! A candidate is the centre of a reachability-grid cell (5 cm) that lies in known-free space
//! with the robot's clearance; candidates carry the connected region of the inflated free
//! space they belong to. Goals are grouped by region and bucketed into square blocks, so the
//! goals of a start's region within the start–goal distance are found by looking at the few
//! blocks the distance annulus touches. Only starts with at least one such goal are kept, so a
//! start is drawn uniformly among those, then a goal uniformly among its valid goals; when no
//! start has a valid goal the request is impossible and that is the (one) error.

use crate::geometry::{Rect, Vec2};
use rand::RngExt;

/// One candidate place for a start or a goal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Candidate {
    /// The cell's centre.
    pub position: Vec2,
    /// Connected region: a start and a goal are connected when their regions are equal.
    pub region: u32,
    /// Whether a start may be here (it has the start clearance).
    pub start: bool,
    /// Whether a goal may be here.
    pub goal: bool,
}

/// Why no start/goal pair can be drawn.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum NoPair {
    /// No candidate may hold a start.
    #[error("no known-free place with {clearance:.2} m clearance for a start")]
    NoStart {
        /// Clearance a start needs (m).
        clearance: f32,
    },
    /// No candidate may hold a goal.
    #[error("no known-free place with {clearance:.2} m clearance for a goal")]
    NoGoal {
        /// Clearance a goal needs (m).
        clearance: f32,
    },
    /// Starts and goals exist, but none of them are connected and the right distance apart.
    #[error(
        "no goal reachable from any start between {min} and {max} m away ({starts} possible starts, \
         {goals} possible goals in {regions} connected region(s); the largest region's goals span \
         {span_x:.1} x {span_y:.1} m)"
    )]
    NoneInRange {
        /// Smallest start–goal distance asked for (m).
        min: f32,
        /// Largest start–goal distance asked for (m).
        max: f32,
        /// Candidate starts.
        starts: usize,
        /// Candidate goals.
        goals: usize,
        /// Connected regions holding goals.
        regions: usize,
        /// Extent along x of the goals of the region with the most goals (m).
        span_x: f32,
        /// Extent along y of that region's goals (m).
        span_y: f32,
    },
}

/// The goals of one connected region, bucketed into square blocks.
#[derive(Clone, Debug)]
struct Region {
    /// The region's label.
    label: u32,
    /// Rectangle around the goals.
    bounds: Rect,
    /// Blocks along x and y; block `(0, 0)`'s lower-left corner is `bounds.min`.
    blocks: (usize, usize),
    /// Goals of block `(bx, by)`: `goals[offsets[i]..offsets[i + 1]]`, `i = by * blocks.0 + bx`.
    offsets: Vec<u32>,
    /// Goal positions, block by block.
    goals: Vec<Vec2>,
}

/// Start and goal candidates of a fixed world, ready to draw connected pairs the requested
/// distance apart. Building it costs one pass over the candidates and, per start, a look at
/// the blocks around it; drawing costs a look at the blocks of one start and allocates nothing.
#[derive(Clone, Debug)]
pub struct CellPlacement {
    /// Starts that have at least one valid goal, with the index of their region.
    starts: Vec<(Vec2, u32)>,
    regions: Vec<Region>,
    distance: [f32; 2],
    /// Side of a block (m).
    block: f32,
}

/// Distances closer than this to the range's ends are checked point by point, not by block.
const EDGE: f32 = 1e-3;

impl CellPlacement {
    /// Lists the candidates, keeping the starts that have a goal in their region between
    /// `distance[0]` and `distance[1]` metres away (straight line). `clearance` is
    /// `[start, goal]` clearance, for the error message only.
    pub fn new(
        candidates: impl IntoIterator<Item = Candidate>,
        distance: [f32; 2],
        clearance: [f32; 2],
    ) -> Result<Self, NoPair> {
        let mut start_cells = Vec::new();
        // Goals by region label, in candidate order (BTreeMap: a deterministic region order).
        let mut by_region: std::collections::BTreeMap<u32, Vec<Vec2>> = Default::default();
        for c in candidates {
            if c.start {
                start_cells.push((c.position, c.region));
            }
            if c.goal {
                by_region.entry(c.region).or_default().push(c.position);
            }
        }
        if start_cells.is_empty() {
            return Err(NoPair::NoStart { clearance: clearance[0] });
        }
        if by_region.is_empty() {
            return Err(NoPair::NoGoal { clearance: clearance[1] });
        }
        // A quarter of the largest distance: the annulus touches at most ~9 x 9 blocks.
        let block = (distance[1] / 4.0).max(0.25);
        let goals = by_region.values().map(Vec::len).sum();
        let regions: Vec<Region> = by_region.into_iter().map(|(label, g)| Region::new(label, g, block)).collect();
        let mut s = Self { starts: Vec::new(), regions, distance, block };
        for (p, label) in &start_cells {
            let Ok(r) = s.regions.binary_search_by_key(label, |r| r.label) else { continue };
            if s.for_each_goal(&s.regions[r], *p, |_| true) {
                s.starts.push((*p, r as u32));
            }
        }
        if s.starts.is_empty() {
            let largest = s.regions.iter().max_by_key(|r| r.goals.len()).map(|r| r.bounds.size()).unwrap_or_default();
            return Err(NoPair::NoneInRange {
                min: distance[0],
                max: distance[1],
                starts: start_cells.len(),
                goals,
                regions: s.regions.len(),
                span_x: largest.x,
                span_y: largest.y,
            });
        }
        Ok(s)
    }

    /// Draws a start uniformly among the starts that have a valid goal, then a goal uniformly
    /// among that start's valid goals.
    pub fn sample<R: rand::Rng>(&self, rng: &mut R) -> (Vec2, Vec2) {
        let (start, r) = self.starts[rng.random_range(0..self.starts.len())];
        let region = &self.regions[r as usize];
        let mut n = 0usize;
        self.for_each_goal(region, start, |_| {
            n += 1;
            false
        });
        // `n >= 1`: the start was kept because this same walk found a goal.
        let pick = rng.random_range(0..n.max(1));
        let (mut i, mut goal) = (0usize, start);
        self.for_each_goal(region, start, |g| {
            goal = g;
            i += 1;
            i > pick
        });
        (start, goal)
    }

    /// Number of starts that have at least one valid goal.
    pub fn start_count(&self) -> usize {
        self.starts.len()
    }

    /// Number of goal candidates.
    pub fn goal_count(&self) -> usize {
        self.regions.iter().map(|r| r.goals.len()).sum()
    }

    /// Number of connected regions that hold goals.
    pub fn region_count(&self) -> usize {
        self.regions.len()
    }

    /// Calls `f` on every goal of `region` within the distance range of `from`, in a fixed
    /// order, until `f` returns true; reports whether it did.
    fn for_each_goal(&self, region: &Region, from: Vec2, mut f: impl FnMut(Vec2) -> bool) -> bool {
        let [dmin, dmax] = self.distance;
        let (near, far) = rect_distances(region.bounds, from);
        if near > dmax || far < dmin {
            return false;
        }
        let (nx, ny) = region.blocks;
        let o = region.bounds.min;
        let span = |c: f32, lo: f32, n: usize| {
            let a = ((c - dmax - lo) / self.block).floor().max(0.0);
            let b = ((c + dmax - lo) / self.block).floor().min((n - 1) as f32);
            (a as usize, b as usize, a <= b)
        };
        let (x0, x1, some_x) = span(from.x, o.x, nx);
        let (y0, y1, some_y) = span(from.y, o.y, ny);
        if !(some_x && some_y) {
            return false;
        }
        for by in y0..=y1 {
            for bx in x0..=x1 {
                let i = by * nx + bx;
                let goals = &region.goals[region.offsets[i] as usize..region.offsets[i + 1] as usize];
                if goals.is_empty() {
                    continue;
                }
                let min = o + Vec2::new(bx as f32, by as f32) * self.block;
                let (near, far) = rect_distances(Rect { min, max: min + Vec2::splat(self.block) }, from);
                if near > dmax || far < dmin {
                    continue;
                }
                // Well inside the range: no need to measure each goal.
                let all_in = near >= dmin + EDGE && far <= dmax - EDGE;
                for g in goals {
                    let in_range = || {
                        let d = (*g - from).length();
                        d >= dmin && d <= dmax
                    };
                    if (all_in || in_range()) && f(*g) {
                        return true;
                    }
                }
            }
        }
        false
    }
}

impl Region {
    fn new(label: u32, goals: Vec<Vec2>, block: f32) -> Self {
        let min = goals.iter().fold(Vec2::splat(f32::INFINITY), |a, g| a.min(*g));
        let max = goals.iter().fold(Vec2::splat(f32::NEG_INFINITY), |a, g| a.max(*g));
        let bounds = Rect { min, max };
        let count = |d: f32| (d / block).floor() as usize + 1;
        let blocks = (count(max.x - min.x), count(max.y - min.y));
        let index = |g: &Vec2| {
            let bx = (((g.x - min.x) / block).floor() as usize).min(blocks.0 - 1);
            let by = (((g.y - min.y) / block).floor() as usize).min(blocks.1 - 1);
            by * blocks.0 + bx
        };
        // Counting sort by block, stable: candidate order within a block.
        let mut offsets = vec![0u32; blocks.0 * blocks.1 + 1];
        for g in &goals {
            offsets[index(g) + 1] += 1;
        }
        for i in 1..offsets.len() {
            offsets[i] += offsets[i - 1];
        }
        let mut next = offsets.clone();
        let mut sorted = vec![Vec2::ZERO; goals.len()];
        for g in &goals {
            let i = index(g);
            sorted[next[i] as usize] = *g;
            next[i] += 1;
        }
        Self { label, bounds, blocks, offsets, goals: sorted }
    }
}

/// Nearest and farthest distance from `p` to the points of `r`.
fn rect_distances(r: Rect, p: Vec2) -> (f32, f32) {
    let near = (r.min - p).max(p - r.max).max(Vec2::ZERO).length();
    let far = (p - r.min).abs().max((r.max - p).abs()).length();
    (near, far)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// Cells of a `w x h` lattice at `step`, in regions by `region(ix, iy)` (0: none).
    fn lattice(w: usize, h: usize, step: f32, region: impl Fn(usize, usize) -> u32) -> Vec<Candidate> {
        let mut v = Vec::new();
        for iy in 0..h {
            for ix in 0..w {
                let r = region(ix, iy);
                if r != 0 {
                    let position = Vec2::new(ix as f32 * step, iy as f32 * step);
                    v.push(Candidate { position, region: r, start: true, goal: true });
                }
            }
        }
        v
    }

    #[test]
    fn pairs_are_in_range_and_in_one_region_and_every_valid_pair_can_come_up() {
        // Two 1 x 1 m regions side by side (x < 1 and x >= 2), 0.1 m cells.
        let cells = lattice(30, 10, 0.1, |ix, _| match ix {
            0..10 => 1,
            20.. => 2,
            _ => 0,
        });
        let p = CellPlacement::new(cells.clone(), [0.75, 0.9], [0.3, 0.2]).unwrap();
        assert_eq!((p.goal_count(), p.region_count()), (200, 2));
        // A start near the middle of its 0.9 x 0.9 m square is within 0.75 m of all of it.
        let expected = cells
            .iter()
            .filter(|s| {
                cells.iter().any(|g| {
                    let d = (g.position - s.position).length();
                    g.region == s.region && (0.75..=0.9).contains(&d)
                })
            })
            .count();
        assert_eq!(p.start_count(), expected);
        assert!(expected < 200, "the middles of the squares have no goal 0.75 m away");
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(3);
        let mut seen = std::collections::HashSet::new();
        for _ in 0..20_000 {
            let (s, g) = p.sample(&mut rng);
            let d = (g - s).length();
            assert!((0.75..=0.9).contains(&d), "{s:?} {g:?} {d}");
            assert_eq!(s.x < 1.5, g.x < 1.5, "same region");
            seen.insert((s.x.to_bits(), s.y.to_bits()));
        }
        assert_eq!(seen.len(), expected, "every start with a goal is drawn");
        // Deterministic for a seed.
        let draw = |seed| {
            let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
            (0..10).map(|_| p.sample(&mut rng)).collect::<Vec<_>>()
        };
        assert_eq!(draw(7), draw(7));
        assert_ne!(draw(7), draw(8));
    }

    #[test]
    fn impossible_requests_say_why() {
        let cells = lattice(10, 10, 0.1, |_, _| 1);
        let e = CellPlacement::new(cells.clone(), [5.0, 6.0], [0.3, 0.2]).unwrap_err();
        assert!(matches!(e, NoPair::NoneInRange { starts: 100, goals: 100, regions: 1, .. }), "{e:?}");
        let text = e.to_string();
        assert!(text.contains("between 5 and 6 m") && text.contains("0.9 x 0.9 m"), "{text}");
        let no_start = cells.iter().map(|c| Candidate { start: false, ..*c });
        assert_eq!(
            CellPlacement::new(no_start, [0.0, 1.0], [0.3, 0.2]).unwrap_err(),
            NoPair::NoStart { clearance: 0.3 }
        );
        let no_goal = cells.iter().map(|c| Candidate { goal: false, ..*c });
        assert!(CellPlacement::new(no_goal, [0.0, 1.0], [0.3, 0.2]).unwrap_err().to_string().contains("for a goal"));
        // Starts in one region, goals only in another.
        let split = lattice(30, 10, 0.1, |ix, _| if ix < 10 { 1 } else { 2 }).into_iter().map(|c| Candidate {
            start: c.region == 1,
            goal: c.region == 2,
            ..c
        });
        assert!(matches!(CellPlacement::new(split, [0.0, 5.0], [0.3, 0.2]), Err(NoPair::NoneInRange { .. })));
    }
}
