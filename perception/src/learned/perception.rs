//! The learned pipeline behind the perception seam: frames of pixels in, part poses in the robot
//! base frame out. Simulated frames (poses without pixels) are refused, so no simulator truth can
//! reach it.

use nalgebra::Isometry3;

use super::pipeline::LearnedPipeline;
use crate::detection::Perceived;
use crate::frame::{Frame, FrameContent, FrameImage};
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

    /// Restricts detection to `roi` (`[x, y, width, height]` in sensor pixels), whichever part
    /// of the sensor a frame carries: a full-sensor image from a production camera and a
    /// simulated capture of just that window give the pipeline the same pixels.
    pub fn with_roi(mut self, roi: [u32; 4]) -> Self {
        self.roi = Some(roi);
        self
    }

    /// The region of interest in pixels of `image` (its overlap with the sensor ROI), or the
    /// whole image without one.
    fn image_roi(&self, image: &FrameImage) -> Result<Option<[u32; 4]>, PerceptionError> {
        let Some([x, y, w, h]) = self.roi else {
            return Ok(None);
        };
        let [ox, oy] = image.origin;
        let (x0, y0) = (x.max(ox), y.max(oy));
        let x1 = (x + w).min(ox + image.width());
        let y1 = (y + h).min(oy + image.height());
        if x1 <= x0 || y1 <= y0 {
            return Err(PerceptionError::Frame(format!(
                "the {} × {} image at sensor pixel ({ox}, {oy}) does not overlap the region of \
                 interest {w} × {h} at ({x}, {y})",
                image.width(),
                image.height()
            )));
        }
        Ok(Some([x0 - ox, y0 - oy, x1 - x0, y1 - y0]))
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
    fn perceive(&mut self, frame: &Frame) -> Result<Perceived, PerceptionError> {
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
        let roi = self.image_roi(image)?;
        let found = self
            .pipeline
            .detect(image, &frame.camera, &camera_T_table, roi)?;
        let pipeline = &self.pipeline;
        Ok(
            found.perceived(&frame.camera, &camera_T_table, &self.base_T_table, |part| {
                pipeline.part_extent(part).unwrap_or(0.0)
            }),
        )
    }
}
