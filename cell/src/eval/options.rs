//! The settings of an evaluation: match and visibility thresholds, the outlier angle, gallery
//! size, and the bar a pick must clear.

use serde::{Deserialize, Serialize};

use super::EvalError;

/// Evaluation settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EvalOptions {
    /// Mask IoU a detection needs to match a ground-truth instance.
    pub min_iou: f64,
    /// Ground-truth instances less visible than this (BOP's visib_fract) are ignored: not
    /// counted as missed, and a detection matching one is not a false positive.
    pub min_visib_fract: f64,
    /// Two instances touch when their visible masks come within this many pixels.
    pub touch_gap_px: u32,
    /// Angle above which an estimate is an outlier (the seed's 10°), degrees.
    pub outlier_deg: f64,
    /// Worst crops kept for the gallery.
    pub gallery: usize,
    /// Evaluate at most this many images (in scene, image order).
    pub limit: Option<usize>,
    /// Surface points sampled per part for ADD(-S), MSSD and MSPD.
    pub model_points: usize,
    /// The least confidence of a pose the cell would pick (a scenario's
    /// `[policy] min_pick_confidence`).
    #[serde(default = "default_pick_confidence")]
    pub pick_confidence: f64,
    /// The least clearance between an open finger and any other part that the cell picks with,
    /// metres, when a scenario's gripper checks each pick
    /// ([`super::fingers::FingerCheck`]); without one, picks are not checked for room for the
    /// fingers.
    #[serde(default)]
    pub finger_margin: Option<f64>,
}

fn default_pick_confidence() -> f64 {
    crate::scenario::DEFAULT_MIN_PICK_CONFIDENCE
}

impl Default for EvalOptions {
    fn default() -> Self {
        Self {
            min_iou: 0.5,
            min_visib_fract: 0.1,
            touch_gap_px: 2,
            outlier_deg: 10.0,
            gallery: 24,
            limit: None,
            model_points: 1000,
            pick_confidence: default_pick_confidence(),
            finger_margin: None,
        }
    }
}

impl EvalOptions {
    /// Checks the ranges.
    pub fn validate(&self) -> Result<(), EvalError> {
        if !(self.min_iou > 0.0 && self.min_iou <= 1.0) {
            return Err(EvalError::Options(format!(
                "the IoU threshold must be in (0, 1], got {}",
                self.min_iou
            )));
        }
        if !(0.0..=1.0).contains(&self.min_visib_fract) {
            return Err(EvalError::Options(format!(
                "the visibility threshold must be in [0, 1], got {}",
                self.min_visib_fract
            )));
        }
        if !(self.outlier_deg.is_finite() && self.outlier_deg > 0.0) {
            return Err(EvalError::Options(format!(
                "the outlier angle must be > 0°, got {}",
                self.outlier_deg
            )));
        }
        if self.model_points < 8 {
            return Err(EvalError::Options(format!(
                "at least 8 model points are needed, got {}",
                self.model_points
            )));
        }
        Ok(())
    }
}
