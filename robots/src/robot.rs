//! The one seam between the orchestrator and an arm: the [`Robot`] trait, its status and errors.
//!
//! # Why boxed futures
//! The methods return [`RobotFuture`], a pinned, boxed, `Send` future, instead of being
//! `async fn`. An `async fn` (or `-> impl Future`) in a trait makes it not dyn-compatible, and the
//! orchestrator picks the implementation at run time (`--robot sim` or `--robot ur://HOST`), so it
//! needs `Box<dyn Robot>` / `&mut dyn Robot`. Boxing costs one allocation per command, nothing
//! next to a motion that lasts seconds. Generic code (`R: Robot`) works as well, and `Send`
//! futures run on tokio's multi-threaded runtime. Implementations write
//! `Box::pin(async move { ... })`.
//!
//! Implementations do not check limits themselves: every construction site wraps its robot in
//! [`crate::limited::Limited`], which checks each target against the [`Limits`] before it is
//! passed on and fails with [`RobotError::LimitViolation`] instead of moving.
//! A rig that only watches the commands (counts motions, records where the arm went) wraps its
//! robot in [`crate::observed::Observed`] instead of writing out the trait again.

use nalgebra::Isometry3;
use serde::{Deserialize, Serialize};
use std::future::Future;
use std::pin::Pin;
use std::time::Duration;
use thiserror::Error;

use crate::kinematics::{IkError, Joints};
use crate::limits::{LimitViolation, Limits};
pub use crate::motion::{JointMotion, LinearMotion};

/// The future every [`Robot`] method returns.
pub type RobotFuture<'a, T> = Pin<Box<dyn Future<Output = Result<T, RobotError>> + Send + 'a>>;

/// The arm's power and control state (UR `robot_mode`): the one type for it, on RTDE, the
/// dashboard (words in [`crate::dashboard`]) and the virtual controller alike.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RobotMode {
    /// No controller is running.
    NoController,
    /// The controller is not connected to the arm.
    Disconnected,
    /// Safety configuration awaits confirmation.
    ConfirmSafety,
    /// The arm is booting.
    Booting,
    /// The arm is powered off.
    PowerOff,
    /// The arm is powered on, brakes engaged.
    PowerOn,
    /// Powered, brakes released, not running a program.
    Idle,
    /// Backdrive mode (brakes released by hand).
    Backdrive,
    /// Running: ready to move.
    Running,
    /// Updating firmware.
    UpdatingFirmware,
}

impl RobotMode {
    /// The mode for a UR `robot_mode` code (−1 … 8), if known.
    pub fn from_ur_code(code: i32) -> Option<Self> {
        use RobotMode::*;
        Some(match code {
            -1 => NoController,
            0 => Disconnected,
            1 => ConfirmSafety,
            2 => Booting,
            3 => PowerOff,
            4 => PowerOn,
            5 => Idle,
            6 => Backdrive,
            7 => Running,
            8 => UpdatingFirmware,
            _ => return None,
        })
    }

    /// The UR `robot_mode` code of this mode.
    pub fn ur_code(self) -> i32 {
        use RobotMode::*;
        match self {
            NoController => -1,
            Disconnected => 0,
            ConfirmSafety => 1,
            Booting => 2,
            PowerOff => 3,
            PowerOn => 4,
            Idle => 5,
            Backdrive => 6,
            Running => 7,
            UpdatingFirmware => 8,
        }
    }
}

/// The arm's safety state (UR `safety_mode`): the one type for it, on RTDE, the dashboard
/// (words in [`crate::dashboard`]) and the virtual controller alike.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SafetyStatus {
    /// Normal operation.
    Normal,
    /// Reduced mode: tighter safety limits, still moving.
    Reduced,
    /// Protective stop: the arm stopped itself (collision, limit); must be unlocked.
    ProtectiveStop,
    /// Recovery mode: the arm is outside its safety limits and may only move back in.
    Recovery,
    /// Safeguard stop from a safety input (light curtain, door).
    SafeguardStop,
    /// Emergency stop from the system (cell) e-stop input.
    SystemEmergencyStop,
    /// Emergency stop from the teach pendant or arm e-stop button.
    RobotEmergencyStop,
    /// Safety system violation.
    Violation,
    /// Safety system fault.
    Fault,
}

impl SafetyStatus {
    /// The status for a UR `safety_mode` code (1 … 9), if known.
    pub fn from_ur_code(code: i32) -> Option<Self> {
        use SafetyStatus::*;
        Some(match code {
            1 => Normal,
            2 => Reduced,
            3 => ProtectiveStop,
            4 => Recovery,
            5 => SafeguardStop,
            6 => SystemEmergencyStop,
            7 => RobotEmergencyStop,
            8 => Violation,
            9 => Fault,
            _ => return None,
        })
    }

    /// The UR `safety_mode` code of this status.
    pub fn ur_code(self) -> i32 {
        use SafetyStatus::*;
        match self {
            Normal => 1,
            Reduced => 2,
            ProtectiveStop => 3,
            Recovery => 4,
            SafeguardStop => 5,
            SystemEmergencyStop => 6,
            RobotEmergencyStop => 7,
            Violation => 8,
            Fault => 9,
        }
    }

    /// True for either emergency stop.
    pub fn is_emergency_stop(self) -> bool {
        matches!(self, Self::SystemEmergencyStop | Self::RobotEmergencyStop)
    }

    /// True when the safety system lets the arm execute motions.
    pub fn allows_motion(self) -> bool {
        matches!(self, Self::Normal | Self::Reduced)
    }

    /// The error a motion fails with in this state, if it cannot run.
    pub fn motion_error(self) -> Option<RobotError> {
        match self {
            Self::Normal | Self::Reduced => None,
            Self::ProtectiveStop => Some(RobotError::ProtectiveStop),
            s if s.is_emergency_stop() => Some(RobotError::EmergencyStop { safety: s }),
            s => Some(RobotError::SafetyStop { safety: s }),
        }
    }
}

/// A snapshot of the arm's state.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct RobotStatus {
    /// Power and control state.
    pub mode: RobotMode,
    /// Safety state.
    pub safety: SafetyStatus,
    /// Whether the controller program that executes our commands is running.
    pub program_running: bool,
}

impl RobotStatus {
    /// True when the arm can execute a motion now.
    pub fn ready(&self) -> bool {
        self.mode == RobotMode::Running && self.safety.allows_motion() && self.program_running
    }
}

/// Why a robot command failed.
#[derive(Debug, Error)]
pub enum RobotError {
    /// The arm is in (or went into) a protective stop.
    #[error("robot is in a protective stop")]
    ProtectiveStop,
    /// An emergency stop is active.
    #[error("emergency stop active ({safety:?})")]
    EmergencyStop {
        /// Which emergency stop.
        safety: SafetyStatus,
    },
    /// Another safety state forbids motion (safeguard stop, recovery, violation, fault).
    #[error("safety system forbids motion ({safety:?})")]
    SafetyStop {
        /// The safety state.
        safety: SafetyStatus,
    },
    /// The arm is not ready to move (powered off, idle, program not running).
    #[error("robot not ready: mode {mode:?}, program running: {program_running}")]
    NotReady {
        /// Its mode.
        mode: RobotMode,
        /// Whether our program runs.
        program_running: bool,
    },
    /// The connection to the controller was lost or broke.
    #[error("connection to the robot lost: {detail}")]
    ConnectionLost {
        /// What happened.
        detail: String,
    },
    /// An operation did not finish in time.
    #[error("{operation} timed out after {after:?}")]
    Timeout {
        /// What timed out.
        operation: String,
        /// The time allowed.
        after: Duration,
    },
    /// The target or motion violates the cell's limits; nothing was sent.
    #[error("limit violation: {0}")]
    LimitViolation(#[from] LimitViolation),
    /// The target pose has no joint solution.
    #[error("target unreachable: {0}")]
    Unreachable(#[from] IkError),
    /// The controller refused or failed the command for another reason.
    #[error("robot rejected the command: {detail}")]
    Rejected {
        /// The controller's reason.
        detail: String,
    },
}

/// A wrench as six numbers: force (N) then moment (N·m).
pub type Wrench = [f64; 6];

/// One wrist reading along a guarded move: when, where the TCP was, and what the wrist felt.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ContactSample {
    /// Seconds since the guarded move began.
    pub t: f64,
    /// TCP position, base frame, metres.
    pub tcp: [f64; 3],
    /// The wrist's reading there (as [`ContactOutcome::wrench`]).
    pub wrench: Wrench,
}

/// How a guarded move ([`Robot::move_until_contact`]) ended.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[allow(non_snake_case)]
pub struct ContactOutcome {
    /// Where the TCP stopped, `base_T_tcp` (measured).
    pub stopped_at: Isometry3<f64>,
    /// The wrist's reading when it stopped: the external wrench on the tool in the base frame,
    /// at the TCP (UR's `actual_TCP_force`: pressing down on a surface reads `+Fz`).
    pub wrench: Wrench,
    /// True when the move stopped on contact (the force against the motion reached the limit);
    /// false when it reached its target without.
    pub contact: bool,
    /// The wrist's readings along the move, in time order (empty where the robot keeps none).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub trace: Vec<ContactSample>,
}

impl ContactOutcome {
    /// The reading's force component along `direction` (base frame, normalised here).
    pub fn force_along(&self, direction: &nalgebra::Vector3<f64>) -> f64 {
        let f = nalgebra::Vector3::new(self.wrench[0], self.wrench[1], self.wrench[2]);
        f.dot(&direction.normalize())
    }
}

/// Where a blended path's via-point is and how the arm gets there.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WaypointTarget {
    /// Joint positions (rad), reached by a joint-space move (URScript `movej`): speed in rad/s,
    /// acceleration in rad/s².
    Joints(Joints),
    /// A TCP pose `base_T_tcp`, reached in a straight tool line (URScript `movel`): speed in
    /// m/s, acceleration in m/s².
    Linear(Isometry3<f64>),
}

/// One via-point of a blended path ([`Robot::move_path`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Waypoint {
    /// The via-point and the kind of move to it.
    pub target: WaypointTarget,
    /// Speed of the move to it (rad/s for joints, m/s for a tool line).
    pub speed: f64,
    /// Acceleration of the move to it (rad/s² or m/s²).
    pub acceleration: f64,
    /// Blend radius around it (m, measured at the TCP): within it the arm starts the next move
    /// instead of stopping. 0 stops at the via-point; the last via-point's radius must be 0.
    pub blend: f64,
}

impl Waypoint {
    /// A joint-space via-point.
    pub fn joints(q: Joints, motion: JointMotion, blend: f64) -> Waypoint {
        Waypoint {
            target: WaypointTarget::Joints(q),
            speed: motion.speed,
            acceleration: motion.acceleration,
            blend,
        }
    }

    /// A straight-line via-point.
    #[allow(non_snake_case)]
    pub fn linear(base_T_tcp: Isometry3<f64>, motion: LinearMotion, blend: f64) -> Waypoint {
        Waypoint {
            target: WaypointTarget::Linear(base_T_tcp),
            speed: motion.speed,
            acceleration: motion.acceleration,
            blend,
        }
    }
}

/// An arm the orchestrator commands: a UR over RTDE, or the in-process simulated cell.
///
/// Motions complete (or fail) before their future resolves. All poses are in the robot's base
/// frame; `tcp` is the tool centre point the implementation was configured with.
pub trait Robot: Send {
    /// The limits every target is checked against before it is sent.
    fn limits(&self) -> &Limits;

    /// Current measured joint angles (rad).
    fn joints(&mut self) -> RobotFuture<'_, Joints>;

    /// Current measured TCP pose, `base_T_tcp`.
    fn tcp_pose(&mut self) -> RobotFuture<'_, Isometry3<f64>>;

    /// Moves in joint space to `target`.
    fn move_j(&mut self, target: Joints, motion: JointMotion) -> RobotFuture<'_, ()>;

    /// Moves the TCP in a straight line to `base_T_tcp`.
    #[allow(non_snake_case)]
    fn move_l(&mut self, base_T_tcp: Isometry3<f64>, motion: LinearMotion) -> RobotFuture<'_, ()>;

    /// Runs a blended path through `path`'s via-points (a URScript `movej`/`movel` sequence
    /// with blend radii): the arm rounds each corner within its via-point's radius instead of
    /// stopping, and stops at the last. Completes when the arm rests at the last via-point.
    fn move_path(&mut self, path: Vec<Waypoint>) -> RobotFuture<'_, ()>;

    /// Opens the gripper the full stroke and waits until it is open.
    fn open_gripper(&mut self) -> RobotFuture<'_, ()>;

    /// Opens the fingers to `width` metres apart (at most the stroke): a grasp opens no wider
    /// than its part needs, so close neighbours leave room. A release waits until they are
    /// there; empty fingers may move while the arm goes on, the next motion ending no earlier
    /// than they arrive. A gripper without a width set-point opens the full stroke.
    fn open_gripper_to(&mut self, width: f64) -> RobotFuture<'_, ()>;

    /// Closes the gripper and waits until it stops (on the part or fully closed).
    fn close_gripper(&mut self) -> RobotFuture<'_, ()>;

    /// Stops any motion (decelerating within the limits) and waits until the arm is still.
    fn stop(&mut self) -> RobotFuture<'_, ()>;

    /// Mode, safety state and whether our program runs.
    fn status(&mut self) -> RobotFuture<'_, RobotStatus>;

    /// A guarded straight-line move towards `base_T_tcp` (UR's `moveUntilContact`): stops as
    /// soon as the wrist feels more than `force_limit` newtons against the direction of motion,
    /// or at the target when nothing is met. A robot without a force sensor fails with
    /// [`RobotError::Rejected`].
    #[allow(non_snake_case)]
    fn move_until_contact(
        &mut self,
        base_T_tcp: Isometry3<f64>,
        motion: LinearMotion,
        force_limit: f64,
    ) -> RobotFuture<'_, ContactOutcome>;

    /// The wrist's present reading: the external wrench on the tool, base frame, at the TCP
    /// (UR's `actual_TCP_force`). A robot without a force sensor fails with
    /// [`RobotError::Rejected`].
    fn wrench(&mut self) -> RobotFuture<'_, Wrench>;
}

/// Forwards every method to the robot behind a pointer, so a decorator such as
/// [`crate::limited::Limited`] can wrap a borrowed or boxed robot.
macro_rules! forward_robot {
    ($ty:ty) => {
        impl<R: Robot + ?Sized> Robot for $ty {
            fn limits(&self) -> &Limits {
                (**self).limits()
            }
            fn joints(&mut self) -> RobotFuture<'_, Joints> {
                (**self).joints()
            }
            fn tcp_pose(&mut self) -> RobotFuture<'_, Isometry3<f64>> {
                (**self).tcp_pose()
            }
            fn move_j(&mut self, target: Joints, motion: JointMotion) -> RobotFuture<'_, ()> {
                (**self).move_j(target, motion)
            }
            #[allow(non_snake_case)]
            fn move_l(
                &mut self,
                base_T_tcp: Isometry3<f64>,
                motion: LinearMotion,
            ) -> RobotFuture<'_, ()> {
                (**self).move_l(base_T_tcp, motion)
            }
            fn move_path(&mut self, path: Vec<Waypoint>) -> RobotFuture<'_, ()> {
                (**self).move_path(path)
            }
            fn open_gripper(&mut self) -> RobotFuture<'_, ()> {
                (**self).open_gripper()
            }
            fn open_gripper_to(&mut self, width: f64) -> RobotFuture<'_, ()> {
                (**self).open_gripper_to(width)
            }
            fn close_gripper(&mut self) -> RobotFuture<'_, ()> {
                (**self).close_gripper()
            }
            fn stop(&mut self) -> RobotFuture<'_, ()> {
                (**self).stop()
            }
            fn status(&mut self) -> RobotFuture<'_, RobotStatus> {
                (**self).status()
            }
            #[allow(non_snake_case)]
            fn move_until_contact(
                &mut self,
                base_T_tcp: Isometry3<f64>,
                motion: LinearMotion,
                force_limit: f64,
            ) -> RobotFuture<'_, ContactOutcome> {
                (**self).move_until_contact(base_T_tcp, motion, force_limit)
            }
            fn wrench(&mut self) -> RobotFuture<'_, Wrench> {
                (**self).wrench()
            }
        }
    };
}

forward_robot!(&mut R);
forward_robot!(Box<R>);

#[cfg(test)]
mod tests {
    use super::*;

    // The trait must stay dyn-compatible and its futures Send.
    const _: fn(&mut dyn Robot) = |_| {};
    const _: fn(Box<dyn Robot>) = |_| {};
    fn _futures_are_send(robot: &mut dyn Robot) -> impl Send + '_ {
        robot.status()
    }

    #[test]
    fn ur_codes_round_trip() {
        for code in -1..=8 {
            assert_eq!(RobotMode::from_ur_code(code).unwrap().ur_code(), code);
        }
        assert_eq!(RobotMode::from_ur_code(9), None);
        for code in 1..=9 {
            assert_eq!(SafetyStatus::from_ur_code(code).unwrap().ur_code(), code);
        }
        assert_eq!(SafetyStatus::from_ur_code(0), None);
    }

    #[test]
    fn safety_states_map_to_typed_errors() {
        assert!(SafetyStatus::Normal.motion_error().is_none());
        assert!(SafetyStatus::Reduced.motion_error().is_none());
        assert!(matches!(
            SafetyStatus::ProtectiveStop.motion_error(),
            Some(RobotError::ProtectiveStop)
        ));
        assert!(matches!(
            SafetyStatus::RobotEmergencyStop.motion_error(),
            Some(RobotError::EmergencyStop { .. })
        ));
        assert!(matches!(
            SafetyStatus::SafeguardStop.motion_error(),
            Some(RobotError::SafetyStop { .. })
        ));
        let status = RobotStatus {
            mode: RobotMode::Running,
            safety: SafetyStatus::Normal,
            program_running: true,
        };
        assert!(status.ready());
        assert!(
            !RobotStatus {
                program_running: false,
                ..status
            }
            .ready()
        );
    }
}
