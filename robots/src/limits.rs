//! Cell limits: the workspace box, speeds, accelerations and joint ranges every commanded target
//! is checked against ([`crate::limited::Limited`] does it for every robot).

use nalgebra::{Isometry3, Vector3};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;
use thiserror::Error;

use crate::kinematics::{JointLimits, Joints, UrKinematics};
use crate::motion::{JointMotion, LinearMotion};

/// An axis-aligned box in the robot base frame the TCP must stay in (m).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorkspaceBox {
    /// Lower corner (x, y, z) in metres.
    pub min: [f64; 3],
    /// Upper corner (x, y, z) in metres.
    pub max: [f64; 3],
}

impl WorkspaceBox {
    /// Checks that `point` (base frame, m) lies inside the box.
    pub fn check(&self, point: &Vector3<f64>) -> Result<(), LimitViolation> {
        if !point.iter().all(|v| v.is_finite()) {
            return Err(LimitViolation::NonFinite { what: "TCP target" });
        }
        for (i, axis) in ['x', 'y', 'z'].into_iter().enumerate() {
            let value = point[i];
            if value < self.min[i] || value > self.max[i] {
                return Err(LimitViolation::OutsideWorkspace {
                    axis,
                    value,
                    min: self.min[i],
                    max: self.max[i],
                });
            }
        }
        Ok(())
    }

    /// True when `point` lies inside the box.
    pub fn contains(&self, point: &Vector3<f64>) -> bool {
        self.check(point).is_ok()
    }
}

/// Limits of a cell: where the TCP may go and how fast the arm may move.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Limits {
    /// Box the TCP must stay in (base frame).
    pub workspace: WorkspaceBox,
    /// Largest TCP speed for linear moves (m/s).
    pub max_tcp_speed: f64,
    /// Largest TCP acceleration for linear moves (m/s²).
    pub max_tcp_acceleration: f64,
    /// Largest joint speed for joint moves (rad/s).
    pub max_joint_speed: f64,
    /// Largest joint acceleration for joint moves (rad/s²).
    pub max_joint_acceleration: f64,
    /// Joint position limits (rad); ±2π when omitted.
    #[serde(default)]
    pub joint_positions: JointLimits,
    /// Largest force limit a guarded move may ask for (N): what the cell's parts and fixture
    /// may take; the arm's own protective stop force (150 N) when omitted, and never above it.
    #[serde(default = "default_max_contact_force")]
    pub max_contact_force: f64,
}

/// The arm's protective stop force: a guarded move never asks for more.
fn default_max_contact_force() -> f64 {
    crate::virtual_ur::force::PROTECTIVE_STOP_FORCE
}

impl Default for Limits {
    /// A UR5e on a table: the TCP within 0.85 m of the base in x and y and between 0 and 1 m
    /// high, 0.25 m/s and 1.2 m/s² for linear moves, π rad/s (the UR5e's maximum) and 2π rad/s²
    /// for joint moves, ±2π joint range.
    fn default() -> Self {
        Self {
            workspace: WorkspaceBox {
                min: [-0.85, -0.85, 0.0],
                max: [0.85, 0.85, 1.0],
            },
            max_tcp_speed: 0.25,
            max_tcp_acceleration: 1.2,
            max_joint_speed: PI,
            max_joint_acceleration: 2.0 * PI,
            joint_positions: JointLimits::default(),
            max_contact_force: default_max_contact_force(),
        }
    }
}

/// A target or motion a [`Limits`] check refused: what, and by how much.
#[derive(Clone, Debug, PartialEq, Error)]
pub enum LimitViolation {
    /// A value is NaN or infinite.
    #[error("{what} is not finite")]
    NonFinite {
        /// What was not finite.
        what: &'static str,
    },
    /// The TCP target leaves the workspace box.
    #[error(
        "TCP {axis} = {value:.4} m is {excess:.4} m outside the workspace [{min:.4}, {max:.4}] m",
        excess = outside(*value, *min, *max)
    )]
    OutsideWorkspace {
        /// The axis (x, y or z).
        axis: char,
        /// The target's coordinate (m).
        value: f64,
        /// The box's lower bound on that axis (m).
        min: f64,
        /// The box's upper bound on that axis (m).
        max: f64,
    },
    /// A requested speed or acceleration is not positive.
    #[error("{what} must be positive, got {value}")]
    NotPositive {
        /// Which quantity.
        what: &'static str,
        /// The requested value.
        value: f64,
    },
    /// A guarded move's force limit over the cell's (or the arm's protective stop).
    #[error("contact force limit {requested:.1} N exceeds the limit {max:.1} N")]
    ContactForce {
        /// Requested (N).
        requested: f64,
        /// Limit (N).
        max: f64,
    },
    /// Linear TCP speed over the limit.
    #[error("TCP speed {requested:.4} m/s exceeds the limit {max:.4} m/s by {:.4} m/s", requested - max)]
    TcpSpeed {
        /// Requested (m/s).
        requested: f64,
        /// Limit (m/s).
        max: f64,
    },
    /// Linear TCP acceleration over the limit.
    #[error(
        "TCP acceleration {requested:.4} m/s² exceeds the limit {max:.4} m/s² by {:.4} m/s²",
        requested - max
    )]
    TcpAcceleration {
        /// Requested (m/s²).
        requested: f64,
        /// Limit (m/s²).
        max: f64,
    },
    /// Joint speed over the limit.
    #[error("joint speed {requested:.4} rad/s exceeds the limit {max:.4} rad/s by {:.4} rad/s", requested - max)]
    JointSpeed {
        /// Requested (rad/s).
        requested: f64,
        /// Limit (rad/s).
        max: f64,
    },
    /// Joint acceleration over the limit.
    #[error(
        "joint acceleration {requested:.4} rad/s² exceeds the limit {max:.4} rad/s² by {:.4} rad/s²",
        requested - max
    )]
    JointAcceleration {
        /// Requested (rad/s²).
        requested: f64,
        /// Limit (rad/s²).
        max: f64,
    },
    /// A blended path the arm model refuses to run (a via-point it cannot reach, a motion it
    /// cannot execute exactly): checked like a limit, before anything moves.
    #[error("the arm model refuses the blended path: {detail}")]
    PathRefused {
        /// The arm model's reason.
        detail: String,
    },
    /// A blended path's via-point radius over half of a segment it blends (or non-zero at the
    /// path's end, where nothing follows to blend into).
    #[error(
        "blend radius {radius:.4} m at via-point {index} exceeds {max:.4} m (half the shorter adjacent segment; 0 at the last via-point)"
    )]
    BlendRadius {
        /// Via-point index, 0 = the first.
        index: usize,
        /// The requested radius (m).
        radius: f64,
        /// The largest radius allowed there (m).
        max: f64,
    },
    /// A joint target outside its position limits.
    #[error(
        "joint {} = {value:.4} rad is {excess:.4} rad outside its range [{lower:.4}, {upper:.4}] rad",
        joint + 1,
        excess = outside(*value, *lower, *upper)
    )]
    JointPosition {
        /// Joint index, 0 = base.
        joint: usize,
        /// The target angle (rad).
        value: f64,
        /// Lower limit (rad).
        lower: f64,
        /// Upper limit (rad).
        upper: f64,
    },
}

/// Distance of `value` outside [min, max] (0 inside).
fn outside(value: f64, min: f64, max: f64) -> f64 {
    (min - value).max(value - max).max(0.0)
}

impl LimitViolation {
    /// By how much the limit is exceeded, in the quantity's SI unit (NaN for non-finite input
    /// and for a path the arm model refuses, the requested value for a non-positive one).
    pub fn excess(&self) -> f64 {
        match *self {
            Self::NonFinite { .. } | Self::PathRefused { .. } => f64::NAN,
            Self::OutsideWorkspace {
                value, min, max, ..
            } => outside(value, min, max),
            Self::NotPositive { value, .. } => value,
            Self::TcpSpeed { requested, max }
            | Self::ContactForce { requested, max }
            | Self::TcpAcceleration { requested, max }
            | Self::JointSpeed { requested, max }
            | Self::JointAcceleration { requested, max } => requested - max,
            Self::BlendRadius { radius, max, .. } => radius - max,
            Self::JointPosition {
                value,
                lower,
                upper,
                ..
            } => outside(value, lower, upper),
        }
    }
}

/// Why a [`Limits`] value itself is unusable.
#[derive(Clone, Debug, PartialEq, Error)]
#[error("invalid limits: {field}: {reason}")]
pub struct InvalidLimits {
    /// The offending field.
    pub field: &'static str,
    /// What is wrong with it.
    pub reason: String,
}

fn check_rate(
    what: &'static str,
    requested: f64,
    max: f64,
    over: impl Fn(f64, f64) -> LimitViolation,
) -> Result<(), LimitViolation> {
    if !requested.is_finite() {
        return Err(LimitViolation::NonFinite { what });
    }
    if requested <= 0.0 {
        return Err(LimitViolation::NotPositive {
            what,
            value: requested,
        });
    }
    if requested > max {
        return Err(over(requested, max));
    }
    Ok(())
}

impl Limits {
    /// Checks the limits themselves (e.g. after loading a scenario): a non-empty box, positive
    /// finite rates, non-empty joint ranges.
    pub fn validate(&self) -> Result<(), InvalidLimits> {
        let bad = |field, reason: String| Err(InvalidLimits { field, reason });
        let w = &self.workspace;
        for i in 0..3 {
            if !(w.min[i].is_finite() && w.max[i].is_finite() && w.min[i] < w.max[i]) {
                return bad(
                    "workspace",
                    format!(
                        "axis {i}: [{}, {}] is not a finite, non-empty range",
                        w.min[i], w.max[i]
                    ),
                );
            }
        }
        for (field, value) in [
            ("max_tcp_speed", self.max_tcp_speed),
            ("max_tcp_acceleration", self.max_tcp_acceleration),
            ("max_joint_speed", self.max_joint_speed),
            ("max_joint_acceleration", self.max_joint_acceleration),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return bad(field, format!("{value} is not a positive finite number"));
            }
        }
        let (force, stop) = (self.max_contact_force, default_max_contact_force());
        if !(force.is_finite() && force > 0.0 && force <= stop) {
            return bad(
                "max_contact_force",
                format!(
                    "must be positive and at most the arm's protective stop force ({stop} N), got {force} N"
                ),
            );
        }
        let j = &self.joint_positions;
        for i in 0..6 {
            if j.lower[i].is_nan() || j.upper[i].is_nan() || j.lower[i] >= j.upper[i] {
                return bad(
                    "joint_positions",
                    format!("joint {}: [{}, {}] is empty", i + 1, j.lower[i], j.upper[i]),
                );
            }
        }
        Ok(())
    }

    /// Checks a TCP target against the workspace box.
    #[allow(non_snake_case)]
    pub fn check_tcp_target(&self, base_T_tcp: &Isometry3<f64>) -> Result<(), LimitViolation> {
        if !base_T_tcp.rotation.coords.iter().all(|v| v.is_finite()) {
            return Err(LimitViolation::NonFinite {
                what: "TCP target orientation",
            });
        }
        self.workspace.check(&base_T_tcp.translation.vector)
    }

    /// Checks a linear move: the target inside the box and speed/acceleration within limits.
    /// The box is convex, so a straight line from a TCP inside it stays inside.
    #[allow(non_snake_case)]
    pub fn check_move_l(
        &self,
        base_T_tcp: &Isometry3<f64>,
        motion: &LinearMotion,
    ) -> Result<(), LimitViolation> {
        self.check_tcp_target(base_T_tcp)?;
        check_rate(
            "TCP speed",
            motion.speed,
            self.max_tcp_speed,
            |requested, max| LimitViolation::TcpSpeed { requested, max },
        )?;
        check_rate(
            "TCP acceleration",
            motion.acceleration,
            self.max_tcp_acceleration,
            |requested, max| LimitViolation::TcpAcceleration { requested, max },
        )
    }

    /// Checks a joint target against the joint position limits.
    pub fn check_joints(&self, target: &Joints) -> Result<(), LimitViolation> {
        if !target.iter().all(|v| v.is_finite()) {
            return Err(LimitViolation::NonFinite {
                what: "joint target",
            });
        }
        let j = &self.joint_positions;
        match j.first_violation(target) {
            Some((joint, value)) => Err(LimitViolation::JointPosition {
                joint,
                value,
                lower: j.lower[joint],
                upper: j.upper[joint],
            }),
            None => Ok(()),
        }
    }

    /// Checks a joint move: joint positions, speed and acceleration, and the TCP along the
    /// joint-space path (`kinematics` gives the TCP; `samples` points from start to target, the start itself not
    /// checked since the arm is already there).
    pub fn check_move_j(
        &self,
        kinematics: &UrKinematics,
        from: &Joints,
        target: &Joints,
        motion: &JointMotion,
        samples: usize,
    ) -> Result<(), LimitViolation> {
        self.check_joints(target)?;
        check_rate(
            "joint speed",
            motion.speed,
            self.max_joint_speed,
            |requested, max| LimitViolation::JointSpeed { requested, max },
        )?;
        check_rate(
            "joint acceleration",
            motion.acceleration,
            self.max_joint_acceleration,
            |requested, max| LimitViolation::JointAcceleration { requested, max },
        )?;
        if !from.iter().all(|v| v.is_finite()) {
            return Err(LimitViolation::NonFinite {
                what: "joint start",
            });
        }
        // A joint move's TCP path is curved: check it at evenly spaced points after the start
        // (where the arm already is), the target included.
        let n = samples.max(2);
        for k in 1..n {
            let s = k as f64 / (n - 1) as f64;
            let q: Joints = std::array::from_fn(|i| from[i] + s * (target[i] - from[i]));
            self.check_tcp_target(&kinematics.forward_tcp(&q))?;
        }
        Ok(())
    }
}
