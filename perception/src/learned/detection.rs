//! What the learned pipeline reports for one frame: every detected instance with its mask, its
//! voted keypoints and, when PnP and refinement succeed, its pose; and the time each stage took.

use std::time::Duration;

use crate::estimate::PoseEstimate;
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
    /// Image pixel of the top-left corner of the keypoint crop (may be negative near borders).
    pub crop_origin: [i64; 2],
    /// Voted keypoints in image pixels, in the part's keypoint order (empty when voting failed).
    pub keypoints: Vec<KeypointVote>,
    /// The pose, or why there is none.
    pub pose: Result<PoseEstimate, String>,
    /// An estimate the pipeline refused: the reprojection gate, or a part lying on or under
    /// another one (evaluation still reports its raw PnP).
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
