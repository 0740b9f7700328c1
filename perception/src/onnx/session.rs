//! A checked ONNX session for batches of crops: opening it verifies the model against its manifest
//! (checksum, input and output names, shapes and types); running it reuses the session, the input
//! buffer and the output buffers across calls.

use super::provision::hex;
use super::{ModelManifest, OnnxError, Runtime, TensorSpec};
use ort::session::Session;
use ort::value::{TensorElementType, TensorRef};
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};

/// One output of a batch run: its name, concrete shape and values (row-major).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct OutputTensor {
    /// Output name from the manifest.
    pub name: String,
    /// Concrete shape of this run (batch first).
    pub shape: Vec<usize>,
    /// Values, row-major.
    pub data: Vec<f32>,
}

impl OutputTensor {
    /// The values of batch item `i` (the slice of one crop).
    pub fn item(&self, i: usize) -> &[f32] {
        let per = self.shape.iter().skip(1).product::<usize>();
        &self.data[i * per..(i + 1) * per]
    }
}

/// A model session with one batched input (`[-1, ...]` in its manifest), reused across batches.
pub struct BatchSession {
    session: Session,
    manifest: ModelManifest,
    model: PathBuf,
    item_len: usize,
    input: Vec<f32>,
    outputs: Vec<OutputTensor>,
}

impl BatchSession {
    /// Opens the model a manifest names: checks its sha256, builds the session with
    /// `intra_threads` threads and checks the session's signature against the manifest.
    pub fn open(
        runtime: &Runtime,
        manifest: &Path,
        intra_threads: usize,
    ) -> Result<Self, OnnxError> {
        let manifest = ModelManifest::load(manifest)?;
        let model = manifest.model_path();
        let bytes = std::fs::read(&model).map_err(|source| OnnxError::Io {
            path: model.clone(),
            source,
        })?;
        let actual = hex(&Sha256::digest(&bytes));
        if actual != manifest.sha256 {
            return Err(OnnxError::Checksum {
                path: model,
                manifest: manifest.path.clone(),
                expected: manifest.sha256.clone(),
                actual,
            });
        }
        let model_error = |e: ort::Error| OnnxError::Model {
            path: model.clone(),
            message: e.to_string(),
        };
        let session = Session::builder(&runtime.environment)
            .map_err(model_error)?
            .with_intra_threads(intra_threads.max(1))
            .map_err(|e| model_error(e.into()))?
            .commit_from_memory(&bytes)
            .map_err(model_error)?;
        check_signature(&session, &manifest, &model)?;
        let [input] = manifest.inputs.as_slice() else {
            return Err(signature(
                &manifest,
                &model,
                "inputs",
                format!(
                    "a batch session takes one input, the manifest lists {}",
                    manifest.inputs.len()
                ),
            ));
        };
        if input.shape.first() != Some(&-1) || input.shape[1..].contains(&-1) {
            return Err(signature(
                &manifest,
                &model,
                "input 0",
                format!(
                    "a batch session needs shape [-1, fixed...], the manifest has {:?}",
                    input.shape
                ),
            ));
        }
        let item_len = input.shape[1..].iter().product::<i64>() as usize;
        let outputs = manifest
            .outputs
            .iter()
            .map(|o| OutputTensor {
                name: o.name.clone(),
                ..OutputTensor::default()
            })
            .collect();
        Ok(Self {
            session,
            manifest,
            model,
            item_len,
            input: Vec::new(),
            outputs,
        })
    }

    /// The manifest the session was checked against.
    pub fn manifest(&self) -> &ModelManifest {
        &self.manifest
    }

    /// Values per batch item (e.g. 3·128·128 for an RGB crop).
    pub fn item_len(&self) -> usize {
        self.item_len
    }

    /// Runs a batch (each item row-major, `item_len` values) and returns the outputs in manifest
    /// order; the returned buffers are reused by the next call.
    pub fn run(&mut self, items: &[&[f32]]) -> Result<&[OutputTensor], OnnxError> {
        if items.is_empty() {
            return Err(self.batch_error("empty batch".into()));
        }
        if let Some((i, item)) = items
            .iter()
            .enumerate()
            .find(|(_, c)| c.len() != self.item_len)
        {
            return Err(self.batch_error(format!(
                "batch item {i} has {} values, the input {} {:?} needs {}",
                item.len(),
                self.manifest.inputs[0].name,
                self.manifest.inputs[0].shape,
                self.item_len
            )));
        }
        self.input.clear();
        for item in items {
            self.input.extend_from_slice(item);
        }
        let mut shape = self.manifest.inputs[0].shape.clone();
        shape[0] = items.len() as i64;
        let run_error = |e: ort::Error| OnnxError::Run {
            path: self.model.clone(),
            message: e.to_string(),
        };
        let tensor =
            TensorRef::from_array_view((shape, self.input.as_slice())).map_err(run_error)?;
        let results = self.session.run(ort::inputs![tensor]).map_err(run_error)?;
        for out in &mut self.outputs {
            let value = results.get(&out.name).ok_or_else(|| OnnxError::Run {
                path: self.model.clone(),
                message: format!("no output {}", out.name),
            })?;
            let (shape, data) = value.try_extract_tensor::<f32>().map_err(run_error)?;
            out.shape.clear();
            out.shape.extend(shape.iter().map(|&d| d.max(0) as usize));
            out.data.clear();
            out.data.extend_from_slice(data);
        }
        Ok(&self.outputs)
    }

    fn batch_error(&self, message: String) -> OnnxError {
        OnnxError::Batch {
            path: self.model.clone(),
            message,
        }
    }
}

fn signature(manifest: &ModelManifest, model: &Path, what: &str, detail: String) -> OnnxError {
    OnnxError::Signature {
        path: model.into(),
        manifest: manifest.path.clone(),
        what: what.into(),
        detail,
    }
}

/// Checks the session's inputs and outputs (count, names, element types, shapes) against the manifest.
fn check_signature(
    session: &Session,
    manifest: &ModelManifest,
    model: &Path,
) -> Result<(), OnnxError> {
    let sides = [
        ("input", session.inputs(), &manifest.inputs),
        ("output", session.outputs(), &manifest.outputs),
    ];
    for (side, outlets, specs) in sides {
        if outlets.len() != specs.len() {
            return Err(signature(
                manifest,
                model,
                &format!("{side} count"),
                format!(
                    "manifest lists {}, model has {} ({})",
                    specs.len(),
                    outlets.len(),
                    outlets
                        .iter()
                        .map(|o| o.name())
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            ));
        }
        for (i, (outlet, spec)) in outlets.iter().zip(specs.iter()).enumerate() {
            let what = format!("{side} {i}");
            check_outlet(outlet, spec)
                .map_err(|detail| signature(manifest, model, &what, detail))?;
        }
    }
    Ok(())
}

fn check_outlet(outlet: &ort::value::Outlet, spec: &TensorSpec) -> Result<(), String> {
    if outlet.name() != spec.name {
        return Err(format!(
            "name: manifest {:?}, model {:?}",
            spec.name,
            outlet.name()
        ));
    }
    let dtype = outlet.dtype();
    if dtype.tensor_type() != Some(TensorElementType::Float32) {
        return Err(format!("{}: type: manifest f32, model {dtype}", spec.name));
    }
    let shape: Vec<i64> = dtype.tensor_shape().map(|s| s.to_vec()).unwrap_or_default();
    if shape != spec.shape {
        return Err(format!(
            "{}: shape: manifest {:?}, model {:?}",
            spec.name, spec.shape, shape
        ));
    }
    Ok(())
}
