//! Puts MuJoCo 3.17.0's `libmujoco.so` on the link path of everything that depends on this
//! crate, so `cargo build` and `cargo test` work on a fresh clone with nothing installed by hand.
//!
//! - `MUJOCO_DYNAMIC_LINK_DIR` set (the variable mujoco-rs itself reads): that folder is used
//!   after checking it holds MuJoCo 3.17.0.
//! - Otherwise the official PyPI wheel of mujoco 3.17.0 is taken from the cache
//!   (`MUJOCO_WHEEL_CACHE`, else `$XDG_CACHE_HOME/cell`, else `~/.cache/cell`) or downloaded
//!   there with `python3 -m pip download` (`MUJOCO_PYTHON` picks the Python), its sha256 checked against the pinned one, and `libmujoco.so.3.17.0`
//!   extracted into this crate's OUT_DIR (inside the target folder, so `cargo run` and
//!   `cargo test` put it on the loader's path).

use std::fs;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::Command;

use sha2::{Digest, Sha256};

/// The MuJoCo version mujoco-rs 7 is generated for.
const VERSION: &str = "3.17.0";
/// The wheel's file name (any wheel of the version carries the same library).
const WHEEL: &str = "mujoco-3.17.0-cp311-cp311-manylinux_2_27_x86_64.manylinux_2_28_x86_64.whl";
/// The requirement pip downloads (by name from PyPI, through pip's own configuration).
const REQUIREMENT: &str = "mujoco==3.17.0";
/// Its sha256, as PyPI publishes it.
const WHEEL_SHA256: &str = "d66928d86a2d1b601bbaa4dc11db50214d17d5301bb8afd84721313b67ff0874";
/// The library inside the wheel.
const MEMBER: &str = "mujoco/libmujoco.so.3.17.0";
/// The library's file name (its soname).
const LIB: &str = "libmujoco.so.3.17.0";

const HOW: &str = "MuJoCo 3.17.0 is provisioned by the `mujoco-provision` build script from the \
PyPI wheel mujoco==3.17.0 (needs python3 with pip and the network once; the wheel is cached), or taken from \
MUJOCO_DYNAMIC_LINK_DIR=/abs/path/to/mujoco-3.17.0/lib. To build without MuJoCo, use \
`--no-default-features` on sim (the `mujoco` feature)";

fn main() {
    println!("cargo::rerun-if-changed=build.rs");
    for var in [
        "MUJOCO_DYNAMIC_LINK_DIR",
        "MUJOCO_WHEEL_CACHE",
        "XDG_CACHE_HOME",
        "HOME",
        "MUJOCO_PYTHON",
    ] {
        println!("cargo::rerun-if-env-changed={var}");
    }
    match provision() {
        Ok(dir) => {
            println!("cargo::rustc-link-search=native={}", dir.display());
            println!("cargo::rustc-env=MUJOCO_PROVISIONED_DIR={}", dir.display());
            println!("cargo::metadata=LIB_DIR={}", dir.display());
        }
        Err(e) => {
            eprintln!("error: MuJoCo {VERSION} is not available: {e}\n{HOW}.");
            std::process::exit(1);
        }
    }
}

/// The folder holding `libmujoco.so` for MuJoCo 3.17.0.
fn provision() -> Result<PathBuf, String> {
    if let Some(dir) = std::env::var_os("MUJOCO_DYNAMIC_LINK_DIR") {
        let dir = PathBuf::from(dir);
        check_dir(&dir)?;
        return Ok(dir);
    }
    let target_os = std::env::var("CARGO_CFG_TARGET_OS").unwrap_or_default();
    let target_arch = std::env::var("CARGO_CFG_TARGET_ARCH").unwrap_or_default();
    if target_os != "linux" || target_arch != "x86_64" {
        return Err(format!(
            "the pinned wheel is for x86_64 Linux, not {target_arch} {target_os}: set \
             MUJOCO_DYNAMIC_LINK_DIR"
        ));
    }
    let out = PathBuf::from(std::env::var_os("OUT_DIR").ok_or("OUT_DIR is not set")?).join("lib");
    let lib = out.join(LIB);
    if !lib.is_file() {
        let wheel = cached_wheel()?;
        extract(&wheel, &out)?;
    }
    let link = out.join("libmujoco.so");
    if fs::symlink_metadata(&link).is_err() {
        std::os::unix::fs::symlink(LIB, &link)
            .map_err(|e| format!("linking {} to {LIB}: {e}", link.display()))?;
    }
    Ok(out)
}

/// Checks that `dir/libmujoco.so` exists and is MuJoCo 3.17.0.
fn check_dir(dir: &Path) -> Result<(), String> {
    let so = dir.join("libmujoco.so");
    let real = fs::canonicalize(&so).map_err(|e| {
        format!(
            "MUJOCO_DYNAMIC_LINK_DIR={} has no libmujoco.so ({e})",
            dir.display()
        )
    })?;
    let name = real
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    if name != LIB {
        return Err(format!(
            "MUJOCO_DYNAMIC_LINK_DIR={}: libmujoco.so is {name}, expected {LIB} (MuJoCo \
             {VERSION}, the version mujoco-rs 7 is generated for)",
            dir.display()
        ));
    }
    Ok(())
}

/// The cache folder for the wheel.
fn cache_dir() -> Result<PathBuf, String> {
    if let Some(d) = std::env::var_os("MUJOCO_WHEEL_CACHE") {
        return Ok(PathBuf::from(d));
    }
    if let Some(d) = std::env::var_os("XDG_CACHE_HOME") {
        return Ok(PathBuf::from(d).join("cell"));
    }
    std::env::var_os("HOME")
        .map(|h| PathBuf::from(h).join(".cache").join("cell"))
        .ok_or_else(|| "neither MUJOCO_WHEEL_CACHE nor HOME is set".into())
}

/// The verified wheel, downloaded into the cache when it is missing or does not match.
fn cached_wheel() -> Result<PathBuf, String> {
    let dir = cache_dir()?;
    fs::create_dir_all(&dir).map_err(|e| format!("creating {}: {e}", dir.display()))?;
    let wheel = dir.join(WHEEL);
    if wheel.is_file() && sha256(&wheel)? == WHEEL_SHA256 {
        return Ok(wheel);
    }
    let scratch = dir.join(format!("download.{}", std::process::id()));
    let _ = fs::remove_dir_all(&scratch);
    let python = std::env::var("MUJOCO_PYTHON").unwrap_or_else(|_| "python3".into());
    let status = Command::new(&python)
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
            "3.11",
        ])
        .args(["--implementation", "cp", "--abi", "cp311", "--dest"])
        .arg(&scratch)
        .arg(REQUIREMENT)
        .status()
        .map_err(|e| format!("running `{python} -m pip download {REQUIREMENT}`: {e}"));
    let fetched = scratch.join(WHEEL);
    let result = match status {
        Err(e) => Err(e),
        Ok(s) if !s.success() => Err(format!(
            "`{python} -m pip download {REQUIREMENT}` failed ({s})"
        )),
        Ok(_) if !fetched.is_file() => Err(format!(
            "`{python} -m pip download {REQUIREMENT}` did not fetch {WHEEL}"
        )),
        Ok(_) => match sha256(&fetched) {
            Err(e) => Err(e),
            Ok(got) if got != WHEEL_SHA256 => Err(format!(
                "{WHEEL} has sha256 {got}, expected {WHEEL_SHA256}: refusing it"
            )),
            Ok(_) => fs::rename(&fetched, &wheel)
                .map_err(|e| format!("moving the wheel into the cache: {e}")),
        },
    };
    let _ = fs::remove_dir_all(&scratch);
    result.map(|()| wheel)
}

/// Hex sha256 of a file.
fn sha256(path: &Path) -> Result<String, String> {
    let mut file = fs::File::open(path).map_err(|e| format!("reading {}: {e}", path.display()))?;
    let mut hasher = Sha256::new();
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = file
            .read(&mut buf)
            .map_err(|e| format!("reading {}: {e}", path.display()))?;
        if n == 0 {
            break;
        }
        hasher.update(&buf[..n]);
    }
    Ok(hasher
        .finalize()
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect())
}

/// Extracts the library from the wheel into `out` (written beside, then renamed).
fn extract(wheel: &Path, out: &Path) -> Result<(), String> {
    let file = fs::File::open(wheel).map_err(|e| format!("opening {}: {e}", wheel.display()))?;
    let mut archive =
        zip::ZipArchive::new(file).map_err(|e| format!("reading {}: {e}", wheel.display()))?;
    let mut member = archive
        .by_name(MEMBER)
        .map_err(|e| format!("{} has no {MEMBER}: {e}", wheel.display()))?;
    fs::create_dir_all(out).map_err(|e| format!("creating {}: {e}", out.display()))?;
    let partial = out.join(format!("{LIB}.part"));
    let mut dst =
        fs::File::create(&partial).map_err(|e| format!("writing {}: {e}", partial.display()))?;
    std::io::copy(&mut member, &mut dst).map_err(|e| format!("extracting {MEMBER}: {e}"))?;
    drop(dst);
    fs::rename(&partial, out.join(LIB)).map_err(|e| format!("placing {LIB}: {e}"))
}
