//! Why a board or a calibration was refused.

use std::path::PathBuf;

/// A board description that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum BoardError {
    /// The board file could not be read.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The board file is malformed or describes an impossible board.
    #[error("{}:{line}:{column}: {message}", path.display())]
    File {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// What is wrong.
        message: String,
    },
    /// A description that cannot be printed or detected.
    #[error("board `{key}`: {message}")]
    Invalid {
        /// The offending key.
        key: &'static str,
        /// What is wrong.
        message: String,
    },
    /// A family the reference library does not define.
    #[error(
        "unknown tag family `{0}` (known: tag36h11, tag25h9, tag16h5, tagStandard41h12, tagStandard52h13)"
    )]
    UnknownFamily(String),
}

impl BoardError {
    /// The board file's key an error is about, if any.
    pub fn key(&self) -> Option<&'static str> {
        match self {
            Self::Invalid { key, .. } => Some(key),
            _ => None,
        }
    }
}
