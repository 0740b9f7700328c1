//! What the learned pipeline reports for one frame: every detected instance with its mask, its
//! voted keypoints and, when PnP and refinement succeed, its pose; and the time each stage took.

use std::time::Duration;

use nalgebra::{Isometry3, Point2, Point3};

use crate::Camera;
use crate::detection::{DetectedPart, Perceived, UnposedPart};
use crate::estimate::PoseEstimate;
use crate::planar::ray_on_table;
use crate::voting::KeypointVote;

/// A binary instance mask over a box of the image.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct InstanceMask {
    /// Image pixel of the box's top-left corner (`[column, row]`).
    pub origin: [u32; 2],
    /// Box width, pixels.
    pub width: u32,
    /// Box height, pixels.
    pub height: u32,
    /// Row-major, `width × height`, true on the instance.
    pub bits: Vec<bool>,
}

impl InstanceMask {
    /// Whether image pixel (x, y) is on the instance.
    pub fn contains(&self, x: u32, y: u32) -> bool {
        let (x0, y0) = (self.origin[0], self.origin[1]);
        x >= x0
            && y >= y0
            && x - x0 < self.width
            && y - y0 < self.height
            && self.bits[((y - y0) * self.width + (x - x0)) as usize]
    }

    /// Pixels on the instance.
    pub fn area(&self) -> usize {
        self.bits.iter().filter(|b| **b).count()
    }

    /// Points in the table frame whose convex hull holds whatever `camera` sees through the
    /// mask between the table at `camera_T_table` and `height` above it: the outer corners of
    /// each row's first and last pixel, met by their rays on both planes. Rays that miss a
    /// plane give no point.
    #[allow(non_snake_case)]
    pub fn on_table(
        &self,
        camera: &Camera,
        camera_T_table: &Isometry3<f64>,
        height: f64,
    ) -> Vec<Point3<f64>> {
        let mut points = Vec::new();
        let (x0, y0) = (f64::from(self.origin[0]), f64::from(self.origin[1]));
        for (row, bits) in self.bits.chunks(self.width.max(1) as usize).enumerate() {
            let (Some(first), Some(last)) =
                (bits.iter().position(|b| *b), bits.iter().rposition(|b| *b))
            else {
                continue;
            };
            let y = y0 + row as f64;
            for (x, y) in [
                (first as f64 - 0.5, y - 0.5),
                (last as f64 + 0.5, y - 0.5),
                (first as f64 - 0.5, y + 0.5),
                (last as f64 + 0.5, y + 0.5),
            ] {
                let Ok(ray) = camera.pixel_ray(Point2::new(x0 + x, y)) else {
                    continue;
                };
                for z in [0.0, height] {
                    if let Ok((tx, ty)) = ray_on_table(camera_T_table, &ray, z) {
                        points.push(Point3::new(tx, ty, z));
                    }
                }
            }
        }
        points
    }
}

/// One detected instance.
#[derive(Debug, Clone, PartialEq)]
pub struct LearnedDetection {
    /// Catalog name of the part.
    pub part: String,
    /// Detection score in (0, 1] (mean class probability over the instance).
    pub score: f64,
    /// The instance's mask in image pixels, from the segmenter.
    pub mask: InstanceMask,
    /// Voted centre of the instance, image pixels.
    pub centre: [f64; 2],
    /// Image pixel of the top-left corner of the keypoint crop's window (may be negative near
    /// borders); the window is 128 of the nets' pixels, more image pixels when the pipeline
    /// resampled the frame to the nets' scale.
    pub crop_origin: [i64; 2],
    /// Voted keypoints in image pixels, in the part's keypoint order (empty when voting failed).
    pub keypoints: Vec<KeypointVote>,
    /// The pose, or why there is none.
    pub pose: Result<PoseEstimate, String>,
    /// An estimate the pipeline refused: the reprojection gate, a mask larger than any stable
    /// pose can show, or a part lying on or under another one (evaluation still reports its raw
    /// PnP).
    pub refused: Option<PoseEstimate>,
}

impl LearnedDetection {
    /// Confidence in the pose, in (0, 1]: the detection score times the pose's confidence
    /// (what the cell ranks and gates picks by); `None` without a pose.
    pub fn confidence(&self) -> Option<f64> {
        let pose = self.pose.as_ref().ok()?;
        Some((self.score * pose.confidence).clamp(f64::MIN_POSITIVE, 1.0))
    }
}

/// Wall time of each stage for one frame.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StageTimes {
    /// Image → segmenter input tensor.
    pub preprocess: Duration,
    /// Segmenter network.
    pub segment: Duration,
    /// Grouping pixels into instances.
    pub instances: Duration,
    /// Cutting crops and building the keypoint net's batch.
    pub crops: Duration,
    /// Keypoint network, all crops in one batch.
    pub keypoint_net: Duration,
    /// RANSAC voting.
    pub voting: Duration,
    /// PnP and planar refinement.
    pub pose: Duration,
    /// The whole frame.
    pub total: Duration,
}

/// The result of one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct LearnedDetections {
    /// Detected instances, in the order the segmenter found them.
    pub detections: Vec<LearnedDetection>,
    /// Time per stage.
    pub times: StageTimes,
}

impl LearnedDetections {
    /// What the perception seam reports of this frame of `camera`, looking at the table at
    /// `camera_T_table` (which lies at `base_T_table` in the robot base frame): each posed
    /// detection in the base frame, its `index` that of the detection here, and each one found
    /// but not posed as the space its mask sweeps up to `extent(part)` above the table.
    #[allow(non_snake_case)]
    pub fn perceived(
        &self,
        camera: &Camera,
        camera_T_table: &Isometry3<f64>,
        base_T_table: &Isometry3<f64>,
        extent: impl Fn(&str) -> f64,
    ) -> Perceived {
        let mut out = Perceived::default();
        for (index, d) in self.detections.iter().enumerate() {
            let (Some(confidence), Ok(pose)) = (d.confidence(), &d.pose) else {
                out.unposed.push(UnposedPart {
                    part: d.part.clone(),
                    table_points: d.mask.on_table(camera, camera_T_table, extent(&d.part)),
                });
                continue;
            };
            let table_T_part = pose.planar.table_T_part;
            out.parts.push(DetectedPart {
                part: d.part.clone(),
                index,
                truth_instance: None,
                base_T_part: base_T_table * table_T_part,
                table_T_part,
                stable_pose: pose.stable_pose.clone(),
                confidence,
                rms_px: pose.rms_px,
                covariance: pose.pnp.covariance,
            });
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    use super::*;

    #[test]
    #[allow(non_snake_case)]
    fn a_mask_on_the_table_is_its_rows_outer_corners_on_both_planes() {
        let camera = Camera::basler_seed();
        // Looking down at the table from 1.5 m, a little tilted.
        let camera_T_table = Isometry3::from_parts(
            Translation3::new(0.01, -0.02, 1.5),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI - 0.05),
        );
        // Rows: a run with a gap after it, an empty row, and a row whose middle is off.
        let bits = [
            [false, true, true, false, false],
            [false; 5],
            [true, false, false, false, true],
        ];
        let mask = InstanceMask {
            origin: [2000, 1500],
            width: 5,
            height: 3,
            bits: bits.iter().flatten().copied().collect(),
        };
        let height = 0.009;
        let points = mask.on_table(&camera, &camera_T_table, height);
        // The outer corners of each row's first and last pixel (pixel centres on integers).
        let mut corners = Vec::new();
        for (row, (first, last)) in [(0, (1.0, 2.0)), (2, (0.0, 4.0))] {
            let y = 1500.0 + f64::from(row);
            for (x, y) in [
                (first - 0.5, y - 0.5),
                (last + 0.5, y - 0.5),
                (first - 0.5, y + 0.5),
                (last + 0.5, y + 0.5),
            ] {
                corners.push(Point2::new(2000.0 + x, y));
            }
        }
        assert_eq!(points.len(), 2 * corners.len(), "{points:?}");
        for (k, p) in points.iter().enumerate() {
            let corner = corners[k / 2];
            let z = [0.0, height][k % 2];
            assert!((p.z - z).abs() < 1e-12, "point {k} at height {}", p.z);
            let seen = camera.project(&(camera_T_table * p)).unwrap();
            assert!(
                (seen - corner).norm() < 1e-6,
                "point {k} is seen at {seen}, not at its corner {corner}"
            );
        }
    }
}
