//! What perception reports: each detected part with its pose, stable pose, confidence and
//! uncertainty, and each part it found but could not pose, as the space it may take up. This is
//! the output side of the perception seam.

use nalgebra::{Isometry3, Matrix6, Point3};

/// What perception made of one frame.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Perceived {
    /// The parts it posed, ordered as the detector found them.
    pub parts: Vec<DetectedPart>,
    /// The parts it found but could not pose: the cell keeps its fingers clear of them.
    pub unposed: Vec<UnposedPart>,
}

/// A part perception found but could not pose (its keypoints failed the gate, it lies on
/// another part, ...): the space it may take up, so that no finger comes down on it.
#[derive(Debug, Clone, PartialEq)]
pub struct UnposedPart {
    /// Catalog name.
    pub part: String,
    /// Points in the table frame (metres) whose convex hull holds the part: where its mask's
    /// outline meets the table, and the same rays at the part's largest extent above it.
    pub table_points: Vec<Point3<f64>>,
}

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
