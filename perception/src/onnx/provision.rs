//! ONNX Runtime provisioning: the shared library comes from the official PyPI wheel of a pinned
//! onnxruntime version, fetched with pip (the ordinary PyPI client), checksum-verified, extracted and
//! cached; `ORT_DYLIB_PATH` overrides it. Failures are errors naming the version and the fix, never a
//! panic: `ort` is only reached with a library that is present.

use super::OnnxError;
use crate::cache::CacheLocation;
use sha2::{Digest, Sha256};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// The ONNX Runtime version `ort` 2.0.0-rc.15 (API 31) is built against.
pub const ORT_VERSION: &str = "1.31.1";
/// The pinned wheel (CPython 3.11, manylinux_2_28 x86_64): its library does not depend on Python.
const WHEEL: &str = "onnxruntime-1.31.1-cp311-cp311-manylinux_2_28_x86_64.whl";
/// sha256 of [`WHEEL`], as PyPI publishes it.
const WHEEL_SHA256: &str = "5752bd508126ae7c49894d3b9d2e83f0c3d487319246d04c444b393308d7ad7f";
/// The library inside the wheel.
const LIBRARY_IN_WHEEL: &str = "onnxruntime/capi/libonnxruntime.so.1.31.1";
/// The library's file name in the cache.
const LIBRARY: &str = "libonnxruntime.so.1.31.1";
/// sha256 of [`LIBRARY_IN_WHEEL`].
const LIBRARY_SHA256: &str = "fc44112fbe06d7d689c57e11d3862031f64711007e4ee020f8eed5185fd2c1d3";

/// Where the library comes from: an explicit override, or the cache (provisioned on first use).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RuntimeConfig {
    /// A library to load as is (from `ORT_DYLIB_PATH`); no checksum, any ONNX Runtime ≥ 1.31.
    pub dylib_override: Option<PathBuf>,
    /// Folder holding `onnxruntime-<version>/libonnxruntime.so.<version>`.
    pub cache_dir: PathBuf,
    /// The Python whose pip downloads the wheel.
    pub python: PathBuf,
}

impl RuntimeConfig {
    /// From the process environment: `ORT_DYLIB_PATH`, then the cache `$CELL_CACHE_DIR`,
    /// `$XDG_CACHE_HOME/cell` or `$HOME/.cache/cell`; pip from `$CELL_PYTHON` or `python3`.
    pub fn from_env() -> Self {
        Self::from_vars(|k| std::env::var_os(k).map(PathBuf::from))
    }

    /// As [`Self::from_env`], with variables looked up by `var` (testable without touching the environment).
    pub fn from_vars(var: impl Fn(&str) -> Option<PathBuf>) -> Self {
        let cache = CacheLocation::from_vars(&var);
        Self {
            dylib_override: var("ORT_DYLIB_PATH").filter(|v| !v.as_os_str().is_empty()),
            cache_dir: cache.dir,
            python: cache.python,
        }
    }

    /// Where the provisioned library lives in the cache.
    pub fn cached_library(&self) -> PathBuf {
        self.cache_dir
            .join(format!("onnxruntime-{ORT_VERSION}"))
            .join(LIBRARY)
    }

    /// The library to load: the override if set (it must exist), else the cached library,
    /// provisioned first when missing or when its checksum is wrong.
    pub fn library(&self) -> Result<PathBuf, OnnxError> {
        if let Some(path) = &self.dylib_override {
            if !path.is_file() {
                return Err(runtime_error(path, "ORT_DYLIB_PATH names no file".into()));
            }
            return Ok(path.clone());
        }
        let path = self.cached_library();
        if path.is_file() && sha256_file(&path)? == LIBRARY_SHA256 {
            return Ok(path);
        }
        provision(self, &path)?;
        Ok(path)
    }
}

/// A loaded ONNX Runtime: the `ort` environment sessions are built in.
#[derive(Clone)]
pub struct Runtime {
    /// The `ort` environment.
    pub environment: ort::environment::Environment,
    /// The library it was loaded from.
    pub library: PathBuf,
}

/// The process's runtime: ONNX Runtime can be loaded once per process.
static LOADED: Mutex<Option<Runtime>> = Mutex::new(None);

impl Runtime {
    /// The runtime for the process environment ([`RuntimeConfig::from_env`]).
    pub fn get() -> Result<Self, OnnxError> {
        Self::load(&RuntimeConfig::from_env())
    }

    /// Loads ONNX Runtime per `config` (provisioning it if needed), once per process; later calls
    /// return the same runtime, or an error if they ask for a different library.
    pub fn load(config: &RuntimeConfig) -> Result<Self, OnnxError> {
        let mut loaded = LOADED.lock().unwrap_or_else(|e| e.into_inner());
        // Once loaded, only compare paths: the library in memory cannot change.
        let library = match loaded.as_ref() {
            Some(_) => config
                .dylib_override
                .clone()
                .unwrap_or_else(|| config.cached_library()),
            None => config.library()?,
        };
        if let Some(runtime) = loaded.as_ref() {
            if same_file(&runtime.library, &library) {
                return Ok(runtime.clone());
            }
            return Err(runtime_error(
                &library,
                format!(
                    "this process already loaded ONNX Runtime from {}; only one library can be loaded per process",
                    runtime.library.display()
                ),
            ));
        }
        let absolute = std::path::absolute(&library).map_err(|source| OnnxError::Io {
            path: library.clone(),
            source,
        })?;
        let environment = ort::init_from(&absolute)
            .map_err(|e| runtime_error(&absolute, e.to_string()))?
            .with_name("cell")
            .build()
            .map_err(|e| runtime_error(&absolute, e.to_string()))?;
        let runtime = Runtime {
            environment,
            library: absolute,
        };
        *loaded = Some(runtime.clone());
        Ok(runtime)
    }
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => a == b,
    }
}

fn runtime_error(path: &Path, reason: String) -> OnnxError {
    OnnxError::Runtime {
        path: path.into(),
        expected: ORT_VERSION,
        reason,
        hint: format!(
            "Unset ORT_DYLIB_PATH to provision it automatically (pip downloads onnxruntime=={ORT_VERSION} \
             into $CELL_CACHE_DIR, $XDG_CACHE_HOME/cell or ~/.cache/cell), or set ORT_DYLIB_PATH to \
             {LIBRARY} from that wheel ({LIBRARY_IN_WHEEL})"
        ),
    }
}

/// Downloads the pinned wheel with pip, verifies it, extracts the library and moves it into place
/// atomically (temp file, fsync, rename), so an interrupted run never leaves a corrupt library.
fn provision(config: &RuntimeConfig, target: &Path) -> Result<(), OnnxError> {
    if !(cfg!(target_os = "linux") && cfg!(target_arch = "x86_64")) {
        return Err(runtime_error(
            target,
            "only a Linux x86_64 wheel is pinned for automatic provisioning".into(),
        ));
    }
    let dir = target.parent().unwrap_or(Path::new("."));
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| OnnxError::Io { path, source }
    };
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let scratch = dir.join(format!(".download-{}", std::process::id()));
    let result = download_and_extract(config, target, &scratch);
    let _ = std::fs::remove_dir_all(&scratch);
    result
}

fn download_and_extract(
    config: &RuntimeConfig,
    target: &Path,
    scratch: &Path,
) -> Result<(), OnnxError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| OnnxError::Io { path, source }
    };
    std::fs::create_dir_all(scratch).map_err(io(scratch))?;
    let out = std::process::Command::new(&config.python)
        .args([
            "-m",
            "pip",
            "download",
            "--quiet",
            "--no-deps",
            "--only-binary=:all:",
        ])
        .args([
            "--platform",
            "manylinux_2_28_x86_64",
            "--python-version",
            "311",
        ])
        .args(["--implementation", "cp", "--abi", "cp311", "--dest"])
        .arg(scratch)
        .arg(format!("onnxruntime=={ORT_VERSION}"))
        .output()
        .map_err(|e| {
            runtime_error(
                target,
                format!("cannot run {} -m pip: {e}", config.python.display()),
            )
        })?;
    if !out.status.success() {
        return Err(runtime_error(
            target,
            format!(
                "pip download of onnxruntime=={ORT_VERSION} failed: {}",
                String::from_utf8_lossy(&out.stderr).trim()
            ),
        ));
    }
    let wheel = scratch.join(WHEEL);
    let actual = sha256_file(&wheel)?;
    if actual != WHEEL_SHA256 {
        return Err(runtime_error(
            &wheel,
            format!("wheel sha256 is {actual}, pinned {WHEEL_SHA256}"),
        ));
    }
    let file = std::fs::File::open(&wheel).map_err(io(&wheel))?;
    let mut archive = zip::ZipArchive::new(file)
        .map_err(|e| runtime_error(&wheel, format!("not a wheel (zip): {e}")))?;
    let mut entry = archive
        .by_name(LIBRARY_IN_WHEEL)
        .map_err(|e| runtime_error(&wheel, format!("{LIBRARY_IN_WHEEL}: {e}")))?;
    let temp = scratch.join(LIBRARY);
    let mut hasher = Sha256::new();
    {
        let mut out = std::fs::File::create(&temp).map_err(io(&temp))?;
        let mut buf = vec![0u8; 1 << 16];
        loop {
            let n = entry.read(&mut buf).map_err(io(&wheel))?;
            if n == 0 {
                break;
            }
            hasher.update(&buf[..n]);
            out.write_all(&buf[..n]).map_err(io(&temp))?;
        }
        out.sync_all().map_err(io(&temp))?;
    }
    let actual = hex(&hasher.finalize());
    if actual != LIBRARY_SHA256 {
        return Err(runtime_error(
            &wheel,
            format!("{LIBRARY_IN_WHEEL} sha256 is {actual}, pinned {LIBRARY_SHA256}"),
        ));
    }
    std::fs::rename(&temp, target).map_err(io(target))
}

/// Hex sha256 of a file's bytes.
pub(crate) fn sha256_file(path: &Path) -> Result<String, OnnxError> {
    let mut file = std::fs::File::open(path).map_err(|source| OnnxError::Io {
        path: path.into(),
        source,
    })?;
    let mut hasher = Sha256::new();
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = file.read(&mut buf).map_err(|source| OnnxError::Io {
            path: path.into(),
            source,
        })?;
        if n == 0 {
            break;
        }
        hasher.update(&buf[..n]);
    }
    Ok(hex(&hasher.finalize()))
}

/// Lower-case hex of bytes.
pub(crate) fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn variables_choose_override_cache_and_python() {
        let vars = |pairs: &'static [(&'static str, &'static str)]| {
            move |k: &str| {
                pairs
                    .iter()
                    .find(|(n, _)| *n == k)
                    .map(|(_, v)| PathBuf::from(v))
            }
        };
        let c = RuntimeConfig::from_vars(vars(&[("ORT_DYLIB_PATH", "/x/lib.so"), ("HOME", "/h")]));
        assert_eq!(c.dylib_override, Some(PathBuf::from("/x/lib.so")));
        assert_eq!(c.cache_dir, PathBuf::from("/h/.cache/cell"));
        assert_eq!(c.python, PathBuf::from("python3"));
        let c = RuntimeConfig::from_vars(vars(&[
            ("ORT_DYLIB_PATH", ""),
            ("XDG_CACHE_HOME", "/xdg"),
            ("HOME", "/h"),
            ("CELL_PYTHON", "/py"),
        ]));
        assert_eq!(c.dylib_override, None);
        assert_eq!(
            c.cached_library(),
            PathBuf::from("/xdg/cell/onnxruntime-1.31.1/libonnxruntime.so.1.31.1")
        );
        assert_eq!(c.python, PathBuf::from("/py"));
        let c = RuntimeConfig::from_vars(vars(&[
            ("CELL_CACHE_DIR", "/c"),
            ("XDG_CACHE_HOME", "/xdg"),
        ]));
        assert_eq!(c.cache_dir, PathBuf::from("/c"));
    }
}
