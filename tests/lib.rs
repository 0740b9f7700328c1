//! End-to-end tests over the `cell` crate live in `tests/tests/`; this library only holds shared helpers.

use std::path::PathBuf;

/// The repository root, for locating scenario files and the `cell` binary's data.
pub fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ lives inside the repository")
        .to_path_buf()
}
