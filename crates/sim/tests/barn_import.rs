//! `rlnav barn import`'s reading: BARN folders as the challenge (world files) and the dataset
//! (grids) lay them out give the same worlds, the reference path lengths and difficulty
//! metrics; the shipped worlds' cylinders are exactly what the dataset's world writer makes of
//! their grids; every bad file is an error that names it.

use rlnav_sim::barn::import::{NpyArray, cylinders_of, grid_from_obstacles, read_npy, reference_path_length};
use rlnav_sim::barn::{BarnGrid, BarnSet, Difficulty, Split, import_dir};
use rlnav_sim::geometry::ObstacleSpec;
use std::path::{Path, PathBuf};

/// A `.npy` (format 1.0) of little-endian int64.
fn npy_i64(shape: &[usize], data: &[i64]) -> Vec<u8> {
    let shape_text = match shape {
        [n] => format!("({n},)"),
        _ => format!("({})", shape.iter().map(|s| s.to_string()).collect::<Vec<_>>().join(", ")),
    };
    let mut header = format!("{{'descr': '<i8', 'fortran_order': False, 'shape': {shape_text}, }}");
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend((header.len() as u16).to_le_bytes());
    out.extend(header.as_bytes());
    for v in data {
        out.extend(v.to_le_bytes());
    }
    out
}

/// A Gazebo world file with a ground plane and one model per cylinder; the `<state>` section
/// repeats the poses, as Gazebo saves them.
fn world_file(cylinders: &[[f32; 2]]) -> String {
    let mut s = String::from("<?xml version='1.0'?>\n<sdf version='1.6'>\n  <world name='default'>\n");
    s += "    <model name='ground_plane'><static>1</static><link name='link'><collision name='collision'>\
          <geometry><plane><normal>0 0 1</normal><size>100 100</size></plane></geometry></collision></link></model>\n";
    for (i, c) in cylinders.iter().enumerate() {
        s += &format!(
            "    <model name='unit_cylinder_{i}'>\n      <static>1</static>\n      <pose frame=''>{:.6} {:.6} 0 0 0 0</pose>\n      \
             <link name='link'><collision name='collision'><geometry><cylinder><radius>0.075000</radius>\
             <length>1</length></cylinder></geometry></collision></link>\n    </model>\n",
            c[0], c[1]
        );
    }
    s += "    <state world_name='default'>\n";
    for (i, c) in cylinders.iter().enumerate() {
        s += &format!(
            "      <model name='unit_cylinder_{i}'><pose frame=''>{:.6} {:.6} 0 0 0 0</pose></model>\n",
            c[0], c[1]
        );
    }
    s + "    </state>\n  </world>\n</sdf>\n"
}

/// A BARN-like grid: side walls (rows 0 and 29), a solid 5 x 5 block (whose middle cells the
/// world file leaves out) and a few single cells; and a path down the middle round the block.
fn sample() -> (BarnGrid, Vec<[i64; 2]>) {
    let mut g = BarnGrid::new(30, 30);
    for c in 0..30 {
        g.set(0, c, true);
        g.set(29, c, true);
    }
    for r in 6..11 {
        for c in 10..15 {
            g.set(r, c, true);
        }
    }
    for (r, c) in [(20, 5), (22, 18), (24, 25)] {
        g.set(r, c, true);
    }
    let path: Vec<[i64; 2]> = (0..30).map(|c| [15 + (c / 10) as i64, c as i64]).collect();
    (g, path)
}

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("rlnav-barn-import-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Writes world `index` the challenge's way (world file + path_files/) and the dataset's way
/// (grid_files/ + path_files/).
fn write_both(challenge: &Path, dataset: &Path, index: u32, g: &BarnGrid, path: &[[i64; 2]]) {
    let flat: Vec<i64> = path.iter().flatten().copied().collect();
    let path_npy = npy_i64(&[path.len(), 2], &flat);
    std::fs::create_dir_all(challenge.join("path_files")).unwrap();
    std::fs::write(challenge.join(format!("world_{index}.world")), world_file(&cylinders_of(g))).unwrap();
    std::fs::write(challenge.join(format!("path_files/path_{index}.npy")), &path_npy).unwrap();
    for sub in ["grid_files", "path_files"] {
        std::fs::create_dir_all(dataset.join(sub)).unwrap();
    }
    let cells: Vec<i64> =
        (0..30).flat_map(|r| (0..30).map(move |c| (r, c))).map(|(r, c)| g.occupied(r, c) as i64).collect();
    std::fs::write(dataset.join(format!("grid_files/grid_{index}.npy")), npy_i64(&[30, 30], &cells)).unwrap();
    std::fs::write(dataset.join(format!("path_files/path_{index}.npy")), &path_npy).unwrap();
}

#[test]
fn world_files_and_grids_import_to_the_same_worlds() {
    let (challenge, dataset) = (temp_dir("challenge"), temp_dir("dataset"));
    let (g, path) = sample();
    for index in [0, 5, 6] {
        write_both(&challenge, &dataset, index, &g, &path);
    }
    let a = import_dir(&challenge, Split::All).unwrap();
    let b = import_dir(&dataset, Split::All).unwrap();
    assert_eq!((a.obstacles_from, b.obstacles_from), ("world", "grid"));
    assert_eq!(a.indices, vec![0, 5, 6]);
    let (sa, sb) = (BarnSet::parse("a", &a.json).unwrap(), BarnSet::parse("b", &b.json).unwrap());
    let expected = Difficulty::measure(&g.c_space(2), &path).unwrap();
    for (wa, wb) in sa.worlds.iter().zip(&sb.worlds) {
        assert_eq!(wa.spec.obstacles, wb.spec.obstacles, "{}", wa.name);
        assert_eq!(wa.path_length, reference_path_length(&path));
        assert_eq!(wa.path_length, wb.path_length);
        // The world file lacks the block's 3 x 3 middle: the metrics are the same.
        assert_eq!(wa.difficulty, Some(expected));
        assert_eq!(wb.difficulty, Some(expected));
    }
    // 30 + 2 x 33 containment cylinders, 60 wall cells, the block's 16 edge cells, 3 singles.
    assert_eq!(sa.worlds[0].spec.obstacles.len(), 96 + 60 + 16 + 3);
    // The challenge's split.
    assert_eq!(import_dir(&challenge, Split::Test).unwrap().indices, vec![0, 6]);
    assert_eq!(import_dir(&challenge, Split::Train).unwrap().indices, vec![5]);
    // The path length as the challenge's run.py computes it: start, the cells shifted, goal.
    let straight = [[15i64, 0], [15, 29]];
    let (x, y0, y1) = (15.0 * 0.15 - 4.575, 5.075, 29.0 * 0.15 + 5.075);
    let expect = (x + 2.25f64).hypot(y0 - 3.0) + (y1 - y0) + (x + 2.25f64).hypot(13.0 - y1);
    assert!((reference_path_length(&straight) as f64 - expect).abs() < 1e-4);
}

#[test]
fn the_shipped_worlds_are_what_the_dataset_writer_makes_of_their_grids() {
    let set = BarnSet::shipped().unwrap();
    for w in &set.worlds {
        let grid = grid_from_obstacles(&w.spec.obstacles);
        let mut rebuilt: Vec<[f32; 2]> = cylinders_of(&grid);
        let mut shipped: Vec<[f32; 2]> = w
            .spec
            .obstacles
            .iter()
            .map(|o| match o {
                ObstacleSpec::Circle { center, .. } => *center,
                other => panic!("{}: {other:?}", w.name),
            })
            .collect();
        let key = |p: &[f32; 2]| ((p[0] * 1000.0).round() as i64, (p[1] * 1000.0).round() as i64);
        rebuilt.sort_by_key(key);
        shipped.sort_by_key(key);
        assert_eq!(
            rebuilt.iter().map(key).collect::<Vec<_>>(),
            shipped.iter().map(key).collect::<Vec<_>>(),
            "{}",
            w.name
        );
        let d = w.difficulty.unwrap_or_else(|| panic!("{} has no difficulty metrics", w.name));
        assert!(d.closest_wall > 0.0 && d.tortuosity >= 1.0 && d.characteristic_dimension > 0.0, "{}: {d:?}", w.name);
    }
}

#[test]
fn npy_files_of_other_layouts_read_the_same() {
    // A 2 x 3 array of big-endian int32 in Fortran order, and a little-endian float32 vector.
    let header = |descr: &str, fortran: bool, shape: &str| {
        let h = format!(
            "{{'descr': '{descr}', 'fortran_order': {}, 'shape': {shape}, }}\n",
            if fortran { "True" } else { "False" }
        );
        let mut out = b"\x93NUMPY\x01\x00".to_vec();
        out.extend((h.len() as u16).to_le_bytes());
        out.extend(h.as_bytes());
        out
    };
    let mut f = header(">i4", true, "(2, 3)");
    for v in [1i32, 4, 2, 5, 3, -6] {
        f.extend(v.to_be_bytes());
    }
    assert_eq!(read_npy("f", &f).unwrap(), NpyArray { shape: vec![2, 3], data: vec![1.0, 2.0, 3.0, 4.0, 5.0, -6.0] });
    let mut v = header("<f4", false, "(2,)");
    for x in [0.5f32, -1.25] {
        v.extend(x.to_le_bytes());
    }
    assert_eq!(read_npy("v", &v).unwrap().data, vec![0.5, -1.25]);
    let mut b = header("|b1", false, "(3,)");
    b.extend([1u8, 0, 1]);
    assert_eq!(read_npy("b", &b).unwrap().data, vec![1.0, 0.0, 1.0]);
}

#[test]
fn bad_barn_folders_are_errors_that_name_the_file() {
    let (g, path) = sample();
    let err = |dir: &Path| import_dir(dir, Split::All).unwrap_err().to_string();

    let empty = temp_dir("empty");
    let e = err(&empty);
    assert!(e.contains("world_N.world") && e.contains("grid_N.npy"), "{e}");
    assert!(err(&empty.join("nowhere")).contains("not a folder"));

    // A world without its path.
    let (missing, other) = (temp_dir("missing"), temp_dir("other"));
    write_both(&missing, &other, 3, &g, &path);
    std::fs::remove_file(missing.join("path_files/path_3.npy")).unwrap();
    std::fs::write(missing.join("path_files/path_4.npy"), b"").unwrap();
    let e = err(&missing);
    assert!(e.contains("path_3.npy") && e.contains("cannot read"), "{e}");

    // A truncated path, a path that leaves the grid, a grid of the wrong shape, not numpy.
    let (c, d) = (temp_dir("c"), temp_dir("d"));
    write_both(&c, &d, 1, &g, &path);
    let p = c.join("path_files/path_1.npy");
    let bytes = std::fs::read(&p).unwrap();
    std::fs::write(&p, &bytes[..bytes.len() - 5]).unwrap();
    let e = err(&c);
    assert!(e.contains("path_1.npy") && e.contains("truncated"), "{e}");
    std::fs::write(&p, npy_i64(&[2, 2], &[0, 0, 40, 3])).unwrap();
    let e = err(&c);
    assert!(e.contains("path_1.npy") && e.contains("in 0..30"), "{e}");
    std::fs::write(&p, b"row,col\n1,2\n").unwrap();
    assert!(err(&c).contains("not a numpy .npy file"));
    std::fs::write(d.join("grid_files/grid_1.npy"), npy_i64(&[3, 3], &[0; 9])).unwrap();
    let e = err(&d);
    assert!(e.contains("grid_1.npy") && e.contains("30 x 30"), "{e}");

    // Malformed XML, a mesh, an include, no cylinders.
    let w = temp_dir("w");
    write_both(&w, &temp_dir("w2"), 2, &g, &path);
    let world = w.join("world_2.world");
    std::fs::write(&world, "<sdf><world><model name='a'>\n<pose>1 2 0 0 0 0</pose>\n</world></sdf>").unwrap();
    let e = err(&w);
    assert!(e.contains("world_2.world") && e.contains("line"), "{e}");
    let mesh = "<sdf><world><model name='rock'><link name='l'><collision name='c'><geometry><mesh><uri>rock.dae</uri>\
                </mesh></geometry></collision></link></model></world></sdf>";
    std::fs::write(&world, mesh).unwrap();
    let e = err(&w);
    assert!(e.contains("world_2.world") && e.contains("rock") && e.contains("mesh"), "{e}");
    std::fs::write(&world, "<sdf><world><include><uri>model://jackal</uri></include></world></sdf>").unwrap();
    let e = err(&w);
    assert!(e.contains("model://jackal") && e.contains("include"), "{e}");
    std::fs::write(&world, "<sdf><world><model name='ground_plane'/></world></sdf>").unwrap();
    let e = err(&w);
    assert!(e.contains("world_2.world") && e.contains("none"), "{e}");
    std::fs::write(&world, "<sdf><world><model name='c'><pose>1 2 0</pose></model></world></sdf>").unwrap();
    let e = err(&w);
    assert!(e.contains("world_2.world") && e.contains("6 numbers"), "{e}");
}
