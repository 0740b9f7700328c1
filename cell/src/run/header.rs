//! The first line of a results file: which scenario file, seed, record format, shard and robot
//! the episodes below it belong to.

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use super::Shard;
use crate::episode::RECORD_VERSION;

/// The `format` value that marks a file as a cell results file.
pub const RESULTS_FORMAT: &str = "cell-episodes";

/// Header line of `episodes.jsonl`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ResultsHeader {
    /// Always [`RESULTS_FORMAT`].
    pub format: String,
    /// Episode record version ([`RECORD_VERSION`]).
    pub record_version: u32,
    /// Scenario name.
    pub scenario: String,
    /// Scenario seed.
    pub seed: u64,
    /// SHA-256 of the scenario file's bytes, lowercase hex.
    pub scenario_sha256: String,
    /// The slice of episodes this file holds.
    pub shard: Shard,
    /// The robot that produced the episodes (`sim`, `virtual-ur` or `ur://HOST:PORT`, as
    /// `--robot` names it); files written before robots were recorded read as [`SIM_ROBOT`].
    #[serde(default = "sim_robot")]
    pub robot: String,
    /// Each assembly step's lateral capture band (clearance / 2 + lead-in), millimetres, for
    /// reports; derived from the scenario file the hash names, so not compared between files.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub capture_mm: Vec<f64>,
    /// The scenario file the run read (absolute), so `cell replay` can find it; not compared
    /// between files (the hash is).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scenario_file: Option<std::path::PathBuf>,
}

/// The robot of the in-process simulation, `--robot`'s default.
pub const SIM_ROBOT: &str = "sim";

fn sim_robot() -> String {
    SIM_ROBOT.into()
}

impl ResultsHeader {
    /// The header for a scenario file's bytes, its name and seed, and a shard.
    pub fn new(scenario: &str, seed: u64, scenario_file: &[u8], shard: Shard) -> Self {
        Self {
            format: RESULTS_FORMAT.into(),
            record_version: RECORD_VERSION,
            scenario: scenario.into(),
            seed,
            scenario_sha256: sha256_hex(scenario_file),
            shard,
            robot: SIM_ROBOT.into(),
            capture_mm: Vec::new(),
            scenario_file: None,
        }
    }

    /// The same header for episodes produced by `robot` (as `--robot` names it).
    pub fn with_robot(self, robot: impl Into<String>) -> Self {
        Self {
            robot: robot.into(),
            ..self
        }
    }

    /// The first field in which `self` (found in a file) differs from `expected`, as
    /// (field, expected, found).
    pub fn mismatch(&self, expected: &ResultsHeader) -> Option<(&'static str, String, String)> {
        let pairs: [(&'static str, String, String); 7] = [
            ("format", expected.format.clone(), self.format.clone()),
            (
                "record_version",
                expected.record_version.to_string(),
                self.record_version.to_string(),
            ),
            ("scenario", expected.scenario.clone(), self.scenario.clone()),
            ("seed", expected.seed.to_string(), self.seed.to_string()),
            (
                "scenario_sha256",
                expected.scenario_sha256.clone(),
                self.scenario_sha256.clone(),
            ),
            ("shard", expected.shard.to_string(), self.shard.to_string()),
            ("robot", expected.robot.clone(), self.robot.clone()),
        ];
        pairs.into_iter().find(|(_, e, f)| e != f)
    }
}

/// SHA-256 of `bytes` as lowercase hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sha256_matches_the_standard_vector() {
        assert_eq!(
            sha256_hex(b"abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }

    #[test]
    fn mismatch_names_the_field() {
        let a = ResultsHeader::new("s", 7, b"x", Shard::ALL);
        assert_eq!(a.mismatch(&a), None);
        let b = ResultsHeader::new("s", 7, b"y", Shard::ALL);
        assert_eq!(b.mismatch(&a).unwrap().0, "scenario_sha256");
        let c = ResultsHeader::new("s", 8, b"x", Shard::ALL);
        assert_eq!(c.mismatch(&a).unwrap().0, "seed");
        let d = a.clone().with_robot("virtual-ur");
        assert_eq!(
            d.mismatch(&a).unwrap(),
            ("robot", "sim".into(), "virtual-ur".into())
        );
    }

    #[test]
    fn a_header_without_a_robot_reads_as_the_simulation() {
        let mut v = serde_json::to_value(ResultsHeader::new("s", 7, b"x", Shard::ALL)).unwrap();
        v.as_object_mut().unwrap().remove("robot");
        let h: ResultsHeader = serde_json::from_value(v).unwrap();
        assert_eq!(h.robot, SIM_ROBOT);
    }
}
