//! Perception: the camera model, part models (mesh, keypoints, stable poses), keypoint voting, PnP,
//! planar refinement with stable poses, and pose metrics.
//!
//! This crate depends on no other crate of the workspace: the simulator renders through its camera
//! model and the orchestrator consumes its poses, so conventions cannot diverge.

pub mod camera;
pub mod part;

pub use camera::{Camera, CameraError, Distortion};
pub use detection::{DetectedPart, Perceived, UnposedPart};
pub use frame::{Frame, FrameContent, FrameImage, TruePart};
pub use perceive::{PartPerception, PerceptionError};
pub mod ablation;
pub mod cache;
pub mod calibration;
pub mod contour;
pub mod detection;
pub mod estimate;
pub mod frame;
pub mod keypoint_noise;
pub mod learned;
pub mod metrics;
pub mod onnx;
pub mod perceive;
pub mod planar;
pub mod pnp;
pub mod stacking;
pub mod symmetry;
pub mod voting;
