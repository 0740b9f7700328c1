//! Loading meshes from OBJ, STL and PLY, and the errors a user gets for bad files.

use std::io::Write;
use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use perception::part::{LengthUnit, PartError, TriMesh, load_mesh};

/// A 9 × 6 × 3 mm box as (vertices in mm, outward triangles).
fn block() -> (Vec<[f64; 3]>, Vec<[usize; 3]>) {
    let mesh = TriMesh::cuboid(Vector3::new(9.0, 6.0, 3.0));
    let v = mesh.vertices.iter().map(|p| [p.x, p.y, p.z]).collect();
    let t = mesh
        .triangles
        .iter()
        .map(|t| t.map(|i| i as usize))
        .collect();
    (v, t)
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::File::create(&p).unwrap().write_all(bytes).unwrap();
    p
}

fn obj_text(scale: f64, drop_last: bool) -> String {
    let (v, mut t) = block();
    if drop_last {
        t.pop();
    }
    let mut s = String::new();
    for p in v {
        s += &format!("v {} {} {}\n", p[0] * scale, p[1] * scale, p[2] * scale);
    }
    for f in t {
        s += &format!("f {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1);
    }
    s
}

fn check_block(mesh: &perception::part::TriMesh) {
    let e = mesh.extents();
    assert!(
        (e.x - 0.009).abs() < 1e-9 && (e.y - 0.006).abs() < 1e-9 && (e.z - 0.003).abs() < 1e-9,
        "{e}"
    );
    assert!((mesh.volume() - 0.009 * 0.006 * 0.003).abs() < 1e-15);
}

#[test]
fn obj_stl_and_ply_load_to_the_same_solid() {
    let dir = tempfile::tempdir().unwrap();
    let obj = write(dir.path(), "b.obj", obj_text(1.0, false).as_bytes());
    check_block(&load_mesh(&obj, LengthUnit::Mm).unwrap());

    let (v, t) = block();
    let tris: Vec<stl_io::Triangle> = t
        .iter()
        .map(|f| stl_io::Triangle {
            normal: stl_io::Normal::new([0.0, 0.0, 0.0]),
            vertices: f.map(|i| stl_io::Vertex::new(v[i].map(|c| c as f32))),
        })
        .collect();
    let mut bytes = Vec::new();
    stl_io::write_stl(&mut bytes, tris.iter()).unwrap();
    let stl = write(dir.path(), "b.stl", &bytes);
    check_block(&load_mesh(&stl, LengthUnit::Mm).unwrap());

    let mut ply = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        v.len(),
        t.len()
    );
    for p in &v {
        ply += &format!("{} {} {}\n", p[0], p[1], p[2]);
    }
    for f in &t {
        ply += &format!("3 {} {} {}\n", f[0], f[1], f[2]);
    }
    let ply = write(dir.path(), "b.ply", ply.as_bytes());
    check_block(&load_mesh(&ply, LengthUnit::Mm).unwrap());
}

#[test]
fn a_millimetre_part_read_as_metres_is_caught_with_the_fix() {
    let dir = tempfile::tempdir().unwrap();
    let obj = write(dir.path(), "b.obj", obj_text(1.0, false).as_bytes());
    let err = load_mesh(&obj, LengthUnit::M).unwrap_err();
    assert!(matches!(err, PartError::ImplausibleSize { .. }), "{err}");
    let msg = err.to_string();
    assert!(
        msg.contains("b.obj") && msg.contains("unit = \"mm\""),
        "{msg}"
    );
    // And the other way round: a part exported in metres but declared in millimetres.
    let metres = write(dir.path(), "m.obj", obj_text(1e-3, false).as_bytes());
    let msg = load_mesh(&metres, LengthUnit::Mm).unwrap_err().to_string();
    assert!(msg.contains("unit = \"m\""), "{msg}");
}

#[test]
fn missing_empty_open_and_unknown_files_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("nope.obj");
    let msg = load_mesh(&missing, LengthUnit::Mm).unwrap_err().to_string();
    assert!(
        msg.contains("nope.obj") && msg.contains("cannot read"),
        "{msg}"
    );

    let empty = write(dir.path(), "empty.obj", b"# nothing\n");
    let err = load_mesh(&empty, LengthUnit::Mm).unwrap_err();
    assert!(matches!(err, PartError::Empty { .. }), "{err}");

    let open = write(dir.path(), "open.obj", obj_text(1.0, true).as_bytes());
    let msg = load_mesh(&open, LengthUnit::Mm).unwrap_err().to_string();
    assert!(
        msg.contains("open.obj") && msg.contains("not closed") && msg.contains("watertight"),
        "{msg}"
    );

    // IGES is CAD too, but not read: STEP is (see cell/tests/prepare_step.rs).
    let iges = write(
        dir.path(),
        "part.igs",
        b"                                        S      1",
    );
    let err = load_mesh(&iges, LengthUnit::Mm).unwrap_err();
    assert!(matches!(err, PartError::UnknownFormat { .. }), "{err}");
    assert!(err.to_string().contains(".step or .stp"), "{err}");

    let garbage = write(dir.path(), "g.stl", &[7u8; 40]);
    assert!(load_mesh(&garbage, LengthUnit::Mm).is_err());
}
