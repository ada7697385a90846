//! Which places a robot can drive between: an occupancy grid inflated by the robot's
//! clearance radius, labelled into connected components (4-connected, run-based union-find).
//! Built once per world; after that "can the robot get from A to B" is two look-ups.

use crate::geometry::{Obstacle, Rect, Vec2};
use crate::world::World;
use std::ops::Range;

/// Square cells over an area, row by row from its lower left corner: what the free space and
/// the clearance field are measured on.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Raster {
    origin: Vec2,
    resolution: f32,
    width: usize,
    height: usize,
}

impl Raster {
    fn new(area: Rect, resolution: f32) -> Self {
        let size = area.size();
        let width = ((size.x / resolution).ceil() as usize).max(1);
        let height = ((size.y / resolution).ceil() as usize).max(1);
        Self { origin: area.min, resolution, width, height }
    }

    fn len(&self) -> usize {
        self.width * self.height
    }

    /// Centre of cell `i` (row-major).
    fn centre(&self, i: usize) -> Vec2 {
        let (ix, iy) = (i % self.width, i / self.width);
        self.origin + Vec2::new((ix as f32 + 0.5) * self.resolution, (iy as f32 + 0.5) * self.resolution)
    }

    /// The cell holding `p`, a point inside the area.
    fn index(&self, p: Vec2) -> usize {
        let q = (p - self.origin) / self.resolution;
        (q.y as usize) * self.width + q.x as usize
    }

    /// The columns and rows of the cells within `margin` of `o`'s bounding box (a wall's
    /// bounding circle would cover the whole room): the only cells `o` can matter to.
    fn near(&self, o: &Obstacle, margin: f32) -> (Range<usize>, Range<usize>) {
        let aabb = o.shape.compute_aabb(&o.pose);
        let (bmin, bmax) = (Vec2::new(aabb.mins.x, aabb.mins.y), Vec2::new(aabb.maxs.x, aabb.maxs.y));
        let lo = ((bmin - Vec2::splat(margin) - self.origin) / self.resolution).floor();
        let hi = ((bmax + Vec2::splat(margin) - self.origin) / self.resolution).ceil();
        (
            lo.x.max(0.0) as usize..(hi.x.max(0.0) as usize).min(self.width),
            lo.y.max(0.0) as usize..(hi.y.max(0.0) as usize).min(self.height),
        )
    }
}

/// Connected free space of a world for a disc-shaped robot.
#[derive(Clone, Debug)]
pub struct ReachabilityGrid {
    raster: Raster,
    /// 0: blocked; otherwise the component label.
    labels: Vec<u32>,
}

impl ReachabilityGrid {
    /// Rasterises `area` of `world` at `resolution`, marking a cell free when its centre is at
    /// least `radius` plus half a cell from every obstacle, then labels components.
    ///
    /// Half a cell is exactly what 4-connected moves need: every point of the segment between
    /// two neighbouring centres lies within half a cell of one of them, so a path of free
    /// cells keeps `radius` all the way. (Half a cell *diagonal* was used before; on the
    /// TurtleBot3 world map its extra centimetre cut the 0.35 m-clearance free space between
    /// the pillars into islands about a metre across.)
    pub fn new(world: &World, area: Rect, radius: f32, resolution: f32) -> Self {
        let raster = Raster::new(area, resolution);
        let mut blocked = vec![false; raster.len()];
        let inflation = radius + 0.5 * resolution;
        // Obstacle-major: only the cells near each obstacle are tested against it.
        for o in world.obstacles() {
            let (xs, ys) = raster.near(o, inflation);
            for iy in ys {
                for i in xs.clone().map(|ix| iy * raster.width + ix) {
                    if !blocked[i] && o.primitive.signed_distance(raster.centre(i)) < inflation {
                        blocked[i] = true;
                    }
                }
            }
        }
        if let Some(grid) = world.grid() {
            for (i, cell) in blocked.iter_mut().enumerate() {
                if !*cell && !grid.is_clear(raster.centre(i), inflation) {
                    *cell = true;
                }
            }
        }
        let labels = label_components(&blocked, raster.width, raster.height);
        Self { raster, labels }
    }

    /// Component label of the cell containing `p` (0 if blocked or outside).
    pub fn label(&self, p: Vec2) -> u32 {
        let q = (p - self.raster.origin) / self.raster.resolution;
        if q.x < 0.0 || q.y < 0.0 {
            return 0;
        }
        let (ix, iy) = (q.x as usize, q.y as usize);
        if ix >= self.raster.width || iy >= self.raster.height {
            return 0;
        }
        self.labels[iy * self.raster.width + ix]
    }

    /// Whether a robot can drive from `a` to `b` keeping its clearance.
    pub fn connected(&self, a: Vec2, b: Vec2) -> bool {
        let la = self.label(a);
        la != 0 && la == self.label(b)
    }

    /// Cell size (m).
    pub fn resolution(&self) -> f32 {
        self.raster.resolution
    }

    /// Every cell's centre and component label (0: blocked), row by row from the lower left.
    pub fn cells(&self) -> impl Iterator<Item = (Vec2, u32)> + '_ {
        self.labels.iter().enumerate().map(move |(i, l)| (self.raster.centre(i), *l))
    }

    /// Length of the shortest path from `a` to `b` that keeps the robot's clearance (m), or
    /// `None` when they are not connected: Theta* (A* whose nodes may take any node in line of
    /// sight as parent) over the free cells, so that the length is close to the any-angle
    /// shortest path rather than a grid staircase (what SPL compares a driven path with).
    pub fn shortest_path_length(&self, a: Vec2, b: Vec2) -> Option<f32> {
        self.shortest_path(a, b).map(|p| crate::plan::path_length(&p))
    }

    /// The cells a path can step to from cell `c` on the 8-connected grid, each with whether
    /// the step is diagonal (no diagonal squeezes past a blocked corner).
    fn neighbours(&self, c: usize) -> impl Iterator<Item = (usize, bool)> + '_ {
        let w = self.raster.width;
        let (x, y) = ((c % w) as i64, (c / w) as i64);
        [(1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1)].into_iter().filter_map(
            move |(dx, dy)| {
                let (nx, ny) = (x + dx, y + dy);
                let diagonal = dx != 0 && dy != 0;
                let ok = self.free(nx, ny) && (!diagonal || (self.free(nx, y) && self.free(x, ny)));
                ok.then_some((ny as usize * w + nx as usize, diagonal))
            },
        )
    }

    /// Whether cell `(x, y)` is inside the grid and free.
    fn free(&self, x: i64, y: i64) -> bool {
        x >= 0 && y >= 0 && (x as usize) < self.raster.width && (y as usize) < self.raster.height && {
            self.labels[y as usize * self.raster.width + x as usize] != 0
        }
    }

    /// Whether the segment `p`–`q` crosses free cells only: every cell it touches, walked
    /// cell by cell (Amanatides–Woo); where it passes exactly through a corner, both cells
    /// beside the corner must be free too.
    fn sight(&self, p: Vec2, q: Vec2) -> bool {
        self.walk(p, q, |_, _| {})
    }

    /// Walks the cells the segment `p`–`q` touches (as [`Self::sight`] describes), calling
    /// `visit(cell, fraction)` with the fraction of the segment inside each; false (and the
    /// walk stops) at the first cell that is blocked.
    fn walk(&self, p: Vec2, q: Vec2, mut visit: impl FnMut(usize, f32)) -> bool {
        let (p, q) =
            ((p - self.raster.origin) / self.raster.resolution, (q - self.raster.origin) / self.raster.resolution);
        let (mut x, mut y) = (p.x.floor() as i64, p.y.floor() as i64);
        let (qx, qy) = (q.x.floor() as i64, q.y.floor() as i64);
        if !self.free(x, y) {
            return false;
        }
        let d = q - p;
        let (sx, sy) = (if d.x > 0.0 { 1 } else { -1 }, if d.y > 0.0 { 1 } else { -1 });
        let (tdx, tdy) = (1.0 / d.x.abs(), 1.0 / d.y.abs());
        let mut tx = if d.x > 0.0 { (x as f32 + 1.0 - p.x) * tdx } else { (p.x - x as f32) * tdx };
        let mut ty = if d.y > 0.0 { (y as f32 + 1.0 - p.y) * tdy } else { (p.y - y as f32) * tdy };
        if d.x == 0.0 {
            tx = f32::INFINITY;
        }
        if d.y == 0.0 {
            ty = f32::INFINITY;
        }
        let cell = |x: i64, y: i64| y as usize * self.raster.width + x as usize;
        let mut entered = 0.0f32;
        // Rounding can make the walk miss the last cell by one step: it is bounded instead.
        for _ in 0..(qx - x).abs() + (qy - y).abs() {
            if (x, y) == (qx, qy) {
                break;
            }
            let left = tx.min(ty).min(1.0);
            visit(cell(x, y), left - entered);
            entered = left;
            if tx < ty {
                x += sx;
                tx += tdx;
            } else if ty < tx {
                y += sy;
                ty += tdy;
            } else {
                if !self.free(x + sx, y) || !self.free(x, y + sy) {
                    return false;
                }
                x += sx;
                y += sy;
                tx += tdx;
                ty += tdy;
            }
            if !self.free(x, y) {
                return false;
            }
        }
        visit(cell(x, y), (1.0 - entered).max(0.0));
        true
    }

    /// The shortest path of [`Self::shortest_path_length`]: its corners, from `a` to `b`.
    ///
    /// Lazy Theta* (Nash, Koenig and Tovey 2010): a node takes its parent's parent when it
    /// is generated and the line of sight is checked once, when the node is expanded, rather
    /// than for each of its eight neighbours (an episode's plan is made at every reset).
    pub fn shortest_path(&self, a: Vec2, b: Vec2) -> Option<Vec<Vec2>> {
        if !self.connected(a, b) {
            return None;
        }
        let (src, dst) = (self.raster.index(a), self.raster.index(b));
        // The exact start and goal stand for their cells; other nodes are cell centres.
        let point = |i: usize| match i {
            _ if i == src => a,
            _ if i == dst => b,
            _ => self.raster.centre(i),
        };
        let neighbours = |c: usize| self.neighbours(c).map(|(n, _)| n);
        let mut g = vec![f32::INFINITY; self.labels.len()];
        let mut parent = vec![usize::MAX; self.labels.len()];
        let mut closed = vec![false; self.labels.len()];
        let mut open = std::collections::BinaryHeap::new();
        // Non-negative f32s order as their bit patterns.
        let key = |f: f32| std::cmp::Reverse(f.to_bits());
        g[src] = 0.0;
        parent[src] = src;
        open.push((key((b - a).length()), src));
        while let Some((_, c)) = open.pop() {
            if std::mem::replace(&mut closed[c], true) {
                continue;
            }
            // The parent was assumed in sight: if it is not, take the best expanded neighbour.
            let pc = parent[c];
            if pc != c && !self.sight(point(pc), point(c)) {
                let (best, cost) = neighbours(c)
                    .filter(|n| closed[*n] && *n != c)
                    .map(|n| (n, g[n] + (point(c) - point(n)).length()))
                    .min_by(|x, y| x.1.total_cmp(&y.1))
                    .expect("a node is generated by an expanded neighbour");
                parent[c] = best;
                g[c] = cost;
            }
            if c == dst {
                let mut path = vec![b];
                let mut k = dst;
                while k != src {
                    k = parent[k];
                    path.push(point(k));
                }
                path.reverse();
                return Some(path);
            }
            let from = parent[c];
            for n in neighbours(c) {
                if closed[n] {
                    continue;
                }
                let cost = g[from] + (point(n) - point(from)).length();
                if cost < g[n] {
                    g[n] = cost;
                    parent[n] = from;
                    open.push((key(cost + (b - point(n)).length()), n));
                }
            }
        }
        None
    }

    /// The cheapest path from `a` to `b` when a metre near an obstacle costs more than a metre
    /// in the open, the way Nav2's planners read the costmap's inflation layer (and the DWA
    /// baseline's A* does): `cost` gives the price of a metre at each distance `field` holds.
    /// Such a path runs down the middle of a corridor or a door and swings wide round a wall's
    /// end where the room allows, and still squeezes through where it must, so that a
    /// controller that steers a lookahead ahead along it is not led onto the wall.
    ///
    /// A* over the 8-connected free cells, then string pulling: a run of cells is replaced by
    /// the straight segment between its ends where that segment is free and costs no more
    /// (otherwise the grid's 45-degree staircase would be the plan). `None` when `a` and `b`
    /// are not connected; `field` must cover the grid's area at its resolution.
    pub fn cheapest_path(
        &self,
        field: &ClearanceField,
        cost: &crate::plan::PlanCost,
        a: Vec2,
        b: Vec2,
    ) -> Option<Vec<Vec2>> {
        if !self.connected(a, b) {
            return None;
        }
        assert_eq!(field.raster, self.raster, "a clearance field measured on another raster");
        let (w, res) = (self.raster.width, self.raster.resolution);
        let (src, dst) = (self.raster.index(a), self.raster.index(b));
        // Price per metre in each cell.
        let prices: Vec<f32> = field.distance.iter().map(|d| cost.per_metre(*d)).collect();
        let price = |i: usize| prices[i];
        let mut g = vec![f32::INFINITY; self.labels.len()];
        let mut parent = vec![usize::MAX; self.labels.len()];
        let mut open = std::collections::BinaryHeap::new();
        let key = |f: f32| std::cmp::Reverse(f.to_bits());
        // Octile distance in metres: no 8-connected path is shorter, and no metre costs less
        // than one, so A* stays optimal.
        let (bx, by) = ((dst % w) as i64, (dst / w) as i64);
        let heuristic = |i: usize| {
            let (dx, dy) = ((((i % w) as i64) - bx).abs() as f32, (((i / w) as i64) - by).abs() as f32);
            (dx.max(dy) + (std::f32::consts::SQRT_2 - 1.0) * dx.min(dy)) * res
        };
        g[src] = 0.0;
        open.push((key(heuristic(src)), src));
        let mut found = false;
        while let Some((std::cmp::Reverse(f), c)) = open.pop() {
            if f32::from_bits(f) > g[c] + heuristic(c) {
                continue;
            }
            if c == dst {
                found = true;
                break;
            }
            let pc = price(c);
            for (n, diagonal) in self.neighbours(c) {
                let len = if diagonal { std::f32::consts::SQRT_2 } else { 1.0 } * res;
                let cand = g[c] + len * 0.5 * (pc + price(n));
                if cand < g[n] {
                    g[n] = cand;
                    parent[n] = c;
                    open.push((key(cand + heuristic(n)), n));
                }
            }
        }
        if !found {
            return None;
        }
        let mut cells = vec![dst];
        while *cells.last().expect("not empty") != src {
            cells.push(parent[*cells.last().expect("not empty")]);
        }
        cells.reverse();
        // The exact start and goal stand for their cells.
        let mut points: Vec<Vec2> = cells.iter().map(|&i| self.raster.centre(i)).collect();
        points[0] = a;
        *points.last_mut().expect("not empty") = b;
        // What the grid path costs from its start to each point (the first and last steps
        // re-priced for the exact start and goal).
        let mut spent = vec![0.0f32; points.len()];
        for k in 1..points.len() {
            let step = (points[k] - points[k - 1]).length() * 0.5 * (price(cells[k - 1]) + price(cells[k]));
            spent[k] = spent[k - 1] + step;
        }
        let line_cost = |p: Vec2, q: Vec2| {
            let len = (q - p).length();
            let mut total = 0.0;
            self.walk(p, q, |i, frac| total += frac * len * price(i)).then_some(total)
        };
        // Greedy string pulling: from each kept point, reach as far along as a cheaper-or-equal
        // free segment goes.
        let mut path = vec![a];
        let mut anchor = 0;
        let mut k = 1;
        while k < points.len() {
            let ok = |j: usize| {
                line_cost(points[anchor], points[j]).is_some_and(|c| c <= (spent[j] - spent[anchor]) * 1.0001 + 1e-6)
            };
            if k + 1 < points.len() && ok(k + 1) {
                k += 1;
                continue;
            }
            path.push(points[k]);
            anchor = k;
            k += 1;
        }
        Some(path)
    }

    /// Fraction of cells that are free.
    pub fn free_fraction(&self) -> f32 {
        self.labels.iter().filter(|l| **l != 0).count() as f32 / self.labels.len() as f32
    }
}

/// Distance (m) from every cell centre of a raster to the nearest obstacle, up to a cap: what
/// a planner's inflation cost is read from ([`ReachabilityGrid::cheapest_path`]). The raster
/// is a [`ReachabilityGrid`]'s for the same area and resolution.
#[derive(Clone, Debug)]
pub struct ClearanceField {
    raster: Raster,
    distance: Vec<f32>,
}

impl ClearanceField {
    /// Measures `area` of `world` at `resolution`, exactly from each obstacle's shape (and from
    /// the map's blocked cells where the world has a map), each distance capped at `cap`.
    pub fn new(world: &World, area: Rect, resolution: f32, cap: f32) -> Self {
        let raster = Raster::new(area, resolution);
        let mut distance = vec![cap; raster.len()];
        for o in world.obstacles() {
            let (xs, ys) = raster.near(o, cap);
            for iy in ys {
                for i in xs.clone().map(|ix| iy * raster.width + ix) {
                    distance[i] = distance[i].min(o.primitive.signed_distance(raster.centre(i)).max(0.0));
                }
            }
        }
        if let Some(grid) = world.grid() {
            for (i, d) in distance.iter_mut().enumerate() {
                if !grid.is_clear(raster.centre(i), *d) {
                    *d = d.min(grid.clearance(raster.centre(i)));
                }
            }
        }
        Self { raster, distance }
    }
}

/// 4-connected component labels of the free cells (0: blocked), numbered in the row-major
/// order of each component's first cell. Run-based: each row's runs of free cells are
/// joined (union-find) with the overlapping runs of the row below, then runs are filled with
/// their component's label; on a room at 5 cm this does a fraction of a per-cell search's
/// work, and a procedural world is labelled at every reset.
fn label_components(blocked: &[bool], width: usize, height: usize) -> Vec<u32> {
    // Runs `[start, end)` of free cells, row by row.
    let mut runs: Vec<(usize, usize)> = Vec::new();
    let mut row_start = Vec::with_capacity(height + 1);
    for y in 0..height {
        row_start.push(runs.len());
        let row = &blocked[y * width..(y + 1) * width];
        let mut x = 0;
        while x < width {
            if row[x] {
                x += 1;
                continue;
            }
            let start = x;
            while x < width && !row[x] {
                x += 1;
            }
            runs.push((y * width + start, y * width + x));
        }
    }
    row_start.push(runs.len());
    let mut parent: Vec<usize> = (0..runs.len()).collect();
    fn find(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    for y in 1..height {
        let (below, here) = (row_start[y - 1]..row_start[y], row_start[y]..row_start[y + 1]);
        let mut j = below.start;
        for i in here {
            let (s, e) = (runs[i].0 - y * width, runs[i].1 - y * width);
            // Runs of the row below that share a column with this one (both lists are sorted).
            while j < below.end && runs[j].1 - (y - 1) * width <= s {
                j += 1;
            }
            let mut k = j;
            while k < below.end && runs[k].0 - (y - 1) * width < e {
                let (a, b) = (find(&mut parent, i), find(&mut parent, k));
                // The root stays the earlier run: components keep their first cell's order.
                if a != b {
                    parent[a.max(b)] = a.min(b);
                }
                k += 1;
            }
        }
    }
    let mut labels = vec![0u32; width * height];
    let mut label_of = vec![0u32; runs.len()];
    let mut next = 0u32;
    for (i, &(s, e)) in runs.iter().enumerate() {
        let root = find(&mut parent, i);
        if label_of[root] == 0 {
            next += 1;
            label_of[root] = next;
        }
        labels[s..e].fill(label_of[root]);
    }
    labels
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Obstacle, ObstacleSpec};

    fn walls(w: f32, extra: Vec<ObstacleSpec>) -> World {
        let h = w / 2.0;
        let mut v = vec![
            ObstacleSpec::Wall { from: [-h, -h], to: [h, -h] },
            ObstacleSpec::Wall { from: [h, -h], to: [h, h] },
            ObstacleSpec::Wall { from: [h, h], to: [-h, h] },
            ObstacleSpec::Wall { from: [-h, h], to: [-h, -h] },
        ];
        v.extend(extra);
        World::new(v.into_iter().map(|s| Obstacle::new(s).unwrap()).collect())
    }

    /// The labels a per-cell breadth-first search gives, numbered as components are first met.
    fn bfs_labels(blocked: &[bool], width: usize) -> Vec<u32> {
        let mut labels = vec![0u32; blocked.len()];
        let mut next = 0;
        for seed in 0..blocked.len() {
            if blocked[seed] || labels[seed] != 0 {
                continue;
            }
            next += 1;
            labels[seed] = next;
            let mut queue = std::collections::VecDeque::from([seed]);
            while let Some(c) = queue.pop_front() {
                let (x, y) = (c % width, c / width);
                let mut near = vec![];
                if x > 0 {
                    near.push(c - 1);
                }
                if x + 1 < width {
                    near.push(c + 1);
                }
                if y > 0 {
                    near.push(c - width);
                }
                if c + width < blocked.len() {
                    near.push(c + width);
                }
                for n in near {
                    if !blocked[n] && labels[n] == 0 {
                        labels[n] = next;
                        queue.push_back(n);
                    }
                }
            }
        }
        labels
    }

    #[test]
    fn run_labels_are_the_breadth_first_labels() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(9);
        for k in 0..300 {
            let (w, h) = (rng.random_range(1..40), rng.random_range(1..40));
            // Sparse to dense, so that components merge in every way (U shapes, spirals).
            let p = [0.1, 0.3, 0.45, 0.6][k % 4];
            let blocked: Vec<bool> = (0..w * h).map(|_| rng.random_bool(p)).collect();
            assert_eq!(label_components(&blocked, w, h), bfs_labels(&blocked, w), "{w}x{h} p {p}");
        }
        // A spiral: one component met again and again from below.
        let (w, h) = (9, 9);
        let art = [
            "........#",
            "#######.#",
            "#.....#.#",
            "#.###.#.#",
            "#.#.#.#.#",
            "#.#...#.#",
            "#.#####.#",
            "#.......#",
            "#########",
        ];
        let blocked: Vec<bool> = art.iter().rev().flat_map(|r| r.chars().map(|c| c == '#')).collect();
        assert_eq!(label_components(&blocked, w, h), bfs_labels(&blocked, w));
    }

    #[test]
    fn a_dividing_wall_with_a_gap() {
        let area = Rect { min: Vec2::splat(-2.0), max: Vec2::splat(2.0) };
        // Wall across the room with a 0.6 m gap at the top.
        let w = walls(4.0, vec![ObstacleSpec::Wall { from: [0.0, -2.0], to: [0.0, 1.4] }]);
        let g = ReachabilityGrid::new(&w, area, 0.2, 0.05);
        let (a, b) = (Vec2::new(-1.0, 0.0), Vec2::new(1.0, 0.0));
        assert!(g.connected(a, b), "0.6 m gap lets a 0.2 m-radius robot through");
        // Free: two halves of about 1.7 x 3.5 m of a 4 x 4 m grid.
        assert!((0.6..0.8).contains(&g.free_fraction()), "{}", g.free_fraction());
        let g = ReachabilityGrid::new(&w, area, 0.35, 0.05);
        assert!(!g.connected(a, b), "too narrow for 0.35 m");
        assert_eq!(g.label(Vec2::new(0.0, 0.0)), 0, "on the wall");
        assert_eq!(g.label(Vec2::new(5.0, 0.0)), 0, "outside");
    }

    /// Least distance from the polyline to the world's obstacles, sampled every centimetre.
    fn closest_approach(world: &World, path: &[Vec2]) -> f32 {
        path.windows(2)
            .flat_map(|s| {
                let n = ((s[1] - s[0]).length() / 0.01).ceil().max(1.0) as usize;
                (0..=n).map(move |k| s[0] + (s[1] - s[0]) * (k as f32 / n as f32))
            })
            .map(|p| world.clearance(p))
            .fold(f32::INFINITY, f32::min)
    }

    fn cheapest(world: &World, area: Rect, clearance: f32, a: Vec2, b: Vec2) -> Option<Vec<Vec2>> {
        let cost = crate::plan::PlanCost::nav2_like(clearance);
        let g = ReachabilityGrid::new(world, area, clearance, 0.05);
        let field = ClearanceField::new(world, area, 0.05, cost.reach());
        g.cheapest_path(&field, &cost, a, b)
    }

    #[test]
    fn clearance_field_holds_each_cells_distance_up_to_its_cap() {
        let area = Rect { min: Vec2::splat(-2.0), max: Vec2::splat(2.0) };
        let w = walls(
            4.0,
            vec![
                ObstacleSpec::Circle { center: [0.5, 0.3], radius: 0.2 },
                ObstacleSpec::Wall { from: [-1.0, -2.0], to: [-1.0, 0.5] },
            ],
        );
        let f = ClearanceField::new(&w, area, 0.05, 0.6);
        assert_eq!((f.raster.width, f.raster.height), (80, 80));
        for (i, d) in f.distance.iter().enumerate() {
            let c = area.min + Vec2::new(((i % 80) as f32 + 0.5) * 0.05, ((i / 80) as f32 + 0.5) * 0.05);
            let want = w.clearance(c).clamp(0.0, 0.6);
            assert!((d - want).abs() < 1e-4, "cell {i} at {c:?}: {d} vs {want}");
        }
    }

    #[test]
    fn cheapest_path_is_straight_in_the_open_and_keeps_off_walls_where_the_room_allows() {
        let area = Rect { min: Vec2::splat(-3.0), max: Vec2::splat(3.0) };
        let (a, b) = (Vec2::new(-2.0, -1.0), Vec2::new(2.0, 0.4));
        // Open room: one segment, not the 8-connected grid's staircase.
        let open = walls(6.0, vec![]);
        let p = cheapest(&open, area, 0.25, a, b).unwrap();
        assert_eq!(p, vec![a, b]);
        // An L corridor 1.2 m wide round an inner block: the shortest path hugs the block's
        // corner at the bare clearance, the cheapest one keeps to the middle.
        let l = walls(
            6.0,
            vec![
                ObstacleSpec::Wall { from: [-3.0, -1.8], to: [1.8, -1.8] },
                ObstacleSpec::Wall { from: [1.8, -1.8], to: [1.8, 3.0] },
            ],
        );
        let (a, b) = (Vec2::new(-2.4, -2.4), Vec2::new(2.4, 2.2));
        let shortest = ReachabilityGrid::new(&l, area, 0.25, 0.05).shortest_path(a, b).unwrap();
        let p = cheapest(&l, area, 0.25, a, b).unwrap();
        let (hug, keep) = (closest_approach(&l, &shortest), closest_approach(&l, &p));
        assert!(hug < 0.32, "the shortest path passes {hug} m from the walls");
        assert!(keep > 0.5, "the cheapest path passes {keep} m from the walls");
        assert_eq!((p[0], *p.last().unwrap()), (a, b));
        assert!(crate::plan::path_length(&p) < crate::plan::path_length(&shortest) + 1.0);
        // A 0.7 m door: too tight for any berth, so the path squeezes through its middle.
        let door = walls(
            6.0,
            vec![
                ObstacleSpec::Wall { from: [0.0, -3.0], to: [0.0, 0.35] },
                ObstacleSpec::Wall { from: [0.0, 1.05], to: [0.0, 3.0] },
            ],
        );
        let (a, b) = (Vec2::new(-2.0, -2.0), Vec2::new(2.0, -2.0));
        let p = cheapest(&door, area, 0.25, a, b).unwrap();
        let through = closest_approach(&door, &p);
        assert!(through > 0.32, "through the door {through} m from its jambs (the middle, 0.35 m, within half a cell)");
        // Cut off entirely: none.
        let shut = walls(6.0, vec![ObstacleSpec::Wall { from: [0.0, -3.0], to: [0.0, 3.0] }]);
        assert_eq!(cheapest(&shut, area, 0.25, a, b), None);
    }

    #[test]
    fn shortest_path_goes_round_a_wall_taut() {
        let area = Rect { min: Vec2::splat(-2.0), max: Vec2::splat(2.0) };
        let (a, b) = (Vec2::new(-1.0, 0.0), Vec2::new(1.0, 0.0));
        // Open room: the straight line, not a grid staircase.
        let g = ReachabilityGrid::new(&walls(4.0, vec![]), area, 0.2, 0.05);
        let l = g.shortest_path_length(a, b + Vec2::new(0.0, 0.7)).unwrap();
        assert!((l - 2.0f32.hypot(0.7)).abs() < 0.03, "{l}");
        // A wall from the floor to y = 1.0 at x = 0: round its end, which the free cells keep
        // r = 0.2 m + half a cell away: two tangents to that disc and the arc between them.
        let w = walls(4.0, vec![ObstacleSpec::Wall { from: [0.0, -2.0], to: [0.0, 1.0] }]);
        let g = ReachabilityGrid::new(&w, area, 0.2, 0.05);
        let l = g.shortest_path_length(a, b).unwrap();
        let (r, d) = (0.225f32, 2.0f32.sqrt());
        let arc = 1.5 * std::f32::consts::PI - 2.0 * (r / d).acos();
        let ideal = 2.0 * (d * d - r * r).sqrt() + r * arc;
        // Lines of sight need their samples in free cells: up to a few centimetres wider.
        assert!(l >= ideal - 0.01 && l < ideal + 0.12, "{l} vs {ideal}");
        // Cut off entirely: none.
        let w = walls(4.0, vec![ObstacleSpec::Wall { from: [0.0, -2.0], to: [0.0, 2.0] }]);
        let g = ReachabilityGrid::new(&w, area, 0.2, 0.05);
        assert_eq!(g.shortest_path_length(a, b), None);
    }

    /// On random cluttered rooms every plan is made of segments in sight of each other (so it
    /// keeps the clearance all along), starts and ends at the given points, and exists exactly
    /// when the two are connected.
    #[test]
    fn plans_in_clutter_keep_to_free_cells() {
        use rand::{RngExt, SeedableRng};
        let area = Rect { min: Vec2::splat(-3.0), max: Vec2::splat(3.0) };
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(5);
        let (mut found, mut none) = (0, 0);
        for k in 0..40 {
            let mut extra: Vec<ObstacleSpec> = (0..12)
                .map(|_| ObstacleSpec::Circle {
                    center: [rng.random_range(-2.8..2.8), rng.random_range(-2.8..2.8)],
                    radius: rng.random_range(0.1..0.6),
                })
                .collect();
            if k % 4 == 0 {
                extra.push(ObstacleSpec::Wall { from: [0.0, -3.0], to: [0.0, 3.0] });
            }
            let g = ReachabilityGrid::new(&walls(6.0, extra), area, 0.15, 0.05);
            let pick = |rng: &mut rand_pcg::Pcg64Mcg| loop {
                let p = Vec2::new(rng.random_range(-2.8..2.8), rng.random_range(-2.8..2.8));
                if g.label(p) != 0 {
                    return p;
                }
            };
            let (a, b) = (pick(&mut rng), pick(&mut rng));
            match g.shortest_path(a, b) {
                Some(path) => {
                    found += 1;
                    assert!(g.connected(a, b));
                    assert_eq!((path[0], *path.last().unwrap()), (a, b));
                    for s in path.windows(2) {
                        assert!(g.sight(s[0], s[1]), "segment {:?} -> {:?} leaves the free cells", s[0], s[1]);
                    }
                    assert!(crate::plan::path_length(&path) >= (b - a).length() - 1e-4);
                }
                None => {
                    none += 1;
                    assert!(!g.connected(a, b));
                }
            }
        }
        assert!(found > 20 && none > 0, "both cases drawn: {found} found, {none} not connected");
    }
}
