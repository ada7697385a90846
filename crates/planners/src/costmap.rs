//! A layered 2D costmap in Nav2's conventions: cell costs 0 (free) to 252 (inflated), 253
//! (inscribed: the robot's centre here means contact) and 254 (lethal: an obstacle).
//!
//! - static layer: the scenario's world or map rasterised once (a cell is lethal when an
//!   obstacle comes within half the cell's diagonal of its centre, so that it touches the cell);
//! - obstacle layer: lidar hits marked lethal; every beam clears the cells it passes through
//!   (up to the hit, or to the raytrace range when there is none), so moving obstacles leave no
//!   ghosts;
//! - inflation: around every lethal cell, 253 within the inscribed radius, then Nav2's
//!   `252 * exp(-cost_scaling_factor * (d - inscribed))` out to the inflation radius.

use rlnav_sim::geometry::Rect;
use rlnav_sim::{LaserScan, Pose2, Vec2, World};
use serde::{Deserialize, Serialize};

/// An obstacle.
pub const LETHAL: u8 = 254;
/// The robot's centre here means contact.
pub const INSCRIBED: u8 = 253;

/// Costmap parameters (Nav2's names; defaults from Nav2's TurtleBot3 configuration).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CostmapConfig {
    /// Cell size (m, default 0.05).
    pub resolution: f32,
    /// Inflation radius (m, default 0.55).
    pub inflation_radius: f32,
    /// Exponential decay of inflated costs (1/m, default 3.0).
    pub cost_scaling_factor: f32,
    /// Lidar hits farther than this are not marked (m, default 2.5).
    pub obstacle_max_range: f32,
    /// Beams clear cells up to this range (m, default 3.0).
    pub raytrace_max_range: f32,
}

impl Default for CostmapConfig {
    fn default() -> Self {
        Self {
            resolution: 0.05,
            inflation_radius: 0.55,
            cost_scaling_factor: 3.0,
            obstacle_max_range: 2.5,
            raytrace_max_range: 3.0,
        }
    }
}

/// The costmap.
#[derive(Clone, Debug)]
pub struct Costmap {
    config: CostmapConfig,
    origin: Vec2,
    width: usize,
    height: usize,
    static_lethal: Vec<bool>,
    static_cost: Vec<u8>,
    marks: Vec<bool>,
    cost: Vec<u8>,
    /// Inflation stamp: cell offsets and their cost.
    kernel: Vec<(i32, i32, u8)>,
}

impl Costmap {
    /// A costmap over `bounds` for a robot whose centre must stay `inscribed` metres from
    /// obstacles, with the static layer from `world` when given.
    pub fn new(bounds: Rect, config: CostmapConfig, inscribed: f32, world: Option<&World>) -> Self {
        let r = config.resolution;
        let size = bounds.size();
        let (width, height) = (((size.x / r).ceil() as usize).max(1), ((size.y / r).ceil() as usize).max(1));
        let mut m = Self::empty(bounds.min, width, height, config, inscribed);
        if let Some(w) = world {
            // A cell is lethal when an obstacle may reach into it: within half the cell's
            // diagonal of its centre. (Half its side missed zero-thickness walls lying on a
            // cell boundary, whose centres are exactly half a cell away: a door jamb vanished
            // from the static layer and DWA cut through it.)
            let reach = 0.5 * r * std::f32::consts::SQRT_2;
            for iy in 0..height {
                for ix in 0..width {
                    let c = m.center(ix, iy);
                    m.static_lethal[iy * width + ix] = !w.is_clear(c, reach);
                }
            }
        }
        m.inflate_static();
        m
    }

    /// A costmap of `width` x `height` cells of `config.resolution` from a map's obstacle
    /// cells (`lethal`, row-major from cell (0, 0), as `nav_msgs/OccupancyGrid` orders them),
    /// in the map's grid frame: cell (0, 0)'s corner at the origin, x along rows. `None` when
    /// `lethal` does not hold `width * height` cells.
    pub fn from_cells(
        width: usize,
        height: usize,
        config: CostmapConfig,
        inscribed: f32,
        lethal: Vec<bool>,
    ) -> Option<Self> {
        if width == 0 || height == 0 || lethal.len() != width.checked_mul(height)? {
            return None;
        }
        let mut m = Self::empty(Vec2::ZERO, width, height, config, inscribed);
        m.static_lethal = lethal;
        m.inflate_static();
        Some(m)
    }

    /// A costmap with no obstacles yet.
    fn empty(origin: Vec2, width: usize, height: usize, config: CostmapConfig, inscribed: f32) -> Self {
        let r = config.resolution;
        let mut kernel = Vec::new();
        let reach = (config.inflation_radius.max(inscribed) / r).ceil() as i32;
        for dy in -reach..=reach {
            for dx in -reach..=reach {
                let d = ((dx * dx + dy * dy) as f32).sqrt() * r;
                let c = inflation_cost(d, inscribed, &config);
                if c > 0 {
                    kernel.push((dx, dy, c));
                }
            }
        }
        Self {
            origin,
            width,
            height,
            static_lethal: vec![false; width * height],
            static_cost: vec![0; width * height],
            marks: vec![false; width * height],
            cost: vec![0; width * height],
            kernel,
            config,
        }
    }

    /// Inflates the static layer's obstacles into the static and combined costs.
    fn inflate_static(&mut self) {
        let mut static_cost = vec![0u8; self.width * self.height];
        for k in (0..self.width * self.height).filter(|k| self.static_lethal[*k]) {
            self.stamp(&mut static_cost, k);
        }
        self.static_cost = static_cost;
        self.cost.clone_from(&self.static_cost);
    }

    fn stamp(&self, grid: &mut [u8], k: usize) {
        let (x, y) = ((k % self.width) as i32, (k / self.width) as i32);
        for &(dx, dy, c) in &self.kernel {
            let (nx, ny) = (x + dx, y + dy);
            if nx >= 0 && ny >= 0 && (nx as usize) < self.width && (ny as usize) < self.height {
                let cell = &mut grid[ny as usize * self.width + nx as usize];
                *cell = (*cell).max(c);
            }
        }
    }

    /// `(width, height)` in cells.
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// Cell size (m).
    pub fn resolution(&self) -> f32 {
        self.config.resolution
    }

    /// Centre of cell `(ix, iy)`.
    pub fn center(&self, ix: usize, iy: usize) -> Vec2 {
        self.origin + Vec2::new(ix as f32 + 0.5, iy as f32 + 0.5) * self.config.resolution
    }

    /// The cell containing `p`, if inside.
    pub fn cell_of(&self, p: Vec2) -> Option<(usize, usize)> {
        let g = (p - self.origin) / self.config.resolution;
        (g.x >= 0.0 && g.y >= 0.0 && (g.x as usize) < self.width && (g.y as usize) < self.height)
            .then_some((g.x as usize, g.y as usize))
    }

    /// Cost of cell `(ix, iy)`.
    pub fn cost(&self, ix: usize, iy: usize) -> u8 {
        self.cost[iy * self.width + ix]
    }

    /// Cost at `p`; outside the map is lethal.
    pub fn cost_at(&self, p: Vec2) -> u8 {
        self.cell_of(p).map_or(LETHAL, |(x, y)| self.cost(x, y))
    }

    /// Updates the obstacle layer from a scan taken at `pose` by a lidar mounted at `mount`,
    /// then recomputes the combined, inflated cost.
    pub fn update(&mut self, pose: &Pose2, mount: &Pose2, scan: &LaserScan) {
        let sensor = pose.compose(mount);
        let o = sensor.position();
        let r = self.config.resolution;
        let beam = |i: usize| {
            let a = sensor.yaw + scan.angle_min + i as f32 * scan.angle_increment;
            Vec2::new(a.cos(), a.sin())
        };
        let is_hit = |r: f32| r.is_finite() && r <= scan.range_max;
        // Clear every beam first, then mark every hit (as Nav2 does): a neighbouring beam
        // that passes by must not erase a hit in a cell it grazes.
        for (i, range) in scan.ranges.iter().enumerate() {
            if range.is_nan() {
                continue;
            }
            let dir = beam(i);
            let clear_to = if is_hit(*range) { *range } else { self.config.raytrace_max_range };
            let clear_to = clear_to.min(self.config.raytrace_max_range);
            // Up to half a cell before the hit.
            let steps = ((clear_to - 0.5 * r) / r).max(0.0) as usize;
            for s in 0..steps {
                if let Some((x, y)) = self.cell_of(o + dir * (s as f32 * r)) {
                    self.marks[y * self.width + x] = false;
                }
            }
        }
        for (i, range) in scan.ranges.iter().enumerate() {
            if is_hit(*range) && *range <= self.config.obstacle_max_range {
                if let Some((x, y)) = self.cell_of(o + beam(i) * *range) {
                    self.marks[y * self.width + x] = true;
                }
            }
        }
        let mut cost = std::mem::take(&mut self.cost);
        cost.clone_from(&self.static_cost);
        for k in 0..self.marks.len() {
            if self.marks[k] {
                self.stamp(&mut cost, k);
            }
        }
        self.cost = cost;
    }

    /// Forgets what the lidar marked (a new episode).
    pub fn clear_obstacles(&mut self) {
        self.marks.fill(false);
        self.cost.clone_from(&self.static_cost);
    }
}

/// Nav2's inflation cost at distance `d` from an obstacle cell.
fn inflation_cost(d: f32, inscribed: f32, c: &CostmapConfig) -> u8 {
    if d == 0.0 {
        LETHAL
    } else if d <= inscribed {
        INSCRIBED
    } else if d <= c.inflation_radius {
        (252.0 * (-c.cost_scaling_factor * (d - inscribed)).exp()).round() as u8
    } else {
        0
    }
}
