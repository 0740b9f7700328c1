//! Errors of the ONNX layer: each names the file and what is wrong with it.

use std::path::PathBuf;

/// What went wrong provisioning ONNX Runtime, reading a manifest or model, or running a session.
#[derive(Debug, thiserror::Error)]
pub enum OnnxError {
    /// ONNX Runtime could not be provisioned or loaded.
    #[error(
        "ONNX Runtime {expected} is not available ({path}): {reason}. {hint}",
        path = path.display()
    )]
    Runtime {
        /// The library path tried (or the cache path it would be provisioned to).
        path: PathBuf,
        /// The ONNX Runtime version this build pins.
        expected: &'static str,
        /// What failed.
        reason: String,
        /// How to fix it.
        hint: String,
    },
    /// A file could not be read.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A manifest is not valid TOML for the schema.
    #[error("{}:{line}:{column}: {message}", path.display())]
    Manifest {
        /// The manifest file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// What is wrong.
        message: String,
    },
    /// A model file's sha256 differs from its manifest.
    #[error("{}: sha256 is {actual}, but the manifest {} says {expected}", path.display(), manifest.display())]
    Checksum {
        /// The model file.
        path: PathBuf,
        /// The manifest naming it.
        manifest: PathBuf,
        /// The sha256 from the manifest.
        expected: String,
        /// The sha256 of the file.
        actual: String,
    },
    /// ONNX Runtime refused the model (corrupt or unsupported).
    #[error("{}: ONNX Runtime cannot load this model: {message}", path.display())]
    Model {
        /// The model file.
        path: PathBuf,
        /// ONNX Runtime's message.
        message: String,
    },
    /// The session's inputs or outputs differ from the manifest.
    #[error("{}: {what} differs from the manifest {}: {detail}", path.display(), manifest.display())]
    Signature {
        /// The model file.
        path: PathBuf,
        /// The manifest.
        manifest: PathBuf,
        /// Which part of the signature (e.g. `input 0`).
        what: String,
        /// Manifest value against model value.
        detail: String,
    },
    /// A batch handed to a session does not fit the model's input.
    #[error("{}: {message}", path.display())]
    Batch {
        /// The model file.
        path: PathBuf,
        /// What is wrong with the batch.
        message: String,
    },
    /// Running the session failed.
    #[error("{}: inference failed: {message}", path.display())]
    Run {
        /// The model file.
        path: PathBuf,
        /// ONNX Runtime's message.
        message: String,
    },
}
