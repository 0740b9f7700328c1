//! Production: the pre-flight checks that must pass before the orchestrator drives a real arm,
//! and the cell side channels that read frames from the camera source (`crate::camera`).
//!
//! A production run needs an explicit opt-in, the scenario's motion limits (checked for sanity:
//! every target is tested against them before it is sent), a camera source that opens (a
//! watched folder, a grab command, recorded images or a GenICam camera), and a perception mode
//! that reads images (keypoint-noise needs the simulated scene, so it is refused until the
//! learned pipeline is available).

use std::time::{Duration, Instant};

use super::cell_io::{CellIo, CellIoError, InsertionCheck};
use crate::calibrate::preflight::CameraCheck;
use crate::camera::{self, CameraError, CameraSource, CameraSpec, Sensor};
use crate::scenario::{PerceptionMode, Scenario};
use perception::Frame;

/// What the operator passed to start a production run.
#[derive(Debug, Clone, PartialEq)]
pub struct ProductionOptions {
    /// The explicit opt-in that the arm will move (`--allow-motion` or similar).
    pub allow_motion: bool,
    /// Where the images come from (`--camera`).
    pub camera: CameraSpec,
    /// How long one capture may wait for its image (`--capture-timeout`).
    pub capture_timeout: Duration,
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
    /// The camera source cannot be opened.
    #[error(transparent)]
    Camera(#[from] CameraError),
    /// The capture timeout is zero.
    #[error("the capture timeout must be positive")]
    CaptureTimeout,
    /// The perception mode cannot read camera images.
    #[error("perception mode {0:?} cannot read camera images")]
    Perception(PerceptionMode),
    /// The scenario inserts by feel and the arm reports no wrist force sensor.
    #[error(
        "the scenario's [force_insertion] inserts by feel and needs the wrist's force/torque \
         sensor, and the arm reports none: {0}"
    )]
    NoForceSensor(String),
}

/// The pre-flight check of a connected arm, before anything moves: a scenario with
/// `[force_insertion]` needs a wrist force sensor, and `sensor` is the arm's own answer
/// (`Err` with why it has none, e.g. `robots::ur_robot::UrRobot::force_sensor`).
pub fn force_sensor_preflight(
    scenario: &Scenario,
    sensor: Result<(), String>,
) -> Result<(), ProductionError> {
    match (&scenario.spec.force_insertion, sensor) {
        (Some(_), Err(why)) => Err(ProductionError::NoForceSensor(why)),
        _ => Ok(()),
    }
}

/// Checks everything a production run needs before anything connects or moves; opens the
/// camera source for images of the scenario camera's full sensor.
pub fn preflight(
    scenario: &Scenario,
    options: &ProductionOptions,
) -> Result<Box<dyn CameraSource>, ProductionError> {
    if !options.allow_motion {
        return Err(ProductionError::NotAllowed);
    }
    scenario
        .spec
        .cell
        .limits
        .validate()
        .map_err(|e| ProductionError::Limits(e.to_string()))?;
    if options.capture_timeout.is_zero() {
        return Err(ProductionError::CaptureTimeout);
    }
    let source = open_camera(scenario, &options.camera)?;
    if scenario.spec.perception.mode != PerceptionMode::Learned {
        return Err(ProductionError::Perception(scenario.spec.perception.mode));
    }
    Ok(source)
}

/// Opens the camera source `spec` for images of `scenario`'s camera sensor (what
/// [`preflight`] and `cell check --camera` do).
pub fn open_camera(
    scenario: &Scenario,
    spec: &CameraSpec,
) -> Result<Box<dyn CameraSource>, CameraError> {
    camera::open(spec, Sensor::of(&scenario.spec.cell.camera.intrinsics))
}

/// A production cell's side channels: the camera source, the wall clock; no feeder shaker and
/// no grasp or seating sensor are configured yet, so those report what they can't do.
pub struct ProductionCellIo {
    scenario: Scenario,
    camera: Box<dyn CameraSource>,
    capture_timeout: Duration,
    start: Instant,
    /// The camera check still to run on the first capture.
    camera_check: Option<CameraCheck>,
    /// Why the camera check refused the run: every later capture fails with it.
    refused: Option<String>,
}

impl ProductionCellIo {
    /// Side channels for a checked production run; each capture waits up to `capture_timeout`.
    pub fn new(
        scenario: Scenario,
        camera: Box<dyn CameraSource>,
        capture_timeout: Duration,
    ) -> Self {
        Self {
            scenario,
            camera,
            capture_timeout,
            start: Instant::now(),
            camera_check: None,
            refused: None,
        }
    }

    /// Checks the board in the run's first capture ([`CameraCheck`]): a camera that appears
    /// moved fails that capture and every later one, so the arm never moves on a stale
    /// calibration.
    pub fn with_camera_check(mut self, check: CameraCheck) -> Self {
        self.camera_check = Some(check);
        self
    }
}

impl CellIo for ProductionCellIo {
    /// One new image from the camera source; any camera error fails the capture (the engine
    /// then aborts the step before any motion and records why).
    fn capture(&mut self) -> Result<Frame, CellIoError> {
        if let Some(why) = &self.refused {
            return Err(CellIoError::Camera(why.clone()));
        }
        let shot = self.camera.capture(self.capture_timeout).map_err(|e| {
            tracing::warn!(camera = %self.camera.describe(), "capture failed: {e}");
            CellIoError::Camera(e.to_string())
        })?;
        if let Some(check) = self.camera_check.take() {
            match check.check(&shot.image) {
                Ok(shift) => tracing::info!(
                    "camera check: the board is {:.3} mm from where the calibration put it",
                    shift * 1e3
                ),
                Err(e) => {
                    let why = e.to_string();
                    tracing::error!("{why}");
                    self.refused = Some(why.clone());
                    return Err(CellIoError::Camera(why));
                }
            }
        }
        tracing::info!(
            camera = %self.camera.describe(),
            path = ?shot.path,
            "captured {} × {}",
            shot.image.width(),
            shot.image.height()
        );
        Ok(shot.into_frame(&self.scenario.spec.cell.camera))
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
