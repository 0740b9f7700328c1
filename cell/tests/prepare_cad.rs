//! `cell parts prepare` on a connector shell as CAD exports it: closed, but with a dozen
//! zero-area triangles on stray copies of vertices. It is prepared, and each repair is counted.

use std::path::Path;

use cell::prepare::prepare_catalog;
use sim::stable_poses::DropSettings;

#[test]
fn a_closed_shell_with_a_dozen_zero_area_triangles_is_prepared_with_its_repairs_counted() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/parts");
    let text = std::fs::read_to_string(root.join("main_shell.obj")).unwrap();
    let mut vertices: Vec<[f64; 3]> = Vec::new();
    let mut faces: Vec<[usize; 3]> = Vec::new();
    for line in text.lines() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => vertices.push([0, 1, 2].map(|_| words.next().unwrap().parse().unwrap())),
            Some("f") => {
                faces.push([0, 1, 2].map(|_| words.next().unwrap().parse::<usize>().unwrap() - 1))
            }
            _ => {}
        }
    }
    // A stray copy of one corner of every 18th triangle, 2 nm off, and the zero-area sliver
    // between the copy and the original that an exporter leaves.
    let original = faces.len();
    for k in 0..12 {
        let [a, b, c] = faces[k * 18];
        let p = vertices[b];
        vertices.push([p[0] + 2e-6, p[1] - 2e-6, p[2] + 2e-6]);
        let s = vertices.len() - 1;
        faces[k * 18] = [a, s, c];
        faces.push([s, b, c]);
    }
    let dir = tempfile::tempdir().unwrap();
    let mut obj = String::new();
    for v in &vertices {
        obj += &format!("v {:.9} {:.9} {:.9}\n", v[0], v[1], v[2]);
    }
    for f in &faces {
        obj += &format!("f {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1);
    }
    std::fs::write(dir.path().join("shell.obj"), obj).unwrap();
    let catalog = dir.path().join("c.toml");
    std::fs::write(
        &catalog,
        "name = \"cad\"\n[[part]]\nname = \"shell\"\nrole = \"main\"\nmesh = \"shell.obj\"\n\
         unit = \"mm\"\nmaterial = \"metal\"\n",
    )
    .unwrap();
    let settings = DropSettings {
        drops: 64,
        ..DropSettings::default()
    };
    let prepared = prepare_catalog(&catalog, &settings, None).unwrap();
    let r = &prepared[0].repairs;
    assert_eq!(
        (r.welded_vertices, r.collapsed_triangles),
        (12, 12),
        "{r:?}"
    );
    assert!(
        r.warnings().join("\n").contains("welded 12 vertices"),
        "{:?}",
        r.warnings()
    );
    assert_eq!(prepared[0].report.unsettled, 0);
    let written = std::fs::read_to_string(&catalog).unwrap();
    assert!(written.contains("[[part.stable_pose]]") && written.contains("name = \"+z\""));
    assert_eq!(faces.len(), original + 12);
}

/// A catalog part whose mesh is `file` (millimetres, metal).
fn part(name: &str, role: &str, file: &str) -> String {
    format!(
        "[[part]]\nname = \"{name}\"\nrole = \"{role}\"\nmesh = \"{file}\"\nunit = \"mm\"\n\
         material = \"metal\"\n"
    )
}

#[test]
fn a_part_of_touching_and_overlapping_bodies_is_prepared_as_one_part() {
    let fixture = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../perception/tests/data/multibody/touching_bodies.obj");
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(&fixture, dir.path().join("mold.obj")).unwrap();
    let catalog = dir.path().join("c.toml");
    std::fs::write(
        &catalog,
        format!("name = \"bodies\"\n{}", part("mold", "main", "mold.obj")),
    )
    .unwrap();
    let settings = DropSettings {
        drops: 64,
        ..DropSettings::default()
    };
    let prepared = prepare_catalog(&catalog, &settings, None).unwrap();
    let p = &prepared[0];
    assert_eq!(p.repairs.bodies, 3, "{:?}", p.repairs);
    // Mass is the union's: 53.08 mm³ in the bodies, the pin's 0.72 mm³ inside the mold counted
    // once.
    let density = perception::part::Catalog::load(&catalog)
        .unwrap()
        .part("mold")
        .unwrap()
        .density();
    assert!(
        (p.mass - 52.36e-9 * density).abs() < 1e-6 * p.mass,
        "{} g",
        p.mass * 1e3
    );
    assert!(p.repairs.overlap_share() > 0.01);
    assert!(!p.report.classes.is_empty());
    let written = std::fs::read_to_string(&catalog).unwrap();
    assert!(written.contains("[[part.stable_pose]]"));
}

#[test]
fn an_open_mesh_anywhere_in_the_catalog_fails_before_the_first_drop() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/parts");
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(root.join("main_shell.obj"), dir.path().join("shell.obj")).unwrap();
    let shell = std::fs::read_to_string(dir.path().join("shell.obj")).unwrap();
    // The same shell with its last triangle gone: open.
    let last_face = shell.rfind("\nf ").unwrap();
    std::fs::write(dir.path().join("open.obj"), &shell[..last_face + 1]).unwrap();
    let catalog = dir.path().join("c.toml");
    let text = format!(
        "name = \"bad\"\n{}{}",
        part("good", "main", "shell.obj"),
        part("bad", "top", "open.obj")
    );
    std::fs::write(&catalog, &text).unwrap();
    // So many drops that dropping the good part first would take minutes.
    let settings = DropSettings {
        drops: 1_000_000,
        ..DropSettings::default()
    };
    let start = std::time::Instant::now();
    let err = prepare_catalog(&catalog, &settings, None).unwrap_err();
    assert!(
        start.elapsed().as_secs_f64() < 30.0,
        "{:?}",
        start.elapsed()
    );
    let msg = err.to_string();
    assert!(
        msg.contains("part \"bad\"") && msg.contains("open.obj") && msg.contains("not closed"),
        "{msg}"
    );
    assert_eq!(std::fs::read_to_string(&catalog).unwrap(), text);
}
