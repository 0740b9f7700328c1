//! Perception through the embedded module's interface: a camera frame in, detected part poses with
//! confidence out. The simulation harness's keypoint-noise perception
//! (`crate::harness::KeypointNoise`) implements [`PartPerception`] until learned models exist;
//! the learned pipeline implements the same trait and drops in without touching the engine.

use std::path::PathBuf;

use nalgebra::Isometry3;
use perception::Camera;

/// A part the camera sees, as the simulator knows it (never available in production).
#[derive(Debug, Clone, PartialEq)]
#[allow(non_snake_case)]
pub struct TruePart {
    /// Instance id in the simulated world (diagnostics only).
    pub instance: u32,
    /// Catalog name.
    pub part: String,
    /// True pose of the part in the true camera frame.
    pub camera_T_part: Isometry3<f64>,
}

/// What the camera delivered.
#[derive(Debug, Clone, PartialEq)]
pub enum FrameContent {
    /// The simulated scene: what a renderer would draw, as poses.
    Simulated(Vec<TruePart>),
    /// An image file from the production camera source.
    ImageFile(PathBuf),
}

/// One camera frame with the calibration it is interpreted with.
#[derive(Debug, Clone, PartialEq)]
#[allow(non_snake_case)]
pub struct Frame {
    /// Intrinsics and distortion.
    pub camera: Camera,
    /// Calibrated camera pose in the robot base frame (the true one may differ).
    pub base_T_camera: Isometry3<f64>,
    /// The pixels, or the simulated scene.
    pub content: FrameContent,
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
    /// Confidence in (0, 1]: stable-pose posterior times reprojection consistency.
    pub confidence: f64,
    /// Reprojection RMS of the final pose, pixels.
    pub rms_px: f64,
}

/// Why perception failed as a whole (single instances that fail are just not reported).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PerceptionError {
    /// The mode cannot interpret this kind of frame.
    #[error("{mode} perception cannot read {what}")]
    UnsupportedFrame {
        /// The perception mode.
        mode: &'static str,
        /// What it was given.
        what: &'static str,
    },
    /// A part of the catalog cannot be perceived (no keypoints or stable poses).
    #[error("part {part}: {reason}")]
    Part {
        /// The part.
        part: String,
        /// Why.
        reason: String,
    },
    /// Bad settings.
    #[error("invalid perception settings: {0}")]
    Settings(String),
}

/// The embedded perception module's interface: a frame in, detected part poses out.
pub trait PartPerception: Send {
    /// Detects the parts in `frame`, ordered as the detector found them.
    fn perceive(&mut self, frame: &Frame) -> Result<Vec<DetectedPart>, PerceptionError>;
}
