//! `cell eval`: the learned perception pipeline against a BOP test split with ground truth.
//!
//! For each image the camera (K, distortion, size) and `camera_T_table` come from
//! scene_camera.json; the detector runs; detections are matched to ground-truth instances (same
//! part, visible-mask IoU ≥ 0.5, greedy by score, each instance at most once); matched poses are
//! scored with [`perception::metrics`] raw (PnP) and after planar refinement. [`table1`] turns the
//! records into the seed's Table 1 (outliers counted, statistics both with and without them),
//! detection precision / recall, stable-pose rate, BOP MSSD / MSPD recall and stage times;
//! [`report_html`] writes eval.json, eval.html, plots and the [`gallery`] of the worst crops.

pub mod bop_results;
pub mod detection_gallery;
pub mod fingers;
pub mod gallery;
pub mod matching;
pub mod report_html;
pub mod stable_poses;
pub mod table1;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Duration;

use nalgebra::{Isometry3, Point3, UnitQuaternion};
use perception::contour::PartOutline;
use perception::learned::{InstanceMask, LearnedDetections, StageTimes};
use perception::metrics::{PoseErrors, pose_errors};
use perception::part::{Catalog, PartRole, StablePose};
use perception::planar::{PlanarConfig, PlanarPose, PlanarRefiner};
use perception::symmetry::{ambiguity_group, symmetric_angle, symmetry_group, view_turns};
use perception::{Camera, Distortion, FrameImage};
use serde::{Deserialize, Serialize};
use sim::dataset::{
    BopDataset, BopImage, BopScene, DatasetError, SceneCamera, pose_from_bop, pose_to_bop,
};

use detection_gallery::{DetectionErrorCrop, DetectionErrorKind, draw_window};
use fingers::FingerCheck;
use gallery::{FailedCrop, GalleryItem, GalleryKeeper};
use matching::{Candidate, Truth, greedy_match, mask_from_raster, touching_flags};

/// The split read when none is named: full-resolution feeder windows.
pub const DEFAULT_SPLIT: &str = "test_feeder";
/// The split read when [`DEFAULT_SPLIT`] does not exist: the reduced-scale overview test images.
pub const FALLBACK_SPLIT: &str = "test";

/// Why an evaluation could not run.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// The dataset could not be read (the message names the file, and line and column or the
    /// key where the JSON is wrong).
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// The dataset does not fit the catalog or holds impossible values.
    #[error("{path}: {message}")]
    Mismatch {
        /// The file or folder.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A part of the catalog could not be used.
    #[error("part {part}: {message}")]
    Part {
        /// The part.
        part: String,
        /// Why.
        message: String,
    },
    /// The settings are unusable.
    #[error("{0}")]
    Options(String),
}

/// The detector under evaluation: the learned pipeline, or in tests a stand-in built from the
/// ground truth.
pub trait FrameDetector {
    /// Detects the parts in one image of `camera` (the image covers the camera's whole sensor)
    /// looking at the table at `camera_T_table`.
    #[allow(non_snake_case)]
    fn detect(
        &mut self,
        image: &FrameImage,
        camera: &Camera,
        camera_T_table: &Isometry3<f64>,
    ) -> Result<LearnedDetections, String>;
}

impl FrameDetector for perception::learned::LearnedPipeline {
    #[allow(non_snake_case)]
    fn detect(
        &mut self,
        image: &FrameImage,
        camera: &Camera,
        camera_T_table: &Isometry3<f64>,
    ) -> Result<LearnedDetections, String> {
        perception::learned::LearnedPipeline::detect(self, image, camera, camera_T_table, None)
            .map_err(|e| e.to_string())
    }
}

/// Evaluation settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EvalOptions {
    /// Mask IoU a detection needs to match a ground-truth instance.
    pub min_iou: f64,
    /// Ground-truth instances less visible than this (BOP's visib_fract) are ignored: not
    /// counted as missed, and a detection matching one is not a false positive.
    pub min_visib_fract: f64,
    /// Two instances touch when their visible masks come within this many pixels.
    pub touch_gap_px: u32,
    /// Angle above which an estimate is an outlier (the seed's 10°), degrees.
    pub outlier_deg: f64,
    /// Worst crops kept for the gallery.
    pub gallery: usize,
    /// Evaluate at most this many images (in scene, image order).
    pub limit: Option<usize>,
    /// Surface points sampled per part for ADD(-S), MSSD and MSPD.
    pub model_points: usize,
    /// The least confidence of a pose the cell would pick (a scenario's
    /// `[policy] min_pick_confidence`).
    #[serde(default = "default_pick_confidence")]
    pub pick_confidence: f64,
    /// The least clearance between an open finger and any other part that the cell picks with,
    /// metres, when a scenario's gripper checks each pick ([`fingers::FingerCheck`]); without
    /// one, picks are not checked for room for the fingers.
    #[serde(default)]
    pub finger_margin: Option<f64>,
}

fn default_pick_confidence() -> f64 {
    crate::scenario::DEFAULT_MIN_PICK_CONFIDENCE
}

impl Default for EvalOptions {
    fn default() -> Self {
        Self {
            min_iou: 0.5,
            min_visib_fract: 0.1,
            touch_gap_px: 2,
            outlier_deg: 10.0,
            gallery: 24,
            limit: None,
            model_points: 1000,
            pick_confidence: default_pick_confidence(),
            finger_margin: None,
        }
    }
}

impl EvalOptions {
    /// Checks the ranges.
    pub fn validate(&self) -> Result<(), EvalError> {
        if !(self.min_iou > 0.0 && self.min_iou <= 1.0) {
            return Err(EvalError::Options(format!(
                "the IoU threshold must be in (0, 1], got {}",
                self.min_iou
            )));
        }
        if !(0.0..=1.0).contains(&self.min_visib_fract) {
            return Err(EvalError::Options(format!(
                "the visibility threshold must be in [0, 1], got {}",
                self.min_visib_fract
            )));
        }
        if !(self.outlier_deg.is_finite() && self.outlier_deg > 0.0) {
            return Err(EvalError::Options(format!(
                "the outlier angle must be > 0°, got {}",
                self.outlier_deg
            )));
        }
        if self.model_points < 8 {
            return Err(EvalError::Options(format!(
                "at least 8 model points are needed, got {}",
                self.model_points
            )));
        }
        Ok(())
    }
}

/// What evaluation needs of one part.
#[derive(Debug, Clone)]
pub struct PartData {
    /// Catalog name.
    pub name: String,
    /// BOP object id (catalog index + 1, as `cell dataset` writes them).
    pub obj_id: u32,
    /// Model keypoints, part frame, metres.
    pub keypoints: Vec<Point3<f64>>,
    /// Surface samples for the distance metrics, part frame, metres.
    pub points: Vec<Point3<f64>>,
    /// Exact symmetry group (what the metrics and the refiner use).
    pub group: Vec<UnitQuaternion<f64>>,
    /// Group of every declared symmetry, exact or not: an error within the outlier angle of a
    /// near-symmetric equivalent is a symmetry flip.
    pub near_group: Vec<UnitQuaternion<f64>>,
    /// Stable poses, in the order classes refer to.
    pub stable_poses: Vec<StablePose>,
    /// Per stable pose, the turns under which the part looks the same from above
    /// ([`perception::part::ViewSymmetry`]; the identity alone for most).
    pub view_turns: Vec<Vec<UnitQuaternion<f64>>>,
    /// The stable poses the cell has a grasp for (the catalog's `grasp`s): the ways up it picks.
    pub graspable: Vec<String>,
    /// Diameter from models_info.json, mm.
    pub diameter_mm: f64,
    /// Outline model of its mesh, to draw the true and estimated outlines in the gallery.
    pub outline: PartOutline,
}

/// A BOP split opened for evaluation against a catalog.
#[derive(Debug, Clone)]
pub struct EvalDataset {
    /// The dataset (cameras, ground truth, scenes).
    pub bop: BopDataset,
    /// The split read.
    pub split: String,
    /// Parts by BOP object id.
    pub parts: BTreeMap<u32, PartData>,
}

/// The split to read: `requested`, or [`DEFAULT_SPLIT`] when it exists, else [`FALLBACK_SPLIT`].
pub fn resolve_split(root: &Path, requested: Option<&str>) -> String {
    match requested {
        Some(s) => s.to_string(),
        None if root.join(DEFAULT_SPLIT).is_dir() => DEFAULT_SPLIT.into(),
        None => FALLBACK_SPLIT.into(),
    }
}

impl EvalDataset {
    /// Opens split `split` of the dataset at `root` for the parts of `catalog` (object id =
    /// catalog index + 1); checks that each object's model size matches the catalog mesh.
    pub fn open(
        root: &Path,
        split: &str,
        catalog: &Catalog,
        options: &EvalOptions,
    ) -> Result<Self, EvalError> {
        options.validate()?;
        let split_dir = root.join(split);
        if !split_dir.is_dir() {
            return Err(EvalError::Mismatch {
                path: split_dir,
                message: "no such split folder (name one with --split)".into(),
            });
        }
        let bop = BopDataset::load(root, split)?;
        let models_info = root.join("models").join("models_info.json");
        let mut parts = BTreeMap::new();
        for (&obj_id, info) in &bop.models {
            let mismatch = |message: String| EvalError::Mismatch {
                path: models_info.clone(),
                message,
            };
            let spec = obj_id
                .checked_sub(1)
                .and_then(|i| catalog.parts.get(i as usize))
                .ok_or_else(|| {
                    mismatch(format!(
                        "object {obj_id} has no part in catalog {} ({} parts)",
                        catalog.file.display(),
                        catalog.parts.len()
                    ))
                })?;
            if spec.role == PartRole::Fixture {
                return Err(mismatch(format!(
                    "object {obj_id} is {}, a fixture in catalog {}",
                    spec.name,
                    catalog.file.display()
                )));
            }
            let part_err = |message: String| EvalError::Part {
                part: spec.name.clone(),
                message,
            };
            let mesh = catalog
                .load_mesh(spec)
                .map_err(|e| part_err(e.to_string()))?;
            let (lo, hi) = mesh.aabb();
            let size = (hi - lo) * 1000.0;
            for (axis, ours, theirs) in [
                ("x", size.x, info.size_x),
                ("y", size.y, info.size_y),
                ("z", size.z, info.size_z),
            ] {
                if (ours - theirs).abs() > 0.01 {
                    return Err(mismatch(format!(
                        "object {obj_id}: size_{axis} is {theirs:.3} mm but part {} of catalog {} \
                         measures {ours:.3} mm: the dataset was made from another catalog",
                        spec.name,
                        catalog.file.display()
                    )));
                }
            }
            if spec.keypoints.len() < 4 || spec.stable_poses.is_empty() {
                return Err(part_err(format!(
                    "not prepared (keypoints and stable poses); run `cell parts prepare {}`",
                    catalog.file.display()
                )));
            }
            parts.insert(
                obj_id,
                PartData {
                    name: spec.name.clone(),
                    obj_id,
                    keypoints: spec.keypoint_points(),
                    points: perception::part::sample_surface(&mesh, options.model_points, 1),
                    group: symmetry_group(&spec.symmetries),
                    near_group: ambiguity_group(&spec.symmetries),
                    stable_poses: spec.stable_poses.clone(),
                    view_turns: spec
                        .stable_poses
                        .iter()
                        .map(|s| view_turns(s, spec.view_order(&s.name)))
                        .collect(),
                    graspable: spec
                        .stable_poses
                        .iter()
                        .filter(|s| spec.grasp_for(&s.name).is_some())
                        .map(|s| s.name.clone())
                        .collect(),
                    diameter_mm: info.diameter,
                    outline: PartOutline::new(&mesh),
                },
            );
        }
        Ok(Self {
            bop,
            split: split.into(),
            parts,
        })
    }

    /// Images of the split, in scene and image order.
    pub fn images(&self) -> impl Iterator<Item = (&BopScene, &BopImage)> {
        self.bop
            .scenes
            .iter()
            .flat_map(|s| s.images.iter().map(move |i| (s, i)))
    }

    /// Part names in object-id order.
    pub fn part_names(&self) -> Vec<String> {
        self.parts.values().map(|p| p.name.clone()).collect()
    }
}

/// The camera of an image from its scene_camera.json entry.
pub fn camera_of(cam: &SceneCamera) -> Result<Camera, String> {
    let k = &cam.cam_K;
    if k[1] != 0.0 || k[3] != 0.0 || k[6] != 0.0 || k[7] != 0.0 || k[8] != 1.0 {
        return Err(format!("cam_K {k:?} is not [fx 0 cx; 0 fy cy; 0 0 1]"));
    }
    let d = cam.dist_coeffs;
    Camera::new(
        k[0],
        k[4],
        k[2],
        k[5],
        cam.width,
        cam.height,
        Distortion {
            k1: d[0],
            k2: d[1],
            p1: d[2],
            p2: d[3],
            k3: d[4],
        },
    )
    .map_err(|e| e.to_string())
}

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

/// `truth`, or the turn of it (`turns`, part frame) nearest `estimate` in rotation.
fn seen_truth(
    truth: &Isometry3<f64>,
    turns: &[UnitQuaternion<f64>],
    estimate: &Isometry3<f64>,
) -> Isometry3<f64> {
    turns
        .iter()
        .map(|g| truth * Isometry3::from_parts(Default::default(), *g))
        .min_by(|a, b| {
            let d = |t: &Isometry3<f64>| t.rotation.angle_to(&estimate.rotation);
            d(a).total_cmp(&d(b))
        })
        .unwrap_or(*truth)
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
    /// Too little visible to count (see [`EvalOptions::min_visib_fract`]).
    pub ignored: bool,
    /// Whether it rests on the table in a stable pose ([`PlanarPose::rests`]: within 1° and
    /// 0.2 mm of the nearest one). A part leaning on or lying on another one is in no stable
    /// pose, so no planar estimate of it can be right: it is left out of the refined rows and
    /// counted apart.
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
    /// Raw angle error to the nearest near-symmetric equivalent of the truth, degrees.
    pub raw_flip_deg: Option<f64>,
    /// Refined angle error to the nearest near-symmetric equivalent of the truth, degrees.
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

/// Runs `detector` over the images of `dataset` (at most `options.limit`), calling `progress`
/// after each with (done, total).
pub fn evaluate(
    dataset: &EvalDataset,
    detector: &mut dyn FrameDetector,
    options: &EvalOptions,
    fingers: Option<&FingerCheck>,
    mut progress: impl FnMut(usize, usize),
) -> Result<EvalRun, EvalError> {
    options.validate()?;
    let total = dataset
        .images()
        .count()
        .min(options.limit.unwrap_or(usize::MAX));
    let mut frames = Vec::with_capacity(total);
    let mut galleries = Galleries {
        worst: GalleryKeeper::new(options.gallery),
        misplaced: GalleryKeeper::new(options.gallery.div_ceil(3)),
        failed: GalleryKeeper::new(options.gallery.div_ceil(3)),
        missed: GalleryKeeper::new(options.gallery.div_ceil(2)),
        false_positives: GalleryKeeper::new(options.gallery.div_ceil(2)),
    };
    for (i, (scene, image)) in dataset.images().take(total).enumerate() {
        frames.push(evaluate_image(
            dataset,
            scene,
            image,
            detector,
            options,
            fingers,
            &mut galleries,
        )?);
        progress(i + 1, total);
    }
    Ok(EvalRun {
        frames,
        gallery: galleries.worst.into_items(),
        misplaced: galleries.misplaced.into_items(),
        failures: galleries.failed.into_items(),
        missed: galleries.missed.into_items(),
        false_positives: galleries.false_positives.into_items(),
    })
}

/// The galleries one evaluation fills (see [`EvalRun`]).
struct Galleries {
    worst: GalleryKeeper,
    misplaced: GalleryKeeper,
    failed: GalleryKeeper<FailedCrop>,
    missed: GalleryKeeper<DetectionErrorCrop>,
    false_positives: GalleryKeeper<DetectionErrorCrop>,
}

/// Evaluates one image.
#[allow(non_snake_case)]
fn evaluate_image(
    dataset: &EvalDataset,
    scene: &BopScene,
    image: &BopImage,
    detector: &mut dyn FrameDetector,
    options: &EvalOptions,
    fingers: Option<&FingerCheck>,
    galleries: &mut Galleries,
) -> Result<FrameRecord, EvalError> {
    let scene_camera = scene.dir.join("scene_camera.json");
    let at = |message: String| EvalError::Mismatch {
        path: scene_camera.clone(),
        message: format!("image {}: {message}", image.id),
    };
    let camera = camera_of(&image.camera).map_err(at)?;
    let camera_T_table = pose_from_bop(&image.camera.cam_R_w2c, &image.camera.cam_t_w2c)
        .ok_or_else(|| at("cam_R_w2c is not a rotation".into()))?;
    let rgb = scene.rgb(image.id)?;
    if (rgb.width(), rgb.height()) != (camera.width, camera.height) {
        return Err(EvalError::Mismatch {
            path: scene.dir.join("rgb").join(format!("{:06}.png", image.id)),
            message: format!(
                "the image is {} × {} but scene_camera.json gives {} × {}",
                rgb.width(),
                rgb.height(),
                camera.width,
                camera.height
            ),
        });
    }

    // Ground truth: part, pose, visible mask.
    let mut truth_masks: Vec<InstanceMask> = Vec::with_capacity(image.gt.len());
    let mut truth_poses = Vec::with_capacity(image.gt.len());
    let mut truth_parts: Vec<&PartData> = Vec::with_capacity(image.gt.len());
    for (k, gt) in image.gt.iter().enumerate() {
        let part = dataset
            .parts
            .get(&gt.obj_id)
            .ok_or_else(|| EvalError::Mismatch {
                path: scene.dir.join("scene_gt.json"),
                message: format!(
                    "image {}: object {} is not a known part",
                    image.id, gt.obj_id
                ),
            })?;
        let bits = scene.mask(image.id, k, true)?;
        if bits.len() != (camera.width * camera.height) as usize {
            return Err(EvalError::Mismatch {
                path: scene
                    .dir
                    .join("mask_visib")
                    .join(format!("{:06}_{k:06}.png", image.id)),
                message: format!("the mask is not {} × {}", camera.width, camera.height),
            });
        }
        truth_masks.push(mask_from_raster(&bits, camera.width, camera.height));
        truth_poses.push(
            image
                .camera_T_part(k)
                .expect("the reader checked rotations"),
        );
        truth_parts.push(part);
    }
    let touching = touching_flags(&truth_masks, options.touch_gap_px);
    // One refiner per part kind in view; the snap of each true pose gives its stable pose and
    // whether it rests there.
    let mut refiners: BTreeMap<u32, PlanarRefiner> = BTreeMap::new();
    for part in &truth_parts {
        if refiners.contains_key(&part.obj_id) {
            continue;
        }
        let refiner = PlanarRefiner::new(
            camera_T_table,
            &part.stable_poses,
            &part.group,
            PlanarConfig::default(),
        )
        .map_err(|e| EvalError::Part {
            part: part.name.clone(),
            message: e.to_string(),
        })?;
        refiners.insert(part.obj_id, refiner);
    }
    let snapped: Vec<Option<PlanarPose>> = truth_parts
        .iter()
        .zip(&truth_poses)
        .map(|(part, truth)| refiners[&part.obj_id].refine(truth).ok())
        .collect();
    let table_T_camera = camera_T_table.inverse();
    let rests = |k: usize| {
        snapped[k]
            .as_ref()
            .is_some_and(|p| p.rests(&(table_T_camera * truth_poses[k])))
    };
    let mut truths: Vec<TruthRecord> = image
        .gt
        .iter()
        .enumerate()
        .map(|(k, _)| {
            let info = &image.info[k];
            TruthRecord {
                part: truth_parts[k].name.clone(),
                visib_fract: info.visib_fract,
                visible_px: truth_masks[k].area(),
                touching: touching[k],
                ignored: info.visib_fract < options.min_visib_fract || truth_masks[k].area() == 0,
                resting: rests(k),
                stable_pose: rests(k)
                    .then(|| snapped[k].as_ref())
                    .flatten()
                    .map(|p| truth_parts[k].stable_poses[p.class].name.clone()),
                detection: None,
                closest: None,
            }
        })
        .collect();

    let frame_image = FrameImage::full(image::DynamicImage::ImageRgb8(rgb));
    let found = match detector.detect(&frame_image, &camera, &camera_T_table) {
        Ok(found) => found,
        Err(message) => {
            return Ok(FrameRecord {
                scene: scene.id,
                image: image.id,
                failure: Some(message),
                times: None,
                truths,
                detections: Vec::new(),
            });
        }
    };

    let candidates: Vec<Candidate<'_>> = found
        .detections
        .iter()
        .map(|d| Candidate {
            part: &d.part,
            score: d.score,
            mask: &d.mask,
        })
        .collect();
    let truth_refs: Vec<Truth<'_>> = truths
        .iter()
        .zip(&truth_masks)
        .map(|(t, m)| Truth {
            part: &t.part,
            mask: m,
        })
        .collect();
    let matches = greedy_match(&candidates, &truth_refs, options.min_iou);
    // Why each miss was missed: the detection overlapping it most, of any part.
    let mut matched = vec![false; truths.len()];
    for m in matches.iter().flatten() {
        matched[m.truth] = true;
    }
    for ((truth, mask), _) in truths
        .iter_mut()
        .zip(&truth_masks)
        .zip(&matched)
        .filter(|(_, m)| !**m)
    {
        truth.closest = matching::most_overlapping(candidates.iter().map(|c| c.mask), mask)
            .map(|(detection, iou)| DetectionOverlap { detection, iou });
    }

    // Why each false positive is one: the truth its mask overlaps most, of any part.
    let closest_truth = |c: &Candidate<'_>| {
        matching::most_overlapping(truth_masks.iter(), c.mask)
            .map(|(truth, iou)| TruthOverlap { truth, iou })
    };
    let clearances = fingers.map(|f| f.clearances(&found, &camera, &camera_T_table));
    let mut detections = Vec::with_capacity(found.detections.len());
    for (d, (det, m)) in found.detections.iter().zip(&matches).enumerate() {
        let own_part = dataset.parts.values().find(|p| p.name == det.part);
        let mut rec = DetectionRecord {
            closest_truth: m.is_none().then(|| closest_truth(&candidates[d])).flatten(),
            obj_id: own_part.map(|p| p.obj_id),
            graspable: det
                .pose
                .as_ref()
                .is_ok_and(|p| own_part.is_some_and(|own| own.graspable.contains(&p.stable_pose))),
            finger_clearance_mm: clearances.as_ref().and_then(|c| c[d]).map(|c| c * 1e3),
            part: det.part.clone(),
            score: det.score,
            crop_origin: det.crop_origin,
            keypoints_px: det
                .keypoints
                .iter()
                .map(|k| [k.position.x, k.position.y])
                .collect(),
            keypoint_covariances_px: det
                .keypoints
                .iter()
                .map(|k| {
                    let c = k.covariance;
                    [c[(0, 0)], c[(0, 1)], c[(1, 1)]]
                })
                .collect(),
            truth: m.map(|m| m.truth),
            iou: m.map(|m| m.iou),
            pose_failure: det.pose.as_ref().err().cloned(),
            raw: None,
            refined: None,
            stable_pose: det.pose.as_ref().ok().map(|p| p.stable_pose.clone()),
            true_stable_pose: None,
            raw_flip_deg: None,
            refined_flip_deg: None,
            contour_support: None,
            confidence: det.confidence(),
            keypoint_refined: None,
            pose: det
                .pose
                .as_ref()
                .ok()
                .map(|p| BopPose::of(&p.planar.camera_T_part)),
        };
        if let Some(m) = m {
            truths[m.truth].detection = Some(d);
            let part = truth_parts[m.truth];
            let truth = &truth_poses[m.truth];
            // The class the refiner assigns to the true pose is the true stable pose.
            rec.true_stable_pose = snapped[m.truth]
                .as_ref()
                .map(|p| part.stable_poses[p.class].name.clone());
            if let (Err(reason), false) = (&det.pose, truths[m.truth].ignored) {
                galleries.failed.offer(det.score, || FailedCrop {
                    scene: scene.id,
                    image: image.id,
                    detection: d,
                    part: part.name.clone(),
                    score: det.score,
                    iou: m.iou,
                    reason: reason.clone(),
                    crop: gallery::draw_crop(&frame_image.pixels, &camera, det, part, truth, None),
                });
            }
            // A part resting in a stable pose whose view repeats on a turn is scored against the
            // turn of its true pose nearest each estimate: vision cannot tell those apart.
            let turns: &[UnitQuaternion<f64>] = match (&snapped[m.truth], truths[m.truth].resting) {
                (Some(p), true) => &part.view_turns[p.class],
                _ => &[],
            };
            let seen = |est: &Isometry3<f64>| seen_truth(truth, turns, est);
            let flip = |est: &Isometry3<f64>| {
                symmetric_angle(&est.rotation, &seen(est).rotation, &part.near_group).to_degrees()
            };
            // Raw PnP is reported for every estimate, also one the reprojection gate refused
            // (the paper's Table 1 is ungated PnP); refined figures only for accepted poses.
            if let Some(estimate) = det.pose.as_ref().ok().or(det.refused.as_ref()) {
                let raw = &estimate.pnp.camera_T_part;
                rec.raw = Some(pose_errors(
                    &camera,
                    &part.points,
                    &part.group,
                    &seen(raw),
                    raw,
                ));
                rec.raw_flip_deg = Some(flip(raw));
            }
            if let (Ok(pose), Some(raw_e)) = (&det.pose, rec.raw) {
                let refined = &pose.planar.camera_T_part;
                let truth = &seen(refined);
                let refined_e = pose_errors(&camera, &part.points, &part.group, truth, refined);
                rec.refined_flip_deg = Some(flip(refined));
                rec.refined = Some(refined_e);
                if let Some(c) = &pose.contour {
                    rec.contour_support = Some(c.fit.support);
                    rec.keypoint_refined = Some(pose_errors(
                        &camera,
                        &part.points,
                        &part.group,
                        &seen(&c.keypoint_planar.camera_T_part),
                        &c.keypoint_planar.camera_T_part,
                    ));
                }
                let item = || GalleryItem {
                    scene: scene.id,
                    image: image.id,
                    detection: d,
                    part: part.name.clone(),
                    iou: m.iou,
                    raw: raw_e,
                    refined: refined_e,
                    stable_pose: pose.stable_pose.clone(),
                    true_stable_pose: rec.true_stable_pose.clone(),
                    crop: gallery::draw_crop(
                        &frame_image.pixels,
                        &camera,
                        det,
                        part,
                        truth,
                        Some(refined),
                    ),
                };
                let counted = &truths[m.truth];
                if !counted.ignored {
                    galleries.worst.offer(refined_e.mssd_mm, item);
                    if counted.resting
                        && rec.true_stable_pose.as_ref() == Some(&pose.stable_pose)
                        && refined_e.angle_deg <= options.outlier_deg
                    {
                        galleries
                            .misplaced
                            .offer(refined_e.x_mm.hypot(refined_e.y_mm), item);
                    }
                }
            }
        }
        detections.push(rec);
    }
    offer_detection_errors(
        galleries,
        (scene.id, image.id),
        &frame_image.pixels,
        (&truths, &truth_masks),
        (&detections, &found),
        options.min_iou,
    );
    Ok(FrameRecord {
        scene: scene.id,
        image: image.id,
        failure: None,
        times: Some(StageMs::from(&found.times)),
        truths,
        detections,
    })
}

/// Offers the frame's missed instances (the most visible first) and false positives (the
/// highest score first) to their galleries, each captioned with its cause.
fn offer_detection_errors(
    galleries: &mut Galleries,
    (scene, image): (usize, usize),
    pixels: &image::DynamicImage,
    (truths, truth_masks): (&[TruthRecord], &[InstanceMask]),
    (records, found): (&[DetectionRecord], &LearnedDetections),
    min_iou: f64,
) {
    let masks: Vec<&InstanceMask> = found.detections.iter().map(|d| &d.mask).collect();
    let others = |own: Option<usize>| -> Vec<&InstanceMask> {
        (masks.iter().enumerate())
            .filter(|(i, _)| Some(*i) != own)
            .map(|(_, m)| *m)
            .collect()
    };
    for (k, t) in truths.iter().enumerate() {
        if t.ignored || t.detection.is_some() {
            continue;
        }
        let closest = t.closest.and_then(|c| Some((records.get(c.detection)?, c)));
        let cause = table1::miss_cause(&t.part, closest.map(|(d, c)| (&d.part, c.iou)), min_iou);
        let caption = match closest {
            Some((d, c)) => format!(
                "{}: the {} detection {} overlaps it most (IoU {:.2})",
                cause.describe(),
                d.part,
                c.detection,
                c.iou
            ),
            None => cause.describe().to_string(),
        };
        let near = closest.map(|(_, c)| c.detection);
        galleries
            .missed
            .offer(t.visible_px as f64, || DetectionErrorCrop {
                scene,
                image,
                kind: DetectionErrorKind::Missed,
                index: k,
                part: t.part.clone(),
                caption: format!("{caption}; {:.0} % visible", 100.0 * t.visib_fract),
                crop: draw_window(
                    pixels,
                    &truth_masks[k],
                    Some(&truth_masks[k]),
                    near.map(|d| masks[d]),
                    &others(near),
                ),
            });
    }
    for (i, d) in records
        .iter()
        .enumerate()
        .filter(|(_, d)| d.truth.is_none())
    {
        let cause = table1::false_positive_cause(d, truths, min_iou);
        let closest = d.closest_truth.filter(|c| c.truth < truth_masks.len());
        let caption = match closest {
            Some(c) => format!(
                "{}: overlaps the {} truth {} most (IoU {:.2}); score {:.2}",
                cause.describe(),
                truths[c.truth].part,
                c.truth,
                c.iou,
                d.score
            ),
            None => format!("{}; score {:.2}", cause.describe(), d.score),
        };
        galleries
            .false_positives
            .offer(d.score, || DetectionErrorCrop {
                scene,
                image,
                kind: DetectionErrorKind::FalsePositive,
                index: i,
                part: d.part.clone(),
                caption,
                crop: draw_window(
                    pixels,
                    masks[i],
                    closest.map(|c| &truth_masks[c.truth]),
                    Some(masks[i]),
                    &others(Some(i)),
                ),
            });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, Vector3};

    #[test]
    fn a_truth_is_seen_as_its_turn_nearest_the_estimate() {
        let truth = Isometry3::from_parts(
            Translation3::new(0.01, 0.02, 1.5),
            UnitQuaternion::from_euler_angles(3.0, 0.1, 0.2),
        );
        let quarter = |k: f64| {
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), k * std::f64::consts::FRAC_PI_2)
        };
        let turns: Vec<_> = (0..4).map(|k| quarter(k as f64)).collect();
        // An estimate 3 quarter turns and 0.01 rad off the truth is 0.01 rad off its third turn.
        let estimate = truth * Isometry3::from_parts(Default::default(), quarter(3.01));
        let seen = seen_truth(&truth, &turns, &estimate);
        assert!(
            (seen.rotation.angle_to(&estimate.rotation) - 0.005 * std::f64::consts::PI).abs()
                < 1e-9
        );
        assert_eq!(seen.translation, truth.translation);
        // Without turns the truth stands.
        assert_eq!(seen_truth(&truth, &[], &estimate), truth);
    }
}
