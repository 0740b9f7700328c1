//! `cell parts prepare` records the drop height its stable-pose table was dropped from in the
//! catalog, so that the file alone reproduces its table: the flag sets it, the catalog's value
//! is used without the flag, and the default applies to a catalog that never had one.

mod support;

use std::path::Path;

use nalgebra::Vector3;
use perception::part::{LengthUnit, TriMesh, write_obj};

/// A 9 × 6 × 3 mm box as OBJ (millimetres).
fn write_box(path: &Path) {
    let block = TriMesh::cuboid(Vector3::new(0.009, 0.006, 0.003));
    std::fs::write(path, write_obj(&block, LengthUnit::Mm, "a block")).unwrap();
}

/// `cell parts prepare --drops 32 EXTRA... CATALOG`: its success, stdout and stderr.
fn prepare(catalog: &Path, extra: &[&str]) -> (bool, String, String) {
    let catalog = catalog.to_str().unwrap();
    let args: Vec<&str> = ["parts", "prepare", "--drops", "32"]
        .into_iter()
        .chain(extra.iter().copied())
        .chain([catalog])
        .collect();
    let out = support::cell(&args);
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn the_catalog_records_the_drop_height_and_the_flag_changes_it() {
    let dir = tempfile::tempdir().unwrap();
    write_box(&dir.path().join("box.obj"));
    let catalog = dir.path().join("c.toml");
    std::fs::write(
        &catalog,
        "name = \"box\"\n[[part]]\nname = \"box\"\nmesh = \"box.obj\"\nunit = \"mm\"\n\
         material = \"metal\"\n",
    )
    .unwrap();
    let read = || std::fs::read_to_string(&catalog).unwrap();

    // Never prepared: the default height, written before the parts with what it means.
    let (ok, stdout, stderr) = prepare(&catalog, &[]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("drops from 30.0 mm"), "{stdout}");
    let text = read();
    assert!(
        text.contains("# Lowest point above the table when the stable-pose drops released")
            && text.contains("\ndrop_height = 0.03\n"),
        "{text}"
    );
    assert!(text.find("drop_height").unwrap() < text.find("[[part]]").unwrap());
    let loaded = perception::part::Catalog::load(&catalog).unwrap();
    assert_eq!(loaded.drop_height, Some(0.03));
    assert!(!loaded.parts[0].stable_poses.is_empty());

    // The flag replaces the recorded value, keeping a comment written beside it.
    std::fs::write(
        &catalog,
        read().replace("drop_height = 0.03\n", "drop_height = 0.03 # our hopper\n"),
    )
    .unwrap();
    let (ok, stdout, stderr) = prepare(&catalog, &["--drop-height", "0.02"]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("drops from 20.0 mm"), "{stdout}");
    let text = read();
    assert!(
        text.contains("\ndrop_height = 0.02 # our hopper\n"),
        "{text}"
    );
    assert_eq!(text.matches("drop_height =").count(), 1, "{text}");

    // Without the flag the recorded value is used and kept.
    let (ok, stdout, stderr) = prepare(&catalog, &[]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("drops from 20.0 mm"), "{stdout}");
    assert!(read().contains("\ndrop_height = 0.02 # our hopper\n"));

    // Out of range, from the flag or from the file: refused, the file untouched.
    let before = read();
    let (ok, _, stderr) = prepare(&catalog, &["--drop-height", "2"]);
    assert!(
        !ok && stderr.contains("--drop-height must be between 0 and 1 m, got 2"),
        "{stderr}"
    );
    std::fs::write(
        &catalog,
        before.replace("drop_height = 0.02", "drop_height = -1.0"),
    )
    .unwrap();
    let (ok, _, stderr) = prepare(&catalog, &[]);
    assert!(
        !ok && stderr.contains("c.toml:")
            && stderr.contains("drop_height must be between 0 and 1 m"),
        "{stderr}"
    );
}
