//! Errors of dataset writing and reading.

use std::path::PathBuf;

use crate::scene::{PartModelError, RandomisationError, SceneError};

/// Why a dataset could not be written or read.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// A file or folder could not be created, written, renamed or read.
    #[error("{path}: {source}")]
    Io {
        /// The path.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// A JSON file is malformed or does not follow the BOP structure.
    #[error("{path}: {message}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// An image could not be encoded or decoded.
    #[error("{path}: image: {message}")]
    Image {
        /// The file.
        path: PathBuf,
        /// The codec's message.
        message: String,
    },
    /// The configuration is unusable.
    #[error("dataset configuration: {0}")]
    Config(String),
    /// A randomisation range is unusable.
    #[error(transparent)]
    Randomisation(#[from] RandomisationError),
    /// A scene could not be built.
    #[error(transparent)]
    Scene(#[from] SceneError),
    /// A part could not be loaded.
    #[error(transparent)]
    Part(#[from] PartModelError),
}

impl DatasetError {
    /// An I/O error at `path`.
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            source,
        }
    }
}
