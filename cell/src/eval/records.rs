//! What evaluation records per image (eval.json's frames): each ground-truth instance, each
//! detection and how it scored, and the stage times; and the galleries of one run.

use std::time::Duration;

use nalgebra::Isometry3;
use perception::learned::StageTimes;
use perception::metrics::PoseErrors;
use serde::{Deserialize, Serialize};
use sim::dataset::pose_to_bop;

use super::detection_gallery::DetectionErrorCrop;
use super::gallery::{FailedCrop, GalleryItem};

/// Stage times of one frame, milliseconds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StageMs {
    /// Image → segmenter input.
    pub preprocess: f64,
    /// Segmenter network.
    pub segment: f64,
    /// Grouping into instances.
    pub instances: f64,
    /// Cutting crops.
    pub crops: f64,
    /// Keypoint network.
    pub keypoint_net: f64,
    /// Voting.
    pub voting: f64,
    /// PnP and refinement.
    pub pose: f64,
    /// The whole frame.
    pub total: f64,
}

/// A stage's name and how to read its time.
pub type Stage = (&'static str, fn(&StageMs) -> f64);

impl StageMs {
    /// Stage names in pipeline order, with their accessors.
    pub const STAGES: [Stage; 8] = [
        ("preprocess", |s| s.preprocess),
        ("segment", |s| s.segment),
        ("instances", |s| s.instances),
        ("crops", |s| s.crops),
        ("keypoint_net", |s| s.keypoint_net),
        ("voting", |s| s.voting),
        ("pose", |s| s.pose),
        ("total", |s| s.total),
    ];
}

impl From<&StageTimes> for StageMs {
    fn from(t: &StageTimes) -> Self {
        let ms = |d: Duration| d.as_secs_f64() * 1e3;
        Self {
            preprocess: ms(t.preprocess),
            segment: ms(t.segment),
            instances: ms(t.instances),
            crops: ms(t.crops),
            keypoint_net: ms(t.keypoint_net),
            voting: ms(t.voting),
            pose: ms(t.pose),
            total: ms(t.total),
        }
    }
}

/// One ground-truth instance of a frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TruthRecord {
    /// Part name.
    pub part: String,
    /// Visible fraction (BOP visib_fract).
    pub visib_fract: f64,
    /// Visible pixels.
    pub visible_px: usize,
    /// Whether its visible mask touches another instance's.
    pub touching: bool,
    /// Too little visible to count (see [`super::EvalOptions::min_visib_fract`]).
    pub ignored: bool,
    /// Whether it rests on the table in a stable pose
    /// ([`perception::planar::PlanarPose::rests`]: within 1° and 0.2 mm of the nearest one). A
    /// part leaning on or lying on another one is in no stable pose, so no planar estimate of it
    /// can be right: it is left out of the refined rows and counted apart.
    #[serde(default = "resting_by_default")]
    pub resting: bool,
    /// The stable pose it rests in (the planar refiner's class of its true pose), when resting.
    #[serde(default)]
    pub stable_pose: Option<String>,
    /// Index of the detection matched to it.
    pub detection: Option<usize>,
    /// For a missed instance, the detection of any part whose mask overlaps it most, and that
    /// IoU: why it was missed (merged with a neighbour, split, the wrong part, or nothing there).
    #[serde(default)]
    pub closest: Option<DetectionOverlap>,
}

/// A detection and its mask IoU with a ground-truth instance.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DetectionOverlap {
    /// Index of the detection.
    pub detection: usize,
    /// Mask IoU.
    pub iou: f64,
}

/// Records written before `resting` existed did not tell: every part counted as resting.
fn resting_by_default() -> bool {
    true
}

/// One detection of a frame and how it scored.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DetectionRecord {
    /// Part name.
    pub part: String,
    /// Detection score.
    pub score: f64,
    /// Image pixel of the keypoint crop's top-left corner (`[column, row]`), so that other
    /// pipelines can be compared on exactly this crop.
    pub crop_origin: [i64; 2],
    /// Voted keypoints in image pixels, in the catalog's keypoint order.
    pub keypoints_px: Vec<[f64; 2]>,
    /// Each voted keypoint's pixel covariance `[σxx, σxy, σyy]` (px²), as PnP weighs it.
    #[serde(default)]
    pub keypoint_covariances_px: Vec<[f64; 3]>,
    /// Matched ground-truth instance.
    pub truth: Option<usize>,
    /// Mask IoU with it.
    pub iou: Option<f64>,
    /// Why the detector gave no pose, if it gave none.
    pub pose_failure: Option<String>,
    /// Errors of the raw PnP pose (matched, with an estimate, also one the gate refused).
    pub raw: Option<PoseErrors>,
    /// Errors after planar refinement.
    pub refined: Option<PoseErrors>,
    /// Stable pose the detector chose.
    pub stable_pose: Option<String>,
    /// Stable pose the refiner assigns to the true pose.
    pub true_stable_pose: Option<String>,
    /// Raw angle error to the nearest near-symmetric equivalent of the truth, turns about a
    /// round axis free ([`perception::part::round_axes`]), degrees.
    pub raw_flip_deg: Option<f64>,
    /// Refined angle error to the nearest near-symmetric equivalent of the truth, turns about a
    /// round axis free, degrees.
    pub refined_flip_deg: Option<f64>,
    /// Share of the outline that found the frame's edges, when contour alignment set the pose.
    #[serde(default)]
    pub contour_support: Option<f64>,
    /// Errors of the keypoint-only planar pose, when contour alignment then moved it.
    #[serde(default)]
    pub keypoint_refined: Option<PoseErrors>,
    /// The pose's confidence, what the cell ranks and gates its picks by (with a pose).
    #[serde(default)]
    pub confidence: Option<f64>,
    /// The refined pose, as BOP writes poses (with a pose, matched or not).
    #[serde(default)]
    pub pose: Option<BopPose>,
    /// The part's BOP object id in the dataset (none if the dataset has no model of it).
    #[serde(default)]
    pub obj_id: Option<u32>,
    /// For an unmatched detection, the ground-truth instance of any part whose mask overlaps
    /// it most, and that IoU: why it is a false positive (the wrong part, a second instance of
    /// a found part, a poor mask, a mask over several parts, or nothing there).
    #[serde(default)]
    pub closest_truth: Option<TruthOverlap>,
    /// Whether its pose is in a stable pose the cell has a grasp for (so it may be picked).
    #[serde(default)]
    pub graspable: bool,
    /// How near the open fingers of its grasp come to the nearest other part of the frame, mm
    /// (with a finger check, a grasp for its pose, and other parts in the frame).
    #[serde(default)]
    pub finger_clearance_mm: Option<f64>,
}

/// A ground-truth instance and its mask IoU with a detection.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TruthOverlap {
    /// Index of the ground-truth instance.
    pub truth: usize,
    /// Mask IoU.
    pub iou: f64,
}

/// A pose as BOP's ground truth and results write it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BopPose {
    /// Model-to-camera rotation, row-major.
    #[serde(rename = "cam_R_m2c")]
    pub r: [f64; 9],
    /// Model-to-camera translation, mm.
    #[serde(rename = "cam_t_m2c")]
    pub t_mm: [f64; 3],
}

impl BopPose {
    /// The BOP form of `camera_T_part` (metres).
    #[allow(non_snake_case)]
    pub fn of(camera_T_part: &Isometry3<f64>) -> Self {
        let (r, t_mm) = pose_to_bop(camera_T_part);
        Self { r, t_mm }
    }
}

/// One evaluated image.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameRecord {
    /// Scene id.
    pub scene: usize,
    /// Image id.
    pub image: usize,
    /// Why the detector failed on the whole frame, if it did.
    pub failure: Option<String>,
    /// Stage times (absent when the detector failed).
    pub times: Option<StageMs>,
    /// Ground-truth instances, in scene_gt.json order.
    pub truths: Vec<TruthRecord>,
    /// Detections, in the detector's order.
    pub detections: Vec<DetectionRecord>,
}

/// Every frame's records and the gallery.
#[derive(Debug, Clone)]
pub struct EvalRun {
    /// Per-frame records.
    pub frames: Vec<FrameRecord>,
    /// The worst crops, worst first.
    pub gallery: Vec<GalleryItem>,
    /// The worst placed of the parts resting in the right stable pose (largest in-plane
    /// error first): where contour alignment missed the outline.
    pub misplaced: Vec<GalleryItem>,
    /// Matched detections without a pose, highest score first.
    pub failures: Vec<FailedCrop>,
    /// Missed instances, the most visible first.
    pub missed: Vec<DetectionErrorCrop>,
    /// False positives, highest score first.
    pub false_positives: Vec<DetectionErrorCrop>,
}
