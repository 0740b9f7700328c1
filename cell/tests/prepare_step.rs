//! STEP parts through `cell parts prepare`: the fixtures in `fixtures/step/` (written by
//! `scripts/step_import/make_fixtures.py` with OpenCASCADE) are tessellated by the provisioned
//! kernel (OpenCASCADE from the pinned PyPI wheel, in the cache; the first run downloads 67 MB),
//! and prepared like any mesh: mass against the B-rep's analytic volume, keypoints, stable poses.
//! The file's errors name the file and what is wrong.

use std::path::{Path, PathBuf};
use std::process::Command;

use cell::prepare::prepare_catalog;
use perception::part::{CHORDAL_TOLERANCE_MM, Catalog, StepKernel, load_mesh, tessellate_step};
use sim::stable_poses::DropSettings;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/step")
        .join(name)
}

/// The block is 20 x 16 x 8 mm with a 6 mm hole through its 8 mm: 2560 - 72 pi mm^3.
const BLOCK_MM3: f64 = 2560.0 - 72.0 * std::f64::consts::PI;
/// The hole's wall: the only curved face, 2 pi 3 mm x 8 mm.
const BLOCK_CURVED_MM2: f64 = 2.0 * std::f64::consts::PI * 3.0 * 8.0;
/// A 6 mm x 12 mm peg and an 8 x 8 x 4 mm block: 108 pi + 256 mm^3.
const PEG_AND_BLOCK_MM3: f64 = 108.0 * std::f64::consts::PI + 256.0;
/// The peg's side: 2 pi 3 mm x 12 mm.
const PEG_CURVED_MM2: f64 = 2.0 * std::f64::consts::PI * 3.0 * 12.0;

/// How far a tessellated volume may be from the B-rep's: a curved face of area A tessellated to
/// a chordal tolerance t moves at most A t of volume (the facets lie within t of the surface).
fn volume_bound_mm3(curved_mm2: f64) -> f64 {
    curved_mm2 * CHORDAL_TOLERANCE_MM
}

fn catalog_with(dir: &Path, parts: &[(&str, &str)]) -> PathBuf {
    let mut text = String::from("name = \"step\"\n");
    for (name, file) in parts {
        std::fs::copy(fixture(file), dir.join(file)).unwrap();
        text += &format!(
            "[[part]]\nname = \"{name}\"\nmesh = \"{file}\"\nunit = \"mm\"\nmaterial = \"metal\"\n"
        );
    }
    let path = dir.join("c.toml");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn step_parts_are_prepared_with_mass_from_the_analytic_volume_keypoints_and_stable_poses() {
    let dir = tempfile::tempdir().unwrap();
    let catalog = catalog_with(
        dir.path(),
        &[
            ("block", "block_with_hole.step"),
            ("pair", "peg_and_block.step"),
        ],
    );
    let settings = DropSettings {
        drops: 96,
        ..DropSettings::default()
    };
    let prepared = prepare_catalog(&catalog, &settings, None).unwrap();
    let loaded = Catalog::load(&catalog).unwrap();
    let density = loaded.part("block").unwrap().density();
    for (p, exact_mm3, curved_mm2, bodies) in [
        (&prepared[0], BLOCK_MM3, BLOCK_CURVED_MM2, 1),
        (&prepared[1], PEG_AND_BLOCK_MM3, PEG_CURVED_MM2, 2),
    ] {
        // Each STEP solid is one body.
        assert_eq!(p.repairs.bodies, bodies, "{}: {:?}", p.name, p.repairs);
        let volume_mm3 = p.mass / density * 1e9;
        assert!(
            (volume_mm3 - exact_mm3).abs() <= volume_bound_mm3(curved_mm2),
            "{}: {volume_mm3} mm^3 against {exact_mm3} (bound {})",
            p.name,
            volume_bound_mm3(curved_mm2)
        );
        assert_eq!(p.keypoints.len(), 9);
        assert_eq!(p.report.unsettled, 0, "{}", p.name);
        assert!(!p.report.classes.is_empty());
    }
    // The block lies on one of its two 20 x 16 faces most often, its centre 4 mm up.
    let block = &prepared[0];
    for k in &block.keypoints {
        assert!(
            k.x.abs() <= 0.010 + 1e-9 && k.y.abs() <= 0.008 + 1e-9 && k.z.abs() <= 0.004 + 1e-9,
            "keypoint {k} outside the 20 x 16 x 8 mm block"
        );
    }
    let top = block.report.classes.iter().max_by_key(|c| c.count).unwrap();
    assert!(
        top.pose.name == "+z" || top.pose.name == "-z",
        "{:?}",
        top.pose
    );
    assert!(
        (top.pose.rest_height - 0.004).abs() < 5e-5,
        "{:?}",
        top.pose
    );
    let written = std::fs::read_to_string(&catalog).unwrap();
    assert!(
        written.contains("[[part.stable_pose]]")
            && written.contains("mesh = \"peg_and_block.step\"")
    );
}

#[test]
fn cell_parts_prepare_accepts_a_stp_file() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(
        fixture("block_with_hole.step"),
        dir.path().join("block.stp"),
    )
    .unwrap();
    let catalog = dir.path().join("c.toml");
    std::fs::write(
        &catalog,
        "name = \"step\"\n[[part]]\nname = \"block\"\nmesh = \"block.stp\"\nunit = \"m\"\n\
         material = \"metal\"\n",
    )
    .unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_cell"))
        .args(["parts", "prepare", "--drops", "32"])
        .arg(&catalog)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let written = std::fs::read_to_string(&catalog).unwrap();
    assert!(written.contains("[[part.stable_pose]]"), "{written}");
}

#[test]
fn the_unit_comes_from_the_step_file() {
    // The same block written in inches (numbers / 25.4, CONVERSION_BASED_UNIT 'INCH'): the
    // catalog's unit is not used for STEP, and the mesh is the same size.
    let mm = load_mesh(
        &fixture("block_with_hole.step"),
        perception::part::LengthUnit::M,
    )
    .unwrap();
    let inch = load_mesh(
        &fixture("block_with_hole_inch.step"),
        perception::part::LengthUnit::Mm,
    )
    .unwrap();
    let (a, b) = (mm.extents(), inch.extents());
    assert!(
        (a - nalgebra::Vector3::new(0.020, 0.016, 0.008)).norm() < 1e-9,
        "{a}"
    );
    assert!((a - b).norm() < 1e-9, "{a} against {b}");
    assert!((mm.volume() - inch.volume()).abs() < 1e-15);
}

#[test]
fn tessellations_are_cached_by_content_and_deterministic() {
    let python = StepKernel::from_env()
        .python_for(&fixture("block_with_hole.step"))
        .unwrap();
    let (one, two) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let kernel = |cache: &Path, python: PathBuf| StepKernel {
        python_override: Some(python),
        cache_dir: cache.into(),
        python: "python3".into(),
    };
    let first = tessellate_step(
        &fixture("block_with_hole.step"),
        &kernel(one.path(), python.clone()),
        0.01,
    )
    .unwrap();
    let second = tessellate_step(
        &fixture("block_with_hole.step"),
        &kernel(two.path(), python.clone()),
        0.01,
    )
    .unwrap();
    assert_eq!(
        std::fs::read(&first).unwrap(),
        std::fs::read(&second).unwrap()
    );
    // A cached file is used without running the kernel (here one that cannot run).
    let again = tessellate_step(
        &fixture("block_with_hole.step"),
        &kernel(one.path(), "/no/such/python".into()),
        0.01,
    )
    .unwrap();
    assert_eq!(again, first);
    // Another tolerance is another tessellation: finer, so more triangles.
    let fine = tessellate_step(
        &fixture("block_with_hole.step"),
        &kernel(one.path(), python),
        0.001,
    )
    .unwrap();
    let faces = |p: &Path| {
        std::fs::read_to_string(p)
            .unwrap()
            .lines()
            .filter(|l| l.starts_with("f "))
            .count()
    };
    assert!(
        faces(&fine) > faces(&first),
        "{} {}",
        faces(&fine),
        faces(&first)
    );
}

fn prepare_error(file: &str) -> String {
    let dir = tempfile::tempdir().unwrap();
    let catalog = catalog_with(dir.path(), &[("bad", file)]);
    let settings = DropSettings {
        drops: 1_000_000,
        ..DropSettings::default()
    };
    let start = std::time::Instant::now();
    let err = prepare_catalog(&catalog, &settings, None)
        .unwrap_err()
        .to_string();
    assert!(start.elapsed().as_secs() < 60, "failed before any drop");
    assert!(err.contains("c.toml:"), "the catalog line is named: {err}");
    err
}

#[test]
fn a_step_file_with_no_solids_is_refused_naming_what_it_holds() {
    let err = prepare_error("shell_only.step");
    assert!(
        err.contains(
            "shell_only.step: the STEP file has no solids: 2 shells and 0 free faces only"
        ),
        "{err}"
    );
}

#[test]
fn a_truncated_step_file_is_refused_with_the_line_the_parser_stopped_at() {
    let err = prepare_error("truncated.step");
    assert!(
        err.contains("truncated.step: the STEP file does not parse")
            && err.contains("Line 262: Incorrect syntax: unexpected end of file"),
        "{err}"
    );
}

#[test]
fn a_file_named_step_that_is_not_step_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("x.step"), "solid x\nendsolid x\n").unwrap();
    let catalog = dir.path().join("c.toml");
    std::fs::write(
        &catalog,
        "name = \"bad\"\n[[part]]\nname = \"x\"\nmesh = \"x.step\"\nunit = \"mm\"\n\
         material = \"metal\"\n",
    )
    .unwrap();
    let err = prepare_catalog(&catalog, &DropSettings::default(), None)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("x.step: not a STEP file: it starts with \"solid x.endsolid x.\""),
        "{err}"
    );
}

#[test]
fn a_kernel_that_cannot_be_provisioned_fails_with_what_failed_and_the_fix() {
    let dir = tempfile::tempdir().unwrap();
    let catalog = catalog_with(dir.path(), &[("block", "block_with_hole.step")]);
    let out = Command::new(env!("CARGO_BIN_EXE_cell"))
        .args(["parts", "prepare", "--drops", "8"])
        .arg(&catalog)
        .env("CELL_CACHE_DIR", dir.path().join("cache"))
        .env("CELL_PYTHON", dir.path().join("no-python"))
        .env_remove("CELL_STEP_PYTHON")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("block_with_hole.step: cannot import STEP: python -m venv: cannot run")
            && stderr.contains("no-python")
            && stderr.contains("pip install cadquery-ocp-novtk==8.0.1.1.0")
            && stderr.contains("CELL_STEP_PYTHON"),
        "{stderr}"
    );
    assert!(
        stderr.contains("c.toml:"),
        "the catalog line is named: {stderr}"
    );
}

/// A one-part catalog of `mesh` with the extra `keys` lines; the block fixture copied in.
fn catalog_of(dir: &Path, mesh: &str, keys: &str) -> PathBuf {
    std::fs::copy(fixture("block_with_hole.step"), dir.join(mesh)).unwrap();
    let path = dir.join("c.toml");
    std::fs::write(
        &path,
        format!("name = \"step\"\n[[part]]\nname = \"block\"\nmesh = \"{mesh}\"\n{keys}material = \"metal\"\n"),
    )
    .unwrap();
    path
}

#[test]
fn a_step_part_needs_no_unit_and_is_tessellated_to_its_own_chordal_tolerance() {
    let dir = tempfile::tempdir().unwrap();
    let triangles_and_volume = |keys: &str| {
        let catalog = Catalog::load(&catalog_of(dir.path(), "block.step", keys)).unwrap();
        let part = catalog.part("block").unwrap();
        assert_eq!(part.unit, None);
        let mesh = catalog.load_mesh(part).unwrap();
        (
            mesh.triangles.len(),
            mesh.volume() * 1e9,
            part.chordal_tolerance_mm(),
        )
    };
    let (default, default_mm3, t) = triangles_and_volume("");
    assert_eq!(t, CHORDAL_TOLERANCE_MM);
    // 0.1 mm: coarser, fewer facets, the volume still within A t of the B-rep's.
    let (coarse, coarse_mm3, t) = triangles_and_volume("chordal_tolerance = 1e-4\n");
    assert!((t - 0.1).abs() < 1e-12, "{t} mm");
    assert!(
        coarse < default,
        "{coarse} triangles at 0.1 mm, {default} at 0.01 mm"
    );
    for (mm3, t) in [(default_mm3, CHORDAL_TOLERANCE_MM), (coarse_mm3, 0.1)] {
        assert!(
            (mm3 - BLOCK_MM3).abs() <= BLOCK_CURVED_MM2 * t,
            "{mm3} mm^3 at {t} mm against {BLOCK_MM3}"
        );
    }
    // The coarse tessellation is far enough off to tell apart from the default one.
    assert!((coarse_mm3 - BLOCK_MM3).abs() > (default_mm3 - BLOCK_MM3).abs());
}

/// The located error a catalog of `mesh` with `keys` is refused with, as text.
fn catalog_refusal(mesh: &str, keys: &str) -> String {
    let dir = tempfile::tempdir().unwrap();
    let path = catalog_of(dir.path(), mesh, keys);
    Catalog::load(&path).unwrap_err().to_string()
}

#[test]
fn bad_units_and_chordal_tolerances_are_refused_at_their_line_and_column() {
    // Millimetres typed as metres.
    let err = catalog_refusal("block.step", "chordal_tolerance = 0.02\n");
    assert!(
        err.contains("c.toml:5:21: part \"block\": chordal_tolerance 0.02 m is 20 mm, coarser than the 0.5 mm allowed")
            && err.contains("(0.02 mm would be 2e-5)"),
        "{err}"
    );
    let err = catalog_refusal("block.step", "chordal_tolerance = -1e-5\n");
    assert!(
        err.contains("c.toml:5:21: part \"block\": chordal_tolerance -0.00001: expected a positive length in metres"),
        "{err}"
    );
    let err = catalog_refusal("block.step", "chordal_tolerance = 1e-9\n");
    assert!(
        err.contains("c.toml:5:21:") && err.contains("finer than the 0.1 µm allowed"),
        "{err}"
    );
    // A tolerance means nothing to a triangle mesh, and a triangle mesh needs its unit.
    let err = catalog_refusal("block.obj", "unit = \"mm\"\nchordal_tolerance = 1e-5\n");
    assert!(
        err.contains("c.toml:6:21: part \"block\": chordal_tolerance applies to STEP meshes only; block.obj is given as triangles"),
        "{err}"
    );
    let err = catalog_refusal("block.stl", "");
    assert!(
        err.contains("c.toml:4:8: part \"block\": unit = \"mm\" or \"m\" is required for mesh block.stl; only a STEP file declares its own unit"),
        "{err}"
    );
}
