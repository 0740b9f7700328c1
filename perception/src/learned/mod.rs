//! Learned perception, the seed's pipeline from pixels: instance segmentation of the feeder view
//! → 128 × 128 crops with shifted intrinsics → PVNet keypoint net → RANSAC voting with covariances
//! → [`crate::estimate::PoseEstimator`] → contour alignment → [`crate::stacking`] (parts lying on
//! one another are withdrawn). The networks run through ONNX Runtime (`crate::onnx`).
//!
//! It reads pixels and calibration only: [`crate::FrameContent::Simulated`] is refused.

mod contour_stage;
pub mod crops;
mod detection;
mod error;
pub mod image;
pub mod instances;
pub mod keypoint_net;
pub mod models;
pub mod net_view;
mod owners;
mod perception;
mod pipeline;
pub mod segmenter;

pub use crops::{CropBatch, crop_camera, crop_origin};
pub use detection::{InstanceMask, LearnedDetection, LearnedDetections, StageTimes};
pub use error::LearnedError;
pub use instances::{Instance, InstanceConfig, InstanceGrouper, join_split};
pub use keypoint_net::KeypointNet;
pub use models::LearnedModels;
pub use net_view::{InputScale, NetView};
pub use perception::LearnedPerception;
pub use pipeline::{
    LearnedPipeline, MAX_JOINED_FILL, MAX_LEAN, MAX_OVERFILL, PipelineConfig, STACKING_TOLERANCE,
};
pub use segmenter::{SegmentMap, Segmenter};
