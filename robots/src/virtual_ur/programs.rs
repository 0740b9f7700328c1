//! Programs the virtual controller runs natively: our `cell_program` register protocol and
//! SDU ur_rtde's `rtde_control` register protocol. Not a URScript interpreter: an uploaded
//! script is recognised by its `def` name and its register protocol is executed here.

use super::arm::{ArmCommand, ArmError, ArmModel};
use super::path::{PathMove, settle_blends, via_points};
use super::registers::{Payload, Registers, StandardIo};
use crate::kinematics::Joints;
use crate::program::layout as L;
use std::collections::VecDeque;

pub use super::ur_rtde_program::{UrRtdeProgram, ur_rtde_cmd};

/// What a program touches in one control cycle.
pub struct ProgramIo<'a> {
    /// Registers.
    pub regs: &'a mut Registers,
    /// Standard and tool I/O.
    pub io: &'a mut StandardIo,
    /// The arm.
    pub arm: &'a mut dyn ArmModel,
    /// Control period (s).
    pub dt: f64,
    /// The arm aborted a motion during this cycle.
    pub arm_error: Option<ArmError>,
    /// Set by the program to trigger a protective stop.
    pub protective_stop: bool,
    /// Set by the program when a statement fails at run time: the controller stops the program
    /// (and the arm) and reports the message, as a UR does on a runtime exception.
    pub runtime_error: Option<String>,
    /// Set by the program to arm the RTDE watchdog (`rtde_set_watchdog`): minimum input
    /// frequency (Hz) on `input_int_register_0`; the program stops when inputs stay away longer.
    pub watchdog: Option<f64>,
    /// The active payload (`set_payload`, `set_target_payload`).
    pub payload: &'a mut Payload,
    /// The `set_gravity` vector (base frame, m/s², pointing away from the earth).
    pub gravity: &'a mut [f64; 3],
    /// Actual joint positions of the last control cycles, newest (this cycle's) first.
    pub history: &'a VecDeque<Joints>,
    /// Warnings the program raises (the controller logs them for clients, as a UR's popups).
    pub warnings: Vec<String>,
    /// The wrist's force/torque sensor and what the tool touches this cycle.
    pub sensor: &'a mut super::force::FtSensorState,
}

impl ProgramIo<'_> {
    /// Sets a standard (0–7), configurable (8–15) or tool (16–17) digital output and tells the
    /// arm model when its level changed; false if there is no such pin.
    pub fn set_digital_output(&mut self, pin: i64, level: bool) -> bool {
        set_digital_output(self.io, self.arm, pin, level)
    }
}

/// Sets digital output `pin` in `io` and calls [`ArmModel::digital_output`] when the level
/// changed; false if there is no such pin.
pub fn set_digital_output(
    io: &mut StandardIo,
    arm: &mut dyn ArmModel,
    pin: i64,
    level: bool,
) -> bool {
    let before = io.digital_output_bits();
    if !io.set_digital_output(pin, level) {
        return false;
    }
    notify_output_changes(arm, before, io.digital_output_bits());
    true
}

/// Sets standard analog output `i` in `io` to `ratio` of its range (in the domain it is in) and
/// calls [`ArmModel::analog_output`] when its value changed; false if there is no such output or
/// the ratio is not a number from 0 to 1.
pub fn set_analog_output(
    io: &mut StandardIo,
    arm: &mut dyn ArmModel,
    i: usize,
    ratio: f64,
) -> bool {
    if i >= 2 || !(0.0..=1.0).contains(&ratio) {
        return false;
    }
    let before = io.analog_out[i];
    io.set_analog_output(i, ratio, io.analog_voltage[i]);
    if io.analog_out[i] != before {
        arm.analog_output(i as u32, ratio);
    }
    true
}

/// Calls [`ArmModel::digital_output`] for every bit that differs between two
/// `actual_digital_output_bits` words, lowest pin first.
pub fn notify_output_changes(arm: &mut dyn ArmModel, before: u64, after: u64) {
    let changed = before ^ after;
    for pin in 0..18u32 {
        if changed >> pin & 1 == 1 {
            arm.digital_output(pin, after >> pin & 1 == 1);
        }
    }
}

/// Whether a program keeps running after a cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ProgramStep {
    /// Keep running.
    Continue,
    /// The program ended.
    Exit,
}

/// A program the virtual controller executes once per control cycle.
pub trait Program: Send {
    /// The program's name (its `def`).
    fn name(&self) -> &'static str;
    /// Called once when the program starts (or resumes after a pause).
    fn start(&mut self, io: &mut ProgramIo<'_>);
    /// One control cycle.
    fn step(&mut self, io: &mut ProgramIo<'_>) -> ProgramStep;
    /// A safety stop halted the arm: abort what was running.
    fn interrupted(&mut self, io: &mut ProgramIo<'_>);
}

/// Our program (`program/cell.script`), executed natively.
#[derive(Debug, Default)]
pub struct CellProgram {
    last_id: i32,
    active: Option<i32>,
    pending: Option<(i32, ArmCommand)>,
    /// A digital-output command waiting for its device to act: id and seconds left.
    settling: Option<(i32, f64)>,
    last_heartbeat: i32,
    silent: f64,
    watchdog_tripped: bool,
    beat: i32,
    /// The guarded move running: the unit direction it travels (base frame) and its force
    /// limit, N.
    guard: Option<([f64; 3], f64)>,
    /// The guarded move running met its limit and is coming to rest.
    contact: bool,
    /// The path buffer (`KIND_PATH_ADD_*`).
    path: Vec<PathMove>,
    /// A path to run once the arm is at rest (after a stop): its command id and moves.
    pending_path: Option<(i32, Vec<PathMove>)>,
}

impl CellProgram {
    /// A fresh program.
    pub fn new() -> CellProgram {
        CellProgram::default()
    }

    fn finish(regs: &mut Registers, id: i32, status: i32, error: i32) {
        regs.output_int[L::ERROR_REG] = error;
        regs.output_int[L::STATUS_REG] = status;
        regs.output_int[L::DONE_ID_REG] = id;
    }

    fn stop_motion(&mut self, io: &mut ProgramIo<'_>, error: i32) {
        self.guard = None;
        self.contact = false;
        if let Some(id) = self.active.take() {
            Self::finish(io.regs, id, L::STATUS_FAILED, error);
        }
        if let Some((id, _)) = self.pending.take() {
            Self::finish(io.regs, id, L::STATUS_FAILED, error);
        }
        if let Some((id, _)) = self.pending_path.take() {
            Self::finish(io.regs, id, L::STATUS_FAILED, error);
        }
        if io.arm.is_moving() {
            // A positive constant deceleration is always accepted.
            let _ = io.arm.command(ArmCommand::Stop {
                decel: L::STOP_DECELERATION,
            });
        }
    }

    fn start_move(&mut self, io: &mut ProgramIo<'_>, id: i32, cmd: ArmCommand) {
        match io.arm.command(cmd) {
            Ok(()) => {
                self.active = Some(id);
                io.regs.output_int[L::STATUS_REG] = L::STATUS_BUSY;
            }
            Err(e) => {
                tracing::warn!(id, error = %e, "cell_program: motion refused");
                if matches!(e, ArmError::ProtectiveStop(_)) {
                    io.protective_stop = true;
                    Self::finish(io.regs, id, L::STATUS_FAILED, L::ERROR_STOPPED);
                } else {
                    Self::finish(io.regs, id, L::STATUS_FAILED, L::ERROR_MOTION);
                }
            }
        }
    }

    /// Starts the buffered path as the script's path thread does: URScript's blend rule
    /// settles the radii (warnings as its popups), then the arm runs the blended sequence.
    fn start_path(&mut self, io: &mut ProgramIo<'_>, id: i32, moves: Vec<PathMove>) {
        let start = io.arm.state().q;
        let points = via_points(io.arm.kinematics(), &start, &moves);
        let (moves, warnings) = settle_blends(&moves, &points);
        io.warnings.extend(warnings);
        match io.arm.command_path(&moves) {
            Ok(()) => {
                self.active = Some(id);
                io.regs.output_int[L::STATUS_REG] = L::STATUS_BUSY;
            }
            Err(e) => {
                tracing::warn!(id, error = %e, "cell_program: path refused");
                if matches!(e, ArmError::ProtectiveStop(_)) {
                    io.protective_stop = true;
                    Self::finish(io.regs, id, L::STATUS_FAILED, L::ERROR_STOPPED);
                } else {
                    Self::finish(io.regs, id, L::STATUS_FAILED, L::ERROR_MOTION);
                }
            }
        }
    }

    fn run_command(&mut self, io: &mut ProgramIo<'_>, id: i32) {
        let regs = &*io.regs;
        let kind = regs.input_int[L::CMD_KIND_REG];
        let target: [f64; 6] = std::array::from_fn(|i| regs.input_double[L::TARGET_REG + i]);
        let speed = regs.input_double[L::SPEED_REG];
        let accel = regs.input_double[L::ACCEL_REG];
        let pin = i64::from(regs.input_int[L::DO_PIN_REG]);
        let level = regs.input_int[L::DO_LEVEL_REG] != 0;
        let wait = regs.input_double[L::DO_WAIT_REG];
        io.regs.output_int[L::ACCEPTED_ID_REG] = id;
        if self.watchdog_tripped {
            Self::finish(io.regs, id, L::STATUS_FAILED, L::ERROR_WATCHDOG);
            return;
        }
        match kind {
            L::KIND_MOVEJ | L::KIND_MOVEL => {
                let cmd = if kind == L::KIND_MOVEJ {
                    ArmCommand::MoveJ {
                        q: target,
                        speed,
                        accel,
                    }
                } else {
                    ArmCommand::MoveL {
                        pose: target,
                        speed,
                        accel,
                    }
                };
                self.stop_motion(io, L::ERROR_STOPPED);
                self.guard = None;
                if io.arm.is_moving() {
                    // Like the script: stopj to rest, then start the new move.
                    self.pending = Some((id, cmd));
                    io.regs.output_int[L::STATUS_REG] = L::STATUS_BUSY;
                } else {
                    self.start_move(io, id, cmd);
                }
            }
            L::KIND_MOVE_UNTIL_CONTACT => {
                let limit = io.regs.input_double[L::FORCE_LIMIT_REG];
                // Like the script: a limit out of range (or NaN) fails before the arm moves.
                if !(limit > 0.0 && limit <= L::MAX_CONTACT_FORCE_N) {
                    Self::finish(io.regs, id, L::STATUS_FAILED, L::ERROR_INVALID_FORCE);
                    return;
                }
                self.stop_motion(io, L::ERROR_STOPPED);
                let here = io.arm.forward(&io.arm.state().q);
                let d: [f64; 3] = std::array::from_fn(|i| target[i] - here[i]);
                let n = d.iter().map(|v| v * v).sum::<f64>().sqrt();
                let dir = if n > 0.0 { d.map(|v| v / n) } else { [0.0; 3] };
                io.regs.output_int[L::CONTACT_REG] = 0;
                let cmd = ArmCommand::MoveL {
                    pose: target,
                    speed,
                    accel,
                };
                if io.arm.is_moving() {
                    self.pending = Some((id, cmd));
                    io.regs.output_int[L::STATUS_REG] = L::STATUS_BUSY;
                } else {
                    self.start_move(io, id, cmd);
                }
                if self.active.is_some() || self.pending.is_some() {
                    self.guard = Some((dir, limit));
                }
            }
            L::KIND_PATH_ADD_MOVEJ | L::KIND_PATH_ADD_MOVEL => {
                let index = io.regs.input_int[L::DO_PIN_REG];
                let blend = io.regs.input_double[L::BLEND_REG];
                if index == 0 {
                    self.path.clear();
                }
                // Like the script: out of order, too many or a negative (or NaN) radius empties
                // the buffer and fails.
                if usize::try_from(index).ok() != Some(self.path.len())
                    || self.path.len() >= L::MAX_PATH_POINTS
                    || blend.is_nan()
                    || blend < 0.0
                {
                    self.path.clear();
                    Self::finish(io.regs, id, L::STATUS_FAILED, L::ERROR_INVALID_PATH);
                    return;
                }
                self.path.push(if kind == L::KIND_PATH_ADD_MOVEJ {
                    PathMove::Joint {
                        q: target,
                        speed,
                        accel,
                        blend,
                    }
                } else {
                    PathMove::Linear {
                        pose: target,
                        speed,
                        accel,
                        blend,
                    }
                });
                Self::finish(io.regs, id, L::STATUS_IDLE, L::ERROR_NONE);
            }
            L::KIND_PATH_RUN => {
                if self.path.is_empty() {
                    Self::finish(io.regs, id, L::STATUS_FAILED, L::ERROR_INVALID_PATH);
                    return;
                }
                let moves = std::mem::take(&mut self.path);
                self.stop_motion(io, L::ERROR_STOPPED);
                if io.arm.is_moving() {
                    self.pending_path = Some((id, moves));
                    io.regs.output_int[L::STATUS_REG] = L::STATUS_BUSY;
                } else {
                    self.start_path(io, id, moves);
                }
            }
            L::KIND_STOP => {
                self.stop_motion(io, L::ERROR_STOPPED);
                Self::finish(io.regs, id, L::STATUS_IDLE, L::ERROR_NONE);
            }
            L::KIND_SET_STANDARD_DO | L::KIND_SET_TOOL_DO => {
                // Like the script: a wait out of range (or NaN) fails before the output changes.
                if !(0.0..=L::MAX_DO_WAIT_S).contains(&wait) {
                    Self::finish(io.regs, id, L::STATUS_FAILED, L::ERROR_INVALID_WAIT);
                    return;
                }
                let pin = if kind == L::KIND_SET_TOOL_DO {
                    pin + 16
                } else {
                    pin
                };
                let in_range = if kind == L::KIND_SET_TOOL_DO {
                    (16..=17).contains(&pin)
                } else {
                    (0..=7).contains(&pin)
                };
                if in_range && io.set_digital_output(pin, level) {
                    // The program sleeps the client's wait (as the script does), then reports
                    // done. It cannot know the device: a wait shorter than the device's stroke
                    // lets the next move start while the gripper still moves.
                    let stroke = io.arm.actuation_time(pin as u32);
                    if stroke.is_finite() && wait < stroke - 1e-9 {
                        tracing::warn!(
                            pin,
                            wait,
                            stroke,
                            "cell_program: output wait shorter than the device's actuation time"
                        );
                    }
                    if wait > 0.0 {
                        self.settling = Some((id, wait));
                        io.regs.output_int[L::STATUS_REG] = L::STATUS_BUSY;
                    } else {
                        Self::finish(io.regs, id, L::STATUS_IDLE, L::ERROR_NONE);
                    }
                } else {
                    Self::finish(io.regs, id, L::STATUS_FAILED, L::ERROR_UNKNOWN_COMMAND);
                }
            }
            L::KIND_SET_STANDARD_AO => {
                // Like the script: the wait first, then the output and ratio, all before the
                // output changes.
                let ratio = target[0];
                if !(0.0..=L::MAX_DO_WAIT_S).contains(&wait) {
                    Self::finish(io.regs, id, L::STATUS_FAILED, L::ERROR_INVALID_WAIT);
                } else if !(0..=1).contains(&pin)
                    || !set_analog_output(io.io, io.arm, pin as usize, ratio)
                {
                    Self::finish(io.regs, id, L::STATUS_FAILED, L::ERROR_INVALID_OUTPUT);
                } else if wait > 0.0 {
                    self.settling = Some((id, wait));
                    io.regs.output_int[L::STATUS_REG] = L::STATUS_BUSY;
                } else {
                    Self::finish(io.regs, id, L::STATUS_IDLE, L::ERROR_NONE);
                }
            }
            _ => Self::finish(io.regs, id, L::STATUS_FAILED, L::ERROR_UNKNOWN_COMMAND),
        }
    }
}

impl Program for CellProgram {
    fn name(&self) -> &'static str {
        crate::program::PROGRAM_NAME
    }

    fn start(&mut self, io: &mut ProgramIo<'_>) {
        self.last_id = io.regs.input_int[L::CMD_ID_REG];
        self.last_heartbeat = io.regs.input_int[L::HEARTBEAT_REG];
        self.silent = 0.0;
        self.watchdog_tripped = false;
        self.settling = None;
        io.regs.output_int[L::ERROR_REG] = L::ERROR_NONE;
        io.regs.output_int[L::STATUS_REG] = L::STATUS_IDLE;
        io.regs.output_int[L::ACCEPTED_ID_REG] = self.last_id;
        io.regs.output_int[L::DONE_ID_REG] = self.last_id;
    }

    fn step(&mut self, io: &mut ProgramIo<'_>) -> ProgramStep {
        self.beat = self.beat.wrapping_add(1);
        io.regs.output_int[L::PROGRAM_BEAT_REG] = self.beat;

        let heartbeat = io.regs.input_int[L::HEARTBEAT_REG];
        if heartbeat != self.last_heartbeat {
            self.last_heartbeat = heartbeat;
            self.silent = 0.0;
            self.watchdog_tripped = false;
        } else {
            self.silent += io.dt;
        }
        if self.silent > L::WATCHDOG_TIMEOUT_S && !self.watchdog_tripped {
            self.watchdog_tripped = true;
            tracing::warn!(silent = self.silent, "cell_program: watchdog stops the arm");
            self.stop_motion(io, L::ERROR_WATCHDOG);
        }

        // A guarded move ends where the wrist reads more than its limit against the motion
        // (`get_tcp_force`, the sensor's reading): the move is killed there and the command is
        // done once the arm is at rest.
        if let (Some(_), Some((dir, limit))) = (self.active, self.guard) {
            let f = &io.sensor.tcp_force;
            let against = -(f[0] * dir[0] + f[1] * dir[1] + f[2] * dir[2]);
            if against > limit {
                self.guard = None;
                self.contact = true;
                // A positive constant deceleration is always accepted.
                let _ = io.arm.command(ArmCommand::StopL {
                    decel: L::STOP_DECELERATION,
                });
            }
        }
        if let Some(id) = self.active {
            if io.arm_error.is_some() {
                self.active = None;
                Self::finish(io.regs, id, L::STATUS_FAILED, L::ERROR_MOTION);
            } else if !io.arm.is_moving() {
                self.active = None;
                // Only a guarded move reports its contact flag (as the script does).
                let contact = std::mem::take(&mut self.contact);
                if self.guard.take().is_some() || contact {
                    io.regs.output_int[L::CONTACT_REG] = i32::from(contact);
                }
                Self::finish(io.regs, id, L::STATUS_IDLE, L::ERROR_NONE);
            }
        }
        if self.pending.is_some()
            && !io.arm.is_moving()
            && let Some((id, cmd)) = self.pending.take()
        {
            self.start_move(io, id, cmd);
        }
        if self.pending_path.is_some()
            && !io.arm.is_moving()
            && let Some((id, moves)) = self.pending_path.take()
        {
            self.start_path(io, id, moves);
        }
        if let Some((id, left)) = self.settling.as_mut() {
            *left -= io.dt;
            if *left > 1e-9 {
                // Still sleeping: the next command is read afterwards.
                return ProgramStep::Continue;
            }
            let id = *id;
            self.settling = None;
            Self::finish(io.regs, id, L::STATUS_IDLE, L::ERROR_NONE);
        }

        let id = io.regs.input_int[L::CMD_ID_REG];
        if id != self.last_id {
            self.last_id = id;
            self.run_command(io, id);
        }
        ProgramStep::Continue
    }

    fn interrupted(&mut self, io: &mut ProgramIo<'_>) {
        self.guard = None;
        self.contact = false;
        if let Some(id) = self.active.take() {
            Self::finish(io.regs, id, L::STATUS_FAILED, L::ERROR_STOPPED);
        }
        if let Some((id, _)) = self.settling.take() {
            Self::finish(io.regs, id, L::STATUS_FAILED, L::ERROR_STOPPED);
        }
        if let Some((id, _)) = self.pending.take() {
            Self::finish(io.regs, id, L::STATUS_FAILED, L::ERROR_STOPPED);
        }
        if let Some((id, _)) = self.pending_path.take() {
            Self::finish(io.regs, id, L::STATUS_FAILED, L::ERROR_STOPPED);
        }
    }
}
