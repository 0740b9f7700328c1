//! Running the real `cell` binary from the integration tests.

#![allow(dead_code)]

use std::path::PathBuf;
use std::process::{Command, Output};

/// The repository root.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

/// `scenarios/usbc_nominal.toml`, as an argument.
pub fn nominal() -> String {
    root()
        .join("scenarios/usbc_nominal.toml")
        .display()
        .to_string()
}

/// Runs `cell ARGS...` to completion.
pub fn cell(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_cell"))
        .args(args)
        .output()
        .expect("cell runs")
}

/// Its stdout and stderr together.
pub fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}
