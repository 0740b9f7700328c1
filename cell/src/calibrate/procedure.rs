//! The commissioning procedure by touch points, the seed's way: the board's pose in the camera
//! from one image, the board's pose in the robot base from pointer touches at its marks, and
//! the camera's pose in the base composed from the two, with its propagated covariance. The
//! result ([`Calibration`]) and the errors are shared with the hand-eye procedure
//! ([`super::hand_eye`]).
//!
//! Everything here reads pixels ([`BoardImages`]) and the robot's TCP readings ([`Operator`])
//! only; who moves the pointer onto a mark is the operator's business (a person at the pendant,
//! or the simulator's stand-in for one).

#![allow(non_snake_case)]

use std::future::Future;
use std::pin::Pin;

use nalgebra::{Isometry3, Point3, Vector3};
use perception::calibration::board_pose::{BoardPose, board_pose, check_full_frame};
use perception::calibration::covariance::compose_covariance;
use perception::calibration::detect::{BoardSighting, DetectorSettings, detect_board};
use perception::calibration::rigid_fit::{RigidFit, TouchPoint, fit_rigid};
use perception::calibration::touch_marks::TouchMark;
use perception::calibration::{Board, CalibrationError};
use perception::{Camera, FrameImage};
use robots::robot::RobotError;

use super::evidence::{BaseEvidence, Calibration};

/// Why a calibration stopped.
#[derive(Debug, thiserror::Error)]
pub enum CalibrateError {
    /// The board, the image or the touch points were refused.
    #[error(transparent)]
    Calibration(#[from] CalibrationError),
    /// The camera gave no image.
    #[error("camera {camera}: {message}")]
    Camera {
        /// The source in words.
        camera: String,
        /// What went wrong.
        message: String,
    },
    /// The robot refused or failed.
    #[error("robot: {0}")]
    Robot(#[from] RobotError),
    /// The operator gave up, or their input could not be read.
    #[error("operator: {0}")]
    Operator(String),
    /// Too few of the planned hand-eye poses were reached with the board seen.
    #[error(
        "hand-eye: only {reached} of {planned} planned poses reached with the flange board posed \
         ({why}); at least {needed} are needed: plan more poses (--poses), or check the \
         scenario's workspace limits and camera pose"
    )]
    TooFewPoses {
        /// Views usable.
        reached: usize,
        /// Poses planned.
        planned: usize,
        /// Views needed.
        needed: usize,
        /// The poses left out and why.
        why: String,
    },
    /// The flange board and the table board share tag ids, so an image of both is ambiguous.
    #[error(
        "the flange board's tag ids {ids:?} are also on the table board: print the flange \
         board with a first_id past the table board's last id"
    )]
    SharedIds {
        /// The ids on both boards.
        ids: Vec<u32>,
    },
}

/// A boxed future of the procedure's steps (object-safe async).
pub type StepFuture<'a, T> = Pin<Box<dyn Future<Output = Result<T, CalibrateError>> + Send + 'a>>;

/// Where the board images come from: a production camera source, or the simulator's camera.
pub trait BoardImages: Send {
    /// One new image (the full sensor, or for a simulated camera the window that shows the
    /// board, placed by [`FrameImage::origin`]).
    fn capture(&mut self) -> Result<FrameImage, CalibrateError>;
    /// The source in words.
    fn describe(&self) -> String;
    /// Whether its images are the whole sensor (a camera), not a window of it (the simulator).
    fn full_sensor(&self) -> bool {
        true
    }
}

/// Brings the pointer's tip onto a board mark and reads the robot there: a person jogging the
/// arm at the pendant (the controller's TCP read over RTDE), or the simulator's stand-in.
pub trait Operator: Send {
    /// The robot's TCP reading (`base_T_tcp`) once the tip touches `mark`, the `index`-th of
    /// `count` (from 1).
    fn touch<'a>(
        &'a mut self,
        mark: &'a TouchMark,
        index: usize,
        count: usize,
    ) -> StepFuture<'a, Isometry3<f64>>;
}

/// How the touch points are taken and judged.
#[derive(Debug, Clone, PartialEq)]
pub struct TouchSettings {
    /// The pointer's tip in the TCP frame, metres (a pointer of length L along the tool's z:
    /// `[0, 0, L]`).
    pub tip: Vector3<f64>,
    /// The farthest a touch may lie from where the others put it, metres.
    pub bound: f64,
    /// The per-axis 1σ of one touch (the arm's repeatability), metres.
    pub touch_sigma: f64,
    /// The detector's settings.
    pub detector: DetectorSettings,
}

/// The board's pose in the camera: detects the board in one image and solves its pose.
pub fn camera_half(
    camera: &Camera,
    board: &Board,
    images: &mut dyn BoardImages,
    detector: &DetectorSettings,
) -> Result<(BoardSighting, BoardPose), CalibrateError> {
    let image = images.capture()?;
    // A camera's image must be its whole sensor (a binned or cropped camera is another
    // calibration); a simulated window must lie on it, which the pose solve checks.
    if images.full_sensor() {
        check_full_frame(camera, [image.width(), image.height()])?;
    }
    let sighting = detect_board(&image, board, detector)?;
    let pose = board_pose(camera, board, &sighting)?;
    Ok((sighting, pose))
}

/// The board in the base from touches: the operator brings the pointer to each of the board's
/// marks, and the TCP reading (with the pointer's tip) gives each mark in the base.
pub async fn touch_half(
    board: &Board,
    operator: &mut dyn Operator,
    settings: &TouchSettings,
) -> Result<(Vec<TouchPoint>, RigidFit), CalibrateError> {
    let marks = board.touch_marks();
    let mut touches = Vec::with_capacity(marks.len());
    for (i, mark) in marks.iter().enumerate() {
        let base_T_tcp = operator.touch(mark, i + 1, marks.len()).await?;
        touches.push(TouchPoint {
            name: mark.name.clone(),
            board: mark.point,
            base: base_T_tcp * Point3::from(settings.tip),
        });
    }
    let fit = fit_rigid(&touches, settings.bound, settings.touch_sigma)?;
    Ok((touches, fit))
}

/// The whole procedure by touch points: the camera half, then the touch half, composed.
pub async fn calibrate_by_touch(
    camera: &Camera,
    board: &Board,
    images: &mut dyn BoardImages,
    operator: &mut dyn Operator,
    settings: &TouchSettings,
) -> Result<Calibration, CalibrateError> {
    let (sighting, board_pose) = camera_half(camera, board, images, &settings.detector)?;
    let (touches, fit) = touch_half(board, operator, settings).await?;
    let base_T_board = fit.base_T_board;
    let camera_T_board = board_pose.camera_T_board;
    let base_T_camera = base_T_board * camera_T_board.inverse();
    let camera_covariance = compose_covariance(
        &base_T_board,
        &fit.covariance,
        &camera_T_board,
        &board_pose.covariance,
    );
    Ok(Calibration {
        base_T_camera,
        base_T_table: base_T_board,
        camera_covariance,
        table_covariance: fit.covariance,
        sighting,
        board_pose,
        base: BaseEvidence::Touch {
            touches,
            fit: Box::new(fit),
        },
    })
}
