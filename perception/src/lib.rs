//! Perception: the camera model, part models (mesh, keypoints, stable poses), keypoint voting, PnP,
//! planar refinement with stable poses, and pose metrics.
//!
//! This crate depends on no other crate of the workspace: the simulator renders through its camera
//! model and the orchestrator consumes its poses, so conventions cannot diverge.

pub mod camera;
pub mod part;

pub use camera::{Camera, CameraError, Distortion};
pub mod ablation;
pub mod metrics;
pub mod onnx;
pub mod planar;
pub mod pnp;
pub mod symmetry;
pub mod voting;
