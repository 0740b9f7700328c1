//! `cell eval`: the learned perception pipeline against a BOP test split with ground truth.
//!
//! For each image the camera (K, distortion, size) and `camera_T_table` come from
//! scene_camera.json; the detector runs; detections are matched to ground-truth instances (same
//! part, visible-mask IoU ≥ 0.5, greedy by score, each instance at most once); matched poses are
//! scored with [`perception::metrics`] raw (PnP) and after planar refinement.
//!
//! The module's layout follows the data:
//! - [`dataset`] opens a BOP split against the part catalog, [`options`] holds the settings;
//! - [`evaluate()`] runs the detector over the images and [`matching`] pairs detections with
//!   ground truth, writing one [`records::FrameRecord`] per image;
//! - [`summary`] turns the records into detection precision / recall with the [`causes`] of each
//!   miss and false positive, the [`picks`] the cell would make, stable-pose rate, BOP MSSD /
//!   MSPD recall and stage times, and [`table1`] into the seed's Table 1 (outliers counted,
//!   statistics both with and without them); [`stable_poses`] tabulates by the way each part
//!   rests;
//! - [`report_html`] writes eval.json, eval.html, plots, the [`bop_results`] file and the
//!   galleries of the worst crops ([`gallery`]) and of the detection errors
//!   ([`detection_gallery`]).

pub mod bop_results;
pub mod causes;
pub mod dataset;
pub mod detection_gallery;
mod evaluate;
pub mod fingers;
pub mod gallery;
pub mod matching;
pub mod options;
pub mod picks;
pub mod records;
pub mod report_html;
pub mod stable_poses;
pub mod summary;
pub mod table1;
pub mod table1_text;

use std::path::PathBuf;

use nalgebra::Isometry3;
use perception::learned::LearnedDetections;
use perception::{Camera, FrameImage};
use sim::dataset::DatasetError;

pub use dataset::{DEFAULT_SPLIT, EvalDataset, FALLBACK_SPLIT, PartData, camera_of, resolve_split};
pub use evaluate::evaluate;
pub use options::EvalOptions;
pub use records::{
    BopPose, DetectionOverlap, DetectionRecord, EvalRun, FrameRecord, Stage, StageMs, TruthOverlap,
    TruthRecord,
};

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
