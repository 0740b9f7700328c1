//! The model manifest: a TOML file next to each ONNX model naming its file, checksum, signature
//! (input and output names, shapes, element type), opset and, for trained models, the provenance.

use super::OnnxError;
use crate::part::line_column;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// One input or output of a model: its name, shape (`-1` marks a dynamic dimension such as the
/// batch) and element type (`f32` is the only type today).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TensorSpec {
    /// Tensor name in the graph.
    pub name: String,
    /// Dimensions; `-1` is dynamic.
    pub shape: Vec<i64>,
    /// Element type (`"f32"`).
    pub dtype: String,
}

/// How a trained model was made: dataset, code, curve and held-out metrics.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Training {
    /// Seed of the generated training dataset.
    pub dataset_seed: u64,
    /// Number of training samples (crops or frames).
    pub dataset_size: u64,
    /// Git commit of the code that trained and exported it.
    pub code_commit: String,
    /// Training curve file (CSV), relative to the manifest.
    pub curve: PathBuf,
    /// Test-split metrics by name (e.g. `mask_iou`, `keypoint_px`).
    pub test_metrics: BTreeMap<String, f64>,
    /// The table's scale in the training frames, pixels per mm, lowest and highest: the net
    /// learned a part's size in pixels over this range, so the pipeline shows it frames at the
    /// range's middle ([`crate::learned::InputScale::Trained`]); absent: frames as captured.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub table_px_per_mm: Option<[f64; 2]>,
}

/// A model manifest (`<model>.toml` next to `<model>.onnx`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelManifest {
    /// Model name.
    pub name: String,
    /// Parts the model handles (catalog names); empty for a part-agnostic model.
    #[serde(default)]
    pub parts: Vec<String>,
    /// The ONNX file, relative to the manifest.
    pub file: PathBuf,
    /// sha256 of the ONNX file (lower-case hex).
    pub sha256: String,
    /// ONNX opset the model was exported with.
    pub opset: u32,
    /// Inputs, in graph order.
    pub inputs: Vec<TensorSpec>,
    /// Outputs, in graph order.
    pub outputs: Vec<TensorSpec>,
    /// Provenance of a trained model; absent for test fixtures that were not trained.
    #[serde(default)]
    pub training: Option<Training>,
    /// The manifest file (set by [`ModelManifest::load`]).
    #[serde(skip)]
    pub path: PathBuf,
}

impl ModelManifest {
    /// Reads and validates a manifest; errors name the file, line and column.
    pub fn load(path: &Path) -> Result<Self, OnnxError> {
        let text = std::fs::read_to_string(path).map_err(|source| OnnxError::Io {
            path: path.into(),
            source,
        })?;
        Self::parse(&text, path)
    }

    /// Parses manifest text read from `path`.
    pub fn parse(text: &str, path: &Path) -> Result<Self, OnnxError> {
        let at = |offset: usize, message: String| {
            let (line, column) = line_column(text, offset);
            OnnxError::Manifest {
                path: path.into(),
                line,
                column,
                message,
            }
        };
        let mut manifest: Self = toml::from_str(text).map_err(|e| {
            at(
                e.span().map_or(0, |s| s.start),
                e.message().trim().to_string(),
            )
        })?;
        let key = |k: &str| {
            text.find(&format!("{k} ="))
                .or_else(|| text.find(k))
                .unwrap_or(0)
        };
        if manifest.sha256.len() != 64 || !manifest.sha256.bytes().all(|b| b.is_ascii_hexdigit()) {
            return Err(at(key("sha256"), "sha256 must be 64 hex digits".into()));
        }
        manifest.sha256.make_ascii_lowercase();
        for spec in manifest.inputs.iter().chain(&manifest.outputs) {
            if spec.dtype != "f32" {
                return Err(at(
                    key(&spec.dtype),
                    format!(
                        "{}: dtype {:?} is not supported (only \"f32\")",
                        spec.name, spec.dtype
                    ),
                ));
            }
            if spec.shape.iter().any(|&d| d == 0 || d < -1) {
                return Err(at(
                    key(&spec.name),
                    format!(
                        "{}: dimensions must be positive or -1, got {:?}",
                        spec.name, spec.shape
                    ),
                ));
            }
        }
        if let Some([lo, hi]) = manifest.training.as_ref().and_then(|t| t.table_px_per_mm)
            && !(lo.is_finite() && lo > 0.0 && hi.is_finite() && hi >= lo)
        {
            return Err(at(
                key("table_px_per_mm"),
                format!("table_px_per_mm must be [lowest, highest] > 0, got [{lo}, {hi}]"),
            ));
        }
        if manifest.inputs.is_empty() || manifest.outputs.is_empty() {
            return Err(at(
                0,
                "a model needs at least one input and one output".into(),
            ));
        }
        manifest.path = path.into();
        Ok(manifest)
    }

    /// The ONNX file this manifest describes.
    pub fn model_path(&self) -> PathBuf {
        self.path
            .parent()
            .unwrap_or(Path::new("."))
            .join(&self.file)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TRAINED: &str = r#"name = "pvnet-main-shell"
parts = ["main_shell"]
file = "pvnet-main-shell.onnx"
sha256 = "A15D2B5113DF6247DB2CF9A9E28658E0C04A4A7E883D30FBD82033A24FBA684F"
opset = 17
[[inputs]]
name = "crops"
shape = [-1, 3, 128, 128]
dtype = "f32"
[[outputs]]
name = "mask"
shape = [-1, 2, 128, 128]
dtype = "f32"
[training]
dataset_seed = 7
dataset_size = 20000
code_commit = "863d068"
curve = "pvnet-main-shell.curve.csv"
test_metrics = { mask_iou = 0.97, keypoint_px = 0.8 }
"#;

    #[test]
    fn a_trained_model_manifest_parses_with_its_provenance() {
        let m = ModelManifest::parse(TRAINED, Path::new("/models/pvnet-main-shell.toml")).unwrap();
        assert_eq!(
            m.model_path(),
            PathBuf::from("/models/pvnet-main-shell.onnx")
        );
        assert_eq!(
            m.sha256,
            "a15d2b5113df6247db2cf9a9e28658e0c04a4a7e883d30fbd82033a24fba684f"
        );
        let t = m.training.unwrap();
        assert_eq!((t.dataset_seed, t.dataset_size), (7, 20000));
        assert_eq!(t.test_metrics["keypoint_px"], 0.8);
    }

    #[test]
    fn unknown_keys_bad_dimensions_and_types_are_located() {
        let err = |text: String| {
            ModelManifest::parse(&text, Path::new("m.toml"))
                .unwrap_err()
                .to_string()
        };
        let e = err(TRAINED.replace("dataset_seed", "datset_seed"));
        assert!(
            e.starts_with("m.toml:15:1: unknown field `datset_seed`"),
            "{e}"
        );
        let e = err(TRAINED.replace("[-1, 2, 128, 128]", "[-1, 0, 128, 128]"));
        assert!(e.contains("mask: dimensions must be positive or -1"), "{e}");
        let e = err(TRAINED.replace("dtype = \"f32\"\n[training]", "dtype = \"f16\"\n[training]"));
        assert!(e.contains("mask: dtype \"f16\" is not supported"), "{e}");
    }

    #[test]
    fn the_training_scale_range_is_read_and_a_reversed_one_is_located() {
        let scaled = |range: &str| {
            TRAINED.replace("curve = ", &format!("table_px_per_mm = {range}\ncurve = "))
        };
        let m = ModelManifest::parse(&scaled("[5.6, 7.7]"), Path::new("m.toml")).unwrap();
        assert_eq!(m.training.unwrap().table_px_per_mm, Some([5.6, 7.7]));
        let e = ModelManifest::parse(&scaled("[7.7, 5.6]"), Path::new("m.toml"))
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("m.toml:18:1: table_px_per_mm must be [lowest, highest] > 0"),
            "{e}"
        );
    }
}
