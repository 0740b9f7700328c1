//! Real-CAD-style meshes, generated here with each defect exports commonly contain, load as the
//! solid they describe, with every repair counted; only a truly open mesh is refused, and the
//! error says where it is open.

use std::io::Write;
use std::path::{Path, PathBuf};

use nalgebra::{Point3, Vector3};
use perception::part::{LengthUnit, MeshDefect, PartError, TriMesh, load_mesh, load_mesh_repaired};

/// The project's main shell (a closed sheet-metal connector shell, 216 triangles), metres.
fn main_shell() -> TriMesh {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/parts/main_shell.obj");
    load_mesh(&path, LengthUnit::Mm).unwrap()
}

/// A box of the given size in millimetres, each face tessellated as an n × n grid of quads, with
/// every face's vertices stored apart (as STL and many OBJ exports do).
fn tessellated_box(
    size: [f64; 3],
    origin: [f64; 3],
    n: usize,
) -> (Vec<Point3<f64>>, Vec<[u32; 3]>) {
    let mut vertices = Vec::new();
    let mut triangles = Vec::new();
    for axis in 0..3 {
        for side in [0.0, 1.0] {
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let base = vertices.len() as u32;
            for i in 0..=n {
                for j in 0..=n {
                    let mut p = origin;
                    p[axis] += side * size[axis];
                    p[u] += size[u] * i as f64 / n as f64;
                    p[v] += size[v] * j as f64 / n as f64;
                    vertices.push(Point3::from(p));
                }
            }
            let id = |i: usize, j: usize| base + (i * (n + 1) + j) as u32;
            for i in 0..n {
                for j in 0..n {
                    let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
                    // u × v is +axis: counter-clockwise seen from outside on the far side.
                    if side == 1.0 {
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

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::File::create(&p).unwrap().write_all(bytes).unwrap();
    p
}

/// A binary STL of the triangles (single precision, corners stored per triangle), millimetres.
fn stl(vertices: &[Point3<f64>], triangles: &[[u32; 3]]) -> Vec<u8> {
    let tris: Vec<stl_io::Triangle> = triangles
        .iter()
        .map(|t| stl_io::Triangle {
            normal: stl_io::Normal::new([0.0, 0.0, 0.0]),
            vertices: t.map(|i| {
                let p = vertices[i as usize];
                stl_io::Vertex::new([p.x as f32, p.y as f32, p.z as f32])
            }),
        })
        .collect();
    let mut bytes = Vec::new();
    stl_io::write_stl(&mut bytes, tris.iter()).unwrap();
    bytes
}

fn obj(vertices: &[Point3<f64>], triangles: &[[u32; 3]]) -> String {
    let mut s = String::new();
    for p in vertices {
        s += &format!("v {:.9} {:.9} {:.9}\n", p.x, p.y, p.z);
    }
    for t in triangles {
        s += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    s
}

/// The shell in millimetres with `count` zero-area triangles an exporter leaves at a corner: a
/// corner of a triangle is moved by `jitter` mm (a stray copy of the vertex) and a sliver
/// between the copy and the original fills the gap.
fn with_zero_area_slivers(
    mesh: &TriMesh,
    count: usize,
    jitter: f64,
) -> (Vec<Point3<f64>>, Vec<[u32; 3]>) {
    let mut vertices: Vec<Point3<f64>> = mesh.vertices.iter().map(|p| p * 1e3).collect();
    let mut triangles = mesh.triangles.clone();
    let step = triangles.len() / count;
    for k in 0..count {
        let ti = k * step;
        let [a, b, c] = triangles[ti];
        let stray = vertices[b as usize] + Vector3::new(jitter, -jitter, jitter);
        vertices.push(stray);
        let s = (vertices.len() - 1) as u32;
        triangles[ti] = [a, s, c];
        // Zero area: two corners a jitter apart. Without welding, edges a–s and s–b stay open.
        triangles.push([s, b, c]);
    }
    (vertices, triangles)
}

#[test]
fn a_closed_shell_with_a_dozen_zero_area_triangles_loads_with_a_warning() {
    let shell = main_shell();
    let (v, t) = with_zero_area_slivers(&shell, 12, 2e-6);
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "shell.stl", &stl(&v, &t));
    let (mesh, repairs) = load_mesh_repaired(&path, LengthUnit::Mm).unwrap();
    assert_eq!(repairs.welded_vertices, 12, "{repairs:?}");
    assert_eq!(repairs.collapsed_triangles, 12, "{repairs:?}");
    assert_eq!(mesh.triangles.len(), shell.triangles.len());
    assert!(
        (mesh.volume() - shell.volume()).abs() < 1e-6 * shell.volume(),
        "{} vs {}",
        mesh.volume(),
        shell.volume()
    );
    let warnings = repairs.warnings().join("\n");
    assert!(
        warnings.contains("welded 12 vertices") && warnings.contains("dropped 12 triangles"),
        "{warnings}"
    );
    // Without the weld the same mesh is open exactly where the stray copies are.
    let raw = TriMesh::new(v.clone(), t.clone());
    assert!(matches!(raw.check_closed(), Err(MeshDefect::Open { .. })));
}

#[test]
fn collinear_slivers_are_dropped_and_their_t_junctions_closed() {
    // A box whose +z face has three collinear slivers along a grid line, as a mesher leaves where
    // one side of an edge is split and the other is not.
    let (mut v, mut t) = tessellated_box([9.0, 6.0, 3.0], [-4.5, -3.0, -1.5], 2);
    let mut slivers = 0;
    let mut dropped_only = 0;
    for k in 0..t.len() {
        let [a, b, c] = t[k];
        let (pa, pb, pc) = (v[a as usize], v[b as usize], v[c as usize]);
        if !(pa.z == 1.5 && pb.z == 1.5 && pc.z == 1.5) {
            continue;
        }
        // Split edge a–b at its midpoint m: this triangle becomes two, and a sliver (a, m, b)
        // stands in for the split on the far side (whose triangle still uses b→a).
        let m = nalgebra::center(&pa, &pb);
        v.push(m);
        let mi = (v.len() - 1) as u32;
        t[k] = [a, mi, c];
        t.push([mi, b, c]);
        if slivers < 3 {
            t.push([b, mi, a]);
            slivers += 1;
        } else {
            // Or no sliver at all: a bare T-junction.
            dropped_only += 1;
        }
        if slivers + dropped_only == 5 {
            break;
        }
    }
    let mut mesh = TriMesh::new(v, t);
    let (lo, hi) = mesh.aabb();
    let repairs = mesh.repair_with(1e-5 * (hi - lo).norm());
    assert_eq!(repairs.zero_area_triangles, 3, "{repairs:?}");
    assert_eq!(repairs.split_triangles, 5, "{repairs:?}");
    mesh.check_closed().unwrap();
    assert!(
        (mesh.volume() - 9.0 * 6.0 * 3.0).abs() < 1e-9,
        "{}",
        mesh.volume()
    );
    assert!((mesh.area() - 2.0 * (54.0 + 27.0 + 18.0)).abs() < 1e-9);
}

#[test]
fn vertices_duplicated_per_face_with_export_noise_are_welded() {
    let (mut v, t) = tessellated_box([9.0, 6.0, 3.0], [-4.5, -3.0, -1.5], 3);
    // Each face stores its own copy of the shared edges' vertices; perturb every vertex by a
    // different few float32 steps (under 1e-6 mm) so no two copies are bit-identical.
    for (i, p) in v.iter_mut().enumerate() {
        let e = 1e-8 * i as f64;
        *p += Vector3::new(e, -e, 0.5 * e);
    }
    let distinct_positions = 6 * 16 - 12 * 4 + 8; // grid points per face, shared edges, corners
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "box.obj", obj(&v, &t).as_bytes());
    let (mesh, repairs) = load_mesh_repaired(&path, LengthUnit::Mm).unwrap();
    assert_eq!(mesh.vertices.len(), distinct_positions);
    assert_eq!(
        repairs.welded_vertices,
        v.len() - distinct_positions,
        "{repairs:?}"
    );
    assert_eq!(repairs.bodies, 1);
    assert!((mesh.volume() - 162e-9).abs() < 1e-6 * 162e-9);
}

#[test]
fn several_touching_bodies_with_shared_edges_form_one_closed_solid() {
    // Three boxes exported as separate bodies: b sits on a (sharing a face, same tessellation),
    // c touches a along one vertical edge only, and d floats apart.
    let mut v = Vec::new();
    let mut t = Vec::new();
    let mut add = |(bv, bt): (Vec<Point3<f64>>, Vec<[u32; 3]>)| {
        let off = v.len() as u32;
        v.extend(bv);
        t.extend(bt.into_iter().map(|x| x.map(|i| i + off)));
    };
    add(tessellated_box([4.0, 4.0, 2.0], [0.0, 0.0, 0.0], 2));
    add(tessellated_box([4.0, 4.0, 1.0], [0.0, 0.0, 2.0], 2));
    add(tessellated_box([2.0, 2.0, 2.0], [4.0, 4.0, 0.0], 2));
    add(tessellated_box([1.0, 1.0, 1.0], [8.0, 0.0, 0.0], 1));
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "bodies.stl", &stl(&v, &t));
    let (mesh, repairs) = load_mesh_repaired(&path, LengthUnit::Mm).unwrap();
    // Each used by 4 triangles: a/b's shared face's 8 rim, 4 inner and 4 diagonal edges, and
    // the two segments of the edge a and c share.
    assert_eq!(repairs.non_manifold_edges, 16 + 2, "{repairs:?}");
    assert_eq!(repairs.bodies, 2, "{repairs:?}");
    let expected = (32.0 + 16.0 + 8.0 + 1.0) * 1e-9;
    assert!(
        (mesh.volume() - expected).abs() < 1e-6 * expected,
        "{}",
        mesh.volume()
    );
    let notes = repairs.notes().join("\n");
    assert!(
        notes.contains("18 edges are shared by more than two triangles")
            && notes.contains("the file holds 2 bodies, each closed"),
        "{notes}"
    );
}

#[test]
fn duplicate_triangles_are_dropped() {
    let (v, mut t) = tessellated_box([9.0, 6.0, 3.0], [-4.5, -3.0, -1.5], 1);
    let copies: Vec<_> = t[..4].to_vec();
    t.extend(copies.iter().map(|x| [x[1], x[2], x[0]]));
    let mut mesh = TriMesh::new(v, t);
    let repairs = mesh.repair();
    assert_eq!(repairs.duplicate_triangles, 4);
    mesh.check_closed().unwrap();
    assert!((mesh.volume() - 162.0).abs() < 1e-9);
}

#[test]
fn a_truly_open_mesh_is_refused_and_its_hole_located() {
    // A 2 × 2 patch of grid cells cut out of the +x face, centred at (4.5, 1.5, 0.75) mm.
    let (v, t) = tessellated_box([9.0, 6.0, 3.0], [-4.5, -3.0, -1.5], 4);
    let centroid = |x: &[u32; 3]| {
        Point3::from(
            x.iter()
                .map(|&i| v[i as usize].coords)
                .sum::<Vector3<f64>>()
                / 3.0,
        )
    };
    let in_patch = |p: Point3<f64>| p.x == 4.5 && p.y > 0.0 && p.y < 3.0 && p.z > 0.0 && p.z < 1.5;
    let kept: Vec<[u32; 3]> = t
        .iter()
        .copied()
        .filter(|x| !in_patch(centroid(x)))
        .collect();
    assert_eq!(kept.len(), t.len() - 8);
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "holed.stl", &stl(&v, &kept));
    let err = load_mesh(&path, LengthUnit::Mm).unwrap_err();
    let PartError::NotClosed { defect, .. } = &err else {
        panic!("expected NotClosed, got {err}");
    };
    let MeshDefect::Open {
        boundary,
        misoriented,
        regions,
    } = defect
    else {
        panic!("expected an open mesh, got {defect}");
    };
    assert_eq!(
        (*boundary, *misoriented, regions.len()),
        (8, 0, 1),
        "{defect}"
    );
    let c = regions[0].centre();
    assert!(
        (c - Point3::new(4.5e-3, 1.5e-3, 0.75e-3)).norm() < 1e-9,
        "hole reported at {c}"
    );
    let msg = err.to_string();
    assert!(
        msg.contains("holed.stl")
            && msg.contains("8 open edges (8 on a boundary")
            && msg.contains(
                "around (4.5000, 1.5000, 0.7500) mm spanning 0.0000 × 3.0000 × 1.5000 mm"
            ),
        "{msg}"
    );
}

#[test]
fn the_project_meshes_need_no_repair_and_repairing_twice_changes_nothing() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/parts");
    for name in [
        "main_shell",
        "insert_mold",
        "top_shell",
        "fixture_nest",
        "tag_board",
    ] {
        let path = dir.join(format!("{name}.obj"));
        let (mesh, repairs) = load_mesh_repaired(&path, LengthUnit::Mm).unwrap();
        assert!(!repairs.changed(), "{name}: {repairs:?}");
        assert!(
            repairs.warnings().is_empty(),
            "{name}: {:?}",
            repairs.warnings()
        );
        let mut again = mesh.clone();
        assert!(!again.repair().changed());
        assert_eq!(again, mesh);
    }
    let shell = main_shell();
    assert_eq!(shell.triangles.len(), 216);
}
