//! Occupancy-grid maps in the ROS `map_server` format (a YAML file naming a PGM or PNG image),
//! used as a scenario's static world.
//!
//! Cells are free, occupied or unknown, decided from the image exactly as `map_server` does
//! (`negate`, `occupied_thresh`, `free_thresh`, `mode`). Unknown cells count as walls unless
//! the scenario says otherwise: a robot should not drive or be placed where the map knows
//! nothing.
//!
//! A ray stops where it enters the first blocked cell. [`OccupancyGrid::cast`] walks one ray
//! through the cells (jumping by the Chebyshev distance to the nearest blocked cell in open
//! space, cell by cell near walls); the lidar instead casts all its beams at once against the
//! blocked cells' outline ([`GridEdges`]), with the same answers, several times faster.

use crate::config::{ConfigError, Invalid, Validate, check_positive, check_range};
use crate::geometry::{Pose2, Rect, Vec2};
use crate::robot::Footprint;
use parry2d::query::intersection_test;
use parry2d::shape::Cuboid;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Maps shipped in `scenarios/maps/`: `(name, yaml, image file name, image bytes)`.
pub const MAP_PRESETS: &[(&str, &str, &str, &[u8])] = &[
    (
        "warehouse",
        include_str!("../../../scenarios/maps/warehouse.yaml"),
        "warehouse.pgm",
        include_bytes!("../../../scenarios/maps/warehouse.pgm"),
    ),
    (
        "turtlebot3-world",
        include_str!("../../../scenarios/maps/turtlebot3-world.yaml"),
        "turtlebot3-world.pgm",
        include_bytes!("../../../scenarios/maps/turtlebot3-world.pgm"),
    ),
];

/// How image pixels become occupancy, as in `map_server`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MapMode {
    /// Occupied, free or unknown by the two thresholds (the default).
    #[default]
    Trinary,
    /// Like trinary; values between the thresholds are occupancy probabilities, which the
    /// simulator treats as unknown. A transparent pixel is unknown.
    Scale,
    /// The pixel value is the occupancy in percent (0–100); anything above 100 is unknown.
    Raw,
}

/// `negate` is written `0`/`1` by `map_saver` and `true`/`false` by people.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Flag {
    /// `true` / `false`.
    Bool(bool),
    /// `0` / `1`.
    Int(i64),
}

impl Flag {
    fn get(self) -> Option<bool> {
        match self {
            Flag::Bool(b) => Some(b),
            Flag::Int(0) => Some(false),
            Flag::Int(1) => Some(true),
            Flag::Int(_) => None,
        }
    }
}

/// A `map_server` map file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MapSpec {
    /// The image, relative to the YAML file.
    pub image: String,
    /// Cell size (m).
    pub resolution: f32,
    /// Pose of the lower-left pixel's corner `[x, y, yaw]` in the world.
    pub origin: Pose2,
    /// Whether white means occupied (default 0).
    #[serde(default = "no_flag")]
    pub negate: Flag,
    /// Occupancy probability above which a cell is occupied (default 0.65).
    #[serde(default = "default_occupied")]
    pub occupied_thresh: f32,
    /// Occupancy probability below which a cell is free (default 0.25).
    #[serde(default = "default_free")]
    pub free_thresh: f32,
    /// Pixel interpretation (default trinary).
    #[serde(default)]
    pub mode: MapMode,
}

fn no_flag() -> Flag {
    Flag::Int(0)
}
fn default_occupied() -> f32 {
    0.65
}
fn default_free() -> f32 {
    0.25
}

impl Validate for MapSpec {
    fn validate(&self) -> Result<(), Invalid> {
        if self.image.trim().is_empty() {
            return Err(Invalid::new("image", "the image file's name"));
        }
        check_positive("resolution", self.resolution)?;
        check_range("resolution", self.resolution, 1e-4, 100.0)?;
        if !(self.origin.x.is_finite() && self.origin.y.is_finite() && self.origin.yaw.is_finite()) {
            return Err(Invalid::new("origin", "finite [x, y, yaw]"));
        }
        if self.negate.get().is_none() {
            return Err(Invalid::new("negate", "0 or 1"));
        }
        check_range("occupied_thresh", self.occupied_thresh, 0.0, 1.0)?;
        check_range("free_thresh", self.free_thresh, 0.0, 1.0)?;
        if self.free_thresh >= self.occupied_thresh {
            return Err(Invalid::new(
                "free_thresh",
                format!("less than occupied_thresh ({}), got {}", self.occupied_thresh, self.free_thresh),
            ));
        }
        Ok(())
    }
}

/// What a cell holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum Cell {
    /// Known free.
    Free = 0,
    /// Occupied.
    Occupied = 1,
    /// Unknown.
    Unknown = 2,
}

/// What unknown cells are to the simulator.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum UnknownCells {
    /// Walls: the lidar sees them and touching one is a collision (default).
    #[default]
    Occupied,
    /// Open space (but never a start or a goal).
    Free,
}

/// Largest map side, in cells.
const MAX_SIDE: u32 = 20_000;

/// A loaded occupancy grid, ready for collision, clearance and ray queries.
#[derive(Clone, Debug)]
pub struct OccupancyGrid {
    /// Where the YAML came from (for messages).
    pub source: String,
    width: usize,
    height: usize,
    resolution: f32,
    origin: Pose2,
    cells: Vec<Cell>,
    blocked: Vec<bool>,
    /// Chebyshev distance (in cells) from each cell to the nearest blocked cell (0 for a
    /// blocked cell; large when there is none).
    cheb: Vec<u32>,
    /// The same two tables for "not known free" (occupied or unknown), kept only when unknown
    /// cells are open space (otherwise they equal `blocked` and `cheb`): starts and goals keep
    /// their clearance from unknown space whatever the robot may drive through.
    not_free: Option<(Vec<bool>, Vec<u32>)>,
    /// `origin.yaw`'s sine and cosine (the cast is hot; `sin_cos` per ray cost a fifth of it).
    rot: (f32, f32),
    /// The blocked cells' outline as segments, binned in tiles: what the lidar casts against.
    edges: GridEdges,
}

impl OccupancyGrid {
    /// Loads a map: a shipped name (`warehouse`, `turtlebot3-world`) or a YAML file path.
    pub fn load(name_or_path: &str, unknown: UnknownCells) -> Result<Self, ConfigError> {
        if let Some((name, yaml, image_name, bytes)) = MAP_PRESETS.iter().find(|m| m.0 == name_or_path) {
            let file = format!("<embedded map {name}>");
            let spec: MapSpec = crate::config::from_yaml_str(&file, yaml)?;
            if spec.image != *image_name {
                return Err(Invalid::new("image", format!("`{image_name}`")).in_file(&file));
            }
            return Self::from_image_bytes(&file, &spec, bytes, unknown);
        }
        if !(name_or_path.ends_with(".yaml") || name_or_path.ends_with(".yml") || name_or_path.contains('/')) {
            return Err(ConfigError::UnknownPreset {
                kind: "map",
                name: name_or_path.to_string(),
                known: MAP_PRESETS.iter().map(|m| m.0).collect::<Vec<_>>().join(", "),
            });
        }
        Self::load_file(Path::new(name_or_path), unknown)
    }

    /// Loads a `map_server` YAML file and the image it names.
    pub fn load_file(path: &Path, unknown: UnknownCells) -> Result<Self, ConfigError> {
        let spec: MapSpec = crate::config::from_yaml_file(path)?;
        let file = path.display().to_string();
        if spec.image.ends_with(".xacro") || spec.image.ends_with(".yaml") {
            return Err(Invalid::new("image", "a PGM or PNG image").in_file(&file));
        }
        let image_path: PathBuf = path.parent().unwrap_or(Path::new(".")).join(&spec.image);
        let bytes = std::fs::read(&image_path).map_err(|source| ConfigError::Invalid {
            file: file.clone(),
            key: "image".into(),
            expected: format!("a readable image at {}: {source}", image_path.display()),
        })?;
        Self::from_image_bytes(&file, &spec, &bytes, unknown)
    }

    /// Builds the grid from the image's encoded bytes (PGM, PNG...).
    pub fn from_image_bytes(
        file: &str,
        spec: &MapSpec,
        bytes: &[u8],
        unknown: UnknownCells,
    ) -> Result<Self, ConfigError> {
        let bad = |expected: String| ConfigError::Invalid { file: file.to_string(), key: "image".into(), expected };
        let img = image::ImageReader::new(std::io::Cursor::new(bytes))
            .with_guessed_format()
            .map_err(|e| bad(format!("a PGM or PNG image `{}`: {e}", spec.image)))?;
        if img.format().is_none() {
            return Err(bad(format!("a PGM or PNG image, but `{}` is neither", spec.image)));
        }
        let img = img.decode().map_err(|e| bad(format!("a decodable image `{}`: {e}", spec.image)))?;
        let (w, h) = (img.width(), img.height());
        if w == 0 || h == 0 || w > MAX_SIDE || h > MAX_SIDE {
            return Err(bad(format!("an image of 1 to {MAX_SIDE} pixels a side, got {w} x {h}")));
        }
        let rgba = img.to_rgba8();
        let has_alpha = img.color().has_alpha();
        let negate = spec.negate.get().unwrap_or(false);
        let (width, height) = (w as usize, h as usize);
        let mut cells = vec![Cell::Unknown; width * height];
        for (x, y, px) in rgba.enumerate_pixels() {
            let [r, g, b, a] = px.0;
            // map_server: the shade is the mean of the colour channels.
            let shade = (r as f32 + g as f32 + b as f32) / 3.0;
            let cell = match spec.mode {
                MapMode::Raw => match r {
                    0..=100 => classify(r as f32 / 100.0, spec),
                    _ => Cell::Unknown,
                },
                MapMode::Scale if has_alpha && a < 255 => Cell::Unknown,
                _ => {
                    let p = if negate { shade / 255.0 } else { (255.0 - shade) / 255.0 };
                    classify(p, spec)
                }
            };
            // Image row 0 is the top of the map; grid row 0 is the bottom (at the origin).
            cells[(height - 1 - y as usize) * width + x as usize] = cell;
        }
        if !cells.contains(&Cell::Free) {
            return Err(ConfigError::Invalid {
                file: file.to_string(),
                key: "image".into(),
                expected: format!(
                    "some free cells, but none of `{}`'s {w} x {h} pixels is free with negate {}, \
                     free_thresh {} (is `negate` or `mode` wrong?)",
                    spec.image, negate as u8, spec.free_thresh
                ),
            });
        }
        Ok(Self::from_cells(file, width, height, spec.resolution, spec.origin, cells, unknown))
    }

    /// Builds a grid from cells, row 0 at the bottom (`cells[iy * width + ix]`).
    pub fn from_cells(
        source: &str,
        width: usize,
        height: usize,
        resolution: f32,
        origin: Pose2,
        cells: Vec<Cell>,
        unknown: UnknownCells,
    ) -> Self {
        assert_eq!(cells.len(), width * height, "cells must be width x height");
        let blocked: Vec<bool> = cells
            .iter()
            .map(|c| *c == Cell::Occupied || (*c == Cell::Unknown && unknown == UnknownCells::Occupied))
            .collect();
        let cheb = chebyshev_transform(&blocked, width, height);
        let not_free = (unknown == UnknownCells::Free && cells.contains(&Cell::Unknown)).then(|| {
            let not_free: Vec<bool> = cells.iter().map(|c| *c != Cell::Free).collect();
            let cheb = chebyshev_transform(&not_free, width, height);
            (not_free, cheb)
        });
        let rot = origin.yaw.sin_cos();
        let edges = GridEdges::new(&blocked, width, height);
        Self {
            source: source.to_string(),
            width,
            height,
            resolution,
            origin,
            cells,
            blocked,
            cheb,
            not_free,
            rot,
            edges,
        }
    }

    /// `(width, height)` in cells.
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// Cell size (m).
    pub fn resolution(&self) -> f32 {
        self.resolution
    }

    /// Pose of the lower-left corner of cell (0, 0).
    pub fn origin(&self) -> Pose2 {
        self.origin
    }

    /// The cell at `(ix, iy)`.
    pub fn cell(&self, ix: usize, iy: usize) -> Cell {
        self.cells[iy * self.width + ix]
    }

    /// Whether the cell at `(ix, iy)` stops rays and robots.
    pub fn is_blocked(&self, ix: usize, iy: usize) -> bool {
        self.blocked[iy * self.width + ix]
    }

    /// The outline of the blocked cells as segments (see [`GridEdges`]).
    pub fn edges(&self) -> &GridEdges {
        &self.edges
    }

    /// Whether `p` lies inside a blocked cell (a ray from there stops at once).
    pub fn blocks(&self, p: Vec2) -> bool {
        self.cell_of(p).is_some_and(|(x, y)| self.is_blocked(x, y))
    }

    /// The cell containing world point `p`, if inside the grid.
    pub fn cell_of(&self, p: Vec2) -> Option<(usize, usize)> {
        let g = self.origin.to_local(p) / self.resolution;
        let (ix, iy) = (g.x.floor(), g.y.floor());
        (ix >= 0.0 && iy >= 0.0 && (ix as usize) < self.width && (iy as usize) < self.height)
            .then_some((ix as usize, iy as usize))
    }

    /// Whether `p` lies in a known-free cell (where starts and goals may go).
    pub fn is_known_free(&self, p: Vec2) -> bool {
        self.cell_of(p).is_some_and(|(x, y)| self.cell(x, y) == Cell::Free)
    }

    /// World-frame rectangle around the known-free cells.
    pub fn free_bounds(&self) -> Rect {
        self.bounds_of(|c| c == Cell::Free)
    }

    /// World-frame rectangle around the known cells (free or occupied): the part of the map
    /// worth showing. A `map_saver` map is mostly unknown around a small mapped area.
    pub fn known_bounds(&self) -> Rect {
        self.bounds_of(|c| c != Cell::Unknown)
    }

    /// World-frame rectangle around the whole grid.
    pub fn bounds(&self) -> Rect {
        self.bounds_of(|_| true)
    }

    fn bounds_of(&self, keep: impl Fn(Cell) -> bool) -> Rect {
        let (mut lo, mut hi) = ((usize::MAX, usize::MAX), (0, 0));
        for iy in 0..self.height {
            for ix in 0..self.width {
                if keep(self.cell(ix, iy)) {
                    lo = (lo.0.min(ix), lo.1.min(iy));
                    hi = (hi.0.max(ix + 1), hi.1.max(iy + 1));
                }
            }
        }
        let r = self.resolution;
        let corners = [(lo.0, lo.1), (hi.0, lo.1), (hi.0, hi.1), (lo.0, hi.1)]
            .map(|(x, y)| self.origin.to_parent(Vec2::new(x as f32 * r, y as f32 * r)));
        let min = corners.iter().fold(Vec2::splat(f32::INFINITY), |a, b| a.min(*b));
        let max = corners.iter().fold(Vec2::splat(f32::NEG_INFINITY), |a, b| a.max(*b));
        Rect { min, max }
    }

    /// Distance from grid point `g` (in cell units, grid frame) to cell `(ix, iy)`'s square.
    #[inline]
    fn cell_distance(g: Vec2, ix: usize, iy: usize) -> f32 {
        let dx = (ix as f32 - g.x).max(g.x - (ix + 1) as f32).max(0.0);
        let dy = (iy as f32 - g.y).max(g.y - (iy + 1) as f32).max(0.0);
        dx.hypot(dy)
    }

    /// Lower bound (cells) on the distance from any point of cell `(ix, iy)` to a blocked cell.
    #[inline]
    fn free_radius(&self, ix: usize, iy: usize) -> f32 {
        self.cheb[iy * self.width + ix].saturating_sub(1) as f32
    }

    /// Calls `f(ix, iy)` for every blocked cell whose square comes within `reach` cells of
    /// grid point `g`; stops early when `f` returns true and reports whether it did.
    fn any_blocked_near(&self, g: Vec2, reach: f32, f: impl FnMut(usize, usize) -> bool) -> bool {
        self.any_marked_near(&self.blocked, g, reach, f)
    }

    /// [`Self::any_blocked_near`] over any cell mask (`blocked` or `not_free`).
    fn any_marked_near(&self, marked: &[bool], g: Vec2, reach: f32, mut f: impl FnMut(usize, usize) -> bool) -> bool {
        let x0 = (g.x - reach).floor().max(0.0) as usize;
        let y0 = (g.y - reach).floor().max(0.0) as usize;
        let x1 = ((g.x + reach).floor() + 1.0).clamp(0.0, self.width as f32) as usize;
        let y1 = ((g.y + reach).floor() + 1.0).clamp(0.0, self.height as f32) as usize;
        for iy in y0..y1 {
            for ix in x0..x1 {
                if marked[iy * self.width + ix] && Self::cell_distance(g, ix, iy) <= reach && f(ix, iy) {
                    return true;
                }
            }
        }
        false
    }

    /// Distance from `p` to the nearest blocked cell (0 inside one; +inf if there is none).
    pub fn clearance(&self, p: Vec2) -> f32 {
        let g = self.origin.to_local(p) / self.resolution;
        let mut reach = match self.cell_of(p) {
            Some((ix, iy)) if self.is_blocked(ix, iy) => return 0.0,
            Some((ix, iy)) => self.free_radius(ix, iy) + 2.0,
            None => 4.0,
        };
        let limit = (self.width + self.height) as f32 + g.abs().max_element();
        loop {
            let mut best = f32::INFINITY;
            self.any_blocked_near(g, reach, |ix, iy| {
                best = best.min(Self::cell_distance(g, ix, iy));
                false
            });
            if best.is_finite() {
                return best * self.resolution;
            }
            if reach > limit {
                return f32::INFINITY;
            }
            reach *= 2.0;
        }
    }

    /// Whether every blocked cell is at least `min` metres from `p`.
    pub fn is_clear(&self, p: Vec2, min: f32) -> bool {
        self.is_clear_of(&self.blocked, &self.cheb, p, min)
    }

    /// Whether every cell that is not known free (occupied, or unknown even where the
    /// scenario lets the robot drive through unknown space) is at least `min` metres from
    /// `p`: where a start or a goal may be.
    pub fn is_known_clear(&self, p: Vec2, min: f32) -> bool {
        match &self.not_free {
            Some((not_free, cheb)) => self.is_clear_of(not_free, cheb, p, min),
            None => self.is_clear(p, min),
        }
    }

    /// Whether every cell marked in `marked` (with its Chebyshev table `cheb`) is at least
    /// `min` metres from `p`.
    fn is_clear_of(&self, marked: &[bool], cheb: &[u32], p: Vec2, min: f32) -> bool {
        let reach = min / self.resolution;
        if let Some((ix, iy)) = self.cell_of(p) {
            let i = iy * self.width + ix;
            if marked[i] {
                return false;
            }
            if cheb[i].saturating_sub(1) as f32 >= reach {
                return true;
            }
        }
        let g = self.origin.to_local(p) / self.resolution;
        // Strictly closer than `min` is a violation.
        !self.any_marked_near(marked, g, reach, |ix, iy| Self::cell_distance(g, ix, iy) < reach)
    }

    /// Whether the footprint at `pose` touches or overlaps a blocked cell.
    pub fn footprint_collides(&self, footprint: &Footprint, pose: &Pose2) -> bool {
        let p = pose.position();
        let reach = footprint.radius() / self.resolution;
        if let Some((ix, iy)) = self.cell_of(p) {
            if self.is_blocked(ix, iy) {
                return true;
            }
            if self.free_radius(ix, iy) > reach {
                return false;
            }
        }
        let g = self.origin.to_local(p) / self.resolution;
        if footprint.is_disc() {
            return self.any_blocked_near(g, reach, |_, _| true);
        }
        let robot = pose.to_parry();
        let half = 0.5 * self.resolution;
        let square = Cuboid::new(Vec2::splat(half));
        self.any_blocked_near(g, reach, |ix, iy| {
            let c = self.origin.compose(&Pose2::new(
                (ix as f32 + 0.5) * self.resolution,
                (iy as f32 + 0.5) * self.resolution,
                0.0,
            ));
            // Unsupported pairs count as contact: a surprise may stop a robot, never pass it.
            intersection_test(&robot, footprint.shape(), &c.to_parry(), &square).map(|h| h.intersecting).unwrap_or(true)
        })
    }

    /// Distance along the world-frame ray `origin + t * dir` (unit `dir`) to the first blocked
    /// cell, or `limit` when there is none closer. A ray starting inside a blocked cell hits at 0.
    pub fn cast(&self, origin: Vec2, dir: Vec2, limit: f32) -> f32 {
        let inv_res = 1.0 / self.resolution;
        let (s, c) = self.rot;
        let rel = origin - self.origin.position();
        let o = Vec2::new(c * rel.x + s * rel.y, -s * rel.x + c * rel.y) * inv_res;
        let d = Vec2::new(c * dir.x + s * dir.y, -s * dir.x + c * dir.y);
        let limit_c = limit * inv_res;
        let (wf, hf) = (self.width as f32, self.height as f32);
        // Clip the ray to the grid rectangle (slab method).
        let (mut t0, mut t1) = (0.0f32, limit_c);
        for (oa, da, size) in [(o.x, d.x, wf), (o.y, d.y, hf)] {
            if da.abs() < 1e-12 {
                if oa < 0.0 || oa > size {
                    return limit;
                }
            } else {
                let (a, b) = ((0.0 - oa) / da, (size - oa) / da);
                t0 = t0.max(a.min(b));
                t1 = t1.min(a.max(b));
            }
        }
        if t0 > t1 {
            return limit;
        }
        let step_x: i64 = if d.x > 0.0 { 1 } else { -1 };
        let step_y: i64 = if d.y > 0.0 { 1 } else { -1 };
        // Multiplying by precomputed inverses keeps divisions out of the loop.
        let inv_x = if d.x != 0.0 { 1.0 / d.x } else { f32::INFINITY };
        let inv_y = if d.y != 0.0 { 1.0 / d.y } else { f32::INFINITY };
        let (delta_x, delta_y) = (inv_x.abs(), inv_y.abs());
        let (w, h) = (self.width as i64, self.height as i64);
        // Boundary crossing along one axis for the cell `i` (infinite when parallel to it).
        let next = |i: i64, step: i64, oa: f32, inv: f32| {
            if inv.is_infinite() {
                return f32::INFINITY;
            }
            let boundary = if step > 0 { (i + 1) as f32 } else { i as f32 };
            (boundary - oa) * inv
        };
        // `p` lies in the grid rectangle (up to rounding), so truncation is floor (`floorf`
        // is a library call on baseline x86-64); on a boundary, take the cell being entered.
        let cell_index = |v: f32, dv: f32, n: i64| {
            let f = v.max(0.0) as i64;
            let i = if f as f32 == v && dv < 0.0 { f - 1 } else { f };
            i.clamp(0, n - 1)
        };
        let mut t = t0;
        'restart: loop {
            // (Re)start the cell walk at distance t.
            let p = o + d * t;
            let mut ix = cell_index(p.x, d.x, w);
            let mut iy = cell_index(p.y, d.y, h);
            let mut tmax_x = next(ix, step_x, o.x, inv_x);
            let mut tmax_y = next(iy, step_y, o.y, inv_y);
            loop {
                // Chebyshev distance 0 is a blocked cell.
                let cheb = self.cheb[iy as usize * self.width + ix as usize];
                if cheb == 0 {
                    return (t * self.resolution).min(limit);
                }
                if cheb >= 3 {
                    // Everything within `cheb - 1` cells of this cell is open: jump.
                    t += (cheb - 1) as f32;
                    if t >= t1 {
                        return limit;
                    }
                    continue 'restart;
                }
                if tmax_x < tmax_y {
                    t = tmax_x;
                    tmax_x += delta_x;
                    ix += step_x;
                    if ix < 0 || ix >= w {
                        return limit;
                    }
                } else {
                    t = tmax_y;
                    tmax_y += delta_y;
                    iy += step_y;
                    if iy < 0 || iy >= h {
                        return limit;
                    }
                }
                if t >= t1 {
                    return limit;
                }
            }
        }
    }
}

/// The boundary between blocked and open cells (outside the grid is open) as axis-aligned
/// edges in the grid frame, in cell units: what the lidar casts a grid against. A ray from open
/// space enters its first blocked cell where it first crosses this outline from the open side,
/// so casting against it gives [`OccupancyGrid::cast`]'s answers (tested) for all beams at once.
///
/// Collinear cell edges are merged up to a tile border (16 x 16 cells). Edges are stored by
/// row of tiles, then by [`EdgeFacing`] class (which side is open), then by tile, so that the
/// edges of one class in a run of tiles of one row are one slice: a scan visits a few slices
/// per row, and skips whole the classes that face away from the sensor there.
#[derive(Clone, Debug, Default)]
pub struct GridEdges {
    /// `[at, lo, hi]`: the edge on the line `y = at` (horizontal classes) or `x = at`
    /// (vertical ones) from `lo` to `hi` along the other axis, grid frame, cell units.
    edges: Vec<[f32; 3]>,
    /// The edges of class `c` in tile `(tx, ty)` are `edges[start[k]..start[k + 1]]` with
    /// `k = (4 ty + c) tiles_x + tx`.
    start: Vec<u32>,
    tiles_x: usize,
    tiles_y: usize,
}

/// Which side of an outline edge is open: the side a ray must come from to hit it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EdgeFacing {
    /// Horizontal, open below (a blocked cell's bottom edge): seen from `y < at`.
    Down = 0,
    /// Horizontal, open above (a blocked cell's top edge): seen from `y > at`.
    Up = 1,
    /// Vertical, open on the left (a blocked cell's left edge): seen from `x < at`.
    Left = 2,
    /// Vertical, open on the right (a blocked cell's right edge): seen from `x > at`.
    Right = 3,
}

impl EdgeFacing {
    const ALL: [EdgeFacing; 4] = [EdgeFacing::Down, EdgeFacing::Up, EdgeFacing::Left, EdgeFacing::Right];
}

/// Tile side in cells: about 0.8 m at 5 cm, so a 3.5 m lidar visits about 10 x 10 tiles.
const EDGE_TILE: usize = 16;

impl GridEdges {
    fn new(blocked: &[bool], width: usize, height: usize) -> Self {
        let at = |x: usize, y: usize| blocked[y * width + x];
        let (tiles_x, tiles_y) = (width.div_ceil(EDGE_TILE), height.div_ceil(EDGE_TILE));
        let mut bins: Vec<Vec<[f32; 3]>> = vec![Vec::new(); 4 * tiles_x * tiles_y];
        // The tile of cell (x, y), as its bin's index less the class's offset.
        let tile_of = |x: usize, y: usize| 4 * (y / EDGE_TILE) * tiles_x + x / EDGE_TILE;
        // Runs of cell edges along one grid line: `kind(i)` gives the class and the tile (of the
        // blocked cell) of the edge at step `i` along the line, if it is on the outline;
        // consecutive edges of one kind merge (so a run ends at a tile border).
        let mut emit_runs = |line: usize, n: usize, kind: &dyn Fn(usize) -> Option<(EdgeFacing, usize)>| {
            let mut i = 0;
            while i < n {
                let Some((facing, tile)) = kind(i) else {
                    i += 1;
                    continue;
                };
                let start = i;
                while i < n && kind(i) == Some((facing, tile)) {
                    i += 1;
                }
                bins[tile + facing as usize * tiles_x].push([line as f32, start as f32, i as f32]);
            }
        };
        // Horizontal grid lines y = 0..=height: a blocked cell above and an open one below is
        // the blocked cell's bottom edge, seen from below; the other way round, its top edge.
        for y in 0..=height {
            let kind = |x: usize| {
                let above = y < height && at(x, y);
                let below = y > 0 && at(x, y - 1);
                match (above, below) {
                    (true, false) => Some((EdgeFacing::Down, tile_of(x, y))),
                    (false, true) => Some((EdgeFacing::Up, tile_of(x, y - 1))),
                    _ => None,
                }
            };
            emit_runs(y, width, &kind);
        }
        // Vertical grid lines x = 0..=width: blocked on the right, seen from the left; blocked
        // on the left, seen from the right.
        for x in 0..=width {
            let kind = |y: usize| {
                let right = x < width && at(x, y);
                let left = x > 0 && at(x - 1, y);
                match (right, left) {
                    (true, false) => Some((EdgeFacing::Left, tile_of(x, y))),
                    (false, true) => Some((EdgeFacing::Right, tile_of(x - 1, y))),
                    _ => None,
                }
            };
            emit_runs(x, height, &kind);
        }
        let mut start = Vec::with_capacity(bins.len() + 1);
        let mut edges = Vec::with_capacity(bins.iter().map(Vec::len).sum());
        for b in &bins {
            start.push(edges.len() as u32);
            edges.extend_from_slice(b);
        }
        start.push(edges.len() as u32);
        Self { edges, start, tiles_x, tiles_y }
    }

    /// Number of edges.
    pub fn len(&self) -> usize {
        self.edges.len()
    }

    /// Whether there are none (a grid without blocked cells).
    pub fn is_empty(&self) -> bool {
        self.edges.is_empty()
    }

    /// Calls `f(facing, edges)` with the edges of the tiles that come within `reach` of the
    /// grid point `g` (grid frame, cell units), a slice per row of tiles and class, leaving out
    /// the tiles where that class faces away from `g` (callers still test each edge's side).
    #[inline]
    pub fn near(&self, g: Vec2, reach: f32, mut f: impl FnMut(EdgeFacing, &[[f32; 3]])) {
        if self.edges.is_empty() {
            return;
        }
        let t = EDGE_TILE as f32;
        // Tile index of a coordinate (cell units), clamped to `[0, n)`; `floor` by truncation
        // of a non-negative value (`floorf` is a library call on baseline x86-64).
        let tile = |v: f32, n: usize| ((v / t).max(0.0) as usize).min(n - 1);
        let (y_lo, y_hi) = (g.y - reach, g.y + reach);
        if y_hi < 0.0 || y_lo > (self.tiles_y * EDGE_TILE) as f32 {
            return;
        }
        let gtx = tile(g.x, self.tiles_x);
        for ty in tile(y_lo, self.tiles_y)..=tile(y_hi, self.tiles_y) {
            let (ylo, yhi) = ((ty * EDGE_TILE) as f32, ((ty + 1) * EDGE_TILE) as f32);
            // The disc's extent along this row of tiles.
            let dy = (ylo - g.y).max(g.y - yhi).max(0.0);
            let half = (reach * reach - dy * dy).max(0.0).sqrt();
            let (x_lo, x_hi) = (g.x - half, g.x + half);
            if x_hi < 0.0 || x_lo > (self.tiles_x * EDGE_TILE) as f32 {
                continue;
            }
            let (x0, x1) = (tile(x_lo, self.tiles_x), tile(x_hi, self.tiles_x));
            for facing in EdgeFacing::ALL {
                // The tiles of the row where this class may face `g`: a horizontal class in
                // the whole row or none, a vertical one from `g`'s column on.
                let (a, b) = match facing {
                    EdgeFacing::Down if g.y < yhi => (x0, x1),
                    EdgeFacing::Up if g.y > ylo => (x0, x1),
                    EdgeFacing::Left => (x0.max(gtx), x1),
                    EdgeFacing::Right => (x0, x1.min(gtx)),
                    _ => continue,
                };
                if a > b {
                    continue;
                }
                let row = (4 * ty + facing as usize) * self.tiles_x;
                let (s, e) = (self.start[row + a] as usize, self.start[row + b + 1] as usize);
                if s < e {
                    f(facing, &self.edges[s..e]);
                }
            }
        }
    }
}

/// Occupancy from a probability, by the spec's thresholds.
fn classify(p: f32, spec: &MapSpec) -> Cell {
    if p > spec.occupied_thresh {
        Cell::Occupied
    } else if p < spec.free_thresh {
        Cell::Free
    } else {
        Cell::Unknown
    }
}

/// Chebyshev (chessboard) distance from every cell to the nearest blocked one, two passes.
fn chebyshev_transform(blocked: &[bool], width: usize, height: usize) -> Vec<u32> {
    const FAR: u32 = u32::MAX / 2;
    let mut d: Vec<u32> = blocked.iter().map(|b| if *b { 0 } else { FAR }).collect();
    let at = |x: usize, y: usize| y * width + x;
    for y in 0..height {
        for x in 0..width {
            let mut v = d[at(x, y)];
            if x > 0 {
                v = v.min(d[at(x - 1, y)] + 1);
            }
            if y > 0 {
                v = v.min(d[at(x, y - 1)] + 1);
                if x > 0 {
                    v = v.min(d[at(x - 1, y - 1)] + 1);
                }
                if x + 1 < width {
                    v = v.min(d[at(x + 1, y - 1)] + 1);
                }
            }
            d[at(x, y)] = v;
        }
    }
    for y in (0..height).rev() {
        for x in (0..width).rev() {
            let mut v = d[at(x, y)];
            if x + 1 < width {
                v = v.min(d[at(x + 1, y)] + 1);
            }
            if y + 1 < height {
                v = v.min(d[at(x, y + 1)] + 1);
                if x + 1 < width {
                    v = v.min(d[at(x + 1, y + 1)] + 1);
                }
                if x > 0 {
                    v = v.min(d[at(x - 1, y + 1)] + 1);
                }
            }
            d[at(x, y)] = v;
        }
    }
    d
}

/// A scenario's reference to a map.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MapRef {
    /// A shipped map's name or a `map_server` YAML path (relative to the scenario file).
    pub file: String,
    /// What unknown cells are (default `occupied`).
    #[serde(default)]
    pub unknown: UnknownCells,
}
