//! What perception reports: each detected part with its pose, stable pose, confidence and
//! uncertainty. This is the output side of the perception seam.

use nalgebra::{Isometry3, Matrix6};

/// One detected part instance with its estimated pose.
#[derive(Debug, Clone, PartialEq)]
#[allow(non_snake_case)]
pub struct DetectedPart {
    /// Catalog name.
    pub part: String,
    /// Index of the detection in its frame (stable across calls for the same frame).
    pub index: usize,
    /// The simulator's instance id when known (diagnostics and error reports only).
    pub truth_instance: Option<u32>,
    /// Estimated pose in the robot base frame (snapped onto a stable pose on the table).
    pub base_T_part: Isometry3<f64>,
    /// Estimated pose in the table frame.
    pub table_T_part: Isometry3<f64>,
    /// Name of the stable pose the part lies in.
    pub stable_pose: String,
    /// Confidence in (0, 1]: detection score times stable-pose posterior times reprojection
    /// consistency (times the contour fit's quality, where learned perception aligned one).
    pub confidence: f64,
    /// Reprojection RMS of the final pose, pixels.
    pub rms_px: f64,
    /// Covariance of the PnP pose error `[δt (m); δω (rad)]` in the camera frame (see
    /// [`crate::pnp::PnpSolution::covariance`]).
    pub covariance: Matrix6<f64>,
}
