//! The runtime-state enumeration, status bits and the newest output state seen by a client.
//!
//! `robot_mode` and `safety_mode` decode into the crate's one [`RobotMode`] and [`SafetyStatus`]
//! (from [`crate::robot`]); a code those do not know reads as `None`.

use super::recipe::Recipe;
use super::types::Value;
use crate::robot::{RobotMode, SafetyStatus};
use std::sync::Arc;
use std::time::Instant;

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

    /// `robot_mode`, when in the recipe and a known code.
    pub fn robot_mode(&self) -> Option<RobotMode> {
        RobotMode::from_ur_code(i32::try_from(self.i64("robot_mode")?).ok()?)
    }

    /// `safety_mode`, when in the recipe and a known code.
    pub fn safety_mode(&self) -> Option<SafetyStatus> {
        SafetyStatus::from_ur_code(i32::try_from(self.i64("safety_mode")?).ok()?)
    }

    /// `runtime_state`, when in the recipe.
    pub fn runtime_state(&self) -> Option<RuntimeState> {
        self.i64("runtime_state")
            .map(|v| RuntimeState::from_u32(v as u32))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rtde::types::DataType;

    fn state(robot_mode: i32, safety_mode: i32) -> OutputState {
        let names = vec!["robot_mode".to_owned(), "safety_mode".to_owned()];
        OutputState {
            recipe: Arc::new(Recipe::new(1, names, vec![DataType::Int32; 2])),
            values: vec![Value::Int32(robot_mode), Value::Int32(safety_mode)],
            received_at: Instant::now(),
        }
    }

    #[test]
    fn known_codes_decode_and_unknown_ones_read_as_none() {
        let s = state(7, 3);
        assert_eq!(s.robot_mode(), Some(RobotMode::Running));
        assert_eq!(s.safety_mode(), Some(SafetyStatus::ProtectiveStop));
        let s = state(42, 0);
        assert_eq!(s.robot_mode(), None);
        assert_eq!(s.safety_mode(), None);
        let s = state(-1, 9);
        assert_eq!(s.robot_mode(), Some(RobotMode::NoController));
        assert_eq!(s.safety_mode(), Some(SafetyStatus::Fault));
        assert_eq!(s.runtime_state(), None, "not in the recipe");
    }
}
