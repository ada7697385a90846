//! The 2D lidar: [`LidarSpec`] (what a scanner is) and [`Lidar`] (the ray caster).
//!
//! Readings follow `sensor_msgs/LaserScan`: beam `i` points at `angle_min + i * angle_increment`
//! in the sensor frame, counter-clockwise; `+inf` means no return within `range_max`; a return
//! closer than `range_min` reads `range_min`.
//!
//! The hot loop ([`Lidar::scan`]) is hand-written: obstacles out of range are culled, and each
//! remaining obstacle is only tested against the beams its angular extent covers. A brute-force
//! reference built on parry2d's ray casts ([`Lidar::scan_reference`]) checks it in property
//! tests, and `rlnav sim-speed --reference-lidar` measures what the culling buys.

use crate::config::{Invalid, Validate, check_range};
use crate::geometry::{Pose2, Primitive, Vec2, point_segment_distance};
use crate::map::{EdgeFacing, OccupancyGrid};
use crate::world::World;
use parry2d::query::Ray;
use rand::RngExt;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};
use std::f32::consts::{PI, TAU};
use std::sync::Arc;

/// What a 2D lidar is: beam geometry, range limits, mount pose and imperfections.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LidarSpec {
    /// Number of beams (default 360).
    pub beams: usize,
    /// Angle of beam 0 in the sensor frame (rad, default -π: beam 0 points backwards).
    pub angle_min: f32,
    /// Angle of the last beam (rad, default π). When `angle_max - angle_min` is a full turn
    /// the beams are spread `2π / beams` apart (no beam is duplicated); otherwise
    /// `(angle_max - angle_min) / (beams - 1)`.
    pub angle_max: f32,
    /// Closest valid return (m, default 0.15).
    pub range_min: f32,
    /// Farthest return (m, default 3.0); beyond it a beam reads `+inf`.
    pub range_max: f32,
    /// Sensor pose in `base_link` `[x, y, yaw]` (default `[0, 0, 0]`).
    pub mount: Pose2,
    /// Standard deviation of additive Gaussian range noise (m, default 0).
    pub noise_std: f32,
    /// Probability that a beam returns nothing (reads `+inf`), default 0.
    pub dropout: f32,
}

impl Default for LidarSpec {
    fn default() -> Self {
        Self {
            beams: 360,
            angle_min: -PI,
            angle_max: PI,
            range_min: 0.15,
            range_max: 3.0,
            mount: Pose2::default(),
            noise_std: 0.0,
            dropout: 0.0,
        }
    }
}

impl Validate for LidarSpec {
    fn validate(&self) -> Result<(), Invalid> {
        if !(1..=100_000).contains(&self.beams) {
            return Err(Invalid::new("beams", format!("an integer in [1, 100000], got {}", self.beams)));
        }
        check_range("angle_min", self.angle_min, -TAU, TAU)?;
        check_range("angle_max", self.angle_max, self.angle_min, self.angle_min + TAU + 1e-4)?;
        check_range("range_min", self.range_min, 0.0, 1000.0)?;
        check_range("range_max", self.range_max, self.range_min + 1e-3, 1000.0)?;
        check_range("noise_std", self.noise_std, 0.0, 1.0)?;
        check_range("dropout", self.dropout, 0.0, 1.0)?;
        if !(self.mount.x.is_finite() && self.mount.y.is_finite() && self.mount.yaw.is_finite()) {
            return Err(Invalid::new("mount", "finite [x, y, yaw]"));
        }
        if self.beams == 1 && !self.is_full_circle() && self.angle_max != self.angle_min {
            return Err(Invalid::new("angle_max", "equal to angle_min for a single-beam scanner"));
        }
        Ok(())
    }
}

impl LidarSpec {
    /// Whether the beams cover a full turn.
    pub fn is_full_circle(&self) -> bool {
        self.angle_max - self.angle_min >= TAU - 1e-4
    }

    /// Angle between consecutive beams (rad).
    pub fn angle_increment(&self) -> f32 {
        if self.is_full_circle() {
            TAU / self.beams as f32
        } else if self.beams > 1 {
            (self.angle_max - self.angle_min) / (self.beams - 1) as f32
        } else {
            TAU
        }
    }

    /// Sensor-frame angle of beam `i`.
    pub fn beam_angle(&self, i: usize) -> f32 {
        self.angle_min + i as f32 * self.angle_increment()
    }
}

/// Obstacles flattened for the ray caster: circles, and groups of segments (a polygon's edges
/// or one wall) each with a bounding circle for range culling.
#[derive(Clone, Debug, Default)]
pub struct RayGeometry {
    circles: Vec<(Vec2, f32)>,
    groups: Vec<SegmentGroup>,
    segments: Vec<(Vec2, Vec2)>,
    /// An occupancy-grid map, cast against its outline (see [`Lidar::scan_layers`]).
    grid: Option<Arc<OccupancyGrid>>,
}

#[derive(Clone, Debug)]
struct SegmentGroup {
    center: Vec2,
    radius: f32,
    start: usize,
    end: usize,
    /// Polygon edges are only seen from outside (back faces are culled); walls from both sides.
    one_sided: bool,
}

impl RayGeometry {
    /// Flattens world primitives.
    pub fn new<'a>(primitives: impl IntoIterator<Item = &'a Primitive>) -> Self {
        let mut g = RayGeometry::default();
        for p in primitives {
            g.push(p);
        }
        g
    }

    /// Adds one primitive.
    pub fn push(&mut self, p: &Primitive) {
        let (center, radius) = p.bounding_circle();
        match p {
            Primitive::Circle { center, radius } => self.circles.push((*center, *radius)),
            Primitive::Segment { a, b } => {
                let start = self.segments.len();
                self.segments.push((*a, *b));
                self.groups.push(SegmentGroup { center, radius, start, end: start + 1, one_sided: false });
            }
            Primitive::Polygon { vertices } => self.push_polygon(vertices),
        }
    }

    /// Empties the geometry, keeping its memory (for per-step moving obstacles).
    pub fn clear(&mut self) {
        self.circles.clear();
        self.groups.clear();
        self.segments.clear();
        self.grid = None;
    }

    /// Adds an occupancy grid (replacing any other).
    pub fn set_grid(&mut self, grid: Arc<OccupancyGrid>) {
        self.grid = Some(grid);
    }

    /// Adds a circle.
    pub fn push_circle(&mut self, center: Vec2, radius: f32) {
        self.circles.push((center, radius));
    }

    /// Adds a convex polygon given by its counter-clockwise vertices.
    pub fn push_polygon(&mut self, vertices: &[Vec2]) {
        let n = vertices.len();
        let center = vertices.iter().copied().fold(Vec2::ZERO, |a, b| a + b) / n as f32;
        let radius = vertices.iter().map(|v| (*v - center).length()).fold(0.0, f32::max);
        let start = self.segments.len();
        self.segments.extend((0..n).map(|i| (vertices[i], vertices[(i + 1) % n])));
        self.groups.push(SegmentGroup { center, radius, start, end: start + n, one_sided: true });
    }

    /// Number of circles and segments (what the caster tests against).
    pub fn primitive_count(&self) -> usize {
        self.circles.len() + self.segments.len() + self.grid.is_some() as usize
    }
}

/// How far (rad) beyond a primitive's angular extent beams are still tested: above the error
/// of the angles involved (about 1e-6 rad, see [`approx_atan2`]); a beam too many costs one miss.
const BEAM_MARGIN: f32 = 1e-4;

/// `atan2(y, x)` to within 1e-6 rad (Abramowitz & Stegun 4.4.49's polynomial after reducing
/// to an octant), for finding which beams a primitive may cover: `for_beams` keeps a beam of
/// margin on each side, far more than the error. libm's `atan2f` was a fifth of a grid scan.
#[inline]
fn approx_atan2(y: f32, x: f32) -> f32 {
    let (ax, ay) = (x.abs(), y.abs());
    let (lo, hi) = (ax.min(ay), ax.max(ay));
    // No branch (so that loops over many angles vectorise): 0 / tiny is 0 at the origin.
    let a = lo / hi.max(f32::MIN_POSITIVE);
    let s = a * a;
    let mut r = a
        * (1.0
            + s * (-0.333_331_45
                + s * (0.199_935_51
                    + s * (-0.142_089
                        + s * (0.106_562_64
                            + s * (-0.075_289_64 + s * (0.042_909_61 + s * (-0.016_165_74 + s * 0.002_866_23))))))));
    if ay > ax {
        r = std::f32::consts::FRAC_PI_2 - r;
    }
    if x < 0.0 {
        r = std::f32::consts::PI - r;
    }
    if y < 0.0 { -r } else { r }
}

/// Grid edges whose beam ranges are worked out together, in a loop LLVM vectorises, before
/// their beams are tested (TurtleBot3 map scans 1.25x faster, `examples/grid_lidar_speed.rs`).
const EDGE_BATCH: usize = 16;

/// A lidar ready to cast: the spec plus precomputed beam directions.
#[derive(Clone, Debug)]
pub struct Lidar {
    spec: LidarSpec,
    /// Unit beam directions in the sensor frame.
    local_dirs: Vec<Vec2>,
    inv_increment: f32,
    /// Whether the beams cover a full turn (beam `n` would be beam 0).
    full_circle: bool,
}

impl Lidar {
    /// Compiles a (validated) spec.
    pub fn new(spec: LidarSpec) -> Self {
        let inc = spec.angle_increment();
        let local_dirs = (0..spec.beams)
            .map(|i| {
                let (s, c) = (spec.angle_min + i as f32 * inc).sin_cos();
                Vec2::new(c, s)
            })
            .collect();
        let full_circle = spec.is_full_circle();
        Self { spec, local_dirs, inv_increment: 1.0 / inc, full_circle }
    }

    /// The spec.
    pub fn spec(&self) -> &LidarSpec {
        &self.spec
    }

    /// Number of beams.
    pub fn beams(&self) -> usize {
        self.spec.beams
    }

    /// The sensor's world pose when the robot is at `robot`.
    pub fn sensor_pose(&self, robot: &Pose2) -> Pose2 {
        robot.compose(&self.spec.mount)
    }

    /// Calls `f(i)` for every beam whose direction lies in the sensor-relative interval
    /// `[lo, lo + width]` (relative to beam 0, `width` below half a turn), widened by
    /// [`BEAM_MARGIN`] on each side so that rounding never drops a beam. Each beam is visited
    /// at most once.
    #[inline]
    fn for_beams(&self, lo: f32, width: f32, f: impl FnMut(usize)) {
        let (a, b) = self.beam_interval(lo, width);
        self.for_beam_indices(a, b, f);
    }

    /// The interval of [`Self::for_beams`] in beam indices, `a` in `[-1, beams)` for a full
    /// circle (a fraction of a turn beyond for partial ones). No branch: it runs in vectorised
    /// loops over many edges.
    #[inline]
    fn beam_interval(&self, lo: f32, width: f32) -> (f32, f32) {
        // Whole turns off by truncation (`rem_euclid`, `floor` and `ceil` are library calls on
        // baseline x86-64 and were a tenth of a grid scan).
        let turns = (lo * (1.0 / TAU)) as i32 - i32::from(lo < 0.0);
        let a = (lo - turns as f32 * TAU - BEAM_MARGIN) * self.inv_increment;
        (a, a + (width + 2.0 * BEAM_MARGIN) * self.inv_increment)
    }

    /// Calls `f(i)` for every beam index in `[a, b]` from [`Self::beam_interval`], each once.
    #[inline]
    fn for_beam_indices(&self, a: f32, b: f32, mut f: impl FnMut(usize)) {
        let n = self.spec.beams as i64;
        if self.full_circle {
            // One range of indices, wrapped once: `a` lies in [-1, n), the range is under half
            // a turn long.
            let (ai, bi) = (a as i64, b as i64);
            let first = if (ai as f32) < a { ai + 1 } else { ai }; // ceil(a)
            let last = if (bi as f32) > b { bi - 1 } else { bi }; // floor(b)
            for k in first..=last {
                f(if k < 0 {
                    k + n
                } else if k >= n {
                    k - n
                } else {
                    k
                } as usize);
            }
            return;
        }
        // The interval may reach past a turn at either end: the beams a turn on either side
        // are visited too.
        let turn = TAU * self.inv_increment;
        for shift in [0.0, -turn, turn] {
            let (a, b) = (a + shift, b + shift);
            let (ai, bi) = (a as i64, b as i64);
            let first = if (ai as f32) < a { ai + 1 } else { ai }.max(0); // ceil(a)
            let last = if (bi as f32) > b { bi - 1 } else { bi }.min(n - 1); // floor(b)
            for i in first..=last {
                f(i as usize);
            }
        }
    }

    /// Casts all beams from the robot pose `robot` into `geometry`, writing exact ranges
    /// (no noise) into `out` (length `beams`). `dirs` is scratch space of the same length.
    pub fn scan(&self, robot: &Pose2, geometry: &RayGeometry, dirs: &mut [Vec2], out: &mut [f32]) {
        self.scan_layers(robot, &[geometry], dirs, out);
    }

    /// Like [`Self::scan`], over several geometries at once (the static world and the moving
    /// obstacles of this instant).
    pub fn scan_layers(&self, robot: &Pose2, layers: &[&RayGeometry], dirs: &mut [Vec2], out: &mut [f32]) {
        let n = self.spec.beams;
        debug_assert!(dirs.len() == n && out.len() == n);
        let sensor = self.sensor_pose(robot);
        let (sy, cy) = sensor.yaw.sin_cos();
        for (d, l) in dirs.iter_mut().zip(&self.local_dirs) {
            *d = Vec2::new(cy * l.x - sy * l.y, sy * l.x + cy * l.y);
        }
        out.fill(self.spec.range_max);
        for g in layers {
            self.cast(&sensor, g, dirs, out);
        }
        // Grids last: every beam a shape already stopped short is cheaper to cast.
        for grid in layers.iter().filter_map(|g| g.grid.as_deref()) {
            self.cast_grid(&sensor, grid, dirs, out);
        }
        self.finish(out);
    }

    /// Lowers `out` (raw distances, `range_max` = no hit yet) to the hits in `geometry`.
    fn cast(&self, sensor: &Pose2, geometry: &RayGeometry, dirs: &[Vec2], out: &mut [f32]) {
        let p = sensor.position();
        let limit = self.spec.range_max;
        // Angles below are relative to beam 0's world direction.
        let base = sensor.yaw + self.spec.angle_min;

        for &(c, r) in &geometry.circles {
            let rel = c - p;
            let d2 = rel.length_squared();
            let d = d2.sqrt();
            if d - r >= limit || d <= r {
                // Out of range, or the sensor is inside the cylinder (no return from its inside).
                continue;
            }
            let half = (r / d).min(1.0).asin();
            let center = approx_atan2(rel.y, rel.x) - base;
            let r2 = r * r;
            self.for_beams(center - half, 2.0 * half, |i| {
                let dir = dirs[i];
                let b = dir.dot(rel);
                // r² - (perpendicular distance)² rather than b² - (d² - r²): no cancellation
                // between large squares when the beam is nearly tangent.
                let perp = dir.perp_dot(rel);
                let disc = r2 - perp * perp;
                if disc >= 0.0 {
                    let t = b - disc.sqrt();
                    if t >= 0.0 && t < out[i] {
                        out[i] = t;
                    }
                }
            });
        }

        for g in &geometry.groups {
            if (g.center - p).length() - g.radius >= limit {
                continue;
            }
            for &(a, b) in &geometry.segments[g.start..g.end] {
                self.cast_segment(p, base, limit, a, b, g.one_sided, true, dirs, out);
            }
        }
    }

    /// Lowers `out` (raw distances) to the hits on `grid`'s outline ([`GridEdges`]: the same
    /// hits as walking each ray through the cells, tested). Works in the grid frame, in cell
    /// units, where every edge is axis-aligned: a beam meets the edge on `y = at` at
    /// `t = (at - o.y) / d.y`, and only the beams between the edge's ends are tested.
    fn cast_grid(&self, sensor: &Pose2, grid: &OccupancyGrid, dirs: &[Vec2], out: &mut [f32]) {
        let p = sensor.position();
        if grid.blocks(p) {
            // Inside a blocked cell: every ray stops at once, as the cell walk says.
            out.fill(0.0);
            return;
        }
        let origin = grid.origin();
        let inv_res = 1.0 / grid.resolution();
        let o = origin.to_local(p) * inv_res;
        // Beam angles relative to the grid's axes; each beam's direction is turned into the
        // grid frame as the cell walk turns it (the same rounding).
        let base = sensor.yaw - origin.yaw + self.spec.angle_min;
        let (s, c) = origin.yaw.sin_cos();
        let aligned = origin.yaw == 0.0;
        let res = grid.resolution();
        grid.edges().near(o, self.spec.range_max * inv_res, |facing, edges| {
            let horizontal = matches!(facing, EdgeFacing::Down | EdgeFacing::Up);
            // Sensor and beams in axes (u along the edge, v across it).
            let (ou, ov) = if horizontal { (o.x, o.y) } else { (o.y, o.x) };
            // The open side: beams must travel towards +v (Down, Left) or -v (Up, Right).
            let toward = if matches!(facing, EdgeFacing::Down | EdgeFacing::Left) { 1.0f32 } else { -1.0 };
            // Seen from the right (x > at) the ends straddle atan2's cut at ±π.
            let wrap = facing == EdgeFacing::Right;
            for batch in edges.chunks(EDGE_BATCH) {
                // First pass, without branches (LLVM vectorises it): each edge's beams, from
                // the angles of its ends. Both lie in the half-plane the edge faces, which for
                // `Right` is brought into one turn.
                let mut span = [(0.0f32, 0.0f32); EDGE_BATCH];
                for (&[at, lo, hi], span) in batch.iter().zip(span.iter_mut()) {
                    let (a, b) = if horizontal {
                        (Vec2::new(lo - o.x, at - o.y), Vec2::new(hi - o.x, at - o.y))
                    } else {
                        (Vec2::new(at - o.x, lo - o.y), Vec2::new(at - o.x, hi - o.y))
                    };
                    let (mut ra, mut rb) = (approx_atan2(a.y, a.x), approx_atan2(b.y, b.x));
                    if wrap {
                        ra += if ra < 0.0 { TAU } else { 0.0 };
                        rb += if rb < 0.0 { TAU } else { 0.0 };
                    }
                    *span = self.beam_interval(ra.min(rb) - base, (ra - rb).abs());
                }
                // Second pass: the beams of each edge that faces the sensor.
                for (&[at, lo, hi], &(first, last)) in batch.iter().zip(&span) {
                    // Distance across, positive on the open side.
                    let dv = (at - ov) * toward;
                    if dv <= 0.0 {
                        continue; // back face
                    }
                    let (lo_u, hi_u) = (lo - ou, hi - ou);
                    self.for_beam_indices(first, last, |i| {
                        let w = dirs[i];
                        let d = if aligned { w } else { Vec2::new(c * w.x + s * w.y, -s * w.x + c * w.y) };
                        let (du, dv_beam) = if horizontal { (d.x, d.y) } else { (d.y, d.x) };
                        // Along the beam towards the open side: t = dv / m > 0 (cell units).
                        let m = dv_beam * toward;
                        // The hit is u = ou + t du: inside [lo, hi] and nearer than out[i],
                        // multiplied through by m > 0 so that only a hit divides.
                        let u = dv * du;
                        if m > 0.0 && u >= lo_u * m && u <= hi_u * m && dv * res < out[i] * m {
                            out[i] = dv / m * res;
                        }
                    });
                }
            }
        });
    }

    /// Lowers `out[i]` to where beam `i` meets the segment `a`-`b`, for the beams whose
    /// direction lies between its ends (`base`: beam 0's world angle). A one-sided segment (a
    /// counter-clockwise outline's edge) is invisible from its left, inner side. With
    /// `cull_range`, a segment out of range is skipped before any angle is computed (a grid's
    /// tiles already keep far segments away; a hit beyond range is never kept either way).
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn cast_segment(
        &self,
        p: Vec2,
        base: f32,
        limit: f32,
        a: Vec2,
        b: Vec2,
        one_sided: bool,
        cull_range: bool,
        dirs: &[Vec2],
        out: &mut [f32],
    ) {
        let e = b - a;
        let w = a - p;
        // Back face: the sensor is on the inner side.
        if one_sided && e.perp_dot(-w) >= 0.0 {
            return;
        }
        if cull_range && point_segment_distance(p, a, b) >= limit {
            return;
        }
        let ra = approx_atan2(w.y, w.x) - base;
        let wb = b - p;
        let rb = approx_atan2(wb.y, wb.x) - base;
        // Both angles lie in one turn, so one correction wraps their difference (a `rem_euclid`
        // here is a library call per segment).
        let mut diff = rb - ra;
        if diff > PI {
            diff -= TAU;
        } else if diff < -PI {
            diff += TAU;
        }
        let (lo, width) = if diff >= 0.0 { (ra, diff) } else { (rb, -diff) };
        let wxe = w.perp_dot(e);
        self.for_beams(lo, width, |i| {
            let dir = dirs[i];
            let denom = dir.perp_dot(e);
            if denom.abs() < 1e-12 {
                return;
            }
            // t = wxe / denom along the beam, s = w x dir / denom along the segment: the tests
            // multiplied through by |denom| so that only a hit divides.
            let (sign, mag) = (denom.signum(), denom.abs());
            let (nt, ns) = (wxe * sign, w.perp_dot(dir) * sign);
            if nt >= 0.0 && ns >= 0.0 && ns <= mag && nt < out[i] * mag {
                out[i] = nt / mag;
            }
        });
    }

    /// Brute force: every beam against every obstacle with parry2d's ray casts. The reference
    /// the fast caster is tested and benchmarked against.
    pub fn scan_reference(&self, robot: &Pose2, world: &World, out: &mut [f32]) {
        let sensor = self.sensor_pose(robot);
        let limit = self.spec.range_max;
        for (i, o) in out.iter_mut().enumerate() {
            let angle = sensor.yaw + self.spec.beam_angle(i);
            let ray = Ray::new(sensor.position(), Vec2::new(angle.cos(), angle.sin()));
            *o = world
                .obstacles()
                .iter()
                .filter_map(|ob| ob.shape.cast_ray(&ob.pose, &ray, limit, true))
                .fold(limit, f32::min);
            if let Some(grid) = world.grid() {
                *o = grid.cast(ray.origin, ray.dir, *o);
            }
        }
        self.finish(out);
    }

    /// Converts raw distances (`>= range_max` means no hit) to LaserScan conventions.
    fn finish(&self, out: &mut [f32]) {
        let (lo, hi) = (self.spec.range_min, self.spec.range_max);
        for r in out.iter_mut() {
            *r = if *r >= hi { f32::INFINITY } else { r.max(lo) };
        }
    }

    /// Adds the spec's Gaussian range noise and dropout to a scan (no-op when both are zero).
    pub fn apply_noise<R: rand::Rng>(&self, rng: &mut R, out: &mut [f32]) {
        self.corrupt(rng, self.spec.noise_std, self.spec.dropout, out);
    }

    /// Adds Gaussian range noise of `std` and drops beams with probability `drop` (both 0:
    /// nothing, and no random draws).
    pub fn corrupt<R: rand::Rng>(&self, rng: &mut R, std: f32, drop: f32, out: &mut [f32]) {
        if std <= 0.0 && drop <= 0.0 {
            return;
        }
        let (lo, hi) = (self.spec.range_min, self.spec.range_max);
        for r in out.iter_mut() {
            if drop > 0.0 && rng.random::<f32>() < drop {
                *r = f32::INFINITY;
            } else if std > 0.0 && r.is_finite() {
                let noise: f32 = rng.sample(StandardNormal);
                let v = *r + std * noise;
                *r = if v >= hi { f32::INFINITY } else { v.max(lo) };
            }
        }
    }
}

/// Down-samples a scan by taking the minimum of each group of `src.len() / out.len()`
/// consecutive beams (the article's 360 -> 120), so that a thin obstacle seen by one beam is
/// never lost. `src.len()` must be a multiple of `out.len()`.
pub fn min_pool(src: &[f32], out: &mut [f32]) {
    let k = src.len() / out.len();
    debug_assert_eq!(k * out.len(), src.len());
    for (o, chunk) in out.iter_mut().zip(src.chunks_exact(k)) {
        *o = chunk.iter().copied().fold(f32::INFINITY, f32::min);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{Obstacle, ObstacleSpec};

    fn world(specs: Vec<ObstacleSpec>) -> World {
        World::new(specs.into_iter().map(|s| Obstacle::new(s).unwrap()).collect())
    }

    fn cast(l: &Lidar, w: &World, pose: Pose2) -> Vec<f32> {
        let mut dirs = vec![Vec2::ZERO; l.beams()];
        let mut out = vec![0.0; l.beams()];
        l.scan(&pose, w.ray_geometry(), &mut dirs, &mut out);
        out
    }

    #[test]
    fn beam_geometry_follows_laserscan() {
        let full = LidarSpec::default();
        assert!((full.angle_increment() - TAU / 360.0).abs() < 1e-7);
        assert_eq!(full.beam_angle(0), -PI);
        let partial = LidarSpec { beams: 721, angle_min: -2.356_194_5, angle_max: 2.356_194_5, ..full };
        assert!((partial.beam_angle(720) - 2.356_194_5).abs() < 1e-5);
    }

    #[test]
    fn circle_ahead_reads_its_near_side() {
        let w = world(vec![ObstacleSpec::Circle { center: [2.0, 0.0], radius: 0.5 }]);
        let l = Lidar::new(LidarSpec::default());
        let r = cast(&l, &w, Pose2::default());
        // Beam 180 points along +x (angle_min = -π).
        assert!((r[180] - 1.5).abs() < 1e-5, "{}", r[180]);
        assert!(r[0].is_infinite(), "behind: nothing");
        let lit = r.iter().filter(|x| x.is_finite()).count();
        // asin(0.5/2) ≈ 14.5° each side.
        assert!((28..=30).contains(&lit), "{lit} beams lit");
    }

    #[test]
    fn mount_pose_and_range_min() {
        let w = world(vec![ObstacleSpec::Wall { from: [1.0, -1.0], to: [1.0, 1.0] }]);
        let spec = LidarSpec { mount: Pose2::new(0.2, 0.0, PI / 2.0), range_min: 0.5, ..Default::default() };
        let l = Lidar::new(spec);
        let r = cast(&l, &w, Pose2::default());
        // Sensor faces +y; the wall straight ahead of the robot is beam angle -π/2 -> index 90.
        assert!((r[90] - 0.8).abs() < 1e-5, "{}", r[90]);
        let close = world(vec![ObstacleSpec::Wall { from: [0.3, -1.0], to: [0.3, 1.0] }]);
        let r = cast(&l, &close, Pose2::default());
        assert_eq!(r[90], 0.5, "closer than range_min reads range_min");
    }

    #[test]
    fn partial_field_of_view_sees_only_its_sector() {
        let w = world(vec![ObstacleSpec::Circle { center: [-2.0, 0.0], radius: 0.3 }]);
        let spec = LidarSpec { beams: 271, angle_min: -2.356_194_5, angle_max: 2.356_194_5, ..Default::default() };
        let l = Lidar::new(spec);
        assert!(cast(&l, &w, Pose2::default()).iter().all(|r| r.is_infinite()), "obstacle is behind");
        let r = cast(&l, &w, Pose2::new(0.0, 0.0, PI));
        assert!((r[135] - 1.7).abs() < 1e-5);
    }

    #[test]
    fn noise_and_dropout_statistics() {
        use rand::SeedableRng;
        let spec = LidarSpec { noise_std: 0.05, dropout: 0.1, range_max: 10.0, ..Default::default() };
        let l = Lidar::new(spec);
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(3);
        let mut scan = vec![2.0f32; 20_000];
        l.apply_noise(&mut rng, &mut scan);
        let kept: Vec<f32> = scan.iter().copied().filter(|r| r.is_finite()).collect();
        let dropped = 1.0 - kept.len() as f32 / scan.len() as f32;
        assert!((dropped - 0.1).abs() < 0.01, "dropout {dropped}");
        let mean = kept.iter().sum::<f32>() / kept.len() as f32;
        let std = (kept.iter().map(|r| (r - mean).powi(2)).sum::<f32>() / kept.len() as f32).sqrt();
        assert!((mean - 2.0).abs() < 0.003 && (std - 0.05).abs() < 0.003, "mean {mean} std {std}");
    }

    #[test]
    fn approx_atan2_is_within_a_microradian() {
        let mut worst = 0.0f32;
        for i in 0..20_000 {
            let a = i as f32 * (std::f32::consts::TAU / 20_000.0) - std::f32::consts::PI;
            for r in [1e-3f32, 0.7, 25.0] {
                let (y, x) = (r * a.sin(), r * a.cos());
                worst = worst.max((approx_atan2(y, x) - y.atan2(x)).abs());
            }
        }
        assert!(worst < 1e-6, "{worst}");
        assert_eq!(approx_atan2(0.0, 0.0), 0.0);
        assert!((approx_atan2(0.0, -1.0) - std::f32::consts::PI).abs() < 1e-6);
    }

    #[test]
    fn min_pool_keeps_thin_obstacles() {
        let mut src = vec![f32::INFINITY; 360];
        src[4] = 1.0;
        let mut out = vec![0.0; 120];
        min_pool(&src, &mut out);
        assert_eq!(out[1], 1.0);
        assert_eq!(out.iter().filter(|x| x.is_finite()).count(), 1);
    }
}
