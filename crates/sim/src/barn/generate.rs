//! New BARN-like worlds, made the way the dataset's 300 were (Perille et al. 2020,
//! `jackal-map-creation/gen_world_ca.py`): a 30 x 30 cellular automaton (random fill, the
//! first and last rows walls, then smoothing: a cell with five or more occupied neighbours
//! fills, one with one or none clears), kept only when the Jackal's configuration space joins
//! the largest open region touching the entry column to the largest touching the exit column;
//! a reference path through it, and the five difficulty metrics along that path. The
//! dataset's own 300 worlds used fill 0.15–0.30 and 2–4 smoothing passes.
//!
//! The worlds are for training: the shipped and imported BARN worlds stay apart for testing.

use super::difficulty::{BarnGrid, Difficulty, GRID_SIZE, ROBOT_CELLS};
use super::import::{cylinders_of, reference_path_length};
use crate::config::{Invalid, Validate, check_count, check_interval};
use rand::RngExt;
use serde::{Deserialize, Serialize};
use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// How new BARN-like worlds are drawn.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CellularSpec {
    /// Initial fill probability `[min, max]` (default the dataset's [0.15, 0.30]).
    pub fill: [f32; 2],
    /// Smoothing passes `[min, max]` (default the dataset's [2, 4]).
    pub smoothing: [u32; 2],
}

impl Default for CellularSpec {
    fn default() -> Self {
        Self { fill: [0.15, 0.30], smoothing: [2, 4] }
    }
}

/// Above this fill the automaton almost never leaves a way through for the Jackal.
const MAX_FILL: f32 = 0.4;
/// Draws before [`draw_world`] gives up on a spec (a connected world comes within a few at
/// the dataset's fills).
const MAX_DRAWS: usize = 1000;

impl Validate for CellularSpec {
    fn validate(&self) -> Result<(), Invalid> {
        check_interval("fill", self.fill, 0.0, MAX_FILL)?;
        check_count("smoothing", self.smoothing, 20)
    }
}

impl CellularSpec {
    /// The spec at difficulty `d` in [0, 1]: the fill's upper end brought down towards its
    /// lower end (sparser clutter).
    pub fn at_difficulty(&self, d: f32) -> Self {
        let d = d.clamp(0.0, 1.0);
        Self { fill: [self.fill[0], self.fill[0] + d * (self.fill[1] - self.fill[0])], ..self.clone() }
    }
}

/// One drawn world.
#[derive(Clone, Debug)]
pub struct GeneratedWorld {
    /// The obstacle grid.
    pub grid: BarnGrid,
    /// Cylinder centres, as the dataset's world writer places them (containment walls too).
    pub cylinders: Vec<[f32; 2]>,
    /// The reference path through the configuration space (cells, `[row, col]`).
    pub path: Vec<[i64; 2]>,
    /// Its length from the challenge's start to its goal (m), as `reference_path_length`.
    pub path_length: f32,
    /// The five metrics along the path.
    pub difficulty: Difficulty,
    /// The fill and smoothing it was drawn with.
    pub fill: f32,
    /// Smoothing passes.
    pub smoothing: u32,
}

/// The automaton's grid: random fill at `fill`, rows 0 and 29 occupied, then `smoothing`
/// passes, each from a copy of the previous grid. Beyond the top and bottom rows counts as
/// occupied, beyond the first and last columns as free (the dataset's rule).
pub fn cellular_grid<R: rand::Rng>(rng: &mut R, fill: f32, smoothing: u32) -> BarnGrid {
    let n = GRID_SIZE as i64;
    let mut g = BarnGrid::new(GRID_SIZE, GRID_SIZE);
    for r in 0..GRID_SIZE {
        for c in 0..GRID_SIZE {
            let wall = r == 0 || r == GRID_SIZE - 1;
            g.set(r, c, wall || rng.random_range(0.0..1.0f32) < fill);
        }
    }
    for _ in 0..smoothing {
        let old = g.clone();
        for r in 0..n {
            for c in 0..n {
                let mut neighbours = 0;
                for i in r - 1..=r + 1 {
                    for j in c - 1..=c + 1 {
                        if (i, j) != (r, c) && (old.occupied(i, j) || i < 0 || i >= n) {
                            neighbours += 1;
                        }
                    }
                }
                if neighbours >= 5 {
                    g.set(r as usize, c as usize, true);
                } else if neighbours <= 1 {
                    g.set(r as usize, c as usize, false);
                }
            }
        }
    }
    g
}

/// Labels of the 4-connected free regions (`u32::MAX` on blocked cells) and each region's
/// size, labelled once per grid: the generator throws most grids away, so this check is the
/// hot loop.
fn regions(cspace: &BarnGrid) -> (Vec<u32>, Vec<usize>) {
    let (rows, cols) = (cspace.rows(), cspace.cols());
    let mut label = vec![u32::MAX; rows * cols];
    let mut sizes = Vec::new();
    let mut stack = Vec::new();
    for start in 0..rows * cols {
        if label[start] != u32::MAX || cspace.occupied((start / cols) as i64, (start % cols) as i64) {
            continue;
        }
        let id = sizes.len() as u32;
        let mut size = 0;
        label[start] = id;
        stack.push(start);
        while let Some(k) = stack.pop() {
            size += 1;
            let (i, j) = ((k / cols) as i64, (k % cols) as i64);
            for (a, b) in [(i, j + 1), (i + 1, j), (i, j - 1), (i - 1, j)] {
                let inside = a >= 0 && b >= 0 && (a as usize) < rows && (b as usize) < cols;
                if inside && !cspace.occupied(a, b) && label[a as usize * cols + b as usize] == u32::MAX {
                    label[a as usize * cols + b as usize] = id;
                    stack.push(a as usize * cols + b as usize);
                }
            }
        }
        sizes.push(size);
    }
    (label, sizes)
}

/// The largest region touching column `col` (the dataset's `biggest_left_region`).
fn biggest_region(label: &[u32], sizes: &[usize], col: usize) -> Option<u32> {
    (0..GRID_SIZE).map(|r| label[r * GRID_SIZE + col]).filter(|&l| l != u32::MAX).max_by_key(|&l| sizes[l as usize])
}

/// A cell on the open list, cheapest first.
#[derive(PartialEq)]
struct Open(f64, usize);
impl Eq for Open {}
impl Ord for Open {
    fn cmp(&self, o: &Self) -> Ordering {
        o.0.total_cmp(&self.0).then(o.1.cmp(&self.1))
    }
}
impl PartialOrd for Open {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}

/// The cheapest 8-connected path from `from` to `to` through free configuration-space cells
/// (no corner cutting between two blocked cells), each step costing its length plus the
/// dataset's penalty near walls: 5 / d for a cell d <= 2 cells (its 0.3 m inflation) from the
/// nearest blocked cell. `None` when there is none.
fn cheapest_path(cspace: &BarnGrid, from: [i64; 2], to: [i64; 2]) -> Option<Vec<[i64; 2]>> {
    let (rows, cols) = (cspace.rows(), cspace.cols());
    let blocked: Vec<[i64; 2]> = (0..rows as i64)
        .flat_map(|r| (0..cols as i64).map(move |c| [r, c]))
        .filter(|p| cspace.occupied(p[0], p[1]))
        .collect();
    let penalty = |r: i64, c: i64| {
        let d = blocked.iter().map(|b| ((b[0] - r) as f64).hypot((b[1] - c) as f64)).fold(f64::INFINITY, f64::min);
        if d <= 2.0 { 5.0 / d } else { 0.0 }
    };
    let idx = |p: [i64; 2]| p[0] as usize * cols + p[1] as usize;
    let mut cost = vec![f64::INFINITY; rows * cols];
    let mut parent = vec![usize::MAX; rows * cols];
    let mut open = BinaryHeap::new();
    cost[idx(from)] = 0.0;
    open.push(Open(0.0, idx(from)));
    while let Some(Open(g, k)) = open.pop() {
        if g > cost[k] {
            continue;
        }
        let (r, c) = ((k / cols) as i64, (k % cols) as i64);
        if [r, c] == to {
            let mut path = vec![to];
            let mut k = k;
            while parent[k] != usize::MAX {
                k = parent[k];
                path.push([(k / cols) as i64, (k % cols) as i64]);
            }
            path.reverse();
            return Some(path);
        }
        for dr in -1..=1i64 {
            for dc in -1..=1i64 {
                let (a, b) = (r + dr, c + dc);
                let inside = a >= 0 && b >= 0 && (a as usize) < rows && (b as usize) < cols;
                if (dr, dc) == (0, 0) || !inside || cspace.occupied(a, b) {
                    continue;
                }
                if dr != 0 && dc != 0 && cspace.occupied(r + dr, c) && cspace.occupied(r, c + dc) {
                    continue;
                }
                let next = g + ((dr * dr + dc * dc) as f64).sqrt() + penalty(a, b);
                let j = idx([a, b]);
                if next < cost[j] {
                    cost[j] = next;
                    parent[j] = k;
                    open.push(Open(next, j));
                }
            }
        }
    }
    None
}

/// One draw at `fill` and `smoothing`: the world when the Jackal can get through it, with a
/// reference path between a random open cell of the entry column and one of the exit column
/// (both in the largest regions there, as the dataset picks them).
pub fn try_world<R: rand::Rng>(rng: &mut R, fill: f32, smoothing: u32) -> Option<GeneratedWorld> {
    let grid = cellular_grid(rng, fill, smoothing);
    let cspace = grid.c_space(ROBOT_CELLS);
    let last = GRID_SIZE - 1;
    let (label, sizes) = regions(&cspace);
    let region = biggest_region(&label, &sizes, 0)?;
    // Left and right regions joined are one region.
    if biggest_region(&label, &sizes, last)? != region {
        return None;
    }
    let rows_open =
        |col: usize| -> Vec<usize> { (0..GRID_SIZE).filter(|&r| label[r * GRID_SIZE + col] == region).collect() };
    let (l, r) = (rows_open(0), rows_open(last));
    let from = [l[rng.random_range(0..l.len())] as i64, 0];
    let to = [r[rng.random_range(0..r.len())] as i64, last as i64];
    let path = cheapest_path(&cspace, from, to)?;
    let difficulty = Difficulty::measure(&cspace, &path)?;
    Some(GeneratedWorld {
        cylinders: cylinders_of(&grid),
        path_length: reference_path_length(&path),
        grid,
        path,
        difficulty,
        fill,
        smoothing,
    })
}

/// A world drawn with `spec` (fill and smoothing drawn anew for every try); `None` only when
/// [`MAX_DRAWS`] draws all leave no way through.
pub fn draw_world<R: rand::Rng>(rng: &mut R, spec: &CellularSpec) -> Option<GeneratedWorld> {
    (0..MAX_DRAWS).find_map(|_| {
        let fill = rng.random_range(spec.fill[0]..=spec.fill[1]);
        let smoothing = rng.random_range(spec.smoothing[0]..=spec.smoothing[1]);
        try_world(rng, fill, smoothing)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn smoothing_fills_crowded_cells_and_clears_lonely_ones() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(1);
        // No fill: the walls alone; smoothing grows no blob in the open middle.
        let g = cellular_grid(&mut rng, 0.0, 4);
        for c in 0..GRID_SIZE as i64 {
            assert!(g.occupied(0, c) && g.occupied(29, c));
            assert!((2..28).all(|r| !g.occupied(r, c)), "column {c}");
        }
        // Full fill stays full.
        let g = cellular_grid(&mut rng, 1.0, 4);
        assert!((0..30).all(|r| (0..30).all(|c| g.occupied(r, c))));
    }

    #[test]
    fn a_drawn_world_has_a_path_the_jackal_fits_through() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
        for _ in 0..20 {
            let w = draw_world(&mut rng, &CellularSpec::default()).expect("a world at the dataset's fills");
            let cspace = w.grid.c_space(ROBOT_CELLS);
            assert_eq!(w.path.first().unwrap()[1], 0);
            assert_eq!(w.path.last().unwrap()[1], 29);
            for p in &w.path {
                assert!(!cspace.occupied(p[0], p[1]), "{p:?} blocked");
            }
            for s in w.path.windows(2) {
                assert!((s[0][0] - s[1][0]).abs() <= 1 && (s[0][1] - s[1][1]).abs() <= 1);
            }
            assert!(w.difficulty.tortuosity >= 1.0 && w.path_length >= 10.0);
        }
    }
}
