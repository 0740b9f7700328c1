//! Scenario files: loading, validation with file:line:column errors, and the resolved scenario
//! (catalog loaded, paths absolute) that runs use.

mod locate;
mod look;
mod messages;
mod spec;
mod validate;

pub use locate::{KeyPath, Locator, Seg};
pub use look::{DEFAULT_LOOK, load_families, load_look, parse_families, parse_look};
pub use sim::config::*;
pub use spec::*;

use std::fmt;
use std::path::{Path, PathBuf};

use perception::part::{Catalog, line_column};
use robots::ur_arm::UrArm;

/// One problem in a scenario file, located.
#[derive(Debug, Clone, PartialEq)]
pub struct Problem {
    /// The scenario file.
    pub file: PathBuf,
    /// 1-based line.
    pub line: usize,
    /// 1-based column.
    pub column: usize,
    /// Key path of the offending value, when known.
    pub key: Option<String>,
    /// What is wrong and what was expected.
    pub message: String,
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}:{}: ", self.file.display(), self.line, self.column)?;
        if let Some(k) = &self.key {
            write!(f, "{k}: ")?;
        }
        write!(f, "{}", self.message)
    }
}

/// Every problem found in a scenario file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub struct ScenarioError(pub Vec<Problem>);

impl ScenarioError {
    /// A TOML syntax or type error in `text` (read from `path`), at its line and column.
    pub fn from_toml(e: &toml::de::Error, text: &str, path: &Path) -> Self {
        let (line, column) = e
            .span()
            .map(|s| line_column(text, s.start))
            .unwrap_or((1, 1));
        Self(vec![Problem {
            file: path.into(),
            line,
            column,
            key: None,
            message: messages::toml_message(e.message(), text, e.span()),
        }])
    }
}

impl fmt::Display for ScenarioError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, p) in self.0.iter().enumerate() {
            if i > 0 {
                writeln!(f)?;
            }
            write!(f, "{p}")?;
        }
        Ok(())
    }
}

/// Reads a scenario file's bytes; a file that cannot be read is a problem at its line 1.
pub fn read_scenario(path: &Path) -> Result<Vec<u8>, ScenarioError> {
    std::fs::read(path).map_err(|e| {
        ScenarioError(vec![Problem {
            file: path.into(),
            line: 1,
            column: 1,
            key: None,
            message: format!("cannot read the scenario: {e}"),
        }])
    })
}

/// A validated scenario with its catalog loaded and its paths resolved.
#[derive(Debug, Clone)]
pub struct Scenario {
    /// The file it came from.
    pub path: PathBuf,
    /// The parsed contents.
    pub spec: ScenarioSpec,
    /// The part catalog.
    pub catalog: Catalog,
    /// The arm `cell.robot` describes: kinematics and joint limits from its URDF.
    pub robot: UrArm,
}

impl Scenario {
    /// Reads, parses and validates a scenario file and loads its catalog.
    pub fn load(path: &Path) -> Result<Self, ScenarioError> {
        let bytes = read_scenario(path)?;
        Self::from_bytes(&bytes, path)
    }

    /// Parses and validates a scenario file's bytes read from `path`: the same errors
    /// `cell check` and `cell run` report, whatever the bytes hold (text that is not UTF-8 is
    /// refused at its first bad byte).
    pub fn from_bytes(bytes: &[u8], path: &Path) -> Result<Self, ScenarioError> {
        let text = std::str::from_utf8(bytes).map_err(|e| {
            let valid = &bytes[..e.valid_up_to()];
            let text = String::from_utf8_lossy(valid);
            let (line, column) = line_column(&text, text.len());
            ScenarioError(vec![Problem {
                file: path.into(),
                line,
                column,
                key: None,
                message: format!(
                    "byte {} is not UTF-8 text; a scenario is a TOML text file (is this a binary \
                     file?)",
                    e.valid_up_to()
                ),
            }])
        })?;
        Self::parse(text, path)
    }

    /// Parses and validates scenario text that was read from `path`.
    pub fn parse(text: &str, path: &Path) -> Result<Self, ScenarioError> {
        let spec: ScenarioSpec =
            toml::from_str(text).map_err(|e| ScenarioError::from_toml(&e, text, path))?;
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        let (catalog, robot, issues) = validate::validate(&spec, &dir);
        if !issues.is_empty() {
            let locator = Locator::new(text);
            let problems = issues
                .into_iter()
                .map(|(key, message)| {
                    let (line, column) = locator
                        .offset(&key)
                        .map(|o| line_column(text, o))
                        .unwrap_or((1, 1));
                    Problem {
                        file: path.into(),
                        line,
                        column,
                        key: Some(key.to_string()),
                        message,
                    }
                })
                .collect();
            return Err(ScenarioError(problems));
        }
        let (Some(catalog), Some(robot)) = (catalog, robot) else {
            unreachable!("validation loads the catalog and the arm when it reports no problem")
        };
        Ok(Self {
            path: path.into(),
            spec,
            catalog,
            robot,
        })
    }

    /// A path in the scenario file, resolved against the scenario's folder.
    pub fn resolve(&self, relative: &Path) -> PathBuf {
        self.path.parent().unwrap_or(Path::new(".")).join(relative)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn nominal() -> (String, PathBuf) {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios");
        let text = std::fs::read_to_string(dir.join("usbc_nominal.toml")).expect("nominal");
        (text, dir.join("policy_variant.toml"))
    }

    /// Asserts that `text` (whose last line sets `[policy] key`) is refused at that value's line
    /// and column, under the key `policy.key`, with a message that holds `says`.
    fn refused_at_its_value(text: &str, path: &Path, key: &str, says: &str) {
        let err = Scenario::parse(text, path).expect_err("out of range");
        let p = &err.0[0];
        let line = text
            .lines()
            .position(|l| l.starts_with(key))
            .expect("written")
            + 1;
        let column = format!("{key} = ").len() + 1;
        assert_eq!((p.line, p.column), (line, column), "{err}");
        assert_eq!(p.key.as_deref(), Some(format!("policy.{key}").as_str()));
        assert!(p.message.contains(says), "{err}");
    }

    #[test]
    fn insertion_attempts_default_from_the_policy_and_are_bounded_with_their_location() {
        let (text, path) = nominal();
        let s = Scenario::parse(&text, &path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            s.spec.policy.max_insertion_attempts,
            DEFAULT_INSERTION_ATTEMPTS
        );
        let with = |n: u32| format!("{text}\n[policy]\nmax_insertion_attempts = {n}\n");
        let s = Scenario::parse(&with(5), &path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(s.spec.policy.max_insertion_attempts, 5);
        for bad in [0, MAX_INSERTION_ATTEMPTS + 1] {
            // Located at the offending value.
            refused_at_its_value(&with(bad), &path, "max_insertion_attempts", "between 1 and");
        }
        // A typo is an unknown key, never a silent default.
        let t = format!("{text}\n[policy]\nmax_insertion_attempt = 2\n");
        assert!(Scenario::parse(&t, &path).is_err());
        // And a negative shake time is refused where it is written.
        let t = text.replace("shake_time = 1.5", "shake_time = -1.0");
        let err = Scenario::parse(&t, &path).expect_err("negative shake time");
        assert_eq!(err.0[0].key.as_deref(), Some("cell.feeder.shake_time"));
    }

    #[test]
    fn the_pick_bar_has_a_default_reaches_the_selection_and_is_bounded_at_its_line() {
        let (text, path) = nominal();
        let s = Scenario::parse(&text, &path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            s.spec.policy.min_pick_confidence,
            DEFAULT_MIN_PICK_CONFIDENCE
        );
        let with = |c: f64| format!("{text}\n[policy]\nmin_pick_confidence = {c:?}\n");
        let s = Scenario::parse(&with(0.5), &path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(s.spec.policy.min_pick_confidence, 0.5);
        let setup = crate::orchestrator::Setup::new(s).expect("the nominal cell plans");
        assert_eq!(setup.settings.selection.min_confidence, 0.5);
        for bad in [-0.1, 1.5] {
            refused_at_its_value(&with(bad), &path, "min_pick_confidence", "between 0 and 1");
        }
    }
}
