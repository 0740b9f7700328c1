//! The STEP kernel: OpenCASCADE 8.0.1 from the pinned PyPI wheel `cadquery-ocp-novtk`, installed
//! once with pip (the ordinary PyPI client, every wheel's sha256 checked) into a venv in the cache,
//! and the tessellation script `scripts/step_import/tessellate.py` (built into the binary) that
//! runs in it. `CELL_STEP_PYTHON` names a Python that already imports OCP instead. Failures are
//! errors naming the STEP file, the version and the fix, never a panic.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

use sha2::{Digest, Sha256};

use super::PartError;
use crate::cache::CacheLocation;

/// The pinned OpenCASCADE wheel's version (`cadquery-ocp-novtk`, OpenCASCADE 8.0.1).
pub const OCP_VERSION: &str = "8.0.1.1.0";
/// The pins, with PyPI's sha256 of each wheel (pip `--require-hashes`).
const REQUIREMENTS: &str = include_str!("../../../scripts/step_import/requirements.txt");
/// The script that reads a STEP file and writes its solids' tessellation as OBJ.
pub(super) const TESSELLATE_PY: &str = include_str!("../../../scripts/step_import/tessellate.py");
/// Written into the venv once pip and the import check succeeded.
const READY_MARK: &str = "cell-ready";

/// One provisioning at a time in this process (threads of one test binary load STEP parts at
/// once); other processes are kept apart by the scratch folder's name and the final rename.
static PROVISIONING: Mutex<()> = Mutex::new(());
/// Makes temporary names unique between the threads of this process.
static TEMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// A name unique to this process and call, for scratch files and folders.
fn unique_suffix() -> String {
    format!(
        "{}-{}",
        std::process::id(),
        TEMP_COUNTER.fetch_add(1, Ordering::Relaxed)
    )
}

/// Where the kernel comes from and where its results are cached.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StepKernel {
    /// A Python that imports OCP already (from `CELL_STEP_PYTHON`); nothing is provisioned.
    pub python_override: Option<PathBuf>,
    /// The cache: `step-ocp-<version>/` (the venv) and `step-meshes/` (tessellations).
    pub cache_dir: PathBuf,
    /// The Python that creates the venv (`CELL_PYTHON`, else `python3`).
    pub python: PathBuf,
}

impl StepKernel {
    /// From the process environment: `CELL_STEP_PYTHON`; the cache `$CELL_CACHE_DIR`,
    /// `$XDG_CACHE_HOME/cell` or `$HOME/.cache/cell`; the venv's base Python `$CELL_PYTHON` or `python3`.
    pub fn from_env() -> Self {
        Self::from_vars(|k| std::env::var_os(k).map(PathBuf::from))
    }

    /// As [`Self::from_env`], with variables looked up by `var` (testable without touching the environment).
    pub fn from_vars(var: impl Fn(&str) -> Option<PathBuf>) -> Self {
        let cache = CacheLocation::from_vars(&var);
        Self {
            python_override: var("CELL_STEP_PYTHON").filter(|v| !v.as_os_str().is_empty()),
            cache_dir: cache.dir,
            python: cache.python,
        }
    }

    /// The provisioned venv's folder.
    pub fn venv_dir(&self) -> PathBuf {
        self.cache_dir.join(format!("step-ocp-{OCP_VERSION}"))
    }

    /// The folder of cached tessellations (and the script that makes them).
    pub fn mesh_cache_dir(&self) -> PathBuf {
        self.cache_dir.join("step-meshes")
    }

    /// A short digest of the script and the kernel version: a cached mesh made by another script
    /// or kernel is not reused.
    pub fn tool_digest() -> String {
        let mut h = Sha256::new();
        h.update(TESSELLATE_PY.as_bytes());
        h.update(OCP_VERSION.as_bytes());
        hex(&h.finalize())[..12].to_string()
    }

    /// The Python to run the script with: the override, or the venv's, provisioned when missing.
    /// `step` is the file being imported, named in errors.
    pub fn python_for(&self, step: &Path) -> Result<PathBuf, PartError> {
        if let Some(python) = &self.python_override {
            return Ok(python.clone());
        }
        let venv = self.venv_dir();
        let python = venv.join("bin/python");
        if venv.join(READY_MARK).is_file() && python.exists() {
            return Ok(python);
        }
        let _one_at_a_time = PROVISIONING.lock().unwrap_or_else(|e| e.into_inner());
        if venv.join(READY_MARK).is_file() && python.exists() {
            return Ok(python);
        }
        self.provision(step)?;
        Ok(python)
    }

    /// The script's path in the mesh cache, written there (atomically) when missing.
    pub fn script(&self, step: &Path) -> Result<PathBuf, PartError> {
        let dir = self.mesh_cache_dir();
        let path = dir.join(format!("tessellate-{}.py", Self::tool_digest()));
        if !path.is_file() {
            write_atomic(&path, TESSELLATE_PY.as_bytes()).map_err(|e| self.error(step, e))?;
        }
        Ok(path)
    }

    /// Creates the venv in a scratch folder beside its place, installs the pinned wheels with
    /// their hashes checked, checks that OCP imports, and renames the folder into place, so an
    /// interrupted run never leaves a half-made venv (a concurrent one that finished first wins).
    fn provision(&self, step: &Path) -> Result<(), PartError> {
        if !(cfg!(target_os = "linux") && cfg!(target_arch = "x86_64")) {
            return Err(self.error(
                step,
                "only Linux x86_64 wheels are pinned for automatic provisioning".into(),
            ));
        }
        let venv = self.venv_dir();
        std::fs::create_dir_all(&self.cache_dir).map_err(|e| {
            self.error(
                step,
                format!("cannot create {}: {e}", self.cache_dir.display()),
            )
        })?;
        let scratch = self
            .cache_dir
            .join(format!(".step-ocp-{OCP_VERSION}-{}", unique_suffix()));
        let _ = std::fs::remove_dir_all(&scratch);
        let result = self.install(step, &scratch);
        let result = result.and_then(|()| match std::fs::rename(&scratch, &venv) {
            Ok(()) => Ok(()),
            Err(_) if venv.join(READY_MARK).is_file() => Ok(()),
            Err(e) => Err(self.error(
                step,
                format!("cannot move the venv into {}: {e}", venv.display()),
            )),
        });
        let _ = std::fs::remove_dir_all(&scratch);
        result
    }

    fn install(&self, step: &Path, scratch: &Path) -> Result<(), PartError> {
        run(
            Command::new(&self.python)
                .arg("-m")
                .arg("venv")
                .arg(scratch),
            "python -m venv",
        )
        .map_err(|e| self.error(step, e))?;
        let requirements = scratch.join("requirements.txt");
        write_atomic(&requirements, REQUIREMENTS.as_bytes()).map_err(|e| self.error(step, e))?;
        let python = scratch.join("bin/python");
        run(
            Command::new(&python)
                .args([
                    "-m",
                    "pip",
                    "install",
                    "--quiet",
                    "--disable-pip-version-check",
                ])
                .args(["--no-deps", "--only-binary=:all:", "--require-hashes", "-r"])
                .arg(&requirements),
            "pip install",
        )
        .map_err(|e| self.error(step, e))?;
        run(
            Command::new(&python).args(["-c", "import OCP.STEPControl, OCP.BRepMesh"]),
            "import OCP",
        )
        .map_err(|e| self.error(step, e))?;
        write_atomic(&scratch.join(READY_MARK), OCP_VERSION.as_bytes())
            .map_err(|e| self.error(step, e))
    }

    /// A kernel error for `step`, with what to do about it.
    pub fn error(&self, step: &Path, reason: String) -> PartError {
        let hint = match &self.python_override {
            Some(python) => format!(
                "CELL_STEP_PYTHON is {}: it must import OCP (pip install cadquery-ocp-novtk=={OCP_VERSION}), \
                 or unset it to provision the kernel automatically",
                python.display()
            ),
            None => format!(
                "STEP import provisions OpenCASCADE (pip install cadquery-ocp-novtk=={OCP_VERSION}, \
                 67 MB from PyPI, once) into {}: reach PyPI once, set CELL_PYTHON to a Python 3.11 to \
                 3.13 with venv and pip, or set CELL_STEP_PYTHON to a Python that imports OCP",
                self.venv_dir().display()
            ),
        };
        PartError::StepKernel {
            path: step.into(),
            reason,
            hint,
        }
    }
}

/// Runs a command; an error says which step failed and the tail of what it printed.
fn run(command: &mut Command, what: &str) -> Result<(), String> {
    let out = command
        .output()
        .map_err(|e| format!("{what}: cannot run {:?}: {e}", command.get_program()))?;
    if out.status.success() {
        return Ok(());
    }
    Err(format!(
        "{what} failed ({}): {}",
        out.status,
        tail(&String::from_utf8_lossy(&out.stderr), 600)
    ))
}

/// The last `n` bytes of a text (at a character boundary), trimmed.
pub(super) fn tail(text: &str, n: usize) -> String {
    let text = text.trim();
    let mut start = text.len().saturating_sub(n);
    while !text.is_char_boundary(start) {
        start += 1;
    }
    text[start..].to_string()
}

/// Lowercase hexadecimal.
pub(super) fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Writes a file through a temporary file beside it (named by the process) and a rename.
pub(super) fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), String> {
    use std::io::Write;
    let dir = path.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    let name = path.file_name().unwrap_or_default().to_string_lossy();
    let tmp = dir.join(format!(".{name}.{}.tmp", unique_suffix()));
    let written = std::fs::File::create(&tmp)
        .and_then(|mut f| f.write_all(bytes).and_then(|()| f.sync_all()))
        .and_then(|()| std::fs::rename(&tmp, path));
    written.map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        format!("cannot write {}: {e}", path.display())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cache_follows_cell_cache_dir_then_xdg_then_home() {
        let vars = |pairs: &'static [(&'static str, &'static str)]| {
            move |k: &str| {
                pairs
                    .iter()
                    .find(|(n, _)| *n == k)
                    .map(|(_, v)| PathBuf::from(v))
            }
        };
        let k = StepKernel::from_vars(vars(&[("HOME", "/h")]));
        assert_eq!(
            k.venv_dir(),
            PathBuf::from(format!("/h/.cache/cell/step-ocp-{OCP_VERSION}"))
        );
        assert_eq!(k.python, PathBuf::from("python3"));
        let k = StepKernel::from_vars(vars(&[("HOME", "/h"), ("XDG_CACHE_HOME", "/x")]));
        assert_eq!(k.mesh_cache_dir(), PathBuf::from("/x/cell/step-meshes"));
        let k = StepKernel::from_vars(vars(&[
            ("CELL_CACHE_DIR", "/c"),
            ("CELL_STEP_PYTHON", "/p/python"),
        ]));
        assert_eq!(k.cache_dir, PathBuf::from("/c"));
        assert_eq!(k.python_override, Some(PathBuf::from("/p/python")));
    }

    #[test]
    fn a_python_that_cannot_run_is_an_error_naming_the_file_the_version_and_the_fix() {
        let dir = tempfile::tempdir().unwrap();
        let kernel = StepKernel {
            python_override: None,
            cache_dir: dir.path().into(),
            python: dir.path().join("no-such-python"),
        };
        let err = kernel
            .python_for(Path::new("peg.step"))
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("peg.step: cannot import STEP"), "{err}");
        assert!(err.contains("no-such-python"), "{err}");
        assert!(
            err.contains(&format!("cadquery-ocp-novtk=={OCP_VERSION}")),
            "{err}"
        );
        assert!(err.contains("CELL_STEP_PYTHON"), "{err}");
        assert!(!kernel.venv_dir().exists(), "no half-made venv is left");
    }
}
