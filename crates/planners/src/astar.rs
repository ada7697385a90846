//! A* on the costmap: 8-connected, each step costing its length times `1 + cost_weight *
//! cost / 252`, cells at or above [`INSCRIBED`] impassable (Nav2's planners' semantics). A
//! start or goal in an impassable cell is moved to the nearest passable one.

use crate::costmap::{Costmap, INSCRIBED};
use rlnav_sim::Vec2;
use std::cmp::Ordering;
use std::collections::BinaryHeap;

#[derive(PartialEq)]
struct Open {
    f: f32,
    k: usize,
}

impl Eq for Open {}

impl Ord for Open {
    fn cmp(&self, other: &Self) -> Ordering {
        other.f.total_cmp(&self.f).then(other.k.cmp(&self.k))
    }
}

impl PartialOrd for Open {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

/// The nearest passable cell to `(x, y)` within `radius` cells.
fn nearest_free(map: &Costmap, x: usize, y: usize, radius: usize) -> Option<(usize, usize)> {
    let (w, h) = map.size();
    let mut best: Option<((usize, usize), usize)> = None;
    for dy in -(radius as i64)..=radius as i64 {
        for dx in -(radius as i64)..=radius as i64 {
            let (nx, ny) = (x as i64 + dx, y as i64 + dy);
            if nx < 0 || ny < 0 || nx >= w as i64 || ny >= h as i64 {
                continue;
            }
            let d = (dx * dx + dy * dy) as usize;
            if map.cost(nx as usize, ny as usize) < INSCRIBED && best.is_none_or(|b| d < b.1) {
                best = Some(((nx as usize, ny as usize), d));
            }
        }
    }
    best.map(|b| b.0)
}

/// The cheapest path from `start` to `goal` as cell centres (start first), or `None`.
pub fn plan(map: &Costmap, start: Vec2, goal: Vec2, cost_weight: f32) -> Option<Vec<Vec2>> {
    let (w, h) = map.size();
    let snap = |p: Vec2| {
        let (x, y) = map.cell_of(p)?;
        if map.cost(x, y) < INSCRIBED { Some((x, y)) } else { nearest_free(map, x, y, 10) }
    };
    let (s, g) = (snap(start)?, snap(goal)?);
    let idx = |x: usize, y: usize| y * w + x;
    let octile = |x: usize, y: usize| {
        let (dx, dy) = ((x as f32 - g.0 as f32).abs(), (y as f32 - g.1 as f32).abs());
        dx.max(dy) + (std::f32::consts::SQRT_2 - 1.0) * dx.min(dy)
    };
    let mut cost = vec![f32::INFINITY; w * h];
    let mut parent = vec![usize::MAX; w * h];
    let mut heap = BinaryHeap::new();
    cost[idx(s.0, s.1)] = 0.0;
    heap.push(Open { f: octile(s.0, s.1), k: idx(s.0, s.1) });
    let goal_k = idx(g.0, g.1);
    while let Some(Open { f, k }) = heap.pop() {
        if k == goal_k {
            break;
        }
        let (x, y) = (k % w, k / w);
        if f - octile(x, y) > cost[k] + 1e-4 {
            continue; // stale entry
        }
        for (dx, dy) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1), (-1, -1), (1, -1), (-1, 1), (1, 1)] {
            let (nx, ny) = (x as i64 + dx, y as i64 + dy);
            if nx < 0 || ny < 0 || nx >= w as i64 || ny >= h as i64 {
                continue;
            }
            let (nx, ny) = (nx as usize, ny as usize);
            let c = map.cost(nx, ny);
            if c >= INSCRIBED {
                continue;
            }
            let len = if dx != 0 && dy != 0 { std::f32::consts::SQRT_2 } else { 1.0 };
            let step = len * (1.0 + cost_weight * c as f32 / 252.0);
            let nk = idx(nx, ny);
            if cost[k] + step < cost[nk] {
                cost[nk] = cost[k] + step;
                parent[nk] = k;
                heap.push(Open { f: cost[nk] + octile(nx, ny), k: nk });
            }
        }
    }
    if !cost[goal_k].is_finite() {
        return None;
    }
    let mut path = vec![goal_k];
    let mut k = goal_k;
    while parent[k] != usize::MAX {
        k = parent[k];
        path.push(k);
    }
    path.reverse();
    Some(path.into_iter().map(|k| map.center(k % w, k / w)).collect())
}
