//! The BARN dataset's grid and its five difficulty metrics (Perille et al., "Benchmarking
//! Metric Ground Navigation", SSRR 2020), computed as the dataset's generator computes them:
//! on the Jackal's configuration space (the obstacle grid grown by two cells each way) and
//! averaged over the cells of the reference path.
//!
//! A BARN world is a 30 x 30 grid of 0.15 m cells. Row `r` runs along world x and column `c`
//! along world y (the robot drives from column 0 to column 29); an occupied cell is a
//! cylinder of radius 0.075 m at its centre. Rows 0 and 29 are always occupied (the side
//! walls), and the world files leave out the cylinders of cells whose eight neighbours are all
//! occupied (nobody sees them).

use serde::{Deserialize, Serialize};

/// Rows and columns of a BARN grid.
pub const GRID_SIZE: usize = 30;
/// Side of a cell, the diameter of a cylinder (m).
pub const CELL: f32 = 0.15;
/// World x of row 0's cell centres (m).
pub const ROW0_X: f32 = -4.425;
/// World y of column 0's cell centres (m).
pub const COL0_Y: f32 = 5.175;
/// Cells the Jackal takes up on each side of its centre cell (the dataset's `jackal_radius`).
pub const ROBOT_CELLS: usize = 2;
/// Radius of the dispersion metric (cells).
pub const DISPERSION_RADIUS: usize = 3;

/// An occupancy grid in BARN's (row, column) order.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BarnGrid {
    rows: usize,
    cols: usize,
    cells: Vec<bool>,
}

impl BarnGrid {
    /// An empty grid.
    pub fn new(rows: usize, cols: usize) -> Self {
        Self { rows, cols, cells: vec![false; rows * cols] }
    }

    /// Rows.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Columns.
    pub fn cols(&self) -> usize {
        self.cols
    }

    /// Whether `(r, c)` is occupied; outside the grid is free (the dataset's rays stop at the
    /// edge without meeting a wall).
    pub fn occupied(&self, r: i64, c: i64) -> bool {
        self.inside(r, c) && self.cells[r as usize * self.cols + c as usize]
    }

    /// Marks `(r, c)` occupied or free.
    pub fn set(&mut self, r: usize, c: usize, occupied: bool) {
        self.cells[r * self.cols + c] = occupied;
    }

    fn inside(&self, r: i64, c: i64) -> bool {
        r >= 0 && c >= 0 && (r as usize) < self.rows && (c as usize) < self.cols
    }

    /// The cells a robot's centre cannot take: every cell within `radius` cells (a square) of
    /// an occupied one.
    pub fn c_space(&self, radius: usize) -> Self {
        // A square's maximum is a row pass then a column pass (the generator calls this for
        // every grid it draws).
        let k = radius as i64;
        let mut rows_done = Self::new(self.rows, self.cols);
        for r in 0..self.rows as i64 {
            for c in 0..self.cols as i64 {
                rows_done.set(r as usize, c as usize, (c - k..=c + k).any(|j| self.occupied(r, j)));
            }
        }
        let mut out = Self::new(self.rows, self.cols);
        for r in 0..self.rows as i64 {
            for c in 0..self.cols as i64 {
                out.set(r as usize, c as usize, (r - k..=r + k).any(|i| rows_done.occupied(i, c)));
            }
        }
        out
    }

    /// Whether `(r, c)` and its eight neighbours are all occupied and inside the grid: the
    /// dataset's world files leave such cells' cylinders out.
    pub fn surrounded(&self, r: usize, c: usize) -> bool {
        let (r, c) = (r as i64, c as i64);
        (r - 1..=r + 1).all(|i| (c - 1..=c + 1).all(|j| self.occupied(i, j)))
    }

    /// World position of a cell's centre (where its cylinder stands).
    pub fn cell_center(r: usize, c: usize) -> [f32; 2] {
        [ROW0_X + r as f32 * CELL, COL0_Y + c as f32 * CELL]
    }

    /// The cell whose centre is within a tenth of a cell of `p`, if any.
    pub fn cell_at(p: [f32; 2]) -> Option<(usize, usize)> {
        let fr = (p[0] - ROW0_X) / CELL;
        let fc = (p[1] - COL0_Y) / CELL;
        let (r, c) = (fr.round(), fc.round());
        let on_centre = (fr - r).abs() < 0.1 && (fc - c).abs() < 0.1;
        let inside = r >= 0.0 && c >= 0.0 && (r as usize) < GRID_SIZE && (c as usize) < GRID_SIZE;
        (on_centre && inside).then_some((r as usize, c as usize))
    }
}

/// The five metrics of one world, averaged over its reference path (cells; tortuosity is a
/// ratio). Higher closest-wall distance, visibility and characteristic dimension mean an
/// easier world; higher dispersion and tortuosity a harder one.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Difficulty {
    /// Distance from the path to the closest occupied configuration-space cell.
    pub closest_wall: f32,
    /// Mean free run along the eight compass directions.
    pub average_visibility: f32,
    /// Free/blocked alternations among 16 rays of 3 cells (how many gaps surround a cell).
    pub dispersion: f32,
    /// Narrowest free width along the four axes through a cell.
    pub characteristic_dimension: f32,
    /// Path length over the straight line between its ends.
    pub tortuosity: f32,
}

impl Difficulty {
    /// Column names, in the dataset's order (and `metrics_N.npy`'s).
    pub const NAMES: [&'static str; 5] =
        ["closest_wall", "average_visibility", "dispersion", "characteristic_dimension", "tortuosity"];

    /// The values in [`Self::NAMES`]' order.
    pub fn values(&self) -> [f32; 5] {
        [self.closest_wall, self.average_visibility, self.dispersion, self.characteristic_dimension, self.tortuosity]
    }

    /// The metrics of a path (cells, `[row, col]`) through a configuration-space grid. `None`
    /// for a path of fewer than two cells or whose ends coincide.
    pub fn measure(cspace: &BarnGrid, path: &[[i64; 2]]) -> Option<Self> {
        let (first, last) = (path.first()?, path.last()?);
        let chord = dist(*first, *last);
        if path.len() < 2 || chord == 0.0 {
            return None;
        }
        let arc: f64 = path.windows(2).map(|w| dist(w[0], w[1])).sum();
        let mean = |f: &dyn Fn(i64, i64) -> f64| path.iter().map(|p| f(p[0], p[1])).sum::<f64>() / path.len() as f64;
        Some(Self {
            closest_wall: mean(&|r, c| closest_wall(cspace, r, c)) as f32,
            average_visibility: mean(&|r, c| average_visibility(cspace, r, c)) as f32,
            dispersion: mean(&|r, c| dispersion(cspace, r, c, DISPERSION_RADIUS)) as f32,
            characteristic_dimension: mean(&|r, c| characteristic_dimension(cspace, r, c)) as f32,
            tortuosity: (arc / chord) as f32,
        })
    }
}

fn dist(a: [i64; 2], b: [i64; 2]) -> f64 {
    ((a[0] - b[0]) as f64).hypot((a[1] - b[1]) as f64)
}

/// Euclidean distance (cells) to the nearest occupied cell; half the grid's rows when there
/// is none (as the dataset's search gives up).
fn closest_wall(g: &BarnGrid, r: i64, c: i64) -> f64 {
    let mut best = f64::INFINITY;
    for i in 0..g.rows as i64 {
        for j in 0..g.cols as i64 {
            if g.occupied(i, j) {
                best = best.min(dist([r, c], [i, j]));
            }
        }
    }
    if best.is_finite() { best } else { (g.rows as f64 - 1.0) / 2.0 }
}

/// Mean over the eight compass directions of the free run from `(r, c)` (the cell itself
/// included) to the first occupied cell or the grid's edge, each step counted by its length.
fn average_visibility(g: &BarnGrid, r: i64, c: i64) -> f64 {
    let mut total = 0.0;
    for dr in -1..=1i64 {
        for dc in -1..=1i64 {
            if dr == 0 && dc == 0 {
                continue;
            }
            let step = ((dr * dr + dc * dc) as f64).sqrt();
            let (mut i, mut j) = (r, c);
            while g.inside(i, j) && !g.occupied(i, j) {
                total += step;
                i += dr;
                j += dc;
            }
        }
    }
    total / 8.0
}

/// The 16 ray directions of the dispersion metric, in turning order: the compass points and,
/// between each pair, a ray of slope 1/2 or 2.
const DISPERSION_RAYS: [(i64, i64); 16] = [
    (0, 1),
    (1, 2),
    (1, 1),
    (2, 1),
    (1, 0),
    (2, -1),
    (1, -1),
    (1, -2),
    (0, -1),
    (-2, -1),
    (-1, -1),
    (-1, -2),
    (-1, 0),
    (-2, 1),
    (-1, 1),
    (-1, 2),
];

/// How many times the 16 rays of `radius` steps from `(r, c)` alternate between meeting an
/// occupied cell and not (round the circle); -1 on an occupied cell.
fn dispersion(g: &BarnGrid, r: i64, c: i64, radius: usize) -> f64 {
    if g.occupied(r, c) {
        return -1.0;
    }
    let hits: Vec<bool> = DISPERSION_RAYS
        .iter()
        .map(|&(dr, dc)| {
            // The dataset counts a slope ray as two steps a cell only where a component is +2
            // (its generator tests `== 2`); the others step one at a time. Kept, so that the
            // figures are the dataset's.
            let cost = if dr == 2 || dc == 2 { 2 } else { 1 };
            let (mut i, mut j, mut count) = (r, c, 0);
            while count < radius {
                i += dr;
                j += dc;
                if !g.inside(i, j) {
                    return false;
                }
                if g.occupied(i, j) {
                    return true;
                }
                count += cost;
            }
            false
        })
        .collect();
    (0..hits.len()).filter(|&k| hits[k] != hits[(k + 1) % hits.len()]).count() as f64
}

/// The narrowest of the four axes (two diagonals included) through `(r, c)`: free cells on
/// both sides up to the first occupied cell or the edge, the cell itself not counted, each
/// step by its length; -1 on an occupied cell.
fn characteristic_dimension(g: &BarnGrid, r: i64, c: i64) -> f64 {
    if g.occupied(r, c) {
        return -1.0;
    }
    [(0i64, 1i64), (1, 1), (1, 0), (1, -1)]
        .iter()
        .map(|&(dr, dc)| {
            let step = ((dr * dr + dc * dc) as f64).sqrt();
            let mut width = 0.0;
            for s in [1, -1] {
                let (mut i, mut j) = (r + s * dr, c + s * dc);
                while g.inside(i, j) && !g.occupied(i, j) {
                    width += step;
                    i += s * dr;
                    j += s * dc;
                }
            }
            width
        })
        .fold(f64::INFINITY, f64::min)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A corridor along the columns, rows 0 and `n - 1` walls, free in between.
    fn corridor(n: usize) -> BarnGrid {
        let mut g = BarnGrid::new(n, n);
        for c in 0..n {
            g.set(0, c, true);
            g.set(n - 1, c, true);
        }
        g
    }

    #[test]
    fn a_straight_path_down_an_open_corridor() {
        // 15 rows: walls at 0 and 14, free rows 1..=13; the path runs along row 7.
        let g = corridor(15);
        let path: Vec<[i64; 2]> = (0..15).map(|c| [7, c]).collect();
        let d = Difficulty::measure(&g, &path).unwrap();
        assert_eq!(d.closest_wall, 7.0);
        assert_eq!(d.tortuosity, 1.0);
        // Across the corridor: 6 free cells each side; the diagonals are shorter still.
        assert!(d.characteristic_dimension <= 12.0 && d.characteristic_dimension > 0.0);
        // Rays of at most 6 cells from row 7 never reach rows 0 or 14: nothing alternates.
        assert_eq!(d.dispersion, 0.0);
        assert!(d.average_visibility > 0.0);
    }

    #[test]
    fn dispersion_counts_the_gaps_round_a_cell() {
        // A wall cell right of (4, 4): the rays towards it hit, the others do not: two
        // alternations (into the blocked arc and out of it).
        let mut g = BarnGrid::new(9, 9);
        g.set(4, 6, true);
        assert_eq!(dispersion(&g, 4, 4, 3), 2.0);
        g.set(4, 2, true);
        assert_eq!(dispersion(&g, 4, 4, 3), 4.0);
        assert_eq!(dispersion(&g, 4, 6, 3), -1.0);
    }

    #[test]
    fn configuration_space_grows_each_obstacle_by_the_robot() {
        let mut g = BarnGrid::new(10, 10);
        g.set(5, 5, true);
        let cs = g.c_space(2);
        assert!(cs.occupied(3, 3) && cs.occupied(7, 7) && !cs.occupied(2, 5) && !cs.occupied(5, 8));
        assert!(!g.surrounded(5, 5));
        let mut full = BarnGrid::new(3, 3);
        (0..3).for_each(|r| (0..3).for_each(|c| full.set(r, c, true)));
        assert!(full.surrounded(1, 1) && !full.surrounded(0, 0), "an edge cell keeps its cylinder");
    }

    #[test]
    fn cells_and_world_positions_round_trip() {
        assert_eq!(BarnGrid::cell_center(0, 0), [ROW0_X, COL0_Y]);
        assert_eq!(BarnGrid::cell_at(BarnGrid::cell_center(29, 29)), Some((29, 29)));
        assert_eq!(BarnGrid::cell_at([-0.075, 0.075]), None, "a containment-wall cylinder");
        assert_eq!(BarnGrid::cell_at([ROW0_X + 0.07, COL0_Y]), None, "off centre");
    }
}
