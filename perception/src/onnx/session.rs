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
            // Workers spin between operators while a run lasts, and stop the moment it
            // returns: voting and pose fitting run on the same cores right after each inference.
            .with_intra_op_spinning(true)
            .map_err(|e| model_error(e.into()))?
            .with_config_entry("session.force_spinning_stop", "1")
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
        if input.shape.first() != Some(&-1) {
            return Err(signature(
                &manifest,
                &model,
                "input 0",
                format!(
                    "a batch session needs shape [-1, ...], the manifest has {:?}",
                    input.shape
                ),
            ));
        }
        // Items of a fixed size go through `run`; dynamic item dimensions (an image of any
        // H × W) through `run_shaped`.
        let item_len = if input.shape[1..].contains(&-1) {
            0
        } else {
            input.shape[1..].iter().product::<i64>() as usize
        };
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

    /// The outputs of the last run (empty before the first), in manifest order.
    pub fn outputs(&self) -> &[OutputTensor] {
        &self.outputs
    }

    /// Values per batch item (e.g. 3·128·128 for an RGB crop); 0 when the input has dynamic
    /// dimensions besides the batch.
    pub fn item_len(&self) -> usize {
        self.item_len
    }

    /// Runs a batch (each item row-major, `item_len` values) and returns the outputs in manifest
    /// order; the returned buffers are reused by the next call.
    pub fn run(&mut self, items: &[&[f32]]) -> Result<&[OutputTensor], OnnxError> {
        if self.item_len == 0 {
            return Err(self.batch_error(format!(
                "the input {} {:?} has dynamic dimensions: give the shape (run_shaped)",
                self.manifest.inputs[0].name, self.manifest.inputs[0].shape
            )));
        }
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
        let mut input = std::mem::take(&mut self.input);
        input.clear();
        for item in items {
            input.extend_from_slice(item);
        }
        let mut shape = self.manifest.inputs[0].shape.clone();
        shape[0] = items.len() as i64;
        let result = self.infer(shape, &input);
        self.input = input;
        result?;
        Ok(&self.outputs)
    }

    /// Runs one input tensor of concrete `shape` (row-major `data`, batch first) without copying
    /// it: for inputs with dynamic dimensions (an image of any H × W) and for callers that build
    /// the batch in their own reused buffer. The shape must match the manifest's fixed dimensions.
    pub fn run_shaped(
        &mut self,
        shape: &[usize],
        data: &[f32],
    ) -> Result<&[OutputTensor], OnnxError> {
        let spec = &self.manifest.inputs[0];
        let fits = shape.len() == spec.shape.len()
            && shape
                .iter()
                .zip(&spec.shape)
                .all(|(&d, &s)| d > 0 && (s == -1 || d as i64 == s));
        if !fits {
            return Err(self.batch_error(format!(
                "input shape {shape:?} does not fit {} {:?}",
                spec.name, spec.shape
            )));
        }
        let len = shape.iter().product::<usize>();
        if len != data.len() {
            return Err(self.batch_error(format!(
                "input shape {shape:?} needs {len} values, got {}",
                data.len()
            )));
        }
        let shape: Vec<i64> = shape.iter().map(|&d| d as i64).collect();
        self.infer(shape, data)?;
        Ok(&self.outputs)
    }

    fn infer(&mut self, shape: Vec<i64>, data: &[f32]) -> Result<(), OnnxError> {
        let run_error = |e: ort::Error| OnnxError::Run {
            path: self.model.clone(),
            message: e.to_string(),
        };
        let tensor = TensorRef::from_array_view((shape, data)).map_err(run_error)?;
        let results = self.session.run(ort::inputs![tensor]).map_err(run_error)?;
        for (i, out) in self.outputs.iter_mut().enumerate() {
            let value = results.get(&out.name).ok_or_else(|| OnnxError::Run {
                path: self.model.clone(),
                message: format!("no output {}", out.name),
            })?;
            let (shape, data) = value.try_extract_tensor::<f32>().map_err(run_error)?;
            out.shape.clear();
            out.shape.extend(shape.iter().map(|&d| d.max(0) as usize));
            let spec = &self.manifest.outputs[i];
            let fits = out.shape.len() == spec.shape.len()
                && out
                    .shape
                    .iter()
                    .zip(&spec.shape)
                    .all(|(&d, &s)| s == -1 || d as i64 == s);
            if !fits {
                return Err(OnnxError::Run {
                    path: self.model.clone(),
                    message: format!(
                        "output {} has shape {:?}, the manifest says {:?}",
                        spec.name, out.shape, spec.shape
                    ),
                });
            }
            out.data.clear();
            out.data.extend_from_slice(data);
        }
        Ok(())
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
    // A dimension the graph leaves dynamic may be fixed by the manifest (exporters lose static
    // sizes through reshapes); every run then checks the concrete size.
    let compatible = shape.len() == spec.shape.len()
        && shape
            .iter()
            .zip(&spec.shape)
            .all(|(&m, &s)| m == s || m == -1);
    if !compatible {
        return Err(format!(
            "{}: shape: manifest {:?}, model {:?}",
            spec.name, spec.shape, shape
        ));
    }
    Ok(())
}
