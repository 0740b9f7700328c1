//! Production: the pre-flight checks that must pass before the orchestrator drives a real arm,
//! and the camera source (image files or a folder of them) it reads frames from.
//!
//! A production run needs an explicit opt-in, the scenario's motion limits (checked for sanity:
//! every target is tested against them before it is sent), a camera source with images, and a
//! perception mode that reads images (keypoint-noise needs the simulated scene, so it is
//! refused until the learned pipeline is available).

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::cell_io::{CellIo, CellIoError, InsertionCheck};
use crate::scenario::{PerceptionMode, Scenario};
use perception::{Frame, FrameContent, FrameImage};

/// Image file extensions a camera folder may hold.
const IMAGE_EXTENSIONS: [&str; 6] = ["png", "jpg", "jpeg", "bmp", "tif", "tiff"];

/// What the operator passed to start a production run.
#[derive(Debug, Clone, PartialEq)]
pub struct ProductionOptions {
    /// The explicit opt-in that the arm will move (`--allow-motion` or similar).
    pub allow_motion: bool,
    /// An image file or a folder of image files.
    pub camera: PathBuf,
}

/// Why a production run refuses to start.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProductionError {
    /// No explicit opt-in.
    #[error("production moves a real arm: pass the explicit opt-in flag to allow motion")]
    NotAllowed,
    /// The scenario's limits are unusable.
    #[error("the scenario's [cell.limits] are invalid: {0}")]
    Limits(String),
    /// The camera source has no images or cannot be read.
    #[error("camera source {path}: {reason}")]
    Camera {
        /// The source.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The perception mode cannot read camera images.
    #[error("perception mode {0:?} cannot read camera images")]
    Perception(PerceptionMode),
    /// The perception mode reads images but has no trained models yet.
    #[error("perception mode {0:?} is not available yet (no trained models)")]
    Unavailable(PerceptionMode),
}

/// Checks everything a production run needs before anything connects or moves.
pub fn preflight(
    scenario: &Scenario,
    options: &ProductionOptions,
) -> Result<ImageSource, ProductionError> {
    if !options.allow_motion {
        return Err(ProductionError::NotAllowed);
    }
    scenario
        .spec
        .cell
        .limits
        .validate()
        .map_err(|e| ProductionError::Limits(e.to_string()))?;
    let source = ImageSource::open(&options.camera)?;
    if scenario.spec.perception.mode != PerceptionMode::Learned {
        return Err(ProductionError::Perception(scenario.spec.perception.mode));
    }
    Ok(source)
}

/// Camera frames from image files, in name order: one file, or every image in a folder.
#[derive(Debug, Clone, PartialEq)]
pub struct ImageSource {
    files: Vec<PathBuf>,
    next: usize,
}

impl ImageSource {
    /// Lists the images at `path` (a file or a folder); fails when there are none.
    pub fn open(path: &Path) -> Result<Self, ProductionError> {
        let err = |reason: String| ProductionError::Camera {
            path: path.into(),
            reason,
        };
        let meta = std::fs::metadata(path).map_err(|e| err(e.to_string()))?;
        let is_image = |p: &Path| {
            p.extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| IMAGE_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
        };
        let mut files = if meta.is_dir() {
            std::fs::read_dir(path)
                .map_err(|e| err(e.to_string()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.is_file() && is_image(p))
                .collect::<Vec<_>>()
        } else if is_image(path) {
            vec![path.to_path_buf()]
        } else {
            return Err(err(format!(
                "not an image (expected one of {IMAGE_EXTENSIONS:?})"
            )));
        };
        files.sort();
        if files.is_empty() {
            return Err(err("no image files".into()));
        }
        Ok(Self { files, next: 0 })
    }

    /// The images, in the order they are delivered.
    pub fn files(&self) -> &[PathBuf] {
        &self.files
    }

    /// The next image, or `None` when every image was delivered.
    pub fn next_image(&mut self) -> Option<PathBuf> {
        let f = self.files.get(self.next).cloned();
        self.next += usize::from(f.is_some());
        f
    }
}

/// A production cell's side channels: the camera from image files, the wall clock; no feeder
/// shaker and no grasp or seating sensor are configured yet, so those report what they can't do.
pub struct ProductionCellIo {
    scenario: Scenario,
    images: ImageSource,
    start: Instant,
}

impl ProductionCellIo {
    /// Side channels for a checked production run.
    pub fn new(scenario: Scenario, images: ImageSource) -> Self {
        Self {
            scenario,
            images,
            start: Instant::now(),
        }
    }
}

impl CellIo for ProductionCellIo {
    fn capture(&mut self) -> Result<Frame, CellIoError> {
        let file = self.images.next_image().ok_or_else(|| {
            CellIoError::Camera("every image of the camera source was used".into())
        })?;
        let pixels = image::open(&file)
            .map_err(|e| CellIoError::Camera(format!("{}: {e}", file.display())))?;
        let cam = &self.scenario.spec.cell.camera;
        Ok(Frame {
            camera: cam.intrinsics,
            base_T_camera: cam.base_T_camera.isometry(),
            content: FrameContent::Image(FrameImage::full(pixels)),
        })
    }

    fn shake_feeder(&mut self) -> Result<(), CellIoError> {
        Err(CellIoError::Feeder(
            "no feeder shaker is configured for this cell".into(),
        ))
    }

    fn part_in_gripper(&mut self) -> Option<bool> {
        None
    }

    fn insertion_check(&mut self) -> Option<InsertionCheck> {
        None
    }

    fn clock(&self) -> f64 {
        self.start.elapsed().as_secs_f64()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn image_folders_list_images_in_order_and_refuse_empty_ones() {
        let dir = tempfile::tempdir().unwrap();
        assert!(matches!(
            ImageSource::open(dir.path()),
            Err(ProductionError::Camera { .. })
        ));
        for name in ["b.png", "a.JPG", "notes.txt"] {
            std::fs::write(dir.path().join(name), b"x").unwrap();
        }
        let mut s = ImageSource::open(dir.path()).unwrap();
        let names: Vec<_> = s
            .files()
            .iter()
            .map(|p| p.file_name().unwrap().to_str().unwrap().to_string())
            .collect();
        assert_eq!(names, ["a.JPG", "b.png"]);
        assert!(s.next_image().is_some() && s.next_image().is_some());
        assert_eq!(s.next_image(), None);
        let missing = dir.path().join("missing");
        assert!(matches!(
            ImageSource::open(&missing),
            Err(ProductionError::Camera { .. })
        ));
        let txt = dir.path().join("notes.txt");
        assert!(matches!(
            ImageSource::open(&txt),
            Err(ProductionError::Camera { .. })
        ));
    }
}
