//! The learned pipeline behind the perception seam: frames of pixels in, part poses in the robot
//! base frame out. Simulated frames (poses without pixels) are refused, so no simulator truth can
//! reach it.

use nalgebra::Isometry3;

use super::pipeline::LearnedPipeline;
use crate::detection::DetectedPart;
use crate::frame::{Frame, FrameContent};
use crate::perceive::{PartPerception, PerceptionError};

/// [`PartPerception`] by the learned pipeline, for a table at a calibrated pose.
#[allow(non_snake_case)]
pub struct LearnedPerception {
    pipeline: LearnedPipeline,
    base_T_table: Isometry3<f64>,
    roi: Option<[u32; 4]>,
}

impl LearnedPerception {
    /// Perceives with `pipeline` on the table at `base_T_table` (extrinsic calibration), over
    /// the whole frame image.
    #[allow(non_snake_case)]
    pub fn new(pipeline: LearnedPipeline, base_T_table: Isometry3<f64>) -> Self {
        Self {
            pipeline,
            base_T_table,
            roi: None,
        }
    }

    /// Restricts detection to `roi` (`[x, y, width, height]`, pixels of the frame image).
    pub fn with_roi(mut self, roi: [u32; 4]) -> Self {
        self.roi = Some(roi);
        self
    }

    /// Gives the pipeline back (to reuse its sessions and buffers).
    pub fn into_pipeline(self) -> LearnedPipeline {
        self.pipeline
    }

    /// The pipeline (for per-stage results and times).
    pub fn pipeline(&mut self) -> &mut LearnedPipeline {
        &mut self.pipeline
    }
}

impl PartPerception for LearnedPerception {
    #[allow(non_snake_case)]
    fn perceive(&mut self, frame: &Frame) -> Result<Vec<DetectedPart>, PerceptionError> {
        let image = match &frame.content {
            FrameContent::Image(image) => image,
            FrameContent::Simulated(_) => {
                return Err(PerceptionError::UnsupportedFrame {
                    mode: "learned",
                    what: "a simulated scene without pixels",
                });
            }
        };
        image
            .check_on_sensor(&frame.camera)
            .map_err(PerceptionError::Frame)?;
        let camera_T_table = frame.base_T_camera.inverse() * self.base_T_table;
        let found = self
            .pipeline
            .detect(image, &frame.camera, &camera_T_table, self.roi)?;
        let mut out = Vec::new();
        for d in found.detections {
            let Ok(pose) = d.pose else { continue };
            let table_T_part = pose.planar.table_T_part;
            out.push(DetectedPart {
                part: d.part,
                index: out.len(),
                truth_instance: None,
                base_T_part: self.base_T_table * table_T_part,
                table_T_part,
                stable_pose: pose.stable_pose,
                confidence: (d.score * pose.confidence).clamp(f64::MIN_POSITIVE, 1.0),
                rms_px: pose.rms_px,
                covariance: pose.pnp.covariance,
            });
        }
        Ok(out)
    }
}
