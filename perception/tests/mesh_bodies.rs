//! A part exported as several closed bodies that touch or overlap (a mold and its pins) loads as
//! one part: each body is kept closed and repaired alone, the mass is the union's, their shared
//! volume measured and counted once; a small planar hole is capped with a warning, and a larger or
//! bent one is refused with the file, its place and its size.

use std::path::{Path, PathBuf};

use perception::part::{LengthUnit, MAX_FILLED_HOLE_M, PartError, load_mesh, load_mesh_repaired};

/// The fixture: a mold block, a cap sitting on it and a pin poking through it (see its header).
fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/multibody/touching_bodies.obj")
}

/// A closed box over the breakpoints of each axis (millimetres), each face a grid of them, as
/// (vertices, outward counter-clockwise triangles).
fn grid_box(bps: [&[f64]; 3]) -> (Vec<[f64; 3]>, Vec<[usize; 3]>) {
    let mut vertices: Vec<[f64; 3]> = Vec::new();
    let mut id = |p: [f64; 3]| {
        vertices.iter().position(|q| *q == p).unwrap_or_else(|| {
            vertices.push(p);
            vertices.len() - 1
        })
    };
    let mut triangles = Vec::new();
    for axis in 0..3 {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        for side in [0, 1] {
            let fixed = if side == 0 {
                bps[axis][0]
            } else {
                *bps[axis].last().unwrap()
            };
            for i in 0..bps[u].len() - 1 {
                for j in 0..bps[v].len() - 1 {
                    let mut at = |ii: usize, jj: usize| {
                        let mut p = [0.0; 3];
                        p[axis] = fixed;
                        p[u] = bps[u][ii];
                        p[v] = bps[v][jj];
                        id(p)
                    };
                    let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
                    if side == 1 {
                        triangles.extend([[a, b, c], [a, c, d]]);
                    } else {
                        triangles.extend([[a, c, b], [a, d, c]]);
                    }
                }
            }
        }
    }
    (vertices, triangles)
}

/// OBJ text of one body, without the triangles whose centroid `cut` picks.
fn obj(body: &(Vec<[f64; 3]>, Vec<[usize; 3]>), cut: impl Fn([f64; 3]) -> bool) -> String {
    let (v, t) = body;
    let mut s = String::from("o body\n");
    for p in v {
        s += &format!("v {} {} {}\n", p[0], p[1], p[2]);
    }
    for f in t {
        let c = [0, 1, 2].map(|k| (v[f[0]][k] + v[f[1]][k] + v[f[2]][k]) / 3.0);
        if !cut(c) {
            s += &format!("f {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1);
        }
    }
    s
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn touching_and_overlapping_bodies_load_as_one_closed_part_weighing_as_their_union() {
    let (mesh, repairs) = load_mesh_repaired(&fixture(), LengthUnit::Mm).unwrap();
    mesh.check_closed().unwrap();
    // Nothing welded across bodies: the pin's bottom cap, a copy of the mold's bottom cell, stays.
    assert!(!repairs.changed(), "{repairs:?}");
    assert_eq!(repairs.bodies, 3, "{repairs:?}");
    assert_eq!(mesh.triangles.len(), 140);
    let sum = (48.0 + 4.0 + 1.08) * 1e-9;
    assert!(
        (mesh.volume() - sum).abs() < 1e-6 * sum,
        "{}",
        mesh.volume()
    );
    assert!((repairs.body_volume - sum).abs() < 1e-6 * sum);
    // The pin shares 0.6 × 0.6 × 2 mm with the mold; the cap only touches it. The union counts
    // the shared volume once.
    let shared = 0.72e-9;
    assert!(
        (repairs.overlap_volume - shared).abs() < 1e-6 * shared,
        "overlap {} mm³",
        repairs.overlap_volume * 1e9
    );
    let union = mesh.union_moments().union.volume;
    assert!(
        (union - (sum - shared)).abs() < 1e-6 * sum,
        "union {} mm³",
        union * 1e9
    );
    assert!(repairs.warnings().is_empty(), "{:?}", repairs.warnings());
    let notes = repairs.notes().join("\n");
    assert!(
        notes.contains("the file holds 3 bodies, each closed")
            && notes.contains("the bodies overlap by 0.7200 mm³")
            && notes.contains("the mass counts the overlap once"),
        "{notes}"
    );
}

#[test]
fn a_small_planar_hole_is_capped_with_a_warning() {
    // A 0.3 × 0.3 mm cell missing from the bottom of a 6 × 4 × 2 mm block: 0.42 mm across.
    let body = grid_box([&[0.0, 1.0, 1.3, 6.0], &[0.0, 1.0, 1.3, 4.0], &[0.0, 2.0]]);
    let text = obj(&body, |c| {
        c[2] == 0.0 && (1.0..1.3).contains(&c[0]) && (1.0..1.3).contains(&c[1])
    });
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "capless.obj", &text);
    let (mesh, repairs) = load_mesh_repaired(&path, LengthUnit::Mm).unwrap();
    mesh.check_closed().unwrap();
    assert_eq!(repairs.filled_holes, 1, "{repairs:?}");
    assert!((repairs.largest_filled_hole - 0.3e-3 * 2f64.sqrt()).abs() < 1e-9);
    assert!(
        (mesh.volume() - 48e-9).abs() < 1e-6 * 48e-9,
        "{}",
        mesh.volume()
    );
    let warnings = repairs.warnings().join("\n");
    assert!(
        warnings.contains(
            "capped 1 small planar holes (the largest 0.424 mm across; holes up to 0.500 mm"
        ),
        "{warnings}"
    );
    assert_eq!(MAX_FILLED_HOLE_M, 0.5e-3);
}

#[test]
fn a_large_hole_in_one_body_is_refused_with_the_file_its_place_and_size() {
    // The fixture's mold with a 2 × 2 mm cell of its bottom missing; the other bodies are closed.
    let text = std::fs::read_to_string(fixture()).unwrap();
    let (mut v, mut kept) = (Vec::new(), String::new());
    let mut in_mold = false;
    for line in text.lines() {
        let w: Vec<&str> = line.split_whitespace().collect();
        match w.first() {
            Some(&"o") => in_mold = w[1] == "mold",
            Some(&"v") => v.push([1, 2, 3].map(|k| w[k].parse::<f64>().unwrap())),
            Some(&"f") if in_mold => {
                let c = [0, 1, 2].map(|k| {
                    w[1..]
                        .iter()
                        .map(|i| v[i.parse::<usize>().unwrap() - 1][k])
                        .sum::<f64>()
                        / 3.0
                });
                if c[2] == 0.0 && (3.0..5.0).contains(&c[0]) && (1.0..3.0).contains(&c[1]) {
                    continue;
                }
            }
            _ => {}
        }
        kept += line;
        kept += "\n";
    }
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "holed_mold.obj", &kept);
    let err = load_mesh(&path, LengthUnit::Mm).unwrap_err();
    assert!(matches!(err, PartError::NotClosed { .. }), "{err}");
    let msg = err.to_string();
    assert!(
        msg.contains("holed_mold.obj")
            && msg.contains("6 open edges (6 on a boundary")
            && msg.contains(
                "around (4.0000, 2.0000, 0.0000) mm spanning 2.0000 × 2.0000 × 0.0000 mm"
            ),
        "{msg}"
    );
}

#[test]
fn a_small_hole_that_is_not_planar_is_refused() {
    // A 0.2 mm corner of a block missing on two faces: the rim bends round the edge.
    let body = grid_box([&[0.0, 0.2, 6.0], &[0.0, 0.2, 4.0], &[0.0, 0.2, 2.0]]);
    let text = obj(&body, |c| {
        let small = |x: f64| x < 0.2;
        (c[2] == 0.0 && small(c[0]) && small(c[1])) || (c[0] == 0.0 && small(c[1]) && small(c[2]))
    });
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "bent.obj", &text);
    let msg = load_mesh(&path, LengthUnit::Mm).unwrap_err().to_string();
    assert!(
        msg.contains("bent.obj") && msg.contains("not closed (6 open edges"),
        "{msg}"
    );
}
