//! SDU ur_rtde 1.6.x's control script (`rtde_control`), executed natively: the register
//! handshake on registers 0–23, each command with the effect the script's URScript statement
//! has on a UR controller. A command the model cannot do exactly is a runtime error: the
//! program stops (and the arm with it), so ur_rtde's call returns False or raises, never True
//! without the effect.

use super::arm::{ArmCommand, ArmError};
use super::dynamics::{ArmDynamics, jacobian, jacobian_time_derivative};
use super::force::{ForceMode, ForceTuning, MAX_GAIN_SCALING};
use super::path::{PathMove, PathStatement, PathTarget, injected_path, settle_blends};
use super::programs::{Program, ProgramIo, ProgramStep};
use super::registers::Registers;
use crate::kinematics::UrDh;
use crate::kinematics::{Joints, from_ur_pose, to_ur_pose};
use crate::program::layout as L;
use nalgebra::{Matrix6, UnitQuaternion, Vector3};

/// ur_rtde 1.6.x command ids (`RTDE::RobotCommand::Type`).
pub mod ur_rtde_cmd {
    /// moveJ.
    pub const MOVE_J: i32 = 1;
    /// moveJ_IK.
    pub const MOVE_J_IK: i32 = 2;
    /// moveL.
    pub const MOVE_L: i32 = 3;
    /// moveL_FK.
    pub const MOVE_L_FK: i32 = 4;
    /// forceMode (realtime).
    pub const FORCE_MODE: i32 = 6;
    /// forceModeStop.
    pub const FORCE_MODE_STOP: i32 = 7;
    /// teachMode.
    pub const TEACH_MODE: i32 = 18;
    /// endTeachMode.
    pub const END_TEACH_MODE: i32 = 19;
    /// forceModeSetDamping.
    pub const FORCE_MODE_SET_DAMPING: i32 = 20;
    /// forceModeSetGainScaling.
    pub const FORCE_MODE_SET_GAIN_SCALING: i32 = 21;
    /// zeroFtSensor.
    pub const ZERO_FT_SENSOR: i32 = 8;
    /// speedJ (realtime).
    pub const SPEED_J: i32 = 9;
    /// speedL (realtime).
    pub const SPEED_L: i32 = 10;
    /// servoJ (realtime).
    pub const SERVO_J: i32 = 11;
    /// servoC.
    pub const SERVO_C: i32 = 12;
    /// Legacy setStandardDigitalOut (not sent by 1.6.x's control interface).
    pub const SET_STD_DIGITAL_OUT: i32 = 13;
    /// Legacy setToolDigitalOut (not sent by 1.6.x's control interface).
    pub const SET_TOOL_DIGITAL_OUT: i32 = 14;
    /// speedStop.
    pub const SPEED_STOP: i32 = 15;
    /// servoStop.
    pub const SERVO_STOP: i32 = 16;
    /// setPayload.
    pub const SET_PAYLOAD: i32 = 17;
    /// servoL (realtime).
    pub const SERVO_L: i32 = 24;
    /// toolContact (realtime).
    pub const TOOL_CONTACT: i32 = 25;
    /// getStepTime (realtime).
    pub const GET_STEPTIME: i32 = 26;
    /// getActualJointPositionsHistory (realtime).
    pub const GET_JOINT_POSITIONS_HISTORY: i32 = 27;
    /// getTargetWaypoint.
    pub const GET_TARGET_WAYPOINT: i32 = 28;
    /// setTcp.
    pub const SET_TCP: i32 = 29;
    /// getInverseKinematics with qnear and tolerances.
    pub const GET_IK_ARGS: i32 = 30;
    /// triggerProtectiveStop.
    pub const PROTECTIVE_STOP: i32 = 31;
    /// stopL.
    pub const STOP_L: i32 = 33;
    /// stopJ.
    pub const STOP_J: i32 = 34;
    /// setWatchdog.
    pub const SET_WATCHDOG: i32 = 35;
    /// isPoseWithinSafetyLimits.
    pub const IS_POSE_WITHIN_SAFETY_LIMITS: i32 = 36;
    /// isJointsWithinSafetyLimits.
    pub const IS_JOINTS_WITHIN_SAFETY_LIMITS: i32 = 37;
    /// getJointTorques (realtime).
    pub const GET_JOINT_TORQUES: i32 = 38;
    /// poseTrans.
    pub const POSE_TRANS: i32 = 39;
    /// getTCPOffset.
    pub const GET_TCP_OFFSET: i32 = 40;
    /// jogStart.
    pub const START_JOG: i32 = 41;
    /// jogStop.
    pub const STOP_JOG: i32 = 42;
    /// getForwardKinematics() at the actual joints with the active TCP.
    pub const GET_FK_DEFAULT: i32 = 43;
    /// getForwardKinematics(q, tcp_offset).
    pub const GET_FK_ARGS: i32 = 44;
    /// moveJ(path) / moveL(path) / movePath: the path injected into the script.
    pub const MOVE_PATH: i32 = 45;
    /// getInverseKinematics(x) near the actual joints.
    pub const GET_IK_DEFAULT: i32 = 46;
    /// isSteady.
    pub const IS_STEADY: i32 = 47;
    /// moveUntilContact.
    pub const MOVE_UNTIL_CONTACT: i32 = 51;
    /// freedriveMode.
    pub const FREEDRIVE_MODE: i32 = 52;
    /// endFreedriveMode.
    pub const END_FREEDRIVE_MODE: i32 = 53;
    /// startContactDetection.
    pub const START_CONTACT_DETECTION: i32 = 62;
    /// stopContactDetection.
    pub const STOP_CONTACT_DETECTION: i32 = 63;
    /// readContactDetection.
    pub const READ_CONTACT_DETECTION: i32 = 64;
    /// getFreedriveStatus.
    pub const GET_FREEDRIVE_STATUS: i32 = 54;
    /// getActualToolFlangePose.
    pub const GET_ACTUAL_TOOL_FLANGE_POSE: i32 = 58;
    /// getInverseKinematicsHasSolution(x).
    pub const GET_IK_HAS_SOLUTION_DEFAULT: i32 = 60;
    /// getInverseKinematicsHasSolution(x, qnear, ...).
    pub const GET_IK_HAS_SOLUTION_ARGS: i32 = 61;
    /// setGravity.
    pub const SET_GRAVITY: i32 = 59;
    /// setTargetPayload.
    pub const SET_TARGET_PAYLOAD: i32 = 65;
    /// directTorque (realtime; PolyScope 5.26).
    pub const DIRECT_TORQUE: i32 = 66;
    /// getMassMatrix (realtime; PolyScope 5.23).
    pub const GET_MASS_MATRIX: i32 = 67;
    /// getCoriolisAndCentrifugalTorques (realtime; PolyScope 5.23).
    pub const GET_CORIOLIS_AND_CENTRIFUGAL_TORQUES: i32 = 68;
    /// getTargetJointAccelerations (realtime; PolyScope 5.23).
    pub const GET_TARGET_JOINT_ACCELERATIONS: i32 = 69;
    /// getJacobian (realtime; PolyScope 5.23).
    pub const GET_JACOBIAN: i32 = 70;
    /// getJacobianTimeDerivative (realtime; PolyScope 5.23).
    pub const GET_JACOBIAN_TIME_DERIVATIVE: i32 = 71;
    /// Watchdog kick (ur_rtde sends it as a plain input update).
    pub const WATCHDOG: i32 = 99;
    /// stopScript.
    pub const STOP_SCRIPT: i32 = 255;
}

use ur_rtde_cmd::*;

/// The script's realtime commands: processed every cycle while in the command register and
/// answered with "ready"; ur_rtde does not clear the register after them.
pub const REALTIME: [i32; 16] = [24, 11, 9, 10, 6, 25, 26, 27, 38, 58, 66, 67, 68, 69, 70, 71];

/// Largest payload a UR5e accepts (kg).
pub const MAX_PAYLOAD_KG: f64 = 5.0;

/// A path in execution: progress reported so far and the via-points' TCP poses.
#[derive(Debug, Clone)]
struct PathRun {
    asynchronous: bool,
    reported: usize,
    poses: Vec<[f64; 6]>,
}

/// `moveUntilContact`'s phases, as the script's loop runs them.
#[derive(Debug, Clone, Copy, PartialEq)]
enum UntilContact {
    /// `speedl(xd, acc)` every cycle until `tool_contact(direction)` reports a contact.
    Seeking {
        xd: [f64; 6],
        direction: [f64; 3],
        accel: f64,
    },
    /// `stopl(3)`, then `movel` back to the joints of the cycle before the contact began.
    Stopping { q: Joints },
    /// The `movel` back to where the contact began.
    Returning,
}

/// Speed (m/s) and acceleration (m/s²) of the script's `movel(q)` back to the contact point:
/// URScript's defaults.
const CONTACT_RETURN: (f64, f64) = (0.25, 1.2);

/// Deceleration of the script's `stopl` when moveUntilContact meets contact (m/s²).
const CONTACT_STOP_DECEL: f64 = 3.0;

/// Deceleration of `force_mode_stop`'s `stopl(10)` (m/s²).
const FORCE_STOP_DECEL: f64 = 10.0;

/// ur_rtde's control script's force-mode tuning at start: `force_mode_set_gain_scaling(0.5)`,
/// `force_mode_set_damping(0.025)`.
const SCRIPT_TUNING: ForceTuning = ForceTuning {
    damping: 0.025,
    gain_scaling: 0.5,
};

/// Tool acceleration (m/s²) of force mode's speed commands: the kinematic arm takes each cycle's
/// twist at once.
const FORCE_MODE_ACCEL: f64 = 15.0;

/// What a command leaves the handshake in.
enum Outcome {
    /// Done at once: signal "done".
    Done,
    /// A blocking motion: signal "done" when the arm is at rest.
    Wait,
    /// stopScript: the program ends.
    Exit,
    /// moveUntilContact: "done" when its loop ends ([`UrRtdeProgram::contact_step`]).
    Contact,
}

/// Commands that move the arm (refused while it is hand-guided or in force mode).
const MOTIONS: [i32; 12] = [
    MOVE_J,
    MOVE_J_IK,
    MOVE_L,
    MOVE_L_FK,
    MOVE_PATH,
    SPEED_J,
    SPEED_L,
    SERVO_J,
    SERVO_L,
    START_JOG,
    MOVE_UNTIL_CONTACT,
    FORCE_MODE,
];

/// The `rtde_control` program.
#[derive(Debug)]
pub struct UrRtdeProgram {
    executing: bool,
    waiting_for_motion: bool,
    async_running: bool,
    async_writes: i32,
    async_op: i32,
    /// The last speed command was speedJ (speedStop then stops in joint space).
    speed_joint: bool,
    /// The jog frame's rotation, fixed when jogging starts.
    jog_frame: Option<UnitQuaternion<f64>>,
    /// The target TCP pose of the running movej/movel (`get_target_waypoint`).
    waypoint: Option<[f64; 6]>,
    /// The path ur_rtde injected into the script (`exec_move_path()`).
    path: Vec<PathStatement>,
    /// Why the injected path cannot run (a statement this controller does not execute).
    path_error: Option<String>,
    /// The path being executed.
    path_run: Option<PathRun>,
    /// The command id the register held when the program started: left by a client whose
    /// program ended, it is not run again until the client writes the register.
    stale: Option<i32>,
    /// The running force mode.
    force_mode: Option<ForceMode>,
    /// Force mode's damping and gain scaling.
    tuning: ForceTuning,
    /// The tool twist force mode commanded last cycle (base frame).
    force_twist: [f64; 6],
    /// Teach mode (`teach_mode`) or freedrive (`freedrive_mode`) is on: the arm is free to be
    /// moved by hand, and no hand moves it here.
    free: Option<FreeMode>,
    /// A running moveUntilContact, or the retreat to a detected contact; whether its end
    /// signals "done" (moveUntilContact waits for it, contact detection does not).
    until_contact: Option<(UntilContact, bool)>,
    /// Contact detection started by `start_contact_detection`.
    detection: Option<Detection>,
}

/// `start_contact_detection(direction)`'s thread: it waits for the tool to be free, then for a
/// contact; on one the main thread stops the arm and moves it back to where the contact began.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Detection {
    /// Direction of the contacts to detect (base frame); zero: the TCP's direction of motion.
    direction: [f64; 3],
    /// The tool has been free since detection started.
    armed: bool,
    /// The cycles back to the contact (`contact_step_back`): 0 until one is detected.
    step_back: i32,
}

/// Which hand-guiding mode is on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum FreeMode {
    /// `teach_mode()`.
    Teach,
    /// `freedrive_mode(free_axes, feature)`.
    Freedrive,
}

impl Default for UrRtdeProgram {
    fn default() -> Self {
        UrRtdeProgram {
            executing: false,
            waiting_for_motion: false,
            async_running: false,
            async_writes: 0,
            async_op: 0,
            speed_joint: false,
            jog_frame: None,
            waypoint: None,
            path: Vec::new(),
            path_error: None,
            path_run: None,
            stale: None,
            force_mode: None,
            tuning: SCRIPT_TUNING,
            force_twist: [0.0; 6],
            free: None,
            until_contact: None,
            detection: None,
        }
    }
}

const READY: i32 = 1;
const DONE: i32 = 2;

fn vector(regs: &Registers, first: usize) -> [f64; 6] {
    std::array::from_fn(|i| regs.input_double[first + i])
}

fn write_vector(regs: &mut Registers, first: usize, v: &[f64; 6]) {
    regs.output_double[first..first + 6].copy_from_slice(v);
}

/// A 6×6 matrix as the script writes `get_mass_matrix()` and `get_jacobian()`: column-major,
/// columns 0–3 in output_double_registers 0–23, columns 4–5 in 36–47.
fn write_matrix(regs: &mut Registers, m: &Matrix6<f64>) {
    for col in 0..6 {
        let first = if col < 4 { col * 6 } else { 36 + (col - 4) * 6 };
        for row in 0..6 {
            regs.output_double[first + row] = m[(row, col)];
        }
    }
}

/// A runtime error for a command the model cannot do exactly.
fn unsupported(cmd: i32) -> String {
    let what = match cmd {
        SERVO_C => "servoc",
        MOVE_PATH => "movePath (custom script code)",
        56 | 57 => "external force/torque sensor",
        DIRECT_TORQUE => {
            "direct_torque (a PolyScope 5.26 function: the kinematic arm takes no torque commands)"
        }
        _ => "this command",
    };
    format!("virtual-ur: ur_rtde command {cmd} is not simulated: {what}")
}

impl UrRtdeProgram {
    /// A fresh program.
    pub fn new() -> UrRtdeProgram {
        UrRtdeProgram::default()
    }

    /// The program as uploaded: `script` is the control script's text, with the path
    /// `moveJ(path)`/`moveL(path)`/`movePath` injected into it.
    pub fn from_script(script: &str) -> UrRtdeProgram {
        let (path, path_error) = match injected_path(script) {
            Ok(path) => (path, None),
            Err(e) => (Vec::new(), Some(e)),
        };
        UrRtdeProgram {
            path,
            path_error,
            ..UrRtdeProgram::default()
        }
    }

    /// The injected path's moves with their targets resolved (`movej(p[…])` through inverse
    /// kinematics near the previous via-point, `movel([q])` through forward kinematics), and
    /// each via-point's TCP pose.
    fn resolve_path(
        io: &ProgramIo<'_>,
        statements: &[PathStatement],
    ) -> Result<(Vec<PathMove>, Vec<[f64; 6]>), String> {
        let mut near = io.arm.state().q;
        let mut moves = Vec::with_capacity(statements.len());
        let mut poses = Vec::with_capacity(statements.len());
        for s in statements {
            let (speed, accel, blend) = (s.speed, s.accel, s.blend);
            let (pose, q) = match s.target {
                PathTarget::Pose(pose) => (pose, Self::inverse(io, &pose, &near)?),
                PathTarget::Joints(q) => (io.arm.forward(&q), q),
            };
            let m = if s.linear {
                PathMove::Linear {
                    pose,
                    speed,
                    accel,
                    blend,
                }
            } else {
                PathMove::Joint {
                    q,
                    speed,
                    accel,
                    blend,
                }
            };
            moves.push(m);
            poses.push(pose);
            near = q;
        }
        Ok((moves, poses))
    }

    /// `exec_move_path()`, synchronously or in the move thread: `signal_async_progress(i)`
    /// before each via-point's statement, the moves blended as URScript blends them.
    fn move_path(&mut self, io: &mut ProgramIo<'_>) -> Result<Outcome, String> {
        let asynchronous = io.regs.input_int[1] == 1;
        if self.async_running {
            // stop_async_move(): a running move thread is killed and reported finished.
            self.write_async(io.regs, false);
        }
        if let Some(e) = &self.path_error {
            return Err(format!("move_path: {e}"));
        }
        let statements = self.path.clone();
        if statements.is_empty() {
            return Err("move_path: no path was injected into the control script".into());
        }
        let (moves, poses) = Self::resolve_path(io, &statements)?;
        let start = io.arm.state().tcp_pose;
        let points: Vec<[f64; 3]> = std::iter::once(start)
            .chain(poses.iter().copied())
            .map(|p| [p[0], p[1], p[2]])
            .collect();
        let (moves, warnings) = settle_blends(&moves, &points);
        io.warnings.extend(warnings);
        match io.arm.command_path(&moves) {
            Ok(()) => {}
            Err(ArmError::ProtectiveStop(why)) => {
                tracing::warn!(why, "rtde_control: protective stop");
                io.protective_stop = true;
                return Ok(Outcome::Done);
            }
            Err(e) => return Err(format!("move_path: {e}")),
        }
        self.waypoint = poses.first().copied();
        if asynchronous {
            self.write_async(io.regs, true);
        }
        self.write_async_progress(io.regs, 0);
        // A synchronous path writes its progress too but no thread ends it: the register keeps
        // the last via-point's progress, as the script leaves it.
        self.async_running &= asynchronous;
        self.path_run = Some(PathRun {
            asynchronous,
            reported: 0,
            poses,
        });
        Ok(if asynchronous {
            Outcome::Done
        } else {
            Outcome::Wait
        })
    }

    /// Reports the path's progress as the arm starts its segments; forgets the path when the
    /// arm is no longer on it.
    fn follow_path(&mut self, io: &mut ProgramIo<'_>) {
        let Some(run) = self.path_run.clone() else {
            return;
        };
        match io.arm.path_progress() {
            Some(i) if i > run.reported => {
                for k in run.reported + 1..=i {
                    self.write_async_progress(io.regs, k.min(32767) as i32);
                    self.async_running &= run.asynchronous;
                }
                self.waypoint = run.poses.get(i).copied();
                self.path_run = Some(PathRun { reported: i, ..run });
            }
            Some(_) => {}
            None => self.path_run = None,
        }
    }

    /// Mirrors `write_async_progress_register(value)` of the script (output_int_register_2):
    /// 0 starts an operation (new id), a positive value is its progress, −1 ends it.
    fn write_async_progress(&mut self, regs: &mut Registers, value: i32) {
        self.async_writes = (self.async_writes + 1) % 128;
        if value == 0 {
            self.async_op = (self.async_op + 1) % 128;
        }
        let mut v = self.async_writes * 65536 + self.async_op * 16_777_216;
        if value >= 0 {
            v += value.min(32767) + 32768;
        }
        regs.output_int[2] = v;
        self.async_running = value >= 0;
    }

    /// `signal_async_operation_started()` (`started`) or `signal_async_operation_finished()`.
    fn write_async(&mut self, regs: &mut Registers, started: bool) {
        self.write_async_progress(regs, if started { 0 } else { -1 });
    }

    /// Sends a motion to the arm: a protective stop from the model stops the arm, any other
    /// refusal is a runtime error.
    fn command(io: &mut ProgramIo<'_>, cmd: ArmCommand) -> Result<(), String> {
        match io.arm.command(cmd) {
            Ok(()) => Ok(()),
            Err(ArmError::ProtectiveStop(why)) => {
                tracing::warn!(why, "rtde_control: protective stop");
                io.protective_stop = true;
                Ok(())
            }
            Err(e) => Err(e.to_string()),
        }
    }

    /// Starts a move; synchronous moves wait for rest, asynchronous ones report progress.
    fn start_move(&mut self, io: &mut ProgramIo<'_>, cmd: ArmCommand) -> Result<Outcome, String> {
        let asynchronous = io.regs.input_int[1] == 1;
        Self::command(io, cmd)?;
        self.waypoint = match cmd {
            ArmCommand::MoveJ { q, .. } => Some(io.arm.forward(&q)),
            ArmCommand::MoveL { pose, .. } => Some(pose),
            _ => None,
        };
        if io.protective_stop {
            return Ok(Outcome::Done);
        }
        if asynchronous {
            self.write_async(io.regs, true);
            Ok(Outcome::Done)
        } else {
            Ok(Outcome::Wait)
        }
    }

    /// The arm's rigid-body model, or the runtime error of a dynamics function on an arm the
    /// controller has no model of.
    fn dynamics(io: &ProgramIo<'_>, cmd: i32) -> Result<(ArmDynamics, UrDh), String> {
        let dh = io.arm.kinematics().dh;
        io.arm.dynamics().map(|d| (d, dh)).ok_or_else(|| {
            format!(
                "virtual-ur: ur_rtde command {cmd}: no dynamics model for this arm's DH lengths"
            )
        })
    }

    fn inverse(io: &ProgramIo<'_>, pose: &[f64; 6], near: &Joints) -> Result<Joints, String> {
        io.arm
            .inverse(pose, near)
            .map_err(|e| format!("get_inverse_kin: {e}"))
    }

    fn flag(regs: &mut Registers, value: bool) {
        regs.output_int[1] = i32::from(value);
    }

    /// Runs one regular command.
    fn process(&mut self, io: &mut ProgramIo<'_>, cmd: i32) -> Result<Outcome, String> {
        self.check_motion_allowed(cmd)?;
        let regs = &*io.regs;
        let target = vector(regs, 0);
        let second = vector(regs, 6);
        let (speed, accel) = (regs.input_double[6], regs.input_double[7]);
        let q_now = io.arm.state().q;
        match cmd {
            MOVE_J => self.start_move(
                io,
                ArmCommand::MoveJ {
                    q: target,
                    speed,
                    accel,
                },
            ),
            MOVE_J_IK => {
                let q = Self::inverse(io, &target, &q_now)?;
                self.start_move(io, ArmCommand::MoveJ { q, speed, accel })
            }
            MOVE_L => self.start_move(
                io,
                ArmCommand::MoveL {
                    pose: target,
                    speed,
                    accel,
                },
            ),
            MOVE_L_FK => {
                let pose = io.arm.forward(&target);
                self.start_move(io, ArmCommand::MoveL { pose, speed, accel })
            }
            ZERO_FT_SENSOR => {
                io.sensor.zero();
                Ok(Outcome::Done)
            }
            FORCE_MODE_STOP => {
                // end_force_mode(), then stopl(10).
                self.force_mode = None;
                self.force_twist = [0.0; 6];
                Self::command(
                    io,
                    ArmCommand::StopL {
                        decel: FORCE_STOP_DECEL,
                    },
                )?;
                Ok(Outcome::Wait)
            }
            FORCE_MODE_SET_DAMPING | FORCE_MODE_SET_GAIN_SCALING => {
                let value = regs.input_double[0];
                let (name, max) = if cmd == FORCE_MODE_SET_DAMPING {
                    ("force_mode_set_damping", 1.0)
                } else {
                    ("force_mode_set_gain_scaling", MAX_GAIN_SCALING)
                };
                if !(0.0..=max).contains(&value) {
                    return Err(format!("{name}({value}): outside 0..{max}"));
                }
                if cmd == FORCE_MODE_SET_DAMPING {
                    self.tuning.damping = value;
                } else {
                    self.tuning.gain_scaling = value;
                }
                Ok(Outcome::Done)
            }
            TEACH_MODE | FREEDRIVE_MODE => {
                let mode = if cmd == TEACH_MODE {
                    FreeMode::Teach
                } else {
                    // free_axes from registers 1-6 (0 or 1), the feature from 0-5.
                    let axes: Vec<i32> = (1..7).map(|i| regs.input_int[i]).collect();
                    if axes.iter().any(|a| !matches!(a, 0 | 1)) {
                        return Err(format!("freedrive_mode: free axes {axes:?} are not 0 or 1"));
                    }
                    if !target.iter().all(|v| v.is_finite()) {
                        return Err("freedrive_mode: feature not finite".into());
                    }
                    FreeMode::Freedrive
                };
                if self.force_mode.is_some() {
                    return Err(
                        "teach/freedrive mode during force mode: call forceModeStop first".into(),
                    );
                }
                if io.arm.is_moving() {
                    return Err("teach/freedrive mode while the arm moves: stop it first".into());
                }
                // Nobody pushes the arm here, and the payload it carries is the one set: it
                // stays where it is until the mode ends.
                self.free = Some(mode);
                self.waypoint = None;
                Ok(Outcome::Done)
            }
            END_TEACH_MODE | END_FREEDRIVE_MODE => {
                let mode = if cmd == END_TEACH_MODE {
                    FreeMode::Teach
                } else {
                    FreeMode::Freedrive
                };
                if self.free == Some(mode) {
                    self.free = None;
                }
                Ok(Outcome::Done)
            }
            START_CONTACT_DETECTION => {
                let direction = [target[0], target[1], target[2]];
                if !direction.iter().all(|v| v.is_finite()) {
                    return Err("start_contact_detection: direction not finite".into());
                }
                self.detection = Some(Detection {
                    direction,
                    armed: false,
                    step_back: 0,
                });
                Ok(Outcome::Done)
            }
            STOP_CONTACT_DETECTION | READ_CONTACT_DETECTION => {
                let step_back = self.detection.map_or(0, |d| d.step_back);
                if cmd == STOP_CONTACT_DETECTION {
                    self.detection = None;
                }
                io.regs.output_int[1] = step_back;
                Ok(Outcome::Done)
            }
            MOVE_UNTIL_CONTACT => {
                let xd = target;
                let direction = [second[0], second[1], second[2]];
                let accel = regs.input_double[12];
                if !(xd.iter().chain(&direction).all(|v| v.is_finite())
                    && accel.is_finite()
                    && accel > 0.0)
                {
                    return Err(format!(
                        "move_until_contact: speed {xd:?}, direction {direction:?} or acceleration {accel} not usable"
                    ));
                }
                if xd.iter().all(|v| *v == 0.0) {
                    return Err("move_until_contact: zero tool speed never meets a contact".into());
                }
                self.waypoint = None;
                self.until_contact = Some((
                    UntilContact::Seeking {
                        xd,
                        direction,
                        accel,
                    },
                    true,
                ));
                Ok(Outcome::Contact)
            }
            SET_STD_DIGITAL_OUT | SET_TOOL_DIGITAL_OUT => {
                let offset = if cmd == SET_TOOL_DIGITAL_OUT { 16 } else { 0 };
                let pin = i64::from(regs.input_int[1]) + offset;
                let level = regs.input_int[2] != 0;
                if io.set_digital_output(pin, level) {
                    Ok(Outcome::Done)
                } else {
                    Err(format!("set digital out: no output {pin}"))
                }
            }
            SPEED_STOP | SERVO_STOP | STOP_L | STOP_J => {
                let decel = regs.input_double[0];
                let decel = if decel.is_finite() && decel > 0.0 {
                    decel
                } else {
                    L::STOP_DECELERATION
                };
                self.waypoint = None;
                let joint = cmd == STOP_J || (cmd == SPEED_STOP && self.speed_joint);
                let asynchronous = (cmd == STOP_L || cmd == STOP_J) && regs.input_int[1] == 1;
                let stop = if joint {
                    ArmCommand::Stop { decel }
                } else {
                    ArmCommand::StopL { decel }
                };
                Self::command(io, stop)?;
                if self.async_running {
                    self.write_async(io.regs, false);
                }
                if asynchronous {
                    self.write_async(io.regs, true);
                    Ok(Outcome::Done)
                } else {
                    Ok(Outcome::Wait)
                }
            }
            SET_PAYLOAD | SET_TARGET_PAYLOAD => {
                let mass = regs.input_double[0];
                let cog = [
                    regs.input_double[1],
                    regs.input_double[2],
                    regs.input_double[3],
                ];
                let valid =
                    (0.0..=MAX_PAYLOAD_KG).contains(&mass) && cog.iter().all(|c| c.is_finite());
                if !valid {
                    return Err(format!(
                        "set_payload: mass {mass} kg outside 0..{MAX_PAYLOAD_KG} kg or cog not finite"
                    ));
                }
                io.payload.mass = mass;
                if cog != [0.0; 3] {
                    io.payload.cog = cog;
                }
                if cmd == SET_TARGET_PAYLOAD {
                    io.payload.inertia = std::array::from_fn(|i| regs.input_double[4 + i]);
                }
                Ok(Outcome::Done)
            }
            // set_gravity(d): the direction and size of the acceleration that holds the arm up
            // (away from the earth); the payload's weight on the sensor and the joints' holding
            // torques and currents follow it.
            SET_GRAVITY => {
                let up = [target[0], target[1], target[2]];
                if !up.iter().all(|v| v.is_finite()) {
                    return Err(format!("set_gravity: {up:?} is not a finite vector"));
                }
                *io.gravity = up;
                Ok(Outcome::Done)
            }
            SET_TCP => {
                io.arm
                    .set_tcp(from_ur_pose(&target))
                    .map_err(|e| format!("set_tcp: {e}"))?;
                Ok(Outcome::Done)
            }
            GET_IK_ARGS | GET_IK_DEFAULT => {
                let near = if cmd == GET_IK_ARGS { second } else { q_now };
                let q = Self::inverse(io, &target, &near)?;
                write_vector(io.regs, 0, &q);
                Ok(Outcome::Done)
            }
            GET_IK_HAS_SOLUTION_DEFAULT | GET_IK_HAS_SOLUTION_ARGS => {
                let near = if cmd == GET_IK_HAS_SOLUTION_ARGS {
                    second
                } else {
                    q_now
                };
                let ok = io.arm.inverse(&target, &near).is_ok();
                Self::flag(io.regs, ok);
                Ok(Outcome::Done)
            }
            PROTECTIVE_STOP => {
                io.protective_stop = true;
                Ok(Outcome::Done)
            }
            SET_WATCHDOG => {
                let frequency = regs.input_double[0];
                if !(frequency.is_finite() && frequency > 0.0) {
                    return Err(format!("rtde_set_watchdog: frequency {frequency} Hz"));
                }
                io.watchdog = Some(frequency);
                Ok(Outcome::Done)
            }
            IS_POSE_WITHIN_SAFETY_LIMITS => {
                let ok = io.arm.inverse(&target, &q_now).is_ok();
                Self::flag(io.regs, ok);
                Ok(Outcome::Done)
            }
            IS_JOINTS_WITHIN_SAFETY_LIMITS => {
                let ok = target.iter().all(|v| v.is_finite())
                    && io.arm.kinematics().joint_limits.contains(&target);
                Self::flag(io.regs, ok);
                Ok(Outcome::Done)
            }
            POSE_TRANS => {
                let p = to_ur_pose(&(from_ur_pose(&target) * from_ur_pose(&second)));
                write_vector(io.regs, 0, &p);
                Ok(Outcome::Done)
            }
            GET_TCP_OFFSET => {
                let tcp = to_ur_pose(&io.arm.kinematics().flange_T_tcp);
                write_vector(io.regs, 0, &tcp);
                Ok(Outcome::Done)
            }
            GET_FK_DEFAULT => {
                let pose = io.arm.forward(&q_now);
                write_vector(io.regs, 0, &pose);
                Ok(Outcome::Done)
            }
            GET_FK_ARGS => {
                // The script computes `get_forward_kin(q, tcp)` with the TCP from registers
                // 6-11, but ur_rtde 1.6.5 writes them only with a non-zero `tcp_offset` (its
                // 12-value recipe); `getForwardKinematics(q)` sends q alone (registers 0-5), and
                // registers 6-11 still hold the previous command's parameters (a moveJ's speed
                // and acceleration: a TCP metres away). Only registers that came with this
                // command count; otherwise the active TCP, as ur_rtde documents.
                let kinematics = io.arm.kinematics();
                let sent_tcp = (6..12).all(|i| regs.command_doubles >> i & 1 == 1);
                let flange_t_tcp = if sent_tcp {
                    from_ur_pose(&second)
                } else {
                    kinematics.flange_T_tcp
                };
                let pose = to_ur_pose(&(kinematics.forward_flange(&target) * flange_t_tcp));
                write_vector(io.regs, 0, &pose);
                Ok(Outcome::Done)
            }
            MOVE_PATH => self.move_path(io),
            GET_TARGET_WAYPOINT => {
                // The target of the running movej/movel; the target TCP pose otherwise.
                let pose = match self.waypoint {
                    Some(pose) if io.arm.is_moving() => pose,
                    _ => io.arm.state().target_tcp_pose,
                };
                write_vector(io.regs, 0, &pose);
                Ok(Outcome::Done)
            }
            // get_freedrive_status(): 1 in freedrive, 0 otherwise.
            GET_FREEDRIVE_STATUS => {
                io.regs.output_int[1] = i32::from(self.free == Some(FreeMode::Freedrive));
                Ok(Outcome::Done)
            }
            GET_ACTUAL_TOOL_FLANGE_POSE => {
                let flange = to_ur_pose(&io.arm.kinematics().forward_flange(&q_now));
                write_vector(io.regs, 0, &flange);
                Ok(Outcome::Done)
            }
            IS_STEADY => {
                let state = io.arm.state();
                let steady = !io.arm.is_moving() && state.qd.iter().all(|v| *v == 0.0);
                Self::flag(io.regs, steady);
                Ok(Outcome::Done)
            }
            START_JOG => {
                let feature = regs.input_double[6].round() as i32;
                let jog_accel = regs.input_double[7];
                let custom = vector(regs, 8);
                let frame = match self.jog_frame {
                    Some(frame) => frame,
                    None => match feature {
                        0 => UnitQuaternion::identity(),
                        1 => from_ur_pose(&io.arm.state().tcp_pose).rotation,
                        2 => from_ur_pose(&custom).rotation,
                        other => return Err(format!("jog: unknown feature {other}")),
                    },
                };
                self.jog_frame = Some(frame);
                self.waypoint = None;
                let linear = frame * Vector3::new(target[0], target[1], target[2]);
                let angular = frame * Vector3::new(target[3], target[4], target[5]);
                let xd = [
                    linear.x, linear.y, linear.z, angular.x, angular.y, angular.z,
                ];
                Self::command(
                    io,
                    ArmCommand::SpeedL {
                        xd,
                        accel: jog_accel,
                    },
                )?;
                Ok(Outcome::Done)
            }
            STOP_JOG => {
                self.jog_frame = None;
                self.waypoint = None;
                Self::command(io, ArmCommand::StopL { decel: 1.2 })?;
                Ok(Outcome::Wait)
            }
            WATCHDOG => Ok(Outcome::Done),
            STOP_SCRIPT => Ok(Outcome::Exit),
            other => Err(unsupported(other)),
        }
    }

    /// Refuses a motion while the arm is hand-guided (teach or freedrive mode) or, for any but
    /// force mode itself, in force mode: the model moves neither (a UR would combine a motion
    /// with force mode's compliance; this model does not).
    fn check_motion_allowed(&self, cmd: i32) -> Result<(), String> {
        if !MOTIONS.contains(&cmd) {
            return Ok(());
        }
        if let Some(mode) = self.free {
            let (what, end) = match mode {
                FreeMode::Teach => ("teach mode", "endTeachMode"),
                FreeMode::Freedrive => ("freedrive mode", "endFreedriveMode"),
            };
            return Err(format!(
                "virtual-ur: ur_rtde command {cmd} moves the arm during {what}: call {end} first"
            ));
        }
        if self.force_mode.is_some() && cmd != FORCE_MODE {
            return Err(format!(
                "virtual-ur: ur_rtde command {cmd} moves the arm during force mode, which this model \
                 does not combine with force control: call forceModeStop first"
            ));
        }
        Ok(())
    }

    /// `tool_contact(direction)`: the control cycles back to the one just before the contact
    /// began (an index into the joint history), or 0 without a contact against `direction`.
    fn contact_steps(&self, io: &ProgramIo<'_>, direction: &[f64; 3]) -> i32 {
        if !io.sensor.touches(direction) {
            return 0;
        }
        let newest = io.history.len().saturating_sub(1);
        (io.sensor.contact_cycles as usize).min(newest).max(1) as i32
    }

    /// One cycle of force mode: the tool twist towards the commanded wrench along the compliant
    /// axes, blended from last cycle's by the damping.
    fn force_step(&mut self, io: &mut ProgramIo<'_>) -> Result<(), String> {
        let Some(mode) = self.force_mode.as_mut() else {
            return Ok(());
        };
        let state = io.arm.state();
        let tcp = from_ur_pose(&state.tcp_pose);
        let velocity = Vector3::new(state.tcp_speed[0], state.tcp_speed[1], state.tcp_speed[2]);
        let rotation = mode.frame_rotation(&tcp, &velocity);
        let target = mode.twist(&rotation, &io.sensor.external, self.tuning.gain_scaling);
        let blend = self.tuning.blend();
        self.force_twist = std::array::from_fn(|i| {
            self.force_twist[i] + blend * (target[i] - self.force_twist[i])
        });
        // The arm takes the twist within the cycle (force-mode speeds are centimetres a second).
        Self::command(
            io,
            ArmCommand::SpeedL {
                xd: self.force_twist,
                accel: FORCE_MODE_ACCEL,
            },
        )
    }

    /// One cycle of moveUntilContact's loop; true when it has ended (at the contact point, or
    /// stopped by a protective stop).
    fn contact_step(&mut self, io: &mut ProgramIo<'_>) -> Result<bool, String> {
        let Some((phase, signal)) = self.until_contact else {
            return Ok(true);
        };
        if io.protective_stop {
            self.until_contact = None;
            return Ok(true);
        }
        let next = match phase {
            UntilContact::Seeking {
                xd,
                direction,
                accel,
            } => {
                let back = self.contact_steps(io, &direction);
                if back > 0 {
                    // q = get_actual_joint_positions_history(step_back); stopl(3); movel(q).
                    let q = io.history[back as usize];
                    Self::command(
                        io,
                        ArmCommand::StopL {
                            decel: CONTACT_STOP_DECEL,
                        },
                    )?;
                    UntilContact::Stopping { q }
                } else {
                    Self::command(io, ArmCommand::SpeedL { xd, accel })?;
                    phase
                }
            }
            UntilContact::Stopping { q } => {
                if io.arm.is_moving() {
                    phase
                } else {
                    let pose = io.arm.forward(&q);
                    let (speed, accel) = CONTACT_RETURN;
                    Self::command(io, ArmCommand::MoveL { pose, speed, accel })?;
                    UntilContact::Returning
                }
            }
            UntilContact::Returning => {
                if io.arm.is_moving() {
                    phase
                } else {
                    self.until_contact = None;
                    return Ok(true);
                }
            }
        };
        self.until_contact = Some((next, signal));
        Ok(io.protective_stop)
    }

    /// One cycle of contact detection: once the tool, free since detection started, meets a
    /// contact, stop the arm (`stopl(3)`) and move it back to the joints of the cycle before
    /// the contact began (`movel(q)`), as the script's command 254 does.
    fn detection_step(&mut self, io: &mut ProgramIo<'_>) -> Result<(), String> {
        let Some(mut d) = self.detection else {
            return Ok(());
        };
        if d.step_back > 0 || self.until_contact.is_some() {
            return Ok(());
        }
        let direction = if d.direction.iter().all(|v| *v == 0.0) {
            // A null direction: the TCP's target speed (`get_target_tcp_speed()`).
            let v = io.arm.state().tcp_speed;
            [v[0], v[1], v[2]]
        } else {
            d.direction
        };
        let back = self.contact_steps(io, &direction);
        if !d.armed {
            d.armed = back == 0;
        } else if back > 0 {
            d.step_back = back;
            let q = io.history[back as usize];
            if self.async_running {
                self.write_async(io.regs, false);
            }
            self.path_run = None;
            self.waypoint = None;
            Self::command(
                io,
                ArmCommand::StopL {
                    decel: CONTACT_STOP_DECEL,
                },
            )?;
            self.until_contact = Some((UntilContact::Stopping { q }, false));
        }
        self.detection = Some(d);
        Ok(())
    }

    /// Realtime commands (processed every cycle, answered with ready).
    fn realtime(&mut self, io: &mut ProgramIo<'_>, cmd: i32) -> Result<(), String> {
        self.check_motion_allowed(cmd)?;
        let regs = &*io.regs;
        let target = vector(regs, 0);
        if matches!(cmd, SPEED_J | SPEED_L | SERVO_J | SERVO_L) {
            self.waypoint = None;
        }
        match cmd {
            SPEED_J => {
                self.speed_joint = true;
                let accel = regs.input_double[6];
                Self::command(io, ArmCommand::SpeedJ { qd: target, accel })
            }
            SPEED_L => {
                self.speed_joint = false;
                let accel = regs.input_double[6];
                Self::command(io, ArmCommand::SpeedL { xd: target, accel })
            }
            SERVO_J => {
                let time = regs.input_double[8];
                Self::command(io, ArmCommand::ServoJ { q: target, time })
            }
            SERVO_L => {
                let time = regs.input_double[8];
                let q = Self::inverse(io, &target, &io.arm.state().q)?;
                Self::command(io, ArmCommand::ServoJ { q, time })
            }
            // tool_contact(direction): the cycles back to just before the contact began, once
            // the tool presses against the direction with the detection force; 0 otherwise.
            TOOL_CONTACT => {
                let direction = [target[0], target[1], target[2]];
                io.regs.output_int[1] = self.contact_steps(io, &direction);
                Ok(())
            }
            FORCE_MODE => {
                let selection: [i32; 6] = std::array::from_fn(|i| regs.input_int[2 + i]);
                let mode = ForceMode::new(
                    &target,
                    &selection,
                    &vector(regs, 6),
                    regs.input_int[1],
                    &vector(regs, 12),
                )?;
                // Re-sent every cycle while the register holds it: a new one replaces the
                // parameters, the same one keeps the frame it tracks.
                match &self.force_mode {
                    Some(m) if m.same_command(&mode) => {}
                    _ => self.force_mode = Some(mode),
                }
                self.waypoint = None;
                Ok(())
            }
            GET_STEPTIME => {
                io.regs.output_double[0] = io.dt;
                Ok(())
            }
            GET_JOINT_POSITIONS_HISTORY => {
                // The controller's buffer; as on a UR, indexing beyond it is a runtime error.
                let steps = regs.input_int[1];
                let q = usize::try_from(steps)
                    .ok()
                    .and_then(|i| io.history.get(i))
                    .copied()
                    .ok_or_else(|| {
                        format!(
                            "get_actual_joint_positions_history({steps}): outside the {} kept cycles",
                            io.history.len()
                        )
                    })?;
                write_vector(io.regs, 0, &q);
                Ok(())
            }
            // `get_joint_torques()`: the joint torques "corrected by the torque needed to move
            // the robot itself (gravity, friction, etc.)" (UR's script manual, quoted in
            // ur_rtde's documentation), i.e. what external forces and a payload the controller
            // was not told of add. The payload the model carries is the one set, so what remains
            // is the contact wrench through the Jacobian's transpose (zero in free space); the
            // gravity torques the joints hold as well are in `target_moment` and, through the
            // torque constants, the currents.
            GET_JOINT_TORQUES => {
                let torques = io.sensor.joint_torques;
                write_vector(io.regs, 0, &torques);
                Ok(())
            }
            GET_ACTUAL_TOOL_FLANGE_POSE => self.process(io, cmd).map(|_| ()),
            GET_TARGET_JOINT_ACCELERATIONS => {
                let qdd = io.arm.state().target_qdd;
                write_vector(io.regs, 0, &qdd);
                Ok(())
            }
            GET_CORIOLIS_AND_CENTRIFUGAL_TORQUES => {
                let (d, dh) = Self::dynamics(io, cmd)?;
                let state = io.arm.state();
                let c = d.coriolis_and_centrifugal(&dh, &state.q, &state.qd, io.payload);
                write_vector(io.regs, 0, &c);
                Ok(())
            }
            GET_MASS_MATRIX => {
                let (d, dh) = Self::dynamics(io, cmd)?;
                let m = d.mass_matrix(&dh, &io.arm.state().q, io.payload);
                write_matrix(io.regs, &m);
                Ok(())
            }
            GET_JACOBIAN => {
                let tcp = io.arm.kinematics().flange_T_tcp;
                let (dh, q) = (io.arm.kinematics().dh, io.arm.state().q);
                write_matrix(io.regs, &jacobian(&dh, &q, &tcp));
                Ok(())
            }
            GET_JACOBIAN_TIME_DERIVATIVE => {
                let tcp = io.arm.kinematics().flange_T_tcp;
                let dh = io.arm.kinematics().dh;
                let state = io.arm.state();
                let jd = jacobian_time_derivative(&dh, &state.q, &state.qd, &tcp);
                write_matrix(io.regs, &jd);
                Ok(())
            }
            other => Err(unsupported(other)),
        }
    }
}

impl Program for UrRtdeProgram {
    fn name(&self) -> &'static str {
        crate::program::UR_RTDE_PROGRAM_NAME
    }

    fn start(&mut self, io: &mut ProgramIo<'_>) {
        // A program starts with the installation's gravity (the arm on its base, upright).
        *io.gravity = super::dynamics::UP;
        self.executing = false;
        self.waiting_for_motion = false;
        self.jog_frame = None;
        self.force_mode = None;
        self.force_twist = [0.0; 6];
        self.until_contact = None;
        self.detection = None;
        self.free = None;
        self.stale = Some(io.regs.input_int[0]).filter(|c| *c != 0);
        self.write_async(io.regs, false);
        io.regs.output_int[0] = READY;
    }

    fn step(&mut self, io: &mut ProgramIo<'_>) -> ProgramStep {
        if let Some(e) = &io.arm_error
            && !matches!(e, ArmError::ProtectiveStop(_))
        {
            // A motion the arm had to abort (singularity, unreachable pose on the way) is a
            // runtime error of the statement that moved it.
            io.runtime_error = Some(e.to_string());
            return ProgramStep::Exit;
        }
        self.follow_path(io);
        if let Err(e) = self.force_step(io) {
            io.runtime_error = Some(e);
            return ProgramStep::Exit;
        }
        if let Err(e) = self.detection_step(io) {
            io.runtime_error = Some(e);
            return ProgramStep::Exit;
        }
        if let Some((_, signal)) = self.until_contact {
            match self.contact_step(io) {
                Ok(true) => {
                    self.until_contact = None;
                    if signal {
                        io.regs.output_int[0] = DONE;
                    }
                }
                // moveUntilContact, and the retreat from a detected contact (command 254), keep
                // the script's main thread: the next command waits.
                Ok(false) => return ProgramStep::Continue,
                Err(e) => {
                    io.runtime_error = Some(e);
                    return ProgramStep::Exit;
                }
            }
        }
        if self.async_running && !io.arm.is_moving() {
            self.write_async(io.regs, false);
        }
        if self.waiting_for_motion {
            if io.arm.is_moving() {
                return ProgramStep::Continue;
            }
            self.waiting_for_motion = false;
            io.regs.output_int[0] = DONE;
        }
        let mut cmd = io.regs.input_int[0];
        if self.stale.is_some() {
            if self.stale == Some(cmd) {
                cmd = 0;
            } else {
                self.stale = None;
            }
        }
        if REALTIME.contains(&cmd) {
            if let Err(e) = self.realtime(io, cmd) {
                io.runtime_error = Some(e);
                return ProgramStep::Exit;
            }
            io.regs.output_int[0] = READY;
            return ProgramStep::Continue;
        }
        if cmd == 0 {
            self.executing = false;
            io.regs.output_int[0] = READY;
        } else if !self.executing {
            self.executing = true;
            match self.process(io, cmd) {
                Ok(Outcome::Exit) => return ProgramStep::Exit,
                Ok(Outcome::Wait) => self.waiting_for_motion = true,
                Ok(Outcome::Contact) => {}
                Ok(Outcome::Done) => io.regs.output_int[0] = DONE,
                Err(e) => {
                    io.runtime_error = Some(e);
                    return ProgramStep::Exit;
                }
            }
        }
        ProgramStep::Continue
    }

    fn interrupted(&mut self, io: &mut ProgramIo<'_>) {
        // A safety stop ends force mode and moveUntilContact's loop with the motion.
        self.force_mode = None;
        self.force_twist = [0.0; 6];
        if let Some((_, true)) = self.until_contact.take() {
            io.regs.output_int[0] = DONE;
        }
        if self.waiting_for_motion {
            self.waiting_for_motion = false;
            io.regs.output_int[0] = DONE;
        }
        if self.async_running {
            self.write_async(io.regs, false);
        }
    }
}
