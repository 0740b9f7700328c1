//! Loading meshes from OBJ, STL, PLY and STEP files, with a plausibility check of the declared unit.

use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use nalgebra::Point3;
use serde::{Deserialize, Serialize};

use super::{
    CHORDAL_TOLERANCE_MM, MAX_FILLED_HOLE_M, MeshRepairs, PartError, StepKernel, TriMesh,
    tessellate_step,
};

/// The length unit a mesh file's numbers are in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LengthUnit {
    /// Metres.
    M,
    /// Millimetres (the usual CAD export unit).
    Mm,
}

impl LengthUnit {
    /// Metres per file unit.
    pub fn to_metres(self) -> f64 {
        match self {
            LengthUnit::M => 1.0,
            LengthUnit::Mm => 1e-3,
        }
    }

    fn name(self) -> &'static str {
        match self {
            LengthUnit::M => "m",
            LengthUnit::Mm => "mm",
        }
    }
}

/// Smallest and largest plausible object size in metres: parts, fixtures and boards in a cell.
const PLAUSIBLE_SIZE_M: (f64, f64) = (0.5e-3, 1.5);

/// Loads a closed mesh from an `.obj`, `.stl`, `.ply`, `.step` or `.stp` file, converting `unit`
/// to metres. A STEP file's solids are tessellated by OpenCASCADE to
/// [`CHORDAL_TOLERANCE_MM`](super::CHORDAL_TOLERANCE_MM), each solid one body, in the unit the
/// file declares (`unit` is not used for it).
///
/// Fails with the file named when it is missing, unparsable, empty, not closed, or when its size
/// is implausible for the unit (a 9 mm part read as 9 m). Export defects are repaired first
/// (see [`load_mesh_repaired`]). A file of several bodies (OBJ `o`/`g` groups, or pieces
/// connected through the file's own vertex indices) is one part whose every body is closed;
/// bodies are never welded to each other.
pub fn load_mesh(path: &Path, unit: LengthUnit) -> Result<TriMesh, PartError> {
    load_mesh_repaired(path, unit).map(|(mesh, _)| mesh)
}

/// As [`load_mesh`], and says what [`TriMesh::repair`] fixed (welded vertices, dropped
/// zero-area triangles, ...) and which small planar holes (at most [`MAX_FILLED_HOLE_M`]
/// across) were capped, so the caller can warn about it. Larger or non-planar holes are refused
/// with their place and size.
pub fn load_mesh_repaired(
    path: &Path,
    unit: LengthUnit,
) -> Result<(TriMesh, MeshRepairs), PartError> {
    load_part_mesh(path, Some(unit), CHORDAL_TOLERANCE_MM)
}

/// As [`load_mesh_repaired`], a STEP file tessellated to `chordal_tolerance_mm`; `unit` may be
/// absent only for a STEP file (which declares its own).
pub(crate) fn load_part_mesh(
    path: &Path,
    unit: Option<LengthUnit>,
    chordal_tolerance_mm: f64,
) -> Result<(TriMesh, MeshRepairs), PartError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    let raw = match ext.as_str() {
        "obj" => read_obj(path)?,
        "stl" => read_stl(path)?,
        "ply" => read_ply(path)?,
        // The solids tessellated, cached as OBJ in metres.
        "step" | "stp" => read_obj(&tessellate_step(
            path,
            &StepKernel::from_env(),
            chordal_tolerance_mm,
        )?)?,
        _ => return Err(PartError::UnknownFormat { path: path.into() }),
    };
    if raw.triangles.is_empty() {
        return Err(PartError::Empty { path: path.into() });
    }
    // A STEP tessellation is in metres already, from the unit the file declares.
    let mut mesh = match (ext.as_str(), unit) {
        ("step" | "stp", _) => {
            check_step_size(path, &raw)?;
            raw
        }
        (_, Some(unit)) => {
            let mesh = raw.scaled(unit.to_metres());
            check_size(path, &mesh, unit)?;
            mesh
        }
        (_, None) => return Err(PartError::NoUnit { path: path.into() }),
    };
    let mut repairs = mesh.repair();
    let filled = mesh.fill_small_holes(MAX_FILLED_HOLE_M);
    repairs.filled_holes = filled.count;
    repairs.largest_filled_hole = filled.largest;
    repairs.hole_bound = MAX_FILLED_HOLE_M;
    mesh.check_closed().map_err(|defect| PartError::NotClosed {
        path: path.into(),
        defect,
    })?;
    Ok((mesh, repairs))
}

fn check_size(path: &Path, mesh: &TriMesh, unit: LengthUnit) -> Result<(), PartError> {
    let size = mesh.extents().max();
    let (lo, hi) = PLAUSIBLE_SIZE_M;
    if (lo..=hi).contains(&size) {
        return Ok(());
    }
    let hint = if size > hi && (lo..=hi).contains(&(size * 1e-3)) {
        "the numbers look like millimetres: set unit = \"mm\" in the catalog".to_string()
    } else if size < lo && (lo..=hi).contains(&(size * 1e3)) {
        "the numbers look like metres: set unit = \"m\" in the catalog".to_string()
    } else {
        format!("expected an object between {lo} and {hi} m: check the export scale")
    };
    Err(PartError::ImplausibleSize {
        path: path.into(),
        size_m: size,
        unit: unit.name().into(),
        hint,
    })
}

/// As [`check_size`] for a STEP file, whose unit is the file's own.
fn check_step_size(path: &Path, mesh: &TriMesh) -> Result<(), PartError> {
    let size = mesh.extents().max();
    let (lo, hi) = PLAUSIBLE_SIZE_M;
    if (lo..=hi).contains(&size) {
        return Ok(());
    }
    Err(PartError::ImplausibleSize {
        path: path.into(),
        size_m: size,
        unit: "declared by the STEP file".into(),
        hint: format!(
            "expected an object between {lo} and {hi} m: check the length unit the STEP file \
             declares (its SI_UNIT or CONVERSION_BASED_UNIT) and the export scale"
        ),
    })
}

fn open(path: &Path) -> Result<BufReader<File>, PartError> {
    File::open(path)
        .map(BufReader::new)
        .map_err(|source| PartError::Io {
            path: path.into(),
            source,
        })
}

fn parse_error(path: &Path, format: &'static str, message: impl ToString) -> PartError {
    PartError::Parse {
        path: path.into(),
        format,
        message: message.to_string(),
    }
}

/// Statements an OBJ file may hold (geometry we read, and grouping, material and free-form
/// statements that are ignored).
const OBJ_STATEMENTS: [&str; 22] = [
    "v", "vt", "vn", "vp", "f", "l", "p", "g", "o", "s", "mtllib", "usemtl", "cstype", "deg",
    "bmat", "step", "curv", "curv2", "surf", "parm", "end", "mg",
];

/// Checks that an OBJ file is text whose statements are OBJ statements, and that vertices hold
/// three numbers and faces at least three indices; the error names the byte or line.
fn check_obj_text(path: &Path, bytes: &[u8]) -> Result<(), PartError> {
    let text = std::str::from_utf8(bytes).map_err(|e| {
        parse_error(
            path,
            "OBJ",
            format!(
                "byte {} is not text (a binary file named .obj?)",
                e.valid_up_to()
            ),
        )
    })?;
    for (i, line) in text.lines().enumerate() {
        let at = |what: String| parse_error(path, "OBJ", format!("line {}: {what}", i + 1));
        let line = line.split('#').next().unwrap_or_default().trim();
        let mut words = line.split_whitespace();
        let Some(statement) = words.next() else {
            continue;
        };
        if !OBJ_STATEMENTS.contains(&statement) {
            let shown: String = statement.chars().take(20).collect();
            return Err(at(format!("\"{shown}\" is not an OBJ statement")));
        }
        let args: Vec<&str> = words.collect();
        match statement {
            "v" if args.len() < 3 || args.iter().take(3).any(|a| a.parse::<f64>().is_err()) => {
                return Err(at("a vertex needs three numbers: v X Y Z".into()));
            }
            "f" if args.len() < 3
                || args.iter().any(|a| {
                    a.split('/')
                        .next()
                        .is_none_or(|v| v.parse::<i64>().map_or(true, |n| n == 0))
                }) =>
            {
                return Err(at(
                    "a face needs three or more vertex indices (1-based): f A B C".into(),
                ));
            }
            _ => {}
        }
    }
    Ok(())
}

/// Checks the size of a binary STL file against its triangle count (an ASCII STL, which starts
/// with `solid` and is text, is left to the parser).
fn check_stl_size(path: &Path, bytes: &[u8]) -> Result<(), PartError> {
    let ascii = bytes.starts_with(b"solid") && std::str::from_utf8(bytes).is_ok();
    if ascii {
        return Ok(());
    }
    if bytes.len() < 84 {
        return Err(parse_error(
            path,
            "STL",
            format!(
                "the file has {} bytes, less than a binary STL's 84-byte header",
                bytes.len()
            ),
        ));
    }
    let count = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]);
    let needed = 84 + 50 * u64::from(count);
    if needed != bytes.len() as u64 {
        return Err(parse_error(
            path,
            "STL",
            format!(
                "bytes 80..84 say {count} triangles, which need {needed} bytes, but the file \
                 has {} (not a binary STL, or truncated)",
                bytes.len()
            ),
        ));
    }
    Ok(())
}

fn read_bytes(path: &Path) -> Result<Vec<u8>, PartError> {
    std::fs::read(path).map_err(|source| PartError::Io {
        path: path.into(),
        source,
    })
}

fn read_obj(path: &Path) -> Result<TriMesh, PartError> {
    let bytes = read_bytes(path)?;
    check_obj_text(path, &bytes)?;
    // Position indices as the file gives them (not split by normal or texture index), so the
    // file's bodies stay apart and each stays connected.
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        ..Default::default()
    };
    let mut reader = std::io::Cursor::new(bytes);
    let (models, _) = tobj::load_obj_buf(&mut reader, &options, |_| {
        Ok((Vec::new(), Default::default()))
    })
    .map_err(|e| parse_error(path, "OBJ", e))?;
    let mut mesh = TriMesh {
        vertices: Vec::new(),
        triangles: Vec::new(),
    };
    for model in models {
        let m = model.mesh;
        let part = TriMesh {
            vertices: m
                .positions
                .chunks_exact(3)
                .map(|c| Point3::new(c[0] as f64, c[1] as f64, c[2] as f64))
                .collect(),
            triangles: m
                .indices
                .chunks_exact(3)
                .map(|c| [c[0], c[1], c[2]])
                .collect(),
        };
        mesh.append(&part);
    }
    // Not welded: vertices at one place in two groups or pieces belong to two bodies.
    Ok(mesh)
}

fn read_stl(path: &Path) -> Result<TriMesh, PartError> {
    let bytes = read_bytes(path)?;
    check_stl_size(path, &bytes)?;
    let mut reader = std::io::Cursor::new(bytes);
    let stl = stl_io::read_stl(&mut reader).map_err(|e| parse_error(path, "STL", e))?;
    let vertices = stl
        .vertices
        .iter()
        .map(|v| Point3::new(v[0] as f64, v[1] as f64, v[2] as f64))
        .collect();
    let triangles = stl
        .faces
        .iter()
        .map(|f| f.vertices.map(|i| i as u32))
        .collect();
    Ok(TriMesh::new(vertices, triangles))
}

fn read_ply(path: &Path) -> Result<TriMesh, PartError> {
    use ply_rs::ply::Property;
    let mut reader = open(path)?;
    let parser = ply_rs::parser::Parser::<ply_rs::ply::DefaultElement>::new();
    let ply = parser
        .read_ply(&mut reader)
        .map_err(|e| parse_error(path, "PLY", e))?;
    let scalar = |p: Option<&Property>| -> Option<f64> {
        match p? {
            Property::Float(v) => Some(*v as f64),
            Property::Double(v) => Some(*v),
            Property::Int(v) => Some(*v as f64),
            Property::UInt(v) => Some(*v as f64),
            Property::Short(v) => Some(*v as f64),
            Property::UShort(v) => Some(*v as f64),
            Property::Char(v) => Some(*v as f64),
            Property::UChar(v) => Some(*v as f64),
            _ => None,
        }
    };
    let mut vertices = Vec::new();
    for (i, v) in ply
        .payload
        .get("vertex")
        .map(Vec::as_slice)
        .unwrap_or_default()
        .iter()
        .enumerate()
    {
        let xyz = ["x", "y", "z"].map(|k| scalar(v.get(k)));
        match xyz {
            [Some(x), Some(y), Some(z)] => vertices.push(Point3::new(x, y, z)),
            _ => {
                return Err(parse_error(
                    path,
                    "PLY",
                    format!("vertex {i} lacks numeric x, y, z"),
                ));
            }
        }
    }
    let mut triangles = Vec::new();
    for (i, f) in ply
        .payload
        .get("face")
        .map(Vec::as_slice)
        .unwrap_or_default()
        .iter()
        .enumerate()
    {
        let idx: Vec<u32> = match f.get("vertex_indices").or_else(|| f.get("vertex_index")) {
            Some(Property::ListInt(l)) => l.iter().map(|&x| x as u32).collect(),
            Some(Property::ListUInt(l)) => l.clone(),
            Some(Property::ListUChar(l)) => l.iter().map(|&x| x as u32).collect(),
            Some(Property::ListShort(l)) => l.iter().map(|&x| x as u32).collect(),
            Some(Property::ListUShort(l)) => l.iter().map(|&x| x as u32).collect(),
            _ => {
                return Err(parse_error(
                    path,
                    "PLY",
                    format!("face {i} lacks vertex_indices"),
                ));
            }
        };
        if idx.len() < 3 {
            return Err(parse_error(
                path,
                "PLY",
                format!("face {i} has fewer than 3 vertices"),
            ));
        }
        for k in 1..idx.len() - 1 {
            triangles.push([idx[0], idx[k], idx[k + 1]]);
        }
    }
    Ok(TriMesh::new(vertices, triangles))
}

/// Writes a mesh as a text OBJ file in `unit`, with fixed precision so output is reproducible.
pub fn write_obj(mesh: &TriMesh, unit: LengthUnit, header: &str) -> String {
    use std::fmt::Write;
    let scale = 1.0 / unit.to_metres();
    let mut s = String::new();
    for line in header.lines() {
        let _ = writeln!(s, "# {line}");
    }
    for p in &mesh.vertices {
        let q = p * scale;
        let _ = writeln!(s, "v {:.6} {:.6} {:.6}", q.x + 0.0, q.y + 0.0, q.z + 0.0);
    }
    for t in &mesh.triangles {
        let _ = writeln!(s, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    s
}
