//! ONNX Runtime that cannot be loaded or provisioned gives errors naming the expected version, the
//! path and the fix, never a panic. No test here loads a real library: ONNX Runtime can be loaded
//! once per process, so these live in their own test binary.

use perception::onnx::{ORT_VERSION, Runtime, RuntimeConfig};
use std::path::PathBuf;
use std::process::Command;

fn load_err(config: &RuntimeConfig) -> String {
    match Runtime::load(config) {
        Ok(rt) => panic!("loaded {}", rt.library.display()),
        Err(e) => e.to_string(),
    }
}

fn offline(cache: &std::path::Path) -> RuntimeConfig {
    RuntimeConfig {
        dylib_override: None,
        cache_dir: cache.into(),
        python: "/nonexistent/python3".into(),
    }
}

#[test]
fn an_override_that_is_not_onnx_runtime_is_refused_with_version_and_fix() {
    let dir = tempfile::tempdir().unwrap();
    let bogus = dir.path().join("libonnxruntime.so");
    std::fs::write(&bogus, b"this is not a shared library").unwrap();
    let err = load_err(&RuntimeConfig {
        dylib_override: Some(bogus.clone()),
        ..offline(dir.path())
    });
    assert!(
        err.starts_with(&format!(
            "ONNX Runtime {ORT_VERSION} is not available ({}",
            bogus.display()
        )),
        "{err}"
    );
    assert!(
        err.contains("failed to load") && err.contains("Unset ORT_DYLIB_PATH"),
        "{err}"
    );
    let missing = dir.path().join("nowhere.so");
    let err = load_err(&RuntimeConfig {
        dylib_override: Some(missing.clone()),
        ..offline(dir.path())
    });
    assert!(
        err.contains(&missing.display().to_string())
            && err.contains("ORT_DYLIB_PATH names no file"),
        "{err}"
    );
}

#[test]
fn provisioning_that_cannot_run_pip_names_the_version_and_the_cache() {
    let dir = tempfile::tempdir().unwrap();
    let config = offline(dir.path());
    let err = load_err(&config);
    assert!(
        err.contains(&format!("ONNX Runtime {ORT_VERSION} is not available")),
        "{err}"
    );
    assert!(
        err.contains("cannot run /nonexistent/python3 -m pip"),
        "{err}"
    );
    assert!(
        err.contains(&config.cached_library().display().to_string()),
        "{err}"
    );
    assert!(
        !config.cached_library().exists(),
        "nothing half-written is left in the cache"
    );
}

#[test]
fn a_corrupt_cached_library_is_not_loaded_but_provisioned_again() {
    let dir = tempfile::tempdir().unwrap();
    let config = offline(dir.path());
    let cached = config.cached_library();
    std::fs::create_dir_all(cached.parent().unwrap()).unwrap();
    std::fs::write(&cached, b"truncated download").unwrap();
    let err = load_err(&config);
    assert!(
        err.contains("cannot run /nonexistent/python3 -m pip"),
        "re-provisioning was attempted: {err}"
    );
    let leftovers: Vec<_> = std::fs::read_dir(cached.parent().unwrap())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(leftovers.len(), 1, "scratch folder removed: {leftovers:?}");
}

/// Run only as the child of the test below, with `ORT_DYLIB_PATH` set by it.
#[test]
#[ignore = "child process of ort_dylib_path_in_the_environment_overrides_the_library"]
fn child_loads_the_runtime_from_the_environment() {
    match Runtime::get() {
        Ok(rt) => println!("LOADED {}", rt.library.display()),
        Err(e) => println!("ERROR {e}"),
    }
}

#[test]
fn ort_dylib_path_in_the_environment_overrides_the_library() {
    let dir = tempfile::tempdir().unwrap();
    let bogus = dir.path().join("libonnxruntime-bogus.so");
    std::fs::write(&bogus, [0x7f, b'E', b'L', b'F', 0, 0, 0, 0]).unwrap();
    let out = Command::new(std::env::current_exe().unwrap())
        .args([
            "--exact",
            "child_loads_the_runtime_from_the_environment",
            "--ignored",
            "--nocapture",
        ])
        .env("ORT_DYLIB_PATH", &bogus)
        .env("CELL_CACHE_DIR", PathBuf::from(dir.path()).join("cache"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "child failed (a panic?):\n{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let line = stdout
        .lines()
        .find(|l| l.starts_with("ERROR "))
        .unwrap_or_else(|| panic!("no error line in\n{stdout}"));
    assert!(
        line.contains(&bogus.display().to_string()) && line.contains(ORT_VERSION),
        "{line}"
    );
    assert!(
        !dir.path().join("cache").exists(),
        "the override skips provisioning"
    );
}
