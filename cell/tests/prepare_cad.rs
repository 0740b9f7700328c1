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
