//! The simulated cell as the virtual UR controller's arm model: the production client drives it
//! over loopback RTDE.
//!
//! [`SimArm`] steps the motion like the kinematic arm (joint and straight-line trajectories with
//! trapezoidal profiles at the control period, the cell's speed and acceleration limits) and, when
//! a motion completes, hands the final joints and the elapsed time to the shared [`SimCell`]:
//! repeatability, insertions and the simulated clock then work exactly as in-process. The gripper
//! follows the controller's tool digital output through [`SimArm::set_tool_output`], and its
//! opening the gripper's analog width output, if it has one ([`SimArm::set_opening_output`]).

use std::cell::Cell;
use std::sync::{Arc, Mutex, MutexGuard, TryLockError};

use robots::kinematics::{Joints, UrKinematics};
use robots::robot::RobotError;
use robots::virtual_ur::arm::{ArmCommand, ArmError, ArmModel, ArmState, KinematicArm};
use robots::virtual_ur::path::PathMove;

use robots::kinematics::from_ur_pose;

use super::SimCell;
use super::sim_cell::ControllerMove;

/// The tool digital output pin that drives the gripper (closed when high), as
/// `robots::ur_robot`'s default gripper configuration.
pub const GRIPPER_TOOL_PIN: u32 = 0;

/// The first tool output's pin number in `actual_digital_output_bits` (and in
/// [`ArmModel::digital_output`]).
pub const TOOL_OUTPUT_BASE: u32 = 16;

/// A [`SimCell`] behind the virtual controller's [`ArmModel`] trait.
pub struct SimArm {
    cell: Arc<Mutex<SimCell>>,
    arm: KinematicArm,
    elapsed: f64,
    was_moving: bool,
    /// The scenario's gripper actuation time (`cell.gripper.actuation_time`), s.
    actuation_time: f64,
    /// The motion in progress is a stop commanded while the tool pressed on something (a
    /// guarded move stopped on force): it ends as the in-process guarded move does.
    guarded_stop: bool,
    /// The contact wrench last read from the cell: the sensor's value while the cell is busy.
    last_wrench: Cell<[f64; 6]>,
    /// The motion in progress as stepped: (seconds since it started, joints) every period,
    /// handed to the cell when it ends (its replay, `SimCell::last_motion_trace`).
    steps: Vec<(f64, Joints)>,
    /// The standard analog output that sets the fingers' opening (`cell.gripper.width_output`).
    width_output: Option<u32>,
    /// Where the fingers open to, metres, as that output last set it (the full stroke before).
    opening_setpoint: Option<f64>,
}

impl SimArm {
    /// Wraps a shared cell; the arm starts at the cell's joints.
    pub fn new(cell: Arc<Mutex<SimCell>>) -> Self {
        // The cell's kinematics carry its gripper TCP, so `actual_TCP_pose` and `movel`
        // targets are the gripper's, as with the TCP set in a real controller's installation.
        let (arm, actuation_time, width_output) = {
            let c = lock(&cell);
            let gripper = &c.model().spec.gripper;
            (
                c.controller_arm(),
                gripper.actuation_time,
                gripper.width_output.map(u32::from),
            )
        };
        Self {
            cell,
            arm,
            elapsed: 0.0,
            was_moving: false,
            actuation_time,
            guarded_stop: false,
            last_wrench: Cell::new([0.0; 6]),
            steps: Vec::new(),
            width_output,
            opening_setpoint: None,
        }
    }

    /// The shared cell (to read outcomes while the controller drives it).
    pub fn cell(&self) -> Arc<Mutex<SimCell>> {
        self.cell.clone()
    }

    /// The controller's tool digital output changed: pin [`GRIPPER_TOOL_PIN`] high closes the
    /// gripper, low opens it (to the width output's set-point, if one was set).
    pub fn set_tool_output(&mut self, pin: u32, level: bool) {
        if pin != GRIPPER_TOOL_PIN {
            return;
        }
        let mut c = lock(&self.cell);
        match (level, self.opening_setpoint) {
            (false, Some(width)) => c.open_gripper_to_sync(width),
            _ => c.set_gripper(level),
        }
    }

    /// The controller's standard analog output `index` changed to `ratio` of its range: on the
    /// gripper's width output it sets where the fingers open to; open empty fingers go there now
    /// (as `Robot::open_gripper_to` sends them in process), closed ones when they next open.
    pub fn set_opening_output(&mut self, index: u32, ratio: f64) {
        if self.width_output != Some(index) {
            return;
        }
        let mut c = lock(&self.cell);
        let width = ratio * c.model().spec.gripper.stroke;
        self.opening_setpoint = Some(width);
        if c.gripper_is_open() {
            c.send_fingers_to(width);
        }
    }
}

/// A refused motion as the controller's arm-model error.
fn arm_error(e: RobotError) -> ArmError {
    match e {
        RobotError::ProtectiveStop => ArmError::ProtectiveStop(e.to_string()),
        _ => ArmError::Unreachable(e.to_string()),
    }
}

fn lock(cell: &Arc<Mutex<SimCell>>) -> MutexGuard<'_, SimCell> {
    cell.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

impl ArmModel for SimArm {
    fn command(&mut self, cmd: ArmCommand) -> Result<(), ArmError> {
        if let Some(e) = lock(&self.cell).status_now().safety.motion_error() {
            return Err(arm_error(e));
        }
        // The same table check as an in-process move: a path into the table protective-stops
        // before the arm moves.
        let planned = match cmd {
            ArmCommand::MoveJ { q, .. } => Some(ControllerMove::Joints(q)),
            ArmCommand::MoveL { pose, .. } => Some(ControllerMove::Linear(from_ur_pose(&pose))),
            _ => None,
        };
        if let Some(m) = planned {
            let mut c = lock(&self.cell);
            c.check_controller_move(m).map_err(arm_error)?;
            // A contact engine's push into the target is simulated before the arm moves, not
            // by the control loop's first sensor reading in contact.
            if let ControllerMove::Linear(target) = m {
                c.prepare_contact(&target);
            }
        }
        let stop = matches!(cmd, ArmCommand::Stop { .. } | ArmCommand::StopL { .. });
        let pressing = stop && self.arm.is_moving() && {
            let c = lock(&self.cell);
            c.pressing_at(&c.model().kinematics.forward_tcp(&self.arm.state().q))
        };
        self.arm.command(cmd)?;
        if pressing {
            // A stop on contact ends the motion in progress: its time keeps counting.
            self.guarded_stop = true;
            self.was_moving = self.arm.is_moving();
            return Ok(());
        }
        self.guarded_stop = false;
        self.elapsed = 0.0;
        self.was_moving = self.arm.is_moving();
        self.steps = vec![(0.0, self.arm.state().q)];
        if !self.was_moving && matches!(cmd, ArmCommand::MoveJ { .. } | ArmCommand::MoveL { .. }) {
            // A move to where the arm already is still ends a motion in the cell (as in
            // process: repeatability is drawn and a held part settles).
            let q = self.arm.state().q;
            lock(&self.cell).set_joints_after_motion(q, 0.0);
        }
        Ok(())
    }

    fn step(&mut self, dt: f64, speed_fraction: f64) -> Result<(), ArmError> {
        let result = self.arm.step(dt, speed_fraction);
        if self.was_moving {
            self.elapsed += dt;
            self.steps.push((self.elapsed, self.arm.state().q));
        }
        let moving = self.arm.is_moving();
        if self.was_moving && !moving {
            let q = self.arm.state().q;
            let steps = std::mem::take(&mut self.steps);
            if std::mem::take(&mut self.guarded_stop) {
                lock(&self.cell).set_joints_after_guarded_stop(q, self.elapsed);
            } else {
                let mut c = lock(&self.cell);
                c.record_controller_motion(steps);
                c.set_joints_after_motion(q, self.elapsed);
            }
            self.elapsed = 0.0;
        }
        self.was_moving = moving;
        result
    }

    fn state(&self) -> ArmState {
        self.arm.state()
    }

    fn is_moving(&self) -> bool {
        self.arm.is_moving()
    }

    fn forward(&self, q: &Joints) -> [f64; 6] {
        self.arm.forward(q)
    }

    fn inverse(&self, pose: &[f64; 6], near: &Joints) -> Result<Joints, ArmError> {
        self.arm.inverse(pose, near)
    }

    fn kinematics(&self) -> &UrKinematics {
        self.arm.kinematics()
    }

    /// A blended path: every segment checked for table clearance as a single move is, then
    /// the kinematic arm's blended execution; the cell gets the final joints and the time when
    /// the arm comes to rest, as for a single move.
    fn command_path(&mut self, path: &[PathMove]) -> Result<(), ArmError> {
        {
            let mut c = lock(&self.cell);
            if let Some(e) = c.status_now().safety.motion_error() {
                return Err(arm_error(e));
            }
            c.check_controller_path(path).map_err(arm_error)?;
        }
        self.arm.command_path(path)?;
        self.guarded_stop = false;
        self.elapsed = 0.0;
        self.was_moving = self.arm.is_moving();
        self.steps = vec![(0.0, self.arm.state().q)];
        if !self.was_moving {
            let q = self.arm.state().q;
            lock(&self.cell).set_joints_after_motion(q, 0.0);
        }
        Ok(())
    }

    fn path_progress(&self) -> Option<usize> {
        self.arm.path_progress()
    }

    fn digital_output(&mut self, pin: u32, level: bool) {
        if let Some(tool) = pin.checked_sub(TOOL_OUTPUT_BASE) {
            self.set_tool_output(tool, level);
        }
    }

    fn analog_output(&mut self, index: u32, ratio: f64) {
        self.set_opening_output(index, ratio);
    }

    /// The cell's contact model at the arm's present pose ([`SimCell::contact_wrench_at`]): a
    /// held part pressed into its target, or the tool on the table. The controller reads the
    /// sensor every cycle and must never wait for the cell: while the cell is busy elsewhere (a
    /// capture rendering, a feeder shake dropping parts) the last reading is held, as a real
    /// sensor's sample is between updates, so the control loop and its RTDE stream keep time.
    fn external_wrench(&self) -> Option<[f64; 6]> {
        let c = match self.cell.try_lock() {
            Ok(c) => c,
            Err(TryLockError::Poisoned(p)) => p.into_inner(),
            Err(TryLockError::WouldBlock) => return Some(self.last_wrench.get()),
        };
        let tcp = c.model().kinematics.forward_tcp(&self.arm.state().q);
        let wrench = c.contact_wrench_at(&tcp);
        self.last_wrench.set(wrench);
        Some(wrench)
    }

    fn actuation_time(&self, pin: u32) -> f64 {
        if pin == TOOL_OUTPUT_BASE + GRIPPER_TOOL_PIN {
            self.actuation_time
        } else {
            0.0
        }
    }
}
