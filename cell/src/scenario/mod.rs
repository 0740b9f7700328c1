//! Scenario files: loading, validation with file:line:column errors, and the resolved scenario
//! (catalog loaded, paths absolute) that runs use.

mod locate;
mod spec;
mod validate;

pub use locate::{KeyPath, Locator, Seg};
pub use sim::config::*;
pub use spec::*;

use std::fmt;
use std::path::{Path, PathBuf};

use perception::part::{Catalog, line_column};

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

/// A validated scenario with its catalog loaded and its paths resolved.
#[derive(Debug, Clone)]
pub struct Scenario {
    /// The file it came from.
    pub path: PathBuf,
    /// The parsed contents.
    pub spec: ScenarioSpec,
    /// The part catalog.
    pub catalog: Catalog,
}

impl Scenario {
    /// Reads, parses and validates a scenario file and loads its catalog.
    pub fn load(path: &Path) -> Result<Self, ScenarioError> {
        let text = std::fs::read_to_string(path).map_err(|e| {
            ScenarioError(vec![Problem {
                file: path.into(),
                line: 1,
                column: 1,
                key: None,
                message: format!("cannot read the scenario: {e}"),
            }])
        })?;
        Self::parse(&text, path)
    }

    /// Parses and validates scenario text that was read from `path`.
    pub fn parse(text: &str, path: &Path) -> Result<Self, ScenarioError> {
        let spec: ScenarioSpec = toml::from_str(text).map_err(|e| {
            let (line, column) = e
                .span()
                .map(|s| line_column(text, s.start))
                .unwrap_or((1, 1));
            ScenarioError(vec![Problem {
                file: path.into(),
                line,
                column,
                key: None,
                message: e.message().trim().to_string(),
            }])
        })?;
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        let (catalog, issues) = validate::validate(&spec, &dir);
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
        let catalog = catalog.expect("validation loads the catalog when it reports no problem");
        Ok(Self {
            path: path.into(),
            spec,
            catalog,
        })
    }

    /// A path in the scenario file, resolved against the scenario's folder.
    pub fn resolve(&self, relative: &Path) -> PathBuf {
        self.path.parent().unwrap_or(Path::new(".")).join(relative)
    }
}
