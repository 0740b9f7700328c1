//! Errors of the learned pipeline: each names the model file, the image or the setting at fault.

use std::path::PathBuf;

use crate::onnx::OnnxError;
use crate::perceive::PerceptionError;

/// Why the learned pipeline could not load its models or process a frame.
#[derive(Debug, thiserror::Error)]
pub enum LearnedError {
    /// A model or manifest could not be read, is corrupt, or fails its checksum or signature.
    #[error(transparent)]
    Onnx(#[from] OnnxError),
    /// A manifest's inputs or outputs differ from the model contract the pipeline is written for.
    #[error("{}: {message}", manifest.display())]
    Contract {
        /// The manifest.
        manifest: PathBuf,
        /// What differs.
        message: String,
    },
    /// A manifest's parts are not the catalog's non-fixture parts in catalog order.
    #[error(
        "{}: parts {found:?} differ from the catalog's non-fixture parts {expected:?} (same order required)",
        manifest.display()
    )]
    Parts {
        /// The manifest.
        manifest: PathBuf,
        /// The catalog's non-fixture parts, in order.
        expected: Vec<String>,
        /// The manifest's parts.
        found: Vec<String>,
    },
    /// A part of the catalog cannot be used (e.g. its keypoint count differs from the network's).
    #[error("part {part}: {reason}")]
    Part {
        /// The part.
        part: String,
        /// Why.
        reason: String,
    },
    /// The image cannot be processed (format, size, region of interest).
    #[error("image: {0}")]
    Image(String),
    /// A network returned outputs of unexpected shape.
    #[error("{}: output {output}: {message}", model.display())]
    Output {
        /// The model file.
        model: PathBuf,
        /// The output name.
        output: String,
        /// What is wrong.
        message: String,
    },
    /// The pose estimator could not be built (settings or catalog).
    #[error("pose estimator: {0}")]
    Estimator(PerceptionError),
    /// Bad pipeline settings.
    #[error("invalid learned-pipeline settings: {0}")]
    Settings(String),
}

impl From<LearnedError> for PerceptionError {
    fn from(e: LearnedError) -> Self {
        match e {
            LearnedError::Image(m) => PerceptionError::Frame(m),
            LearnedError::Estimator(p) => p,
            LearnedError::Settings(m) => PerceptionError::Settings(m),
            LearnedError::Part { part, reason } => PerceptionError::Part { part, reason },
            other => PerceptionError::Model(other.to_string()),
        }
    }
}
