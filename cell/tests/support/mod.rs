//! Running the real `cell` binary from the integration tests.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
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

/// Writes `text` as a scenario beside the committed ones (so its relative paths resolve), loads
/// it and removes it; `tag` keeps concurrent tests' files apart.
pub fn load_variant(
    tag: &str,
    text: &str,
) -> Result<cell::scenario::Scenario, cell::scenario::ScenarioError> {
    let path = root().join(format!("scenarios/.test_{tag}_{}.toml", std::process::id()));
    std::fs::write(&path, text).unwrap();
    let result = cell::scenario::Scenario::load(&path);
    std::fs::remove_file(&path).ok();
    result
}

/// The 1-based line of `text` holding `needle`.
pub fn line_of(text: &str, needle: &str) -> usize {
    text.lines()
        .position(|l| l.contains(needle))
        .expect("needle in text")
        + 1
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

/// A copy of the nominal scenario with 3 px keypoint noise (so some episodes fail), written
/// beside it (its relative paths must resolve) and removed when dropped, even by a failed test.
pub struct NoisyScenario(PathBuf);

impl NoisyScenario {
    /// Writes `scenarios/.TAG_PID.toml`.
    pub fn new(tag: &str) -> Self {
        let nominal = std::fs::read_to_string(nominal()).unwrap();
        let noisy = nominal.replace("keypoint_noise_px = 0.5", "keypoint_noise_px = 3.0");
        let path = root().join(format!("scenarios/.{tag}_{}.toml", std::process::id()));
        std::fs::write(&path, noisy).unwrap();
        Self(path)
    }

    /// Its path.
    pub fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for NoisyScenario {
    fn drop(&mut self) {
        std::fs::remove_file(&self.0).ok();
    }
}
