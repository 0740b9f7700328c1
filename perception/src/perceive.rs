//! The perception seam: a frame in, detected parts out. Keypoint-noise perception (simulation
//! only) and the learned pipeline implement [`PartPerception`]; the orchestrator knows only it.

use crate::detection::Perceived;
use crate::frame::Frame;

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
    /// The frame's pixels cannot be used (wrong size, off the sensor, unsupported format).
    #[error("bad frame: {0}")]
    Frame(String),
    /// A model failed to run.
    #[error("model: {0}")]
    Model(String),
}

/// The embedded perception module's interface: a frame in, detected part poses out.
pub trait PartPerception: Send {
    /// Detects the parts in `frame`: those it posed, ordered as the detector found them, and
    /// those it found but could not pose.
    fn perceive(&mut self, frame: &Frame) -> Result<Perceived, PerceptionError>;
}
