//! STEP (ISO 10303-21, AP203/AP214/AP242) import: the file's solids tessellated by OpenCASCADE
//! (see [`StepKernel`]) to [`CHORDAL_TOLERANCE_MM`], each solid one closed body, in metres from
//! the unit the file declares. Tessellations are cached under the file's content hash, the
//! tolerances and the tool's digest, so a file is tessellated once; the tessellation is
//! deterministic (one thread, the file's order), so a cached and a fresh one are the same bytes.

use std::path::{Path, PathBuf};
use std::process::Command;

use sha2::{Digest, Sha256};

use super::PartError;
use super::step_kernel::{StepKernel, hex, tail};

/// Largest distance between the tessellation and the B-rep surface OpenCASCADE aims for, in mm
/// (BRepMesh's linear deflection; it may exceed it on some B-spline faces, see the STEP import page).
pub const CHORDAL_TOLERANCE_MM: f64 = 0.01;
/// Largest angle between neighbouring facets' normals along a curved face, in radians.
pub const ANGULAR_TOLERANCE_RAD: f64 = 0.5;

/// Tessellates a STEP file's solids to `tolerance_mm` (chordal) and returns the cached OBJ
/// (metres, one `o solid_N` group per solid), tessellating only when no cached copy exists.
///
/// Errors name the STEP file: not a STEP file, a syntax error (with its line where OpenCASCADE
/// gives one), no solids (with the shells and free faces it does hold), or a kernel that cannot
/// be provisioned or run.
pub fn tessellate_step(
    path: &Path,
    kernel: &StepKernel,
    tolerance_mm: f64,
) -> Result<PathBuf, PartError> {
    if !(tolerance_mm.is_finite() && tolerance_mm > 0.0) {
        return Err(step_error(
            path,
            format!("chordal tolerance {tolerance_mm} mm: expected a positive number"),
        ));
    }
    let bytes = std::fs::read(path).map_err(|source| PartError::Io {
        path: path.into(),
        source,
    })?;
    check_header(path, &bytes)?;
    let cached = kernel.mesh_cache_dir().join(format!(
        "{}-{tolerance_mm:e}mm-{ANGULAR_TOLERANCE_RAD:e}rad-{}.obj",
        hex(&Sha256::digest(&bytes)),
        StepKernel::tool_digest()
    ));
    if cached.is_file() {
        return Ok(cached);
    }
    let python = kernel.python_for(path)?;
    let script = kernel.script(path)?;
    let out = Command::new(&python)
        .arg(&script)
        .arg(path)
        .arg(&cached)
        .arg(format!("{tolerance_mm:e}"))
        .arg(format!("{ANGULAR_TOLERANCE_RAD:e}"))
        .output()
        .map_err(|e| kernel.error(path, format!("cannot run {}: {e}", python.display())))?;
    let stderr = String::from_utf8_lossy(&out.stderr);
    match out.status.code() {
        Some(0) if cached.is_file() => Ok(cached),
        Some(2) => {
            let line = stderr.lines().rev().find(|l| l.starts_with("error: "));
            let message = line.map_or_else(|| tail(&stderr, 400), |l| l["error: ".len()..].into());
            Err(step_error(path, message))
        }
        _ => Err(kernel.error(
            path,
            format!(
                "{} {} failed ({}): {}",
                python.display(),
                script.display(),
                out.status,
                tail(&stderr, 600)
            ),
        )),
    }
}

/// A STEP file starts with `ISO-10303-21;` (after blanks); checked before the kernel is started.
fn check_header(path: &Path, bytes: &[u8]) -> Result<(), PartError> {
    let start = bytes
        .iter()
        .position(|b| !b.is_ascii_whitespace())
        .unwrap_or(bytes.len());
    let head = &bytes[start..];
    if head.starts_with(b"ISO-10303-21;") {
        return Ok(());
    }
    let shown: String = String::from_utf8_lossy(&head[..head.len().min(20)])
        .chars()
        .map(|c| if c.is_control() { '.' } else { c })
        .collect();
    Err(step_error(
        path,
        format!("not a STEP file: it starts with {shown:?}, not ISO-10303-21;"),
    ))
}

fn step_error(path: &Path, message: String) -> PartError {
    PartError::Step {
        path: path.into(),
        message,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_that_is_not_step_is_refused_before_the_kernel_starts() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("peg.step");
        std::fs::write(&path, "solid peg\nfacet normal 0 0 1\n").unwrap();
        let kernel = StepKernel {
            python_override: Some(dir.path().join("no-such-python")),
            cache_dir: dir.path().join("cache"),
            python: "python3".into(),
        };
        let err = tessellate_step(&path, &kernel, CHORDAL_TOLERANCE_MM)
            .unwrap_err()
            .to_string();
        assert!(err.contains("peg.step: not a STEP file"), "{err}");
        assert!(err.contains("\"solid peg.facet norm\""), "{err}");
        let err = tessellate_step(&path, &kernel, 0.0)
            .unwrap_err()
            .to_string();
        assert!(err.contains("expected a positive number"), "{err}");
    }
}
