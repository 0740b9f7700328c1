//! The cell's side channels besides the arm: camera, feeder, grasp and insertion checks, clock.
//! [`CellIo`] is implemented by the simulated cell ([`SimCellIo`]); production implements it
//! with its camera source and sensors.

use std::sync::{Arc, Mutex, MutexGuard};

use nalgebra::Isometry3;
use robots::kinematics::Joints;
use robots::limits::Limits;
use robots::robot::{JointMotion, LinearMotion, Robot, RobotFuture, RobotStatus};
use sim::cell::insertion::{InsertionCause, Verdict};
use sim::cell::noise::ErrorSource;
use sim::cell::{ReleaseReport, SimCell};

use super::perception::{Frame, FrameContent, TruePart};
use crate::episode::{PoseError, StepOutcome};

/// Why a cell side channel failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CellIoError {
    /// The camera delivered no frame.
    #[error("camera: {0}")]
    Camera(String),
    /// The feeder could not shake.
    #[error("feeder: {0}")]
    Feeder(String),
}

/// What the cell says about an insertion after release.
#[derive(Debug, Clone, PartialEq)]
pub struct InsertionCheck {
    /// Seated, jammed or missed.
    pub outcome: StepOutcome,
    /// Why it was not seated.
    pub cause: Option<String>,
    /// Error sources blamed, by scenario parameter name.
    pub sources: Vec<String>,
    /// True pose error (simulation only).
    pub pose_error: Option<PoseError>,
    /// How far above fully seated the part stopped, metres: what the cell measures (arm height
    /// at the force threshold), and the slip of the part up the fingers when it was pushed.
    pub stop_height: Option<f64>,
}

/// The camera, feeder and sensors of a cell.
pub trait CellIo: Send {
    /// Takes a camera frame.
    fn capture(&mut self) -> Result<Frame, CellIoError>;
    /// Starts a feeder shake so parts come to rest anew; the feeder runs on its own and the next
    /// [`CellIo::capture`] waits until the parts are at rest.
    fn shake_feeder(&mut self) -> Result<(), CellIoError>;
    /// Whether a part is between the closed fingers; `None` when the cell has no grasp sensor
    /// (the grasp is then assumed to hold and the insertion check decides).
    fn part_in_gripper(&mut self) -> Option<bool>;
    /// The result of the insertion just released, if there was one.
    fn insertion_check(&mut self) -> Option<InsertionCheck>;
    /// Whether the part still in the fingers is seated, checked before the fingers open (by
    /// height and force in production); `None` when the cell cannot tell before release (the
    /// part is then released and [`CellIo::insertion_check`] decides, with no retry).
    fn seating_check(&mut self) -> Option<InsertionCheck> {
        None
    }
    /// Seconds on the cell's clock since the episode started (simulated time in simulation).
    fn clock(&self) -> f64;
    /// True table pose of a simulated instance (simulation only; for error reports).
    #[allow(non_snake_case)]
    fn true_table_T_part(&self, _instance: u32) -> Option<Isometry3<f64>> {
        None
    }
}

fn lock(cell: &Arc<Mutex<SimCell>>) -> MutexGuard<'_, SimCell> {
    cell.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// The simulated cell's camera, feeder and verdicts, on a shared cell.
pub struct SimCellIo {
    cell: Arc<Mutex<SimCell>>,
}

impl SimCellIo {
    /// Side channels of a shared simulated cell.
    pub fn new(cell: Arc<Mutex<SimCell>>) -> Self {
        Self { cell }
    }
}

/// The scenario parameter name of a simulated error source.
pub fn source_name(s: ErrorSource) -> &'static str {
    match s {
        ErrorSource::RobotRepeatability => "robot_repeatability",
        ErrorSource::CameraCalibration => "calibration_translation",
        ErrorSource::GraspResidual => "grasp_offset",
        ErrorSource::PerceptionAndPlanning => "perception",
    }
}

fn cause_text(c: &InsertionCause) -> Option<String> {
    Some(match c {
        InsertionCause::None => return None,
        InsertionCause::LateralBeyondCapture { offset, capture } => format!(
            "lateral offset {:.3} mm beyond the {:.3} mm capture band",
            offset * 1e3,
            capture * 1e3
        ),
        InsertionCause::TiltBeyondJam { tilt, jam_angle } => format!(
            "tilt {:.2}° beyond the {:.2}° jam angle",
            tilt.to_degrees(),
            jam_angle.to_degrees()
        ),
        InsertionCause::YawBeyondClearance { yaw, limit } => format!(
            "yaw {:.2}° beyond the {:.2}° the clearance allows",
            yaw.to_degrees(),
            limit.to_degrees()
        ),
        InsertionCause::StoppedShort { height } => {
            format!("stopped {:.3} mm short of seated", height * 1e3)
        }
        InsertionCause::OutOfTolerance { lateral, tilt } => format!(
            "fully down but out of tolerance: {:.3} mm lateral, {:.2}° tilt",
            lateral * 1e3,
            tilt.to_degrees()
        ),
        InsertionCause::ReleasedAwayFromTarget => "released away from the target".into(),
    })
}

/// What an insertion report says, in the orchestrator's terms.
fn check_of(r: &ReleaseReport) -> InsertionCheck {
    let outcome = match r.verdict {
        Verdict::Seated => StepOutcome::Seated,
        Verdict::Jammed => StepOutcome::Jammed,
        Verdict::Missed => StepOutcome::Missed,
    };
    let mut sources = Vec::new();
    if outcome != StepOutcome::Seated
        && let Some(b) = &r.budget
    {
        let mut shares = b.shares.clone();
        shares.sort_by(|a, b| b.1.total_cmp(&a.1));
        sources = shares
            .iter()
            .filter(|(_, s)| *s >= 0.2)
            .map(|(s, _)| source_name(*s).to_string())
            .collect();
    }
    let pose_error = r.insertion.as_ref().map(|i| PoseError {
        dx_mm: i.start.lateral.x * 1e3,
        dy_mm: i.start.lateral.y * 1e3,
        depth_mm: i.end.height * 1e3,
        tilt_deg: i.start.tilt.to_degrees(),
        yaw_deg: i.start.yaw.to_degrees(),
    });
    InsertionCheck {
        outcome,
        cause: cause_text(&r.cause),
        sources,
        pose_error,
        stop_height: r.insertion.as_ref().map(|i| i.end.height),
    }
}

impl CellIo for SimCellIo {
    fn capture(&mut self) -> Result<Frame, CellIoError> {
        let mut c = lock(&self.cell);
        c.wait_for_feeder();
        let parts = c
            .camera_view()
            .into_iter()
            .map(|p| TruePart {
                instance: p.instance,
                part: p.part,
                camera_T_part: p.camera_T_part,
            })
            .collect();
        Ok(Frame {
            camera: c.model().spec.camera.intrinsics,
            base_T_camera: c.base_T_camera_nominal(),
            content: FrameContent::Simulated(parts),
        })
    }

    fn shake_feeder(&mut self) -> Result<(), CellIoError> {
        lock(&self.cell)
            .shake()
            .map_err(|e| CellIoError::Feeder(e.to_string()))
    }

    fn part_in_gripper(&mut self) -> Option<bool> {
        Some(lock(&self.cell).held().is_some())
    }

    fn insertion_check(&mut self) -> Option<InsertionCheck> {
        lock(&self.cell).last_release().map(check_of)
    }

    fn seating_check(&mut self) -> Option<InsertionCheck> {
        let c = lock(&self.cell);
        c.held()?;
        Some(match c.held_insertion() {
            Some(r) => check_of(&r),
            // Held but never came down into the target: it stopped on whatever it met first.
            None => InsertionCheck {
                outcome: StepOutcome::Missed,
                cause: Some("the part did not enter the target".into()),
                sources: vec![],
                pose_error: None,
                stop_height: None,
            },
        })
    }

    fn clock(&self) -> f64 {
        lock(&self.cell).clock()
    }

    #[allow(non_snake_case)]
    fn true_table_T_part(&self, instance: u32) -> Option<Isometry3<f64>> {
        lock(&self.cell)
            .feeder_parts()
            .iter()
            .find(|p| p.instance == instance)
            .map(|p| p.table_T_part)
    }
}

/// The simulated cell's arm, on a shared cell (so [`SimCellIo`] can read the same world).
pub struct SharedSimRobot {
    cell: Arc<Mutex<SimCell>>,
    limits: Limits,
}

impl SharedSimRobot {
    /// The arm of a shared simulated cell.
    pub fn new(cell: Arc<Mutex<SimCell>>) -> Self {
        let limits = lock(&cell).model().spec.limits.clone();
        Self { cell, limits }
    }
}

impl Robot for SharedSimRobot {
    fn limits(&self) -> &Limits {
        &self.limits
    }

    fn joints(&mut self) -> RobotFuture<'_, Joints> {
        let q = lock(&self.cell).joints_now();
        Box::pin(async move { Ok(q) })
    }

    #[allow(non_snake_case)]
    fn tcp_pose(&mut self) -> RobotFuture<'_, Isometry3<f64>> {
        let p = lock(&self.cell).tcp_pose_now();
        Box::pin(async move { Ok(p) })
    }

    fn move_j(&mut self, target: Joints, motion: JointMotion) -> RobotFuture<'_, ()> {
        let r = lock(&self.cell).move_j_sync(target, motion);
        Box::pin(async move { r })
    }

    #[allow(non_snake_case)]
    fn move_l(&mut self, base_T_tcp: Isometry3<f64>, motion: LinearMotion) -> RobotFuture<'_, ()> {
        let r = lock(&self.cell).move_l_sync(base_T_tcp, motion);
        Box::pin(async move { r })
    }

    fn open_gripper(&mut self) -> RobotFuture<'_, ()> {
        lock(&self.cell).open_gripper_sync();
        Box::pin(async move { Ok(()) })
    }

    fn close_gripper(&mut self) -> RobotFuture<'_, ()> {
        lock(&self.cell).close_gripper_sync();
        Box::pin(async move { Ok(()) })
    }

    fn stop(&mut self) -> RobotFuture<'_, ()> {
        Box::pin(async move { Ok(()) })
    }

    fn status(&mut self) -> RobotFuture<'_, RobotStatus> {
        let s = lock(&self.cell).status_now();
        Box::pin(async move { Ok(s) })
    }
}
