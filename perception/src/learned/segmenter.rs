//! The segmenter: one run over the padded region of interest, then per stride-4 cell the class
//! probabilities (softmax over `logits`), the winning class (0 = background) and the offset to the
//! instance centre.

use super::LearnedError;
use super::models::{SEGMENTER_STRIDE, output_index};
use crate::onnx::{BatchSession, OutputTensor};

/// The segmenter's reading of one region at stride 4; cells outside the unpadded region are
/// background.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SegmentMap {
    /// Cells per row.
    pub width: usize,
    /// Cell rows.
    pub height: usize,
    /// Classes including background (1 + parts).
    pub classes: usize,
    /// Winning class per cell (0 = background), row-major.
    pub class: Vec<u8>,
    /// Class probabilities, `[classes][height][width]`.
    pub probs: Vec<f32>,
    /// Offsets to the instance centre, `[2][height][width]` (dx then dy), pixels.
    pub offsets: Vec<f32>,
}

impl SegmentMap {
    /// Fills the map from the segmenter's `logits` and `offsets` for a region of `valid`
    /// `[width, height]` pixels (the rest is padding).
    pub fn read(
        &mut self,
        logits: &OutputTensor,
        offsets: &OutputTensor,
        valid: [usize; 2],
    ) -> Result<(), String> {
        let [n, classes, h, w] = logits.shape[..] else {
            return Err(format!("logits has shape {:?}, not 4-D", logits.shape));
        };
        if n != 1 || classes < 2 || classes > usize::from(u8::MAX) {
            return Err(format!("logits has shape {:?}", logits.shape));
        }
        if offsets.shape != [1, 2, h, w] {
            return Err(format!(
                "offsets has shape {:?}, logits {:?}",
                offsets.shape, logits.shape
            ));
        }
        let plane = w * h;
        self.width = w;
        self.height = h;
        self.classes = classes;
        self.class.clear();
        self.class.resize(plane, 0);
        self.probs.clear();
        self.probs.resize(classes * plane, 0.0);
        self.offsets.clear();
        self.offsets.extend_from_slice(&offsets.data);
        let s = SEGMENTER_STRIDE as f64;
        for i in 0..h {
            // A cell belongs to the region when its centre (4j + 1.5) lies inside it.
            let row_in = s * i as f64 + 1.5 < valid[1] as f64;
            for j in 0..w {
                let c = i * w + j;
                let mut max = f32::NEG_INFINITY;
                for k in 0..classes {
                    max = max.max(logits.data[k * plane + c]);
                }
                let mut sum = 0.0;
                let mut best = (0, f32::NEG_INFINITY);
                for k in 0..classes {
                    let l = logits.data[k * plane + c];
                    let e = (l - max).exp();
                    self.probs[k * plane + c] = e;
                    sum += e;
                    if l > best.1 {
                        best = (k, l);
                    }
                }
                for k in 0..classes {
                    self.probs[k * plane + c] /= sum;
                }
                if !max.is_finite() {
                    return Err(format!("non-finite logits at cell ({j}, {i})"));
                }
                let inside = row_in && s * j as f64 + 1.5 < valid[0] as f64;
                self.class[c] = if inside { best.0 as u8 } else { 0 };
            }
        }
        Ok(())
    }
}

/// The segmenter network with its reused session and output map.
pub struct Segmenter {
    session: BatchSession,
    logits: usize,
    offsets: usize,
    classes: usize,
}

impl Segmenter {
    /// Wraps an opened, contract-checked segmenter session.
    pub fn new(session: BatchSession) -> Self {
        let m = session.manifest();
        let logits = output_index(m, "logits").unwrap_or(0);
        let offsets = output_index(m, "offsets").unwrap_or(1);
        let classes = m.outputs[logits].shape[1] as usize;
        Self {
            session,
            logits,
            offsets,
            classes,
        }
    }

    /// Runs the planar RGB `tensor` of `[height, width]` (multiples of 16) covering a region of
    /// `valid` `[width, height]` pixels into `map`.
    pub fn run(
        &mut self,
        tensor: &[f32],
        size: [usize; 2],
        valid: [usize; 2],
        map: &mut SegmentMap,
    ) -> Result<(), LearnedError> {
        let [h, w] = size;
        self.session.run_shaped(&[1, 3, h, w], tensor)?;
        let outputs = self.session.outputs();
        let (logits, offsets) = (&outputs[self.logits], &outputs[self.offsets]);
        let expect = [1, self.classes, h / SEGMENTER_STRIDE, w / SEGMENTER_STRIDE];
        if logits.shape != expect {
            return Err(LearnedError::Output {
                model: self.session.manifest().model_path(),
                output: "logits".into(),
                message: format!(
                    "shape {:?} for a {w} × {h} input, expected {expect:?} (stride 4)",
                    logits.shape
                ),
            });
        }
        map.read(logits, offsets, valid)
            .map_err(|message| LearnedError::Output {
                model: self.session.manifest().model_path(),
                output: "offsets".into(),
                message,
            })
    }
}
