//! Reading BARN worlds as the challenge and the dataset distribute them: Gazebo world files
//! (`world_N.world`, SDF), occupancy grids (`grid_N.npy`) and reference paths
//! (`path_N.npy`), into the project's BARN data file (`barn_worlds.json`).
//!
//! The reference path length is computed as the challenge's `run.py` computes it (the path's
//! cells mapped to Gazebo coordinates, with the start and the goal added at its ends), so that
//! the score's optimal time is the official one. Everything is read and checked before
//! anything is returned: a missing, truncated or malformed file is an error naming it.

use super::difficulty::{BarnGrid, CELL, Difficulty, GRID_SIZE, ROBOT_CELLS};
use super::{About, BarnFile, Entry, GoalPoint, StartPose};
use crate::config::ConfigError;
use crate::geometry::ObstacleSpec;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::rc::Rc;

/// The challenge's start pose (`run.py`'s `INIT_POSITION` for the BARN worlds).
const START: [f32; 3] = [-2.25, 3.0, 1.57];
/// The challenge's goal (start + `GOAL_POSITION`).
const GOAL: [f32; 2] = [-2.25, 13.0];
/// Cylinders of the BARN worlds (m).
pub const CYLINDER_RADIUS: f32 = 0.075;

/// Which of a BARN folder's worlds to import.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Split {
    /// Every world found.
    All,
    /// The challenge's 50 test worlds: indices 0, 6, ..., 294 (its `test.sh`).
    Test,
    /// The others.
    Train,
}

impl Split {
    /// Whether world `index` belongs to the split.
    pub fn contains(self, index: u32) -> bool {
        match self {
            Split::All => true,
            Split::Test => index % 6 == 0,
            Split::Train => index % 6 != 0,
        }
    }
}

/// A BARN folder read into the project's format.
#[derive(Debug)]
pub struct Imported {
    /// `barn_worlds.json`'s text.
    pub json: String,
    /// The indices imported, in order.
    pub indices: Vec<u32>,
    /// Where the obstacles came from: `world` files or `grid` files.
    pub obstacles_from: &'static str,
    /// The folder the worlds (or grids) were read from.
    pub world_dir: PathBuf,
}

/// A numpy array (`.npy`, format 1.0–3.0) of a numeric type, as `f64`, in C order.
#[derive(Clone, Debug, PartialEq)]
pub struct NpyArray {
    /// Its shape.
    pub shape: Vec<usize>,
    /// Its values, row-major.
    pub data: Vec<f64>,
}

/// Reads a `.npy` file's bytes: little- or big-endian integers, unsigned integers and floats
/// of 1–8 bytes and booleans; `label` names it in errors.
pub fn read_npy(label: &str, bytes: &[u8]) -> Result<NpyArray, ConfigError> {
    let bad = |message: String| ConfigError::Parse { file: label.to_string(), message };
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err(bad("not a numpy .npy file (no `\\x93NUMPY` magic)".into()));
    }
    let (header_len, start) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize, 12),
        v => return Err(bad(format!("npy format version {v} (rlnav reads 1, 2 and 3)"))),
    };
    let header = bytes
        .get(start..start + header_len)
        .ok_or_else(|| bad("truncated: the header is cut short".into()))
        .and_then(|h| std::str::from_utf8(h).map_err(|_| bad("the header is not text".into())))?;
    let field = |key: &str| -> Result<&str, ConfigError> {
        let at = header.find(&format!("'{key}'")).ok_or_else(|| bad(format!("the header has no `{key}`")))?;
        let rest = header[at + key.len() + 2..].trim_start();
        Ok(rest.strip_prefix(':').unwrap_or(rest).trim_start())
    };
    let descr = field("descr")?;
    let descr = descr
        .strip_prefix('\'')
        .and_then(|d| d.split('\'').next())
        .ok_or_else(|| bad("`descr` is not a quoted type string".into()))?;
    let fortran = field("fortran_order")?.starts_with("True");
    let shape_text = field("shape")?;
    let shape_text = shape_text
        .strip_prefix('(')
        .and_then(|s| s.split(')').next())
        .ok_or_else(|| bad("`shape` is not a tuple".into()))?;
    let shape = shape_text
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.trim_end_matches('L').parse::<usize>())
        .collect::<Result<Vec<_>, _>>()
        .map_err(|_| bad(format!("`shape` ({shape_text}) is not a tuple of sizes")))?;
    let (order, kind, size) = {
        let mut chars = descr.chars();
        let order = chars.next().unwrap_or('?');
        let kind = chars.next().unwrap_or('?');
        (order, kind, chars.as_str().parse::<usize>().unwrap_or(0))
    };
    let supported = matches!((kind, size), ('i' | 'u', 1 | 2 | 4 | 8) | ('f', 4 | 8) | ('b', 1))
        && matches!(order, '<' | '>' | '|' | '=');
    if !supported {
        return Err(bad(format!("element type `{descr}` (rlnav reads integers, floats and booleans)")));
    }
    let count: usize = shape.iter().product();
    let body = &bytes[start + header_len..];
    if body.len() < count * size {
        return Err(bad(format!(
            "truncated: the header says {count} values of {size} bytes ({} bytes), the file holds {}",
            count * size,
            body.len()
        )));
    }
    let value = |chunk: &[u8]| -> f64 {
        let mut b = [0u8; 8];
        if order == '>' {
            b[..size].copy_from_slice(chunk);
            b[..size].reverse();
        } else {
            b[..size].copy_from_slice(chunk);
        }
        let sign_extend = |bits: u32| ((u64::from_le_bytes(b) << (64 - bits)) as i64 >> (64 - bits)) as f64;
        match (kind, size) {
            ('f', 4) => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            ('f', _) => f64::from_le_bytes(b),
            ('i', n) => sign_extend(8 * n as u32),
            _ => u64::from_le_bytes(b) as f64,
        }
    };
    let mut data: Vec<f64> = body[..count * size].chunks_exact(size).map(value).collect();
    if fortran && shape.len() == 2 {
        let (rows, cols) = (shape[0], shape[1]);
        data = (0..rows * cols).map(|k| data[(k % cols) * rows + k / cols]).collect();
    } else if fortran && shape.len() > 2 {
        return Err(bad("Fortran-ordered arrays of more than two dimensions".into()));
    }
    Ok(NpyArray { shape, data })
}

/// A reference path: an `n x 2` array of grid cells `(row, column)` inside the 30 x 30 grid.
fn path_cells(label: &str, a: &NpyArray) -> Result<Vec<[i64; 2]>, ConfigError> {
    let ok_shape = a.shape.len() == 2 && a.shape[1] == 2 && a.shape[0] >= 2;
    let in_grid = |v: f64| v.fract() == 0.0 && (0.0..GRID_SIZE as f64).contains(&v);
    if !ok_shape || !a.data.iter().all(|&v| in_grid(v)) {
        return Err(ConfigError::Parse {
            file: label.to_string(),
            message: format!(
                "expected a reference path: an n x 2 array (n >= 2) of grid cells (row, column) in 0..{GRID_SIZE}, \
                 found shape {:?}",
                a.shape
            ),
        });
    }
    Ok(a.data.chunks_exact(2).map(|p| [p[0] as i64, p[1] as i64]).collect())
}

/// An occupancy grid: a 30 x 30 array of 0 and 1.
fn grid_cells(label: &str, a: &NpyArray) -> Result<BarnGrid, ConfigError> {
    if a.shape != [GRID_SIZE, GRID_SIZE] || !a.data.iter().all(|&v| v == 0.0 || v == 1.0) {
        return Err(ConfigError::Parse {
            file: label.to_string(),
            message: format!(
                "expected a BARN occupancy grid: a {GRID_SIZE} x {GRID_SIZE} array of 0 and 1, found shape {:?}",
                a.shape
            ),
        });
    }
    let mut g = BarnGrid::new(GRID_SIZE, GRID_SIZE);
    for (k, &v) in a.data.iter().enumerate() {
        g.set(k / GRID_SIZE, k % GRID_SIZE, v == 1.0);
    }
    Ok(g)
}

/// The reference path length (m) as the challenge's `run.py` computes it: cells to Gazebo
/// coordinates (`x = row * 0.15 - 4.575`, `y = col * 0.15 + 5.075`), the start before them and
/// the goal after.
pub fn reference_path_length(path: &[[i64; 2]]) -> f32 {
    let shift_x = -CYLINDER_RADIUS as f64 - 30.0 * CELL as f64;
    let shift_y = CYLINDER_RADIUS as f64 + 5.0;
    let mut points = vec![[START[0] as f64, START[1] as f64]];
    points.extend(path.iter().map(|p| [p[0] as f64 * CELL as f64 + shift_x, p[1] as f64 * CELL as f64 + shift_y]));
    points.push([GOAL[0] as f64, GOAL[1] as f64]);
    points.windows(2).map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1])).sum::<f64>() as f32
}

/// A 2D pose from SDF's `x y z roll pitch yaw`.
#[derive(Clone, Copy, Debug, Default)]
struct Pose {
    x: f32,
    y: f32,
    yaw: f32,
}

impl Pose {
    fn then(self, p: Pose) -> Pose {
        let (s, c) = self.yaw.sin_cos();
        Pose { x: self.x + c * p.x - s * p.y, y: self.y + s * p.x + c * p.y, yaw: self.yaw + p.yaw }
    }
}

type El = crate::xacro::dom::Element;

fn children<'a>(e: &'a El, name: &'a str) -> impl Iterator<Item = &'a El> + 'a {
    e.children.iter().filter_map(move |n| match n {
        crate::xacro::dom::Node::Element(c) if c.name == name => Some(c),
        _ => None,
    })
}

fn text(e: &El) -> String {
    e.children
        .iter()
        .filter_map(|n| match n {
            crate::xacro::dom::Node::Text(t, _) => Some(t.as_str()),
            _ => None,
        })
        .collect()
}

fn numbers(label: &str, e: &El, want: usize) -> Result<Vec<f32>, ConfigError> {
    let t = text(e);
    let v: Option<Vec<f32>> = t.split_whitespace().map(|s| s.parse().ok().filter(|x: &f32| x.is_finite())).collect();
    match v {
        Some(v) if v.len() == want => Ok(v),
        _ => Err(ConfigError::Parse {
            file: label.to_string(),
            message: format!("line {}: `<{}>` should hold {want} numbers, found `{}`", e.pos.line, e.name, t.trim()),
        }),
    }
}

fn pose_of(label: &str, e: &El) -> Result<Pose, ConfigError> {
    match children(e, "pose").next() {
        Some(p) => {
            let v = numbers(label, p, 6)?;
            Ok(Pose { x: v[0], y: v[1], yaw: v[5] })
        }
        None => Ok(Pose::default()),
    }
}

/// The obstacles of a Gazebo world file seen from above: every model's collision cylinders
/// (circles), boxes (oriented rectangles) and spheres (circles), at the model, link and
/// collision poses composed, a pose in the world's `<state>` taking the place of the model's
/// own (as Gazebo loads it). Ground planes are skipped; meshes and `<include>`d models, which
/// rlnav cannot see from the file alone, are errors.
pub fn world_obstacles(label: &str, text_: &str) -> Result<Vec<ObstacleSpec>, ConfigError> {
    let file: Rc<str> = Rc::from(label);
    let root = crate::xacro::dom::parse(&file, text_).map_err(|e| ConfigError::Parse {
        file: label.to_string(),
        message: format!("line {}: {}", e.line, e.message),
    })?;
    let world = if root.name == "world" { Some(&root) } else { children(&root, "world").next() };
    let world = world.ok_or_else(|| ConfigError::Parse {
        file: label.to_string(),
        message: "no `<world>` element: not a Gazebo world file".into(),
    })?;
    if let Some(inc) = children(world, "include").next() {
        let uri = children(inc, "uri").next().map(text).unwrap_or_default();
        return Err(ConfigError::Parse {
            file: label.to_string(),
            message: format!(
                "line {}: `<include>` of `{}`: rlnav reads the models written in the world file, not included ones",
                inc.pos.line,
                uri.trim()
            ),
        });
    }
    let mut state_poses = BTreeMap::new();
    for state in children(world, "state") {
        for m in children(state, "model") {
            if let Some(name) = m.attr("name") {
                state_poses.insert(name.to_string(), pose_of(label, m)?);
            }
        }
    }
    let mut out = Vec::new();
    for model in children(world, "model") {
        let name = model.attr("name").unwrap_or("");
        let model_pose = match state_poses.get(name) {
            Some(p) => *p,
            None => pose_of(label, model)?,
        };
        for link in children(model, "link") {
            let link_pose = model_pose.then(pose_of(label, link)?);
            for collision in children(link, "collision") {
                let p = link_pose.then(pose_of(label, collision)?);
                let Some(geometry) = children(collision, "geometry").next() else { continue };
                let shape = geometry.children.iter().find_map(|n| match n {
                    crate::xacro::dom::Node::Element(g) => Some(g),
                    _ => None,
                });
                let Some(shape) = shape else { continue };
                let radius = |g: &El| -> Result<f32, ConfigError> {
                    let r = children(g, "radius").next().map(|r| numbers(label, r, 1)).transpose()?;
                    r.map(|r| r[0]).filter(|r| *r > 0.0).ok_or_else(|| ConfigError::Parse {
                        file: label.to_string(),
                        message: format!(
                            "line {}: model `{name}`: `<{}>` without a positive radius",
                            g.pos.line, g.name
                        ),
                    })
                };
                match shape.name.as_str() {
                    "cylinder" | "sphere" => {
                        out.push(ObstacleSpec::Circle { center: [p.x, p.y], radius: radius(shape)? })
                    }
                    "box" => {
                        let size = children(shape, "size").next().map(|s| numbers(label, s, 3)).transpose()?;
                        let size = size.filter(|s| s[0] > 0.0 && s[1] > 0.0).ok_or_else(|| ConfigError::Parse {
                            file: label.to_string(),
                            message: format!(
                                "line {}: model `{name}`: `<box>` without a positive size",
                                shape.pos.line
                            ),
                        })?;
                        out.push(ObstacleSpec::Box { center: [p.x, p.y], size: [size[0], size[1]], yaw: p.yaw });
                    }
                    "plane" | "empty" => {}
                    other => {
                        return Err(ConfigError::Parse {
                            file: label.to_string(),
                            message: format!(
                                "line {}: model `{name}`: `<{other}>` geometry (rlnav reads cylinder, box, sphere and plane)",
                                shape.pos.line
                            ),
                        });
                    }
                }
            }
        }
    }
    Ok(out)
}

/// Where a BARN folder keeps its files.
struct Layout {
    /// `world_N.world` files, or `grid_N.npy` when there are none.
    worlds: BTreeMap<u32, PathBuf>,
    from_worlds: bool,
    world_dir: PathBuf,
    path_dir: PathBuf,
    grid_dir: Option<PathBuf>,
}

fn numbered(dir: &Path, prefix: &str, ext: &str) -> BTreeMap<u32, PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else { return BTreeMap::new() };
    entries
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let name = e.file_name().into_string().ok()?;
            let n = name.strip_prefix(prefix)?.strip_suffix(ext)?.parse().ok()?;
            Some((n, e.path()))
        })
        .collect()
}

fn layout(dir: &Path) -> Result<Layout, ConfigError> {
    if !dir.is_dir() {
        return Err(ConfigError::Io {
            file: dir.display().to_string(),
            error: std::io::Error::new(std::io::ErrorKind::NotFound, "not a folder"),
        });
    }
    // The challenge's repository keeps the worlds in jackal_helper/worlds/BARN, the dataset in
    // world_files/, grid_files/ and path_files/.
    let candidates =
        [dir.to_path_buf(), dir.join("world_files"), dir.join("jackal_helper/worlds/BARN"), dir.join("worlds/BARN")];
    let grid_dir =
        [dir.join("grid_files"), dir.to_path_buf()].into_iter().find(|d| !numbered(d, "grid_", ".npy").is_empty());
    let found = candidates.iter().find(|d| !numbered(d, "world_", ".world").is_empty());
    let (worlds, from_worlds, world_dir) = match (found, &grid_dir) {
        (Some(d), _) => (numbered(d, "world_", ".world"), true, d.clone()),
        (None, Some(g)) => (numbered(g, "grid_", ".npy"), false, g.clone()),
        (None, None) => {
            return Err(ConfigError::Invalid {
                file: dir.display().to_string(),
                key: "worlds".into(),
                expected:
                    "BARN worlds: world_N.world files (the challenge's jackal_helper/worlds/BARN, or the dataset's \
                           world_files/) or grid_N.npy files (grid_files/), with path_files/path_N.npy beside them"
                        .into(),
            });
        }
    };
    let path_dir = [world_dir.join("path_files"), dir.join("path_files"), world_dir.clone(), dir.to_path_buf()]
        .into_iter()
        .find(|d| !numbered(d, "path_", ".npy").is_empty())
        .unwrap_or_else(|| world_dir.join("path_files"));
    Ok(Layout { worlds, from_worlds, world_dir, path_dir, grid_dir })
}

fn read(path: &Path) -> Result<Vec<u8>, ConfigError> {
    std::fs::read(path).map_err(|error| ConfigError::Io { file: path.display().to_string(), error })
}

/// Reads the BARN worlds of `dir` (see [`world_obstacles`], [`read_npy`]) in `split`, with
/// each world's reference path and difficulty metrics, into a BARN data file's text.
pub fn import_dir(dir: &Path, split: Split) -> Result<Imported, ConfigError> {
    let l = layout(dir)?;
    let mut entries = BTreeMap::new();
    let mut indices = Vec::new();
    for (&index, file) in l.worlds.iter().filter(|(i, _)| split.contains(**i)) {
        let label = file.display().to_string();
        let path_file = l.path_dir.join(format!("path_{index}.npy"));
        let path = path_cells(
            &path_file.display().to_string(),
            &read_npy(&path_file.display().to_string(), &read(&path_file)?)?,
        )?;
        // The obstacles, and the occupancy grid the metrics are measured on.
        let (cylinders, grid) = if l.from_worlds {
            let text_ = String::from_utf8(read(file)?)
                .map_err(|_| ConfigError::Parse { file: label.clone(), message: "not UTF-8 text".into() })?;
            let obstacles = world_obstacles(&label, &text_)?;
            let grid_file = l.grid_dir.as_ref().map(|d| d.join(format!("grid_{index}.npy"))).filter(|f| f.is_file());
            let grid = match grid_file {
                Some(g) => grid_cells(&g.display().to_string(), &read_npy(&g.display().to_string(), &read(&g)?)?)?,
                None => grid_from_obstacles(&obstacles),
            };
            let mut centres = Vec::with_capacity(obstacles.len());
            for o in obstacles {
                match o {
                    ObstacleSpec::Circle { center, radius } if (radius - CYLINDER_RADIUS).abs() < 1e-4 => {
                        centres.push(center)
                    }
                    _ => {
                        return Err(ConfigError::Invalid {
                            file: label,
                            key: "model".into(),
                            expected: format!(
                                "BARN worlds of cylinders of radius {CYLINDER_RADIUS} m only; found {o:?}"
                            ),
                        });
                    }
                }
            }
            if centres.is_empty() {
                return Err(ConfigError::Invalid {
                    file: label,
                    key: "model".into(),
                    expected: "cylinders (a BARN world holds a few hundred); this file has none".into(),
                });
            }
            (centres, grid)
        } else {
            let grid = grid_cells(&label, &read_npy(&label, &read(file)?)?)?;
            (cylinders_of(&grid), grid)
        };
        let difficulty = Difficulty::measure(&grid.c_space(ROBOT_CELLS), &path);
        let length = reference_path_length(&path);
        entries.insert(
            format!("world_{index}"),
            Entry {
                cylinders: cylinders.iter().map(|c| [round6(c[0]), round6(c[1])]).collect(),
                optimal_time_s: length / 2.0,
                reference_path_length_m: length,
                difficulty,
            },
        );
        indices.push(index);
    }
    if indices.is_empty() {
        return Err(ConfigError::Invalid {
            file: l.world_dir.display().to_string(),
            key: "worlds".into(),
            expected: format!(
                "at least one world in the {split:?} split; found indices {:?}",
                l.worlds.keys().collect::<Vec<_>>()
            ),
        });
    }
    let data = BarnFile {
        about: About {
            source: Some(format!(
                "imported by `rlnav barn import` from {} ({} files and path_files/path_N.npy)",
                l.world_dir.display(),
                if l.from_worlds { "world_N.world" } else { "grid_N.npy" }
            )),
            cylinder_radius_m: CYLINDER_RADIUS,
            start: StartPose { x: START[0], y: START[1], yaw: START[2] },
            goal: GoalPoint { x: GOAL[0], y: GOAL[1] },
            success_radius_m: 1.0,
            time_limit_s: 100.0,
            score: Some(super::SCORE_NOTE.into()),
            robot: Some(super::ROBOT_NOTE.into()),
        },
        worlds: entries,
    };
    let json = serde_json::to_string(&data)
        .map_err(|e| ConfigError::Parse { file: "<import>".into(), message: e.to_string() })?;
    Ok(Imported { json, indices, obstacles_from: if l.from_worlds { "world" } else { "grid" }, world_dir: l.world_dir })
}

fn round6(v: f32) -> f32 {
    ((v as f64 * 1e6).round() / 1e6) as f32
}

/// The occupancy grid behind a world file's cylinders: every cylinder on a cell centre of the
/// 30 x 30 field (the containment walls outside it are not part of the grid). The cells the
/// world files leave out (inside solid blocks) stay free here; they are enclosed by occupied
/// cells, so no metric measured from the path reaches them.
pub fn grid_from_obstacles(obstacles: &[ObstacleSpec]) -> BarnGrid {
    let mut g = BarnGrid::new(GRID_SIZE, GRID_SIZE);
    for o in obstacles {
        if let ObstacleSpec::Circle { center, .. } = o
            && let Some((r, c)) = BarnGrid::cell_at(*center)
        {
            g.set(r, c, true);
        }
    }
    g
}

/// A grid's cylinders as the dataset's world writer places them: the containment walls behind
/// the start (a back wall at y = 0.075 and two side walls to y = 5.075), then every occupied
/// cell that is not surrounded by occupied cells.
pub fn cylinders_of(grid: &BarnGrid) -> Vec<[f32; 2]> {
    let d = 2.0 * CYLINDER_RADIUS;
    let (x_lo, x_hi) = (super::difficulty::ROW0_X, super::difficulty::ROW0_X + (GRID_SIZE - 1) as f32 * d);
    let mut out = Vec::new();
    for k in 0..GRID_SIZE {
        out.push([x_hi - k as f32 * d, CYLINDER_RADIUS]);
    }
    // Side walls from y = 0.225 up to the field, one cell short of its first column.
    let wall_cells = ((super::difficulty::COL0_Y - d - CYLINDER_RADIUS) / d).round() as usize;
    for k in 1..=wall_cells {
        let y = CYLINDER_RADIUS + k as f32 * d;
        out.push([x_hi, y]);
        out.push([x_lo, y]);
    }
    for r in 0..GRID_SIZE {
        for c in 0..GRID_SIZE {
            if grid.occupied(r as i64, c as i64) && !grid.surrounded(r, c) {
                out.push(BarnGrid::cell_center(r, c));
            }
        }
    }
    out
}
