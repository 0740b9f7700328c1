//! The simulated cell as the engine's cell: its camera, feeder and verdicts as [`CellIo`], and the
//! whole cell, wrapped in the scenario's limits, as a [`Workcell`] whose arm is the cell's own
//! `impl Robot for SimCell` (the one `Robot` implementation of the simulated cell) behind
//! [`Limited`]. [`SimCellIo`] reads the same side channels from
//! a cell shared with the virtual UR controller, whose arm model drives it over RTDE.

use std::sync::{Arc, Mutex, MutexGuard};

use robots::limited::Limited;
use robots::robot::Robot;
use sim::cell::SimCell;

use super::SimulatedCamera;
use super::audit;
use super::verdict::{blamed, check_of};
use crate::camera::{CameraError, CameraSource, DEFAULT_CAPTURE_TIMEOUT};
use crate::episode::{PoseError, StepOutcome};
use crate::orchestrator::{CellIo, CellIoError, InsertionCheck, PerceptionAudit, Workcell};
use perception::{DetectedPart, Frame, FrameContent, FrameImage, TruePart};

/// How far above its receiver's top a held part that never came down into its target still
/// counts as over it, metres: a part stopped on the rim rests there, lifted by at most the slip
/// up the fingers the engine allows for (half the planner's clearance height).
const OVER_TARGET: f64 = crate::scenario::PLANNER_CLEARANCE_HEIGHT / 2.0;

/// The verdict when the insertion scorer failed: the step is aborted with the engine's reason,
/// never judged as if the part had been released elsewhere.
fn scorer_failed(cell: &SimCell) -> Option<InsertionCheck> {
    cell.scorer_failure().map(|e| InsertionCheck {
        outcome: StepOutcome::Aborted,
        cause: Some(format!("the insertion scorer failed: {e}")),
        sources: vec!["simulation.insertion_scorer".into()],
        pose_error: None,
        stop_height: None,
    })
}

impl CellIo for SimCell {
    fn capture(&mut self) -> Result<Frame, CellIoError> {
        self.wait_for_feeder();
        if self.renders_captures() {
            let shot = self
                .render_feeder()
                .map_err(|e| CellIoError::Camera(e.to_string()))?;
            return Ok(Frame {
                camera: self.model().spec.camera.intrinsics,
                base_T_camera: self.base_T_camera_nominal(),
                content: FrameContent::Image(FrameImage {
                    pixels: image::DynamicImage::ImageRgb8(shot.image),
                    origin: [shot.window.x0, shot.window.y0],
                }),
            });
        }
        let parts = self
            .camera_view()
            .into_iter()
            .map(|p| TruePart {
                instance: p.instance,
                part: p.part,
                camera_T_part: p.camera_T_part,
            })
            .collect();
        Ok(Frame {
            camera: self.model().spec.camera.intrinsics,
            base_T_camera: self.base_T_camera_nominal(),
            content: FrameContent::Simulated(parts),
        })
    }

    fn capture_fixture(&mut self) -> Result<Frame, CellIoError> {
        let shot = self
            .render_fixture()
            .map_err(|e| CellIoError::Camera(e.to_string()))?;
        Ok(Frame {
            camera: self.model().spec.camera.intrinsics,
            base_T_camera: self.base_T_camera_nominal(),
            content: FrameContent::Image(FrameImage {
                pixels: image::DynamicImage::ImageRgb8(shot.image),
                origin: [shot.window.x0, shot.window.y0],
            }),
        })
    }

    fn placed_truth(&self, step: usize) -> Option<nalgebra::Isometry3<f64>> {
        self.placed()
            .iter()
            .rev()
            .find(|p| p.step == step)
            .map(|p| p.base_T_part)
    }

    fn shake_feeder(&mut self) -> Result<(), CellIoError> {
        self.shake().map_err(|e| CellIoError::Feeder(e.to_string()))
    }

    fn shake_feeder_at(&mut self, t: f64) -> Result<(), CellIoError> {
        self.shake_from(t)
            .map_err(|e| CellIoError::Feeder(e.to_string()))
    }

    fn last_motion_trace(&self, step: f64) -> Option<Vec<(f64, robots::kinematics::Joints)>> {
        Some(SimCell::last_motion_trace(self, step))
    }

    fn part_in_gripper(&mut self) -> Option<bool> {
        Some(self.held().is_some())
    }

    fn insertion_check(&mut self) -> Option<InsertionCheck> {
        if let Some(check) = scorer_failed(self) {
            return Some(check);
        }
        self.last_release().map(check_of)
    }

    fn seating_check(&mut self) -> Option<InsertionCheck> {
        self.held()?;
        if let Some(check) = scorer_failed(self) {
            return Some(check);
        }
        Some(match self.held_insertion() {
            Some(r) => check_of(&r),
            // Held but never came down into the target: it stopped on whatever it met first,
            // its lateral error blamed as a missed insertion's when it is over the target.
            None => {
                let over = self.held_budget(OVER_TARGET);
                InsertionCheck {
                    outcome: StepOutcome::Missed,
                    cause: Some("the part did not enter the target".into()),
                    sources: over.as_ref().map(|(_, b)| blamed(b)).unwrap_or_default(),
                    pose_error: over.map(|(e, _)| PoseError {
                        dx_mm: e.lateral.x * 1e3,
                        dy_mm: e.lateral.y * 1e3,
                        depth_mm: e.height * 1e3,
                        tilt_deg: e.tilt.to_degrees(),
                        yaw_deg: e.yaw.to_degrees(),
                    }),
                    stop_height: None,
                }
            }
        })
    }

    fn clock(&self) -> f64 {
        SimCell::clock(self)
    }

    fn wait_until(&mut self, t: f64) {
        SimCell::wait_until(self, t);
    }

    fn feeder_at_rest(&self) -> Option<bool> {
        Some(self.feeder_rest_at() <= SimCell::clock(self))
    }

    fn audit(&self, detection: &DetectedPart) -> Option<PerceptionAudit> {
        Some(audit::audit(self, detection))
    }

    fn missed(&self, part: &str, detections: &[DetectedPart]) -> Option<usize> {
        Some(audit::missed(self, part, detections))
    }
}

impl Workcell for Limited<SimCell> {
    fn robot(&mut self) -> &mut dyn Robot {
        self
    }

    fn io(&mut self) -> &mut dyn CellIo {
        self.inner_mut()
    }
}

/// The side channels of a simulated cell shared with the virtual UR controller (which moves its
/// arm): each call locks the cell and asks its [`CellIo`]; captures may instead come through a
/// production camera source.
pub struct SimCellIo {
    cell: Arc<Mutex<SimCell>>,
    camera: Option<Box<dyn CameraSource>>,
}

impl SimCellIo {
    /// Side channels of a shared simulated cell, its captures handed over in memory.
    pub fn new(cell: Arc<Mutex<SimCell>>) -> Self {
        Self { cell, camera: None }
    }

    /// Side channels of a shared simulated cell whose captures are full-sensor image files read
    /// back through the camera interface, as a production run reads its camera's
    /// ([`SimulatedCamera`]).
    pub fn through_files(cell: Arc<Mutex<SimCell>>) -> Result<Self, CameraError> {
        let camera = SimulatedCamera::new(cell.clone())?;
        Ok(Self {
            cell,
            camera: Some(Box::new(camera)),
        })
    }

    fn lock(&self) -> MutexGuard<'_, SimCell> {
        self.cell
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }
}

impl CellIo for SimCellIo {
    fn capture(&mut self) -> Result<Frame, CellIoError> {
        let Some(camera) = self.camera.as_mut() else {
            return self.lock().capture();
        };
        let shot = camera
            .capture(DEFAULT_CAPTURE_TIMEOUT)
            .map_err(|e| CellIoError::Camera(e.to_string()))?;
        Ok(shot.into_frame(&self.lock().model().spec.camera))
    }

    fn capture_fixture(&mut self) -> Result<Frame, CellIoError> {
        self.lock().capture_fixture()
    }

    fn placed_truth(&self, step: usize) -> Option<nalgebra::Isometry3<f64>> {
        self.lock().placed_truth(step)
    }

    fn shake_feeder(&mut self) -> Result<(), CellIoError> {
        self.lock().shake_feeder()
    }

    /// The simulated cell behind the virtual controller keeps each controller motion as its
    /// arm model stepped it, so a shake is dated mid-motion as in process (a side channel of
    /// the simulation, as the audit is: a real controller's cell reads the reported joints).
    fn shake_feeder_at(&mut self, t: f64) -> Result<(), CellIoError> {
        self.lock().shake_feeder_at(t)
    }

    fn last_motion_trace(&self, step: f64) -> Option<Vec<(f64, robots::kinematics::Joints)>> {
        CellIo::last_motion_trace(&*self.lock(), step)
    }

    fn part_in_gripper(&mut self) -> Option<bool> {
        self.lock().part_in_gripper()
    }

    fn insertion_check(&mut self) -> Option<InsertionCheck> {
        self.lock().insertion_check()
    }

    fn seating_check(&mut self) -> Option<InsertionCheck> {
        self.lock().seating_check()
    }

    fn clock(&self) -> f64 {
        CellIo::clock(&*self.lock())
    }

    fn wait_until(&mut self, t: f64) {
        CellIo::wait_until(&mut *self.lock(), t);
    }

    fn feeder_at_rest(&self) -> Option<bool> {
        self.lock().feeder_at_rest()
    }

    fn audit(&self, detection: &DetectedPart) -> Option<PerceptionAudit> {
        self.lock().audit(detection)
    }

    fn missed(&self, part: &str, detections: &[DetectedPart]) -> Option<usize> {
        self.lock().missed(part, detections)
    }
}
