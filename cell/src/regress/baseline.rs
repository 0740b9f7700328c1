//! Baselines: `scenarios/baselines/<scenario>.json`, the success counts a change is compared
//! against, with the commit and date they were measured at.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::stats::Counts;
use crate::run::Summary;
use crate::run::runner::safe_name;

/// Seated-of-reached counts of one assembly step.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StepCounts {
    /// Position in the assembly sequence (0-based).
    pub index: usize,
    /// Part placed by the step.
    pub part: String,
    /// Episodes that attempted the step.
    pub reached: u32,
    /// Episodes in which it seated.
    pub seated: u32,
}

/// A scenario's baseline success counts.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Baseline {
    /// Scenario name.
    pub scenario: String,
    /// SHA-256 of the scenario file the baseline ran.
    pub scenario_sha256: String,
    /// Scenario seed.
    pub seed: u64,
    /// Episode record version.
    pub record_version: u32,
    /// Episodes run.
    pub episodes: u32,
    /// Episodes with every step seated.
    pub successes: u32,
    /// Per-step counts, in assembly order.
    pub steps: Vec<StepCounts>,
    /// Git commit the baseline was measured at (with `-dirty` for uncommitted changes).
    pub commit: Option<String>,
    /// When it was measured (RFC 3339, UTC).
    pub date: String,
}

/// Why a baseline cannot be read or written.
#[derive(Debug, thiserror::Error)]
pub enum BaselineError {
    /// No baseline for the scenario.
    #[error("{}: no baseline for this scenario (create one with `cell regress --update`)", path.display())]
    Missing {
        /// Where it was looked for.
        path: PathBuf,
    },
    /// The file cannot be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The failure.
        source: std::io::Error,
    },
    /// The file is not a valid baseline.
    #[error("{}:{line}:{column}: not a valid baseline: {message}", path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// What is wrong.
        message: String,
    },
}

impl Baseline {
    /// The baseline file of scenario `name` in `dir`.
    pub fn path(dir: &Path, name: &str) -> PathBuf {
        dir.join(format!("{}.json", safe_name(name)))
    }

    /// The baseline a summary would become.
    pub fn from_summary(s: &Summary, commit: Option<String>, date: String) -> Self {
        Self {
            scenario: s.scenario.clone(),
            scenario_sha256: s.scenario_sha256.clone(),
            seed: s.seed,
            record_version: s.record_version,
            episodes: s.episodes,
            successes: s.successes,
            steps: s
                .steps
                .iter()
                .map(|t| StepCounts {
                    index: t.index,
                    part: t.part.clone(),
                    reached: t.reached,
                    seated: t.seated,
                })
                .collect(),
            commit,
            date,
        }
    }

    /// Successes out of episodes.
    pub fn counts(&self) -> Counts {
        Counts::new(self.successes, self.episodes)
    }

    /// Reads and checks a baseline file.
    pub fn load(path: &Path) -> Result<Self, BaselineError> {
        let text = match std::fs::read_to_string(path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err(BaselineError::Missing { path: path.into() });
            }
            Err(source) => {
                return Err(BaselineError::Io {
                    path: path.into(),
                    source,
                });
            }
        };
        let parse = |line, column, message| BaselineError::Parse {
            path: path.into(),
            line,
            column,
            message,
        };
        let b: Baseline =
            serde_json::from_str(&text).map_err(|e| parse(e.line(), e.column(), e.to_string()))?;
        if b.successes > b.episodes {
            return Err(parse(
                1,
                1,
                format!("{} successes of {} episodes", b.successes, b.episodes),
            ));
        }
        if let Some(s) = b
            .steps
            .iter()
            .find(|s| s.seated > s.reached || s.reached > b.episodes)
        {
            return Err(parse(
                1,
                1,
                format!(
                    "step {} ({}): {} seated of {} reached in {} episodes",
                    s.index, s.part, s.seated, s.reached, b.episodes
                ),
            ));
        }
        Ok(b)
    }

    /// Writes the baseline atomically as pretty JSON.
    pub fn save(&self, path: &Path) -> Result<(), BaselineError> {
        let io = |source| BaselineError::Io {
            path: path.into(),
            source,
        };
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(io)?;
        }
        let mut text = serde_json::to_string_pretty(self).expect("a baseline serialises");
        text.push('\n');
        sim::fsutil::write_atomic(path, text.as_bytes()).map_err(io)
    }
}
