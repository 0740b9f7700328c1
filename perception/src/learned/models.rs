//! Which trained models the learned pipeline runs, and the checks that they fit its contract:
//! a segmenter (`image` [-1, 3, -1, -1] → `logits` [-1, 1 + P, -1, -1] and `offsets`
//! [-1, 2, -1, -1] at stride 4) and a keypoint net (`crop` [-1, 3 + P, 128, 128] → `mask`
//! [-1, 1, 64, 64] and `vectors` [-1, 2K, 64, 64] at stride 2), both over the catalog's P
//! non-fixture parts in catalog order.

use std::path::{Path, PathBuf};

use super::LearnedError;
use crate::onnx::{ModelManifest, TensorSpec};
use crate::part::{Catalog, PartRole};

/// Side of the square keypoint crop, pixels.
pub const CROP_SIZE: usize = 128;
/// Side of the keypoint net's output field (stride 2 over the crop), cells.
pub const FIELD_SIZE: usize = 64;
/// Stride of the segmenter's outputs, pixels per cell.
pub const SEGMENTER_STRIDE: usize = 4;
/// The segmenter's input height and width must be multiples of this.
pub const SEGMENTER_MULTIPLE: usize = 16;

/// The two manifests of the learned pipeline, read and checked against the model contract.
#[derive(Debug, Clone, PartialEq)]
pub struct LearnedModels {
    /// The segmenter's manifest (`segmenter.toml`).
    pub segmenter: ModelManifest,
    /// The keypoint net's manifest (`keypoints.toml`).
    pub keypoints: ModelManifest,
}

impl LearnedModels {
    /// The committed models' directory: `scenarios/models/usbc` in the workspace.
    pub fn default_dir() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .parent()
            .unwrap_or(Path::new("."))
            .join("scenarios/models/usbc")
    }

    /// The models tests and benches run: `LEARNED_MODELS_DIR` (e.g. a training run's output)
    /// when set, else [`Self::default_dir`].
    pub fn dir_from_env() -> PathBuf {
        std::env::var_os("LEARNED_MODELS_DIR")
            .map(PathBuf::from)
            .unwrap_or_else(Self::default_dir)
    }

    /// Reads `segmenter.toml` and `keypoints.toml` in `dir` and checks their signatures against
    /// the contract (the model files themselves are checked when the pipeline loads them).
    pub fn in_dir(dir: &Path) -> Result<Self, LearnedError> {
        Self::from_manifests(&dir.join("segmenter.toml"), &dir.join("keypoints.toml"))
    }

    /// Reads and checks two manifests given by path.
    pub fn from_manifests(segmenter: &Path, keypoints: &Path) -> Result<Self, LearnedError> {
        let models = Self {
            segmenter: ModelManifest::load(segmenter)?,
            keypoints: ModelManifest::load(keypoints)?,
        };
        models.check_contract()?;
        Ok(models)
    }

    /// The parts both models handle, in channel order.
    pub fn parts(&self) -> &[String] {
        &self.segmenter.parts
    }

    /// Keypoints per part that the keypoint net votes for.
    pub fn keypoint_count(&self) -> usize {
        (self.keypoints.outputs[output_index(&self.keypoints, "vectors").unwrap_or(0)].shape[1] / 2)
            as usize
    }

    /// Checks both signatures against the contract and that both models list the same parts.
    fn check_contract(&self) -> Result<(), LearnedError> {
        let (seg, kp) = (&self.segmenter, &self.keypoints);
        if seg.parts.is_empty() {
            return Err(contract(seg, "lists no parts".into()));
        }
        if kp.parts != seg.parts {
            return Err(LearnedError::Parts {
                manifest: kp.path.clone(),
                expected: seg.parts.clone(),
                found: kp.parts.clone(),
            });
        }
        let p = seg.parts.len() as i64;
        expect_io(seg, "input", &seg.inputs, &[("image", &[-1, 3, -1, -1])])?;
        expect_io(
            seg,
            "output",
            &seg.outputs,
            &[
                ("logits", &[-1, 1 + p, -1, -1]),
                ("offsets", &[-1, 2, -1, -1]),
            ],
        )?;
        let field = FIELD_SIZE as i64;
        let crop = CROP_SIZE as i64;
        expect_io(
            kp,
            "input",
            &kp.inputs,
            &[("crop", &[-1, 3 + p, crop, crop])],
        )?;
        let vectors = kp
            .outputs
            .iter()
            .find(|o| o.name == "vectors")
            .map_or(0, |o| o.shape.get(1).copied().unwrap_or(0));
        if vectors < 2 || vectors % 2 != 0 {
            return Err(contract(
                kp,
                format!("output vectors needs an even channel count 2K ≥ 2, got {vectors}"),
            ));
        }
        expect_io(
            kp,
            "output",
            &kp.outputs,
            &[
                ("mask", &[-1, 1, field, field]),
                ("vectors", &[-1, vectors, field, field]),
            ],
        )
    }

    /// Checks the models' parts against the catalog: its non-fixture parts, in order, each with
    /// the keypoint count of the keypoint net.
    pub fn check_catalog(&self, catalog: &Catalog) -> Result<(), LearnedError> {
        let expected: Vec<String> = catalog
            .parts
            .iter()
            .filter(|p| p.role != PartRole::Fixture)
            .map(|p| p.name.clone())
            .collect();
        for manifest in [&self.segmenter, &self.keypoints] {
            if manifest.parts != expected {
                return Err(LearnedError::Parts {
                    manifest: manifest.path.clone(),
                    expected: expected.clone(),
                    found: manifest.parts.clone(),
                });
            }
        }
        let k = self.keypoint_count();
        for name in &expected {
            let spec = catalog.part(name).ok_or_else(|| LearnedError::Part {
                part: name.clone(),
                reason: "not in the catalog".into(),
            })?;
            if spec.keypoints.len() != k {
                return Err(LearnedError::Part {
                    part: name.clone(),
                    reason: format!(
                        "has {} keypoints, the keypoint net {} votes for {k}",
                        spec.keypoints.len(),
                        self.keypoints.path.display()
                    ),
                });
            }
        }
        Ok(())
    }
}

/// Index of the output called `name`.
pub(crate) fn output_index(manifest: &ModelManifest, name: &str) -> Option<usize> {
    manifest.outputs.iter().position(|o| o.name == name)
}

fn contract(manifest: &ModelManifest, message: String) -> LearnedError {
    LearnedError::Contract {
        manifest: manifest.path.clone(),
        message,
    }
}

/// Checks that `specs` are exactly the named tensors with these shapes (any order).
fn expect_io(
    manifest: &ModelManifest,
    side: &str,
    specs: &[TensorSpec],
    expected: &[(&str, &[i64])],
) -> Result<(), LearnedError> {
    let names = |s: &[TensorSpec]| s.iter().map(|t| t.name.clone()).collect::<Vec<_>>();
    if specs.len() != expected.len() {
        return Err(contract(
            manifest,
            format!(
                "the contract needs {side}s {:?}, the manifest lists {:?}",
                expected.iter().map(|e| e.0).collect::<Vec<_>>(),
                names(specs)
            ),
        ));
    }
    for (name, shape) in expected {
        let spec = specs.iter().find(|s| s.name == *name).ok_or_else(|| {
            contract(
                manifest,
                format!("{side} {name:?} is missing (it lists {:?})", names(specs)),
            )
        })?;
        if spec.shape != *shape {
            return Err(contract(
                manifest,
                format!(
                    "{side} {name}: shape {:?}, the contract needs {shape:?}",
                    spec.shape
                ),
            ));
        }
    }
    Ok(())
}
