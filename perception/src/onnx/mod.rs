//! ONNX inference plumbing for the learned perception: the ONNX Runtime library (provisioned from a
//! pinned PyPI wheel, loaded through `ort`), model manifests checked against the model file and the
//! session, and a batch session that reuses its buffers across calls.
//!
//! No trained network exists yet: `scenarios/models/` is where trained models and their manifests go.

mod error;
pub mod manifest;
pub mod provision;
pub mod session;

pub use error::OnnxError;
pub use manifest::{ModelManifest, TensorSpec, Training};
pub use provision::{ORT_VERSION, Runtime, RuntimeConfig};
pub use session::{BatchSession, OutputTensor};
