//! The USB-C meshes: the committed files are exactly what the generator writes, they are closed,
//! and their outer sizes match the seed's parts.

use std::path::Path;

use perception::part::{LengthUnit, load_mesh};
use sim::cad::{obj_text, usbc_meshes};

fn parts_dir() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../scenarios/parts"))
}

#[test]
fn committed_meshes_are_regenerated_bit_for_bit() {
    for (name, mesh) in usbc_meshes() {
        let committed = std::fs::read_to_string(parts_dir().join(name)).unwrap();
        assert!(
            committed == obj_text(name, &mesh),
            "{name} differs from the generator: run `cell parts cad scenarios/parts`"
        );
    }
}

#[test]
fn meshes_are_closed_and_match_the_seed_sizes() {
    // Outer sizes x × y × z in mm from the seed's parts table.
    let expected = [
        ("main_shell.obj", [8.84, 9.07, 3.00]),
        ("top_shell.obj", [11.80, 8.91, 4.39]),
        ("insert_mold.obj", [8.40, 8.54, 4.15]),
    ];
    for (name, size) in expected {
        let mesh = load_mesh(&parts_dir().join(name), LengthUnit::Mm).unwrap();
        let e = mesh.extents() * 1e3;
        for i in 0..3 {
            assert!(
                (e[i] - size[i]).abs() < 1e-4,
                "{name}: extent {i} is {} mm, want {}",
                e[i],
                size[i]
            );
        }
        let (lo, hi) = mesh.aabb();
        assert!(
            (lo.coords + hi.coords).norm() < 1e-9,
            "{name}: origin is not the box centre"
        );
        assert!(mesh.volume() > 0.0);
    }
}

#[test]
fn the_insert_fits_the_cavity_with_usb_c_clearance() {
    use sim::cad::usbc::{INSERT_CLEARANCE_MM, assembly_targets, insert_mold, main_shell};
    // The shell's cavity walls are its vertices closest to the centre along x; the insert's
    // lower body is its widest part below the shell rim. Measure both from the meshes.
    let shell = main_shell();
    let insert = insert_mold().transformed(&assembly_targets().main_t_insert);
    // Between the floor and the start of the rim chamfer only the cavity ring has vertices.
    let rim = shell.aabb().1.z - 0.1e-3 + 1e-9;
    let floor = shell.aabb().0.z + 0.31e-3;
    let cavity_half_x = shell
        .vertices
        .iter()
        .filter(|p| p.z > floor && p.z < rim)
        .map(|p| p.x.abs())
        .fold(f64::INFINITY, f64::min);
    let insert_half_x = insert
        .vertices
        .iter()
        .filter(|p| p.z < rim)
        .map(|p| p.x.abs())
        .fold(0.0, f64::max);
    let clearance_mm = 2.0 * (cavity_half_x - insert_half_x) * 1e3;
    assert!(
        (clearance_mm - INSERT_CLEARANCE_MM).abs() < 1e-6,
        "clearance {clearance_mm} mm"
    );
    // Seated, the insert's bottom rests on the shell floor.
    let insert_bottom = insert.aabb().0.z;
    let shell_floor_top = shell.aabb().0.z + 0.30e-3;
    assert!((insert_bottom - shell_floor_top).abs() < 1e-9);
}
