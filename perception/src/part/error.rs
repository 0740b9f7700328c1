//! Errors from loading meshes and catalogs.

use std::path::PathBuf;

/// What went wrong loading a part's mesh or catalog; every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum PartError {
    /// The file could not be read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The file's extension names no mesh format we read.
    #[error("{path}: unknown mesh format (expected .obj, .stl, .ply, .step or .stp)")]
    UnknownFormat {
        /// The file.
        path: PathBuf,
    },
    /// The mesh file could not be parsed.
    #[error("{path}: not a valid {format} mesh: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The format we tried.
        format: &'static str,
        /// What the parser said.
        message: String,
    },
    /// The STEP file gives no solids: not a STEP file, a syntax error, no solids, a face that
    /// does not tessellate.
    #[error("{path}: {message}")]
    Step {
        /// The STEP file.
        path: PathBuf,
        /// What is wrong with it.
        message: String,
    },
    /// The STEP kernel (OpenCASCADE in a provisioned venv) could not be provisioned or run.
    #[error("{path}: cannot import STEP: {reason}; {hint}")]
    StepKernel {
        /// The STEP file being imported.
        path: PathBuf,
        /// What failed.
        reason: String,
        /// What to do about it.
        hint: String,
    },
    /// A triangle mesh (OBJ, STL, PLY) was loaded without a length unit.
    #[error(
        "{path}: no length unit given: set unit = \"mm\" or \"m\" (only a STEP file declares its own)"
    )]
    NoUnit {
        /// The file.
        path: PathBuf,
    },
    /// The mesh has no triangles.
    #[error("{path}: the mesh is empty (no triangles); export the part as a solid")]
    Empty {
        /// The file.
        path: PathBuf,
    },
    /// The mesh is not a closed surface, so volume, mass and inside/outside are undefined.
    #[error(
        "{path}: the mesh is not closed ({defect}); export it as a watertight solid (close holes, \
         unify normals)"
    )]
    NotClosed {
        /// The file.
        path: PathBuf,
        /// The first defect found.
        defect: crate::part::MeshDefect,
    },
    /// The mesh's size is implausible for the declared unit.
    #[error("{path}: the part is {size_m:.4} m across with unit \"{unit}\"; {hint}")]
    ImplausibleSize {
        /// The file.
        path: PathBuf,
        /// Largest bounding-box side in metres after applying the declared unit.
        size_m: f64,
        /// The declared unit.
        unit: String,
        /// What to change.
        hint: String,
    },
    /// The catalog file is not valid TOML for the catalog schema.
    #[error("{path}:{line}:{column}: {message}")]
    Catalog {
        /// The catalog file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// What was wrong and what was expected.
        message: String,
    },
    /// A part's mesh could not be loaded: located at the catalog's `mesh` key, with the mesh
    /// file's own error (its path and why: not found, or where it fails to parse).
    #[error("{0}")]
    Mesh(Box<MeshAt>),
}

/// Where a catalog names a mesh that could not be loaded, and why.
#[derive(Debug, thiserror::Error)]
#[error("{catalog}:{line}:{column}: part \"{part}\": mesh = {mesh:?}: {error}")]
pub struct MeshAt {
    /// The catalog file.
    pub catalog: PathBuf,
    /// 1-based line of the part's `mesh` value.
    pub line: usize,
    /// 1-based column of it.
    pub column: usize,
    /// The part.
    pub part: String,
    /// The `mesh` value as written.
    pub mesh: PathBuf,
    /// What loading the mesh file said.
    pub error: PartError,
}
