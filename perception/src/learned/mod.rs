//! Learned perception, the seed's pipeline from pixels: instance segmentation of the feeder view
//! → 128 × 128 crops with shifted intrinsics → PVNet keypoint net → RANSAC voting with covariances
//! → [`crate::estimate::PoseEstimator`]. The networks run through ONNX Runtime (`crate::onnx`).
//!
//! It reads pixels and calibration only: [`crate::FrameContent::Simulated`] is refused.

mod detection;

pub use detection::{InstanceMask, LearnedDetection, LearnedDetections, StageTimes};
