//! ONNX inference plumbing for the learned perception: the ONNX Runtime library (provisioned from a
//! pinned PyPI wheel, loaded through `ort`), model manifests checked against the model file and the
//! session, and a batch session that reuses its buffers across calls.
//!
//! No trained network exists yet: `scenarios/models/` is where trained models and their manifests go.
//!
//! ONNX Runtime: [`Runtime::get`] loads `ORT_DYLIB_PATH` if set, else the cached
//! `libonnxruntime.so.1.31.1` under `$CELL_CACHE_DIR`, `$XDG_CACHE_HOME/cell` or `~/.cache/cell`
//! (`onnxruntime-1.31.1/`), provisioned on first use by `python3 -m pip download onnxruntime==1.31.1`
//! (`$CELL_PYTHON` picks the Python), with the wheel's and the library's sha256 pinned.
//!
//! A manifest (`<model>.toml` beside `<model>.onnx`):
//! ```toml
//! name = "pvnet-main-shell"
//! parts = ["main_shell"]
//! file = "pvnet-main-shell.onnx"
//! sha256 = "<64 hex digits of the .onnx file>"
//! opset = 17
//! [[inputs]]                       # graph order; -1 = dynamic (the batch)
//! name = "crops"
//! shape = [-1, 3, 128, 128]
//! dtype = "f32"
//! [[outputs]]
//! name = "mask"
//! shape = [-1, 2, 128, 128]
//! dtype = "f32"
//! [training]                       # required of trained models, absent for test fixtures
//! dataset_seed = 7
//! dataset_size = 20000
//! code_commit = "<git sha>"
//! curve = "pvnet-main-shell.curve.csv"
//! test_metrics = { mask_iou = 0.97, keypoint_px = 0.8 }
//! ```

mod error;
pub mod manifest;
pub mod provision;
pub mod session;

pub use error::OnnxError;
pub use manifest::{ModelManifest, TensorSpec, Training};
pub use provision::{ORT_VERSION, Runtime, RuntimeConfig};
pub use session::{BatchSession, OutputTensor};
