//! The virtual controller's state: arm, safety, program, registers, I/O; its 500 Hz control
//! loop; and the RTDE variable mapping (it implements [`crate::rtde::server::Controller`]).

use super::arm::{ArmCommand, ArmError, ArmModel, ArmState};
use super::force::{
    ContactEnvironment, ContactPlane, FtNoise, FtSensorState, PROTECTIVE_STOP_FORCE,
};
use super::programs::{
    CellProgram, Program, ProgramIo, ProgramStep, UrRtdeProgram, notify_output_changes,
    set_analog_output, set_digital_output,
};
use super::registers::{Payload, Registers, StandardIo};
use crate::dashboard::{robot_mode_word, safety_status_word};
use crate::kinematics::Joints;
use crate::program::{PROGRAM_NAME, UR_RTDE_PROGRAM_NAME, program_name};
use crate::robot::{RobotMode, SafetyStatus};
use crate::rtde::ControllerVersion;
use crate::rtde::server::{ConnId, Controller, InputField, OutputField};
use crate::rtde::state::{
    ROBOT_BIT_PROGRAM_RUNNING, RuntimeState, SAFETY_BIT_EMERGENCY_STOPPED,
    SAFETY_BIT_PROTECTIVE_STOPPED,
};
use crate::rtde::types::{DataType, Slot, Value};
use crate::rtde::variables::{self, Register};
use std::collections::{HashMap, VecDeque};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};
use thiserror::Error;
use tokio::sync::watch;

/// Joint deceleration (rad/s²) when a program stops or pauses with the arm moving.
pub const PROGRAM_STOP_DECELERATION: f64 = 3.0;

/// Messages kept by [`VirtualController::messages`].
pub const MAX_TEXT_LOG: usize = 64;

/// Seed of the wrist sensor's bias and noise unless [`VirtualController::set_sensor_noise`]
/// replaces it: every run of the virtual controller reads the same numbers.
pub const DEFAULT_SENSOR_SEED: u64 = 0x5E45_0E5E;

/// Control cycles of actual joint positions the controller keeps for
/// `get_actual_joint_positions_history` (1 s at 500 Hz; a modelled buffer size).
pub const HISTORY_LEN: usize = 500;

/// Why a program upload or a dashboard action was refused.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum ControllerError {
    /// The uploaded script is not a program this controller can run.
    #[error("program {0:?} is not one the virtual controller executes")]
    UnknownProgram(String),
    /// The text has no `def name():` line.
    #[error("script has no def line")]
    NotAProgram,
    /// Program uploads are refused (fault injection).
    #[error("program refused (fault injection)")]
    Refused,
    /// The robot is not in RUNNING mode, or a safety stop is active.
    #[error("robot not ready: mode {mode:?}, safety {safety:?}")]
    NotReady {
        /// Robot mode.
        mode: RobotMode,
        /// Safety mode.
        safety: SafetyStatus,
    },
}

/// One control cycle's state, as streamed to RTDE clients.
#[derive(Debug, Clone)]
pub struct Snapshot {
    /// Control cycle number.
    pub cycle: u64,
    /// Seconds since controller start.
    pub timestamp: f64,
    /// Arm state.
    pub arm: ArmState,
    /// Robot mode.
    pub robot_mode: RobotMode,
    /// Safety mode.
    pub safety_mode: SafetyStatus,
    /// Program state.
    pub runtime_state: RuntimeState,
    /// Registers.
    pub regs: Registers,
    /// Digital I/O and speed slider.
    pub io: StandardIo,
    /// The active payload.
    pub payload: Payload,
    /// The active TCP in the flange frame (UR pose vector).
    pub tcp_offset: [f64; 6],
    /// Joint torques (N·m) the model needs at the target joints to hold the arm and the payload
    /// against gravity (`target_moment`); zero when the arm model has no inertials.
    pub target_moment: [f64; 6],
    /// Motor currents (A) for those torques at the target joints (`target_current`).
    pub target_current: [f64; 6],
    /// Motor currents (A) at the actual joints (`actual_current`).
    pub actual_current: [f64; 6],
    /// Those currents as joint torques (N·m) through the torque constants
    /// (`actual_current_as_torque`, PolyScope 5.23).
    pub actual_current_as_torque: [f64; 6],
    /// The external wrench as the wrist sensor reads it (`actual_TCP_force`: base frame, at the
    /// TCP, payload compensated, with the sensor's noise).
    pub tcp_force: [f64; 6],
    /// The sensor's raw reading (`ft_raw_wrench`: flange frame, the payload's weight included).
    pub ft_raw_wrench: [f64; 6],
}

impl Snapshot {
    /// `robot_status_bits`.
    pub fn robot_status_bits(&self) -> u32 {
        let power = !matches!(
            self.robot_mode,
            RobotMode::PowerOff | RobotMode::Disconnected | RobotMode::NoController
        );
        u32::from(power)
            | if self.runtime_state == RuntimeState::Playing {
                ROBOT_BIT_PROGRAM_RUNNING
            } else {
                0
            }
    }

    /// `safety_status_bits`.
    pub fn safety_status_bits(&self) -> u32 {
        match self.safety_mode {
            SafetyStatus::Normal => 1,
            SafetyStatus::Reduced => 1 << 1,
            SafetyStatus::ProtectiveStop => SAFETY_BIT_PROTECTIVE_STOPPED | (1 << 10),
            SafetyStatus::Recovery => 1 << 3,
            SafetyStatus::SafeguardStop => (1 << 4) | (1 << 10),
            SafetyStatus::SystemEmergencyStop => {
                (1 << 5) | SAFETY_BIT_EMERGENCY_STOPPED | (1 << 10)
            }
            SafetyStatus::RobotEmergencyStop => (1 << 6) | SAFETY_BIT_EMERGENCY_STOPPED | (1 << 10),
            SafetyStatus::Violation => (1 << 8) | (1 << 10),
            SafetyStatus::Fault => (1 << 9) | (1 << 10),
        }
    }
}

/// Simulated quantities with their own output key (kind 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Quantity {
    Timestamp,
    TargetQ,
    TargetQd,
    TargetQdd,
    ActualQ,
    ActualQd,
    ActualTcpPose,
    TargetTcpPose,
    ActualTcpSpeed,
    TargetTcpSpeed,
    RobotMode,
    SafetyMode,
    RuntimeState,
    RobotStatusBits,
    SafetyStatusBits,
    SpeedScaling,
    TargetSpeedFraction,
    DigitalOutputBits,
    StandardDo,
    ToolDo,
    ConfigurableDo,
    JointMode,
    InputBitsLow,
    InputBitsHigh,
    OutputBitsLow,
    OutputBitsHigh,
    AnalogOut0,
    AnalogOut1,
    Payload,
    PayloadCog,
    PayloadInertia,
    TcpOffset,
    TargetMoment,
    TargetCurrent,
    ActualCurrent,
    ActualCurrentAsTorque,
    ActualTcpForce,
    FtRawWrench,
}

const QUANTITIES: &[(&str, Quantity)] = &[
    ("timestamp", Quantity::Timestamp),
    ("target_q", Quantity::TargetQ),
    ("target_qd", Quantity::TargetQd),
    ("target_qdd", Quantity::TargetQdd),
    ("actual_q", Quantity::ActualQ),
    ("actual_qd", Quantity::ActualQd),
    ("actual_TCP_pose", Quantity::ActualTcpPose),
    ("target_TCP_pose", Quantity::TargetTcpPose),
    ("actual_TCP_speed", Quantity::ActualTcpSpeed),
    ("target_TCP_speed", Quantity::TargetTcpSpeed),
    ("robot_mode", Quantity::RobotMode),
    ("safety_mode", Quantity::SafetyMode),
    ("safety_status", Quantity::SafetyMode),
    ("runtime_state", Quantity::RuntimeState),
    ("robot_status_bits", Quantity::RobotStatusBits),
    ("safety_status_bits", Quantity::SafetyStatusBits),
    ("speed_scaling", Quantity::SpeedScaling),
    ("target_speed_fraction", Quantity::TargetSpeedFraction),
    ("speed_slider_fraction", Quantity::TargetSpeedFraction),
    ("actual_digital_output_bits", Quantity::DigitalOutputBits),
    ("standard_digital_output", Quantity::StandardDo),
    ("tool_digital_output", Quantity::ToolDo),
    ("configurable_digital_output", Quantity::ConfigurableDo),
    ("joint_mode", Quantity::JointMode),
    ("input_bit_registers0_to_31", Quantity::InputBitsLow),
    ("input_bit_registers32_to_63", Quantity::InputBitsHigh),
    ("output_bit_registers0_to_31", Quantity::OutputBitsLow),
    ("output_bit_registers32_to_63", Quantity::OutputBitsHigh),
    ("standard_analog_output0", Quantity::AnalogOut0),
    ("standard_analog_output1", Quantity::AnalogOut1),
    ("payload", Quantity::Payload),
    ("payload_cog", Quantity::PayloadCog),
    ("payload_inertia", Quantity::PayloadInertia),
    ("tcp_offset", Quantity::TcpOffset),
    ("target_moment", Quantity::TargetMoment),
    ("target_current", Quantity::TargetCurrent),
    ("actual_current", Quantity::ActualCurrent),
    ("actual_current_as_torque", Quantity::ActualCurrentAsTorque),
    ("actual_TCP_force", Quantity::ActualTcpForce),
    ("ft_raw_wrench", Quantity::FtRawWrench),
];

// Output key kinds (high 16 bits) and input key kinds.
const K_QUANTITY: u32 = 0;
const K_OUT_INT: u32 = 1;
const K_OUT_DOUBLE: u32 = 2;
const K_OUT_BIT: u32 = 3;
const K_IN_INT: u32 = 4;
const K_IN_DOUBLE: u32 = 5;
const K_IN_BIT: u32 = 6;
const K_CONSTANT: u32 = 7;
const K_NAMED_INPUT: u32 = 8;

fn key(kind: u32, index: usize) -> u32 {
    (kind << 16) | (index as u32 & 0xffff)
}

/// `joint_mode` of every joint in a robot mode (UR's joint mode codes): 253 running (brakes
/// released, under control), 255 idle (powered, brakes on), 238 backdrive, 247 booting, 239 power
/// off.
fn joint_mode(mode: RobotMode) -> i32 {
    match mode {
        RobotMode::Running => 253,
        RobotMode::PowerOn | RobotMode::Idle => 255,
        RobotMode::Backdrive => 238,
        RobotMode::Booting => 247,
        RobotMode::NoController
        | RobotMode::Disconnected
        | RobotMode::ConfirmSafety
        | RobotMode::PowerOff
        | RobotMode::UpdatingFirmware => 239,
    }
}

/// A plausible constant for table variables the model does not simulate.
fn constant_value(name: &str, ty: DataType) -> Value {
    match name {
        "actual_main_voltage" | "actual_robot_voltage" => Value::Double(48.0),
        "actual_robot_current" => Value::Double(0.4),
        "joint_temperatures" => Value::Vector6d([32.0; 6]),
        "actual_joint_voltage" => Value::Vector6d([47.5; 6]),
        "actual_tool_accelerometer" => Value::Vector3d([0.0, 0.0, 9.81]),
        "tool_output_voltage" => Value::Int32(24),
        "actual_execution_time" => Value::Double(0.3),
        "tool_temperature" => Value::Double(30.0),
        "io_current" => Value::Double(0.05),
        "tool_mode" => Value::Uint32(255),
        _ => ty.zero(),
    }
}

/// A script made only of digital-output statements.
#[derive(Debug, Clone, PartialEq)]
struct IoScript {
    /// A `sec` program (runs beside the main program) rather than bare statements.
    secondary: bool,
    /// (pin as in `actual_digital_output_bits`, level), in order.
    writes: Vec<(i64, bool)>,
}

/// Parses `set_standard_digital_out(n, b)`, `set_digital_out(n, b)`,
/// `set_configurable_digital_out(n, b)` and `set_tool_digital_out(n, b)` statements, bare or in
/// one `sec name():` … `end` block; `None` for anything else (or an out-of-range pin).
fn io_script(script: &str) -> Option<IoScript> {
    let mut lines = script
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .peekable();
    let secondary = lines
        .peek()
        .is_some_and(|l| l.starts_with("sec ") && l.ends_with(':'));
    if secondary {
        lines.next();
    }
    let mut writes = Vec::new();
    let mut ended = false;
    for line in lines {
        if ended {
            return None;
        }
        if secondary && line == "end" {
            ended = true;
            continue;
        }
        let (call, args) = line.strip_suffix(')')?.split_once('(')?;
        let (offset, count) = match call.trim() {
            "set_standard_digital_out" | "set_digital_out" => (0, 8),
            "set_configurable_digital_out" => (8, 8),
            "set_tool_digital_out" => (16, 2),
            _ => return None,
        };
        let (n, level) = args.split_once(',')?;
        let n: i64 = n.trim().parse().ok()?;
        let level = match level.trim() {
            "True" | "true" | "1" => true,
            "False" | "false" | "0" => false,
            _ => return None,
        };
        if !(0..count).contains(&n) {
            return None;
        }
        writes.push((offset + n, level));
    }
    (!writes.is_empty() && ended == secondary).then_some(IoScript { secondary, writes })
}

/// Mutable controller state, behind one mutex.
pub(crate) struct Core {
    pub arm: Box<dyn ArmModel>,
    pub cycle: u64,
    pub time: f64,
    pub robot_mode: RobotMode,
    pub safety_mode: SafetyStatus,
    pub runtime_state: RuntimeState,
    pub regs: Registers,
    pub io: StandardIo,
    pub owners: HashMap<u32, ConnId>,
    pub program: Option<Box<dyn Program>>,
    /// Name and text of the newest accepted program, for dashboard `play`.
    pub loaded: Option<String>,
    pub protective_stop_at: Option<Instant>,
    pub text_log: Vec<String>,
    pub payload: Payload,
    /// The running program's `set_gravity` vector (base frame, m/s², away from the earth).
    pub gravity: [f64; 3],
    /// The RTDE watchdog the running program armed: minimum period between updates of
    /// `input_int_register_0` (s) and the controller time of the last update.
    pub watchdog: Option<Watchdog>,
    /// Actual joint positions of the last [`HISTORY_LEN`] control cycles, newest first
    /// (`get_actual_joint_positions_history`).
    pub history: VecDeque<Joints>,
    /// The text of the newest accepted program, for dashboard `play`.
    pub loaded_script: Option<String>,
    /// What the tool touches when the arm model does not say ([`ArmModel::external_wrench`]).
    pub environment: ContactEnvironment,
    /// The wrist's force/torque sensor.
    pub sensor: FtSensorState,
}

/// An armed RTDE watchdog (`rtde_set_watchdog(..., "stop")`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Watchdog {
    /// Longest allowed gap between input updates (s).
    pub period: f64,
    /// Controller time of the last update (s).
    pub last: f64,
}

/// Output of one program call.
struct ProgramCall<R> {
    result: R,
    protective_stop: bool,
    runtime_error: Option<String>,
    watchdog: Option<f64>,
}

impl Core {
    /// Records a message for clients, keeping the newest [`MAX_TEXT_LOG`].
    fn log(&mut self, message: String) {
        if self.text_log.len() >= MAX_TEXT_LOG {
            self.text_log.remove(0);
        }
        self.text_log.push(message);
    }

    /// Runs `f` on the loaded program, if any, with the I/O it acts on; `dt` and `arm_error` are
    /// the control step's (0 and none for calls outside it).
    fn with_program<R>(
        &mut self,
        dt: f64,
        arm_error: Option<ArmError>,
        f: impl FnOnce(&mut dyn Program, &mut ProgramIo<'_>) -> R,
    ) -> Option<R> {
        self.call_program(dt, arm_error, f).map(|c| c.result)
    }

    /// As [`Core::with_program`], also returning what the program asked of the controller.
    fn call_program<R>(
        &mut self,
        dt: f64,
        arm_error: Option<ArmError>,
        f: impl FnOnce(&mut dyn Program, &mut ProgramIo<'_>) -> R,
    ) -> Option<ProgramCall<R>> {
        let program = self.program.as_deref_mut()?;
        let mut io = ProgramIo {
            regs: &mut self.regs,
            io: &mut self.io,
            arm: self.arm.as_mut(),
            dt,
            arm_error,
            protective_stop: false,
            runtime_error: None,
            watchdog: None,
            payload: &mut self.payload,
            gravity: &mut self.gravity,
            history: &self.history,
            warnings: Vec::new(),
            sensor: &mut self.sensor,
        };
        let result = f(program, &mut io);
        let (protective_stop, runtime_error, watchdog, warnings) = (
            io.protective_stop,
            io.runtime_error,
            io.watchdog,
            io.warnings,
        );
        for w in warnings {
            tracing::warn!("{w}");
            self.log(w);
        }
        Some(ProgramCall {
            result,
            protective_stop,
            runtime_error,
            watchdog,
        })
    }
}

/// The virtual UR controller.
pub struct VirtualController {
    core: Mutex<Core>,
    snapshots: watch::Sender<Arc<Snapshot>>,
    version: ControllerVersion,
    /// Control period (2 ms at 500 Hz).
    pub period: Duration,
    /// How long after a protective stop the dashboard may unlock it (5 s on a real UR).
    pub unlock_delay: Duration,
    refuse_programs: AtomicBool,
}

impl VirtualController {
    /// A controller around `arm`, powered on, brakes released, no program running.
    pub fn new(
        arm: Box<dyn ArmModel>,
        version: ControllerVersion,
        period: Duration,
        unlock_delay: Duration,
    ) -> VirtualController {
        let core = Core {
            arm,
            cycle: 0,
            time: 0.0,
            robot_mode: RobotMode::Running,
            safety_mode: SafetyStatus::Normal,
            runtime_state: RuntimeState::Stopped,
            regs: Registers::default(),
            io: StandardIo::default(),
            owners: HashMap::new(),
            program: None,
            loaded: None,
            protective_stop_at: None,
            text_log: Vec::new(),
            payload: Payload::default(),
            gravity: super::dynamics::UP,
            watchdog: None,
            history: VecDeque::with_capacity(HISTORY_LEN),
            loaded_script: None,
            environment: ContactEnvironment::Plane(ContactPlane::table()),
            sensor: FtSensorState::new(FtNoise::ur5e(DEFAULT_SENSOR_SEED)),
        };
        let snapshot = Arc::new(Self::snapshot_of(&core));
        VirtualController {
            core: Mutex::new(core),
            snapshots: watch::channel(snapshot).0,
            version,
            period,
            unlock_delay,
            refuse_programs: AtomicBool::new(false),
        }
    }

    pub(crate) fn lock(&self) -> MutexGuard<'_, Core> {
        self.core.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn snapshot_of(core: &Core) -> Snapshot {
        let arm = core.arm.state();
        // The joints hold gravity and, through the Jacobian's transpose, what the tool touches.
        let contact = core.sensor.joint_torques;
        let with_contact = |g: Joints| -> Joints { std::array::from_fn(|i| g[i] + contact[i]) };
        let (target_moment, target_current, actual_current, actual_current_as_torque) =
            match core.arm.dynamics() {
                Some(d) => {
                    let dh = &core.arm.kinematics().dh;
                    let hold = |q| d.holding_torques(dh, q, &core.payload, &core.gravity);
                    let target = with_contact(hold(&arm.target_q));
                    let actual = with_contact(hold(&arm.q));
                    (target, d.currents(&target), d.currents(&actual), actual)
                }
                None => ([0.0; 6], [0.0; 6], [0.0; 6], [0.0; 6]),
            };
        Snapshot {
            cycle: core.cycle,
            timestamp: core.time,
            arm,
            robot_mode: core.robot_mode,
            safety_mode: core.safety_mode,
            runtime_state: core.runtime_state,
            regs: core.regs.clone(),
            io: core.io,
            payload: core.payload,
            tcp_offset: crate::kinematics::to_ur_pose(&core.arm.kinematics().flange_T_tcp),
            target_moment,
            target_current,
            actual_current,
            actual_current_as_torque,
            tcp_force: core.sensor.tcp_force,
            ft_raw_wrench: core.sensor.raw,
        }
    }

    /// Reads the wrist sensor for this cycle: the arm model's contact wrench, or the contact
    /// environment's at the TCP.
    fn sense(core: &mut Core) {
        let q = core.arm.state().q;
        let kinematics = core.arm.kinematics();
        let tcp = kinematics.forward_tcp(&q);
        let flange = kinematics.forward_flange(&q);
        let jacobian = kinematics.jacobian(&q);
        let external = core
            .arm
            .external_wrench()
            .unwrap_or_else(|| core.environment.wrench_at(&tcp));
        core.sensor.update(
            external,
            &tcp,
            &flange,
            &jacobian,
            &core.gravity.map(|g| -g * core.payload.mass),
            &core.payload.cog,
        );
    }

    /// Sets what the tool touches when the arm model does not simulate contacts itself.
    pub fn set_contact_environment(&self, environment: ContactEnvironment) {
        let mut core = self.lock();
        core.environment = environment;
        Self::sense(&mut core);
    }

    /// Replaces the wrist sensor's reading error (a seeded [`FtNoise`], or [`FtNoise::ideal`]).
    pub fn set_sensor_noise(&self, noise: FtNoise) {
        self.lock().sensor = FtSensorState::new(noise);
    }

    /// The true external wrench on the tool this cycle (base frame, at the TCP), without the
    /// sensor's error.
    pub fn external_wrench(&self) -> [f64; 6] {
        self.lock().sensor.external
    }

    /// The newest snapshot.
    pub fn snapshot(&self) -> Arc<Snapshot> {
        self.snapshots.borrow().clone()
    }

    /// One control cycle: step the arm and the program, publish a snapshot.
    pub fn tick(&self) {
        let dt = self.period.as_secs_f64();
        let snapshot = {
            let mut guard = self.lock();
            let core = &mut *guard;
            let can_move =
                core.robot_mode == RobotMode::Running && core.safety_mode.allows_motion();
            let arm_error = if can_move {
                core.arm.step(dt, core.io.speed_slider).err()
            } else {
                None
            };
            if let Some(e) = &arm_error {
                tracing::warn!(error = %e, "virtual arm aborted a motion");
            }
            if core.history.len() == HISTORY_LEN {
                core.history.pop_back();
            }
            let q = core.arm.state().q;
            core.history.push_front(q);
            Self::sense(core);
            // A collision reported by the arm model stops the arm like a real controller.
            let mut protective_stop = matches!(arm_error, Some(ArmError::ProtectiveStop(_)));
            let e = &core.sensor.external;
            let force = (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt();
            if can_move && force > PROTECTIVE_STOP_FORCE {
                let why = format!(
                    "protective stop: the tool pushes with {force:.0} N, over the {PROTECTIVE_STOP_FORCE:.0} N force limit"
                );
                tracing::warn!("{why}");
                core.log(why);
                protective_stop = true;
            }
            if core.runtime_state == RuntimeState::Playing
                && let Some(call) = core.call_program(dt, arm_error, |p, io| (p.step(io), p.name()))
            {
                let (step, name) = call.result;
                protective_stop |= call.protective_stop;
                if let Some(frequency) = call.watchdog {
                    core.watchdog = Some(Watchdog {
                        period: 1.0 / frequency,
                        last: core.time,
                    });
                }
                if let Some(e) = call.runtime_error {
                    tracing::warn!(name, error = %e, "program stopped by a runtime error");
                    core.log(e);
                    Self::stop_program(core);
                } else if step == ProgramStep::Exit {
                    tracing::info!(name, "program finished");
                    Self::stop_program(core);
                }
            }
            if core.runtime_state == RuntimeState::Playing
                && let Some(w) = core.watchdog
                && core.time - w.last > w.period + 1e-9
            {
                let e = format!(
                    "RTDE watchdog: input_int_register_0 not updated for {:.3} s (limit {:.3} s): program stopped",
                    core.time - w.last,
                    w.period
                );
                tracing::warn!("{e}");
                core.log(e);
                Self::stop_program(core);
            }
            if protective_stop {
                Self::enter_protective_stop(core);
            }
            core.cycle += 1;
            core.time += dt;
            Self::snapshot_of(core)
        };
        self.snapshots.send_replace(Arc::new(snapshot));
    }

    fn enter_protective_stop(core: &mut Core) {
        core.safety_mode = SafetyStatus::ProtectiveStop;
        core.protective_stop_at = Some(Instant::now());
        let _ = core.arm.command(ArmCommand::Halt);
        if core
            .with_program(0.0, None, |p, io| p.interrupted(io))
            .is_some()
        {
            core.runtime_state = RuntimeState::Paused;
        }
    }

    /// Fault: a protective stop (arm halts, program pauses).
    pub fn protective_stop(&self) {
        Self::enter_protective_stop(&mut self.lock());
    }

    /// Fault: an emergency stop (arm halts, program stops, power is cut).
    pub fn emergency_stop(&self) {
        let mut core = self.lock();
        core.safety_mode = SafetyStatus::RobotEmergencyStop;
        let _ = core.arm.command(ArmCommand::Halt);
        Self::stop_program(&mut core);
        core.robot_mode = RobotMode::PowerOff;
    }

    /// Releases the emergency stop button: safety returns to normal, power stays off.
    pub fn release_emergency_stop(&self) {
        let mut core = self.lock();
        if matches!(
            core.safety_mode,
            SafetyStatus::RobotEmergencyStop | SafetyStatus::SystemEmergencyStop
        ) {
            core.safety_mode = SafetyStatus::Normal;
        }
    }

    /// How many RTDE input variables clients hold (their recipes claim them; a client's are
    /// freed once the controller notices it has gone).
    pub fn claimed_inputs(&self) -> usize {
        self.lock().owners.len()
    }

    /// Messages the controller logged for clients (runtime errors, refused programs), oldest
    /// first; the newest [`MAX_TEXT_LOG`] are kept.
    pub fn messages(&self) -> Vec<String> {
        self.lock().text_log.clone()
    }

    /// Fault: refuse (or accept again) uploaded programs.
    pub fn refuse_programs(&self, refuse: bool) {
        self.refuse_programs.store(refuse, Ordering::Relaxed);
    }

    /// Ends the program (if any): motion it started decelerates to rest, as when a UR program
    /// stops, and its watchdog is removed.
    fn stop_program(core: &mut Core) {
        core.with_program(0.0, None, |p, io| p.interrupted(io));
        core.program = None;
        core.watchdog = None;
        core.runtime_state = RuntimeState::Stopped;
        if core.arm.is_moving() {
            let _ = core.arm.command(ArmCommand::Stop {
                decel: PROGRAM_STOP_DECELERATION,
            });
        }
    }

    /// Starts program `name`; `script` is its text when it came over the script port (ur_rtde's
    /// control script carries the path its `moveL(path)`/`moveJ(path)` injected).
    fn start_program(
        core: &mut Core,
        name: &str,
        script: Option<&str>,
    ) -> Result<(), ControllerError> {
        if core.robot_mode != RobotMode::Running || !core.safety_mode.allows_motion() {
            return Err(ControllerError::NotReady {
                mode: core.robot_mode,
                safety: core.safety_mode,
            });
        }
        let program: Box<dyn Program> = match name {
            PROGRAM_NAME => Box::new(CellProgram::new()),
            UR_RTDE_PROGRAM_NAME => Box::new(UrRtdeProgram::from_script(script.unwrap_or(""))),
            other => return Err(ControllerError::UnknownProgram(other.to_owned())),
        };
        Self::stop_program(core);
        core.program = Some(program);
        core.with_program(0.0, None, |p, io| p.start(io));
        core.runtime_state = RuntimeState::Playing;
        core.loaded = Some(name.to_owned());
        core.loaded_script = script.map(str::to_owned);
        tracing::info!(name, "program started");
        Ok(())
    }

    /// A script arrived on the script port: recognise it and run it (replacing the program).
    /// A script of digital-output statements only is executed at once: as a secondary program
    /// (`sec name():` … `end`) beside the running program, or as bare statements, which (as on a
    /// real controller) stop the running program first.
    pub fn upload_script(&self, script: &str) -> Result<(), ControllerError> {
        if let Some(outputs) = io_script(script) {
            if self.refuse_programs.load(Ordering::Relaxed) {
                return Err(ControllerError::Refused);
            }
            let mut core = self.lock();
            let core = &mut *core;
            if !outputs.secondary {
                Self::stop_program(core);
            }
            for (pin, level) in outputs.writes {
                set_digital_output(&mut core.io, core.arm.as_mut(), pin, level);
            }
            return Ok(());
        }
        let name = program_name(script).ok_or(ControllerError::NotAProgram)?;
        if self.refuse_programs.load(Ordering::Relaxed) {
            return Err(ControllerError::Refused);
        }
        let mut core = self.lock();
        let result = Self::start_program(&mut core, name, Some(script));
        if let Err(e) = &result {
            core.log(e.to_string());
        }
        result
    }

    /// Answers one dashboard command line.
    pub fn dashboard(&self, line: &str) -> String {
        let line = line.trim();
        let mut core = self.lock();
        let lower = line.to_ascii_lowercase();
        match lower.as_str() {
            "polyscopeversion" => format!(
                "URSoftware {}.{}.{}.{} (virtual-ur)",
                self.version.major, self.version.minor, self.version.bugfix, self.version.build
            ),
            "get serial number" => "20235500001".into(),
            "get robot model" => "UR5".into(),
            "is in remote control" => "true".into(),
            "robotmode" => format!("Robotmode: {}", robot_mode_word(core.robot_mode)),
            "safetystatus" => format!("Safetystatus: {}", safety_status_word(core.safety_mode)),
            "safetymode" => format!("Safetymode: {}", safety_status_word(core.safety_mode)),
            "programstate" => match (&core.loaded, core.runtime_state) {
                (Some(name), RuntimeState::Playing) => format!("PLAYING {name}"),
                (Some(name), RuntimeState::Paused) => format!("PAUSED {name}"),
                (Some(name), _) => format!("STOPPED {name}"),
                (None, _) => "STOPPED <unnamed>".into(),
            },
            "running" => format!(
                "Program running: {}",
                core.runtime_state == RuntimeState::Playing
            ),
            "get loaded program" => match &core.loaded {
                Some(name) => format!("Loaded program: {name}"),
                None => "No program loaded".into(),
            },
            "power on" => {
                if !core.safety_mode.allows_motion() {
                    "Failed to execute: power on".into()
                } else {
                    if core.robot_mode == RobotMode::PowerOff {
                        core.robot_mode = RobotMode::Idle;
                    }
                    "Powering on".into()
                }
            }
            "power off" => {
                Self::stop_program(&mut core);
                let _ = core.arm.command(ArmCommand::Halt);
                core.robot_mode = RobotMode::PowerOff;
                "Powering off".into()
            }
            "brake release" => {
                if matches!(core.robot_mode, RobotMode::Idle | RobotMode::Running) {
                    core.robot_mode = RobotMode::Running;
                    "Brake releasing".into()
                } else {
                    "Failed to execute: brake release".into()
                }
            }
            "play" => {
                if core.runtime_state == RuntimeState::Paused && core.program.is_some() {
                    if !core.safety_mode.allows_motion() {
                        return "Failed to execute: Play".into();
                    }
                    core.with_program(0.0, None, |p, io| p.start(io));
                    core.runtime_state = RuntimeState::Playing;
                    return "Starting program".into();
                }
                let Some(name) = core.loaded.clone() else {
                    return "Failed to execute: Play".into();
                };
                let script = core.loaded_script.clone();
                match Self::start_program(&mut core, &name, script.as_deref()) {
                    Ok(()) => "Starting program".into(),
                    Err(_) => "Failed to execute: Play".into(),
                }
            }
            // A controller answers "Stopped" whether or not a program was running.
            "stop" => {
                Self::stop_program(&mut core);
                "Stopped".into()
            }
            "pause" => {
                if core.runtime_state == RuntimeState::Playing {
                    core.runtime_state = RuntimeState::Paused;
                    let _ = core.arm.command(ArmCommand::Stop {
                        decel: PROGRAM_STOP_DECELERATION,
                    });
                    "Pausing program".into()
                } else {
                    "Failed to execute: Pause".into()
                }
            }
            "unlock protective stop" => {
                if core.safety_mode != SafetyStatus::ProtectiveStop {
                    return "Cannot unlock protective stop: robot is not protective stopped".into();
                }
                let waited = core
                    .protective_stop_at
                    .map_or(Duration::MAX, |t| t.elapsed());
                if waited < self.unlock_delay {
                    return "Cannot unlock protective stop until 5s after occurrence. Always inspect cause of protective stop before unlocking".into();
                }
                core.safety_mode = SafetyStatus::Normal;
                core.protective_stop_at = None;
                "Protective stop releasing".into()
            }
            "close safety popup" => "closing safety popup".into(),
            "close popup" => "closing popup".into(),
            "quit" => "Disconnected".into(),
            "shutdown" => "Shutting down".into(),
            _ => {
                if let Some(file) = line.strip_prefix("load ") {
                    let name = file.trim().trim_end_matches(".urp");
                    if name == PROGRAM_NAME || name == UR_RTDE_PROGRAM_NAME {
                        Self::stop_program(&mut core);
                        core.loaded = Some(name.to_owned());
                        core.loaded_script = None;
                        format!("Loading program: {}", file.trim())
                    } else {
                        format!("File not found: {}", file.trim())
                    }
                } else {
                    format!("could not understand: '{line}'")
                }
            }
        }
    }

    fn resolve_input(name: &str) -> Option<InputField> {
        let ty = variables::input_type(name)?;
        let key = match Register::parse(name) {
            Some(Register::InputInt(i)) => key(K_IN_INT, i),
            Some(Register::InputDouble(i)) => key(K_IN_DOUBLE, i),
            Some(Register::InputBit(i)) => key(K_IN_BIT, i),
            Some(_) => return None,
            None => key(
                K_NAMED_INPUT,
                variables::INPUTS.iter().position(|(n, _)| *n == name)?,
            ),
        };
        Some(InputField { key, ty })
    }
}

impl Controller for VirtualController {
    type Snapshot = Snapshot;

    fn version(&self) -> ControllerVersion {
        self.version
    }

    fn control_frequency(&self) -> f64 {
        1.0 / self.period.as_secs_f64()
    }

    fn resolve_output(&self, name: &str) -> Option<OutputField> {
        let ty = variables::output_type(name)?;
        let key = match Register::parse(name) {
            Some(Register::OutputInt(i)) => key(K_OUT_INT, i),
            Some(Register::OutputDouble(i)) => key(K_OUT_DOUBLE, i),
            Some(Register::OutputBit(i)) => key(K_OUT_BIT, i),
            Some(Register::InputInt(i)) => key(K_IN_INT, i),
            Some(Register::InputDouble(i)) => key(K_IN_DOUBLE, i),
            Some(Register::InputBit(i)) => key(K_IN_BIT, i),
            None => match QUANTITIES.iter().position(|(n, _)| *n == name) {
                Some(i) => key(K_QUANTITY, i),
                None => key(
                    K_CONSTANT,
                    variables::OUTPUTS.iter().position(|(n, _)| *n == name)?,
                ),
            },
        };
        Some(OutputField { key, ty })
    }

    fn output_value(&self, s: &Snapshot, key: u32) -> Value {
        let index = (key & 0xffff) as usize;
        let bit = |bits: u128, i: usize| Value::Bool(bits >> i & 1 == 1);
        match key >> 16 {
            K_OUT_INT => Value::Int32(s.regs.output_int[index]),
            K_OUT_DOUBLE => Value::Double(s.regs.output_double[index]),
            K_OUT_BIT => bit(s.regs.output_bits, index),
            K_IN_INT => Value::Int32(s.regs.input_int[index]),
            K_IN_DOUBLE => Value::Double(s.regs.input_double[index]),
            K_IN_BIT => bit(s.regs.input_bits, index),
            K_CONSTANT => {
                let (name, ty) = variables::OUTPUTS[index];
                constant_value(name, ty)
            }
            _ => {
                let q = QUANTITIES[index].1;
                let a = &s.arm;
                match q {
                    Quantity::Timestamp => Value::Double(s.timestamp),
                    Quantity::TargetQ => Value::Vector6d(a.target_q),
                    Quantity::TargetQd => Value::Vector6d(a.target_qd),
                    Quantity::TargetQdd => Value::Vector6d(a.target_qdd),
                    Quantity::ActualQ => Value::Vector6d(a.q),
                    Quantity::ActualQd => Value::Vector6d(a.qd),
                    Quantity::ActualTcpPose => Value::Vector6d(a.tcp_pose),
                    Quantity::TargetTcpPose => Value::Vector6d(a.target_tcp_pose),
                    Quantity::ActualTcpSpeed | Quantity::TargetTcpSpeed => {
                        Value::Vector6d(a.tcp_speed)
                    }
                    Quantity::RobotMode => Value::Int32(s.robot_mode.ur_code()),
                    Quantity::SafetyMode => Value::Int32(s.safety_mode.ur_code()),
                    Quantity::RuntimeState => Value::Uint32(s.runtime_state.to_u32()),
                    Quantity::RobotStatusBits => Value::Uint32(s.robot_status_bits()),
                    Quantity::SafetyStatusBits => Value::Uint32(s.safety_status_bits()),
                    Quantity::SpeedScaling | Quantity::TargetSpeedFraction => {
                        Value::Double(s.io.speed_slider)
                    }
                    Quantity::DigitalOutputBits => Value::Uint64(s.io.digital_output_bits()),
                    Quantity::StandardDo => Value::Uint8(s.io.standard_do),
                    Quantity::ToolDo => Value::Uint8(s.io.tool_do),
                    Quantity::ConfigurableDo => Value::Uint8(s.io.configurable_do),
                    Quantity::JointMode => Value::Vector6Int32([joint_mode(s.robot_mode); 6]),
                    Quantity::InputBitsLow => Value::Uint32(s.regs.input_bits as u32),
                    Quantity::InputBitsHigh => Value::Uint32((s.regs.input_bits >> 32) as u32),
                    Quantity::OutputBitsLow => Value::Uint32(s.regs.output_bits as u32),
                    Quantity::OutputBitsHigh => Value::Uint32((s.regs.output_bits >> 32) as u32),
                    Quantity::AnalogOut0 => Value::Double(s.io.analog_out[0]),
                    Quantity::AnalogOut1 => Value::Double(s.io.analog_out[1]),
                    Quantity::Payload => Value::Double(s.payload.mass),
                    Quantity::PayloadCog => Value::Vector3d(s.payload.cog),
                    Quantity::PayloadInertia => Value::Vector6d(s.payload.inertia),
                    Quantity::TcpOffset => Value::Vector6d(s.tcp_offset),
                    Quantity::TargetMoment => Value::Vector6d(s.target_moment),
                    Quantity::TargetCurrent => Value::Vector6d(s.target_current),
                    Quantity::ActualCurrent => Value::Vector6d(s.actual_current),
                    Quantity::ActualCurrentAsTorque => Value::Vector6d(s.actual_current_as_torque),
                    Quantity::ActualTcpForce => Value::Vector6d(s.tcp_force),
                    Quantity::FtRawWrench => Value::Vector6d(s.ft_raw_wrench),
                }
            }
        }
    }

    fn cycle(&self, snapshot: &Snapshot) -> u64 {
        snapshot.cycle
    }

    fn subscribe(&self) -> watch::Receiver<Arc<Snapshot>> {
        self.snapshots.subscribe()
    }

    fn claim_input(&self, conn: ConnId, name: &str) -> Result<InputField, Slot> {
        let field = Self::resolve_input(name).ok_or(Slot::NotFound)?;
        let mut core = self.lock();
        match core.owners.get(&field.key) {
            Some(owner) if *owner != conn => Err(Slot::InUse),
            _ => {
                core.owners.insert(field.key, conn);
                Ok(field)
            }
        }
    }

    fn write_inputs(&self, _conn: ConnId, fields: &[InputField], values: &[Value]) {
        let mut core = self.lock();
        if fields.iter().any(|f| f.key == key(K_IN_INT, 0)) {
            let now = core.time;
            if let Some(w) = core.watchdog.as_mut() {
                w.last = now;
            }
            core.regs.command_doubles = fields
                .iter()
                .filter(|f| f.key >> 16 == K_IN_DOUBLE)
                .fold(0, |bits, f| bits | 1 << (f.key & 0xffff));
        }
        let mut named: [Option<Value>; 16] = [None; 16];
        for (f, v) in fields.iter().zip(values) {
            let index = (f.key & 0xffff) as usize;
            match (f.key >> 16, *v) {
                (K_IN_INT, Value::Int32(x)) => core.regs.input_int[index] = x,
                (K_IN_DOUBLE, Value::Double(x)) => core.regs.input_double[index] = x,
                (K_IN_BIT, Value::Bool(b)) => {
                    core.regs.input_bits =
                        (core.regs.input_bits & !(1 << index)) | (u128::from(b) << index)
                }
                (K_NAMED_INPUT, v) if index < named.len() => named[index] = Some(v),
                _ => {}
            }
        }
        let get = |name: &str| {
            variables::INPUTS
                .iter()
                .position(|(n, _)| *n == name)
                .and_then(|i| named.get(i).copied().flatten())
        };
        if get("external_force_torque").is_some() && core.program.is_some() {
            // ur_rtde's setExternalForceTorque: the model has no force control to feed.
            let e = "virtual-ur: external_force_torque input is not simulated (no force control)";
            tracing::warn!("{e}");
            core.log(e.into());
            Self::stop_program(&mut core);
        }
        let masked = |old: u8, mask: Option<Value>, value: Option<Value>| match (mask, value) {
            (Some(Value::Uint8(m)), Some(Value::Uint8(v))) => (old & !m) | (v & m),
            _ => old,
        };
        let core = &mut *core;
        let before = core.io.digital_output_bits();
        let io = &mut core.io;
        io.standard_do = masked(
            io.standard_do,
            get("standard_digital_output_mask"),
            get("standard_digital_output"),
        );
        io.configurable_do = masked(
            io.configurable_do,
            get("configurable_digital_output_mask"),
            get("configurable_digital_output"),
        );
        io.tool_do = masked(
            io.tool_do,
            get("tool_digital_output_mask"),
            get("tool_digital_output"),
        ) & 0b11;
        let after = io.digital_output_bits();
        notify_output_changes(core.arm.as_mut(), before, after);
        if let (Some(Value::Uint32(1)), Some(Value::Double(f))) =
            (get("speed_slider_mask"), get("speed_slider_fraction"))
            && f.is_finite()
        {
            io.speed_slider = f.clamp(0.0, 1.0);
        }
        if let Some(Value::Uint8(mask)) = get("standard_analog_output_mask") {
            let domain = match get("standard_analog_output_type") {
                Some(Value::Uint8(t)) => t,
                _ => 0,
            };
            for i in 0..2 {
                if mask >> i & 1 == 1
                    && let Some(Value::Double(ratio)) =
                        get(["standard_analog_output_0", "standard_analog_output_1"][i])
                {
                    io.analog_voltage[i] = domain >> i & 1 == 1;
                    if ratio.is_finite() {
                        set_analog_output(io, core.arm.as_mut(), i, ratio.clamp(0.0, 1.0));
                    }
                }
            }
        }
        if let Some(Value::Uint32(bits)) = get("input_bit_registers0_to_31") {
            core.regs.input_bits = (core.regs.input_bits & !0xffff_ffff) | u128::from(bits);
        }
        if let Some(Value::Uint32(bits)) = get("input_bit_registers32_to_63") {
            core.regs.input_bits =
                (core.regs.input_bits & !(0xffff_ffff << 32)) | (u128::from(bits) << 32);
        }
    }

    fn disconnected(&self, conn: ConnId) {
        self.lock().owners.retain(|_, owner| *owner != conn);
    }
}
