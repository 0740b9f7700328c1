//! Robot, safety and runtime enumerations and the newest output state seen by a client.

use super::recipe::Recipe;
use super::types::Value;
use std::sync::Arc;
use std::time::Instant;

/// `robot_mode`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RobotMode {
    /// −1.
    NoController,
    /// 0.
    Disconnected,
    /// 1.
    ConfirmSafety,
    /// 2.
    Booting,
    /// 3.
    PowerOff,
    /// 4.
    PowerOn,
    /// 5.
    Idle,
    /// 6.
    Backdrive,
    /// 7.
    Running,
    /// Any other value.
    Unknown(i32),
}

impl RobotMode {
    /// From the wire value.
    pub fn from_i32(v: i32) -> RobotMode {
        match v {
            -1 => RobotMode::NoController,
            0 => RobotMode::Disconnected,
            1 => RobotMode::ConfirmSafety,
            2 => RobotMode::Booting,
            3 => RobotMode::PowerOff,
            4 => RobotMode::PowerOn,
            5 => RobotMode::Idle,
            6 => RobotMode::Backdrive,
            7 => RobotMode::Running,
            other => RobotMode::Unknown(other),
        }
    }

    /// To the wire value.
    pub fn to_i32(self) -> i32 {
        match self {
            RobotMode::NoController => -1,
            RobotMode::Disconnected => 0,
            RobotMode::ConfirmSafety => 1,
            RobotMode::Booting => 2,
            RobotMode::PowerOff => 3,
            RobotMode::PowerOn => 4,
            RobotMode::Idle => 5,
            RobotMode::Backdrive => 6,
            RobotMode::Running => 7,
            RobotMode::Unknown(v) => v,
        }
    }

    /// The dashboard's word for it (`robotmode` reply).
    pub fn dashboard_name(self) -> &'static str {
        match self {
            RobotMode::NoController => "NO_CONTROLLER",
            RobotMode::Disconnected => "DISCONNECTED",
            RobotMode::ConfirmSafety => "CONFIRM_SAFETY",
            RobotMode::Booting => "BOOTING",
            RobotMode::PowerOff => "POWER_OFF",
            RobotMode::PowerOn => "POWER_ON",
            RobotMode::Idle => "IDLE",
            RobotMode::Backdrive => "BACKDRIVE",
            RobotMode::Running => "RUNNING",
            RobotMode::Unknown(_) => "UNKNOWN",
        }
    }

    /// Parses the dashboard's word.
    pub fn from_dashboard_name(s: &str) -> Option<RobotMode> {
        (-1..=7)
            .map(RobotMode::from_i32)
            .find(|m| m.dashboard_name() == s)
    }
}

/// `safety_mode`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SafetyMode {
    /// 1.
    Normal,
    /// 2.
    Reduced,
    /// 3.
    ProtectiveStop,
    /// 4.
    Recovery,
    /// 5.
    SafeguardStop,
    /// 6.
    SystemEmergencyStop,
    /// 7.
    RobotEmergencyStop,
    /// 8.
    Violation,
    /// 9.
    Fault,
    /// Any other value.
    Unknown(i32),
}

impl SafetyMode {
    /// From the wire value.
    pub fn from_i32(v: i32) -> SafetyMode {
        match v {
            1 => SafetyMode::Normal,
            2 => SafetyMode::Reduced,
            3 => SafetyMode::ProtectiveStop,
            4 => SafetyMode::Recovery,
            5 => SafetyMode::SafeguardStop,
            6 => SafetyMode::SystemEmergencyStop,
            7 => SafetyMode::RobotEmergencyStop,
            8 => SafetyMode::Violation,
            9 => SafetyMode::Fault,
            other => SafetyMode::Unknown(other),
        }
    }

    /// To the wire value.
    pub fn to_i32(self) -> i32 {
        match self {
            SafetyMode::Normal => 1,
            SafetyMode::Reduced => 2,
            SafetyMode::ProtectiveStop => 3,
            SafetyMode::Recovery => 4,
            SafetyMode::SafeguardStop => 5,
            SafetyMode::SystemEmergencyStop => 6,
            SafetyMode::RobotEmergencyStop => 7,
            SafetyMode::Violation => 8,
            SafetyMode::Fault => 9,
            SafetyMode::Unknown(v) => v,
        }
    }

    /// The dashboard's word for it (`safetystatus` reply).
    pub fn dashboard_name(self) -> &'static str {
        match self {
            SafetyMode::Normal => "NORMAL",
            SafetyMode::Reduced => "REDUCED",
            SafetyMode::ProtectiveStop => "PROTECTIVE_STOP",
            SafetyMode::Recovery => "RECOVERY",
            SafetyMode::SafeguardStop => "SAFEGUARD_STOP",
            SafetyMode::SystemEmergencyStop => "SYSTEM_EMERGENCY_STOP",
            SafetyMode::RobotEmergencyStop => "ROBOT_EMERGENCY_STOP",
            SafetyMode::Violation => "VIOLATION",
            SafetyMode::Fault => "FAULT",
            SafetyMode::Unknown(_) => "UNKNOWN",
        }
    }

    /// Parses the dashboard's word.
    pub fn from_dashboard_name(s: &str) -> Option<SafetyMode> {
        (1..=9)
            .map(SafetyMode::from_i32)
            .find(|m| m.dashboard_name() == s)
    }

    /// Whether the arm is halted by a stop of any kind (protective, safeguard, e-stop, fault).
    pub fn is_stopped(self) -> bool {
        !matches!(self, SafetyMode::Normal | SafetyMode::Reduced)
    }
}

/// `runtime_state`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RuntimeState {
    /// 0.
    Stopping,
    /// 1.
    Stopped,
    /// 2.
    Playing,
    /// 3.
    Pausing,
    /// 4.
    Paused,
    /// 5.
    Resuming,
    /// Any other value.
    Unknown(u32),
}

impl RuntimeState {
    /// From the wire value.
    pub fn from_u32(v: u32) -> RuntimeState {
        match v {
            0 => RuntimeState::Stopping,
            1 => RuntimeState::Stopped,
            2 => RuntimeState::Playing,
            3 => RuntimeState::Pausing,
            4 => RuntimeState::Paused,
            5 => RuntimeState::Resuming,
            other => RuntimeState::Unknown(other),
        }
    }

    /// To the wire value.
    pub fn to_u32(self) -> u32 {
        match self {
            RuntimeState::Stopping => 0,
            RuntimeState::Stopped => 1,
            RuntimeState::Playing => 2,
            RuntimeState::Pausing => 3,
            RuntimeState::Paused => 4,
            RuntimeState::Resuming => 5,
            RuntimeState::Unknown(v) => v,
        }
    }
}

/// `safety_status_bits` bit: protective stopped.
pub const SAFETY_BIT_PROTECTIVE_STOPPED: u32 = 1 << 2;
/// `safety_status_bits` bit: emergency stopped.
pub const SAFETY_BIT_EMERGENCY_STOPPED: u32 = 1 << 7;
/// `robot_status_bits` bit: program running.
pub const ROBOT_BIT_PROGRAM_RUNNING: u32 = 1 << 1;

/// One decoded output data package, as a client sees it.
#[derive(Debug, Clone)]
pub struct OutputState {
    /// The output recipe the values follow.
    pub recipe: Arc<Recipe>,
    /// Values in recipe order.
    pub values: Vec<Value>,
    /// When the package arrived.
    pub received_at: Instant,
}

impl OutputState {
    /// A variable's value by name.
    pub fn get(&self, name: &str) -> Option<Value> {
        self.recipe
            .index_of(name)
            .and_then(|i| self.values.get(i).copied())
    }

    /// A scalar variable as f64.
    pub fn f64(&self, name: &str) -> Option<f64> {
        self.get(name)?.as_f64()
    }

    /// An integer variable as i64.
    pub fn i64(&self, name: &str) -> Option<i64> {
        self.get(name)?.as_i64()
    }

    /// A VECTOR6D variable.
    pub fn vector6d(&self, name: &str) -> Option<[f64; 6]> {
        self.get(name)?.as_vector6d()
    }

    /// `robot_mode`, when in the recipe.
    pub fn robot_mode(&self) -> Option<RobotMode> {
        self.i64("robot_mode")
            .map(|v| RobotMode::from_i32(v as i32))
    }

    /// `safety_mode`, when in the recipe.
    pub fn safety_mode(&self) -> Option<SafetyMode> {
        self.i64("safety_mode")
            .map(|v| SafetyMode::from_i32(v as i32))
    }

    /// `runtime_state`, when in the recipe.
    pub fn runtime_state(&self) -> Option<RuntimeState> {
        self.i64("runtime_state")
            .map(|v| RuntimeState::from_u32(v as u32))
    }
}
