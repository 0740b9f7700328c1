//! Part CAD authored by this project: a small solid modeller and the USB Type-C parts, nest and
//! tag board built with it, and the NIST task board's pegs and plate, written reproducibly as OBJ
//! files.

pub mod nist;
pub mod solid;
pub mod usbc;

use std::path::{Path, PathBuf};

use perception::part::{LengthUnit, TriMesh, write_obj};

/// The meshes of the USB-C cell, by file name.
pub fn usbc_meshes() -> Vec<(&'static str, TriMesh)> {
    vec![
        ("main_shell.obj", usbc::main_shell()),
        ("insert_mold.obj", usbc::insert_mold()),
        ("top_shell.obj", usbc::top_shell()),
        ("fixture_nest.obj", usbc::fixture_nest()),
        ("tag_board.obj", usbc::tag_board()),
    ]
}

/// The meshes of the NIST task board's peg-in-hole set, by file name.
pub fn nist_meshes() -> Vec<(&'static str, TriMesh)> {
    let mut meshes: Vec<(&'static str, TriMesh)> =
        nist::PEGS.iter().map(|p| (p.file_name, p.mesh())).collect();
    meshes.push(("nist_plate.obj", nist::fixture_plate()));
    meshes
}

/// The OBJ text of a USB-C mesh as this project stores it: millimetres, fixed precision.
pub fn obj_text(name: &str, mesh: &TriMesh) -> String {
    obj_text_of("usbc", name, mesh)
}

/// The OBJ text of a mesh authored by `sim::cad::{module}`: millimetres, fixed precision.
pub fn obj_text_of(module: &str, name: &str, mesh: &TriMesh) -> String {
    let header = format!(
        "{name}: authored by this project (sim::cad::{module}), not vendor CAD.\n\
         Regenerate with `cell parts cad DIR`. Units: millimetres; origin: bounding-box centre."
    );
    write_obj(mesh, LengthUnit::Mm, &header)
}

/// Writes every NIST peg and the plate into `dir` (atomically, file by file) and returns the
/// paths.
pub fn write_nist_meshes(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir)?;
    let mut written = Vec::new();
    for (name, mesh) in nist_meshes() {
        let path = dir.join(name);
        crate::fsutil::write_atomic(&path, obj_text_of("nist", name, &mesh).as_bytes())?;
        written.push(path);
    }
    Ok(written)
}

/// Writes every USB-C mesh into `dir` (atomically, file by file) and returns the paths.
pub fn write_usbc_meshes(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir)?;
    let mut written = Vec::new();
    for (name, mesh) in usbc_meshes() {
        let path = dir.join(name);
        crate::fsutil::write_atomic(&path, obj_text(name, &mesh).as_bytes())?;
        written.push(path);
    }
    Ok(written)
}
