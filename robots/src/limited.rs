//! `Limited<R>`: the decorator that checks every commanded target against the cell's [`Limits`]
//! before any [`Robot`] implementation sees it (in the spirit of openrr's limiters), so no
//! implementation checks by hand and none can forget to.
//!
//! A joint move is checked for the joint range, the joint speed and acceleration, and the TCP
//! along its curved joint-space path (sampled from the measured joints to the target) against the
//! workspace box; a linear move for the target in the box (convex, so the straight line stays
//! inside) and the TCP speed and acceleration; a guarded move (`move_until_contact`) as a linear
//! move, and its force limit positive and at most the cell's `max_contact_force` (itself at most
//! [`MAX_CONTACT_FORCE`]). A blended path
//! ([`Robot::move_path`]) is checked by [`check_path`]: every via-point as the move to it, every
//! blend radius at most half of either segment it blends, and the blended motion itself, run on
//! the virtual UR's arm model and sampled every millisecond, for joint range, speed and
//! acceleration, the TCP in the workspace, and the TCP speed where it moves on tool lines. A
//! refused command fails with [`RobotError::LimitViolation`] and nothing reaches the robot.

use nalgebra::Isometry3;

use crate::kinematics::{Joints, UrKinematics};
use crate::limits::LimitViolation;
use crate::limits::{InvalidLimits, Limits};
use crate::motion::{JointMotion, LinearMotion};
use crate::robot::{
    ContactOutcome, Robot, RobotError, RobotFuture, RobotStatus, Waypoint, WaypointTarget, Wrench,
};
use crate::virtual_ur::arm::{ArmError, KinematicArm};
use crate::virtual_ur::path::{PathCycle, execute_path, via_points, waypoint_moves};

/// Largest force limit a guarded move may ask for, N: the arm's protective stop force (UR's
/// default safety limit), which would stop it first.
pub const MAX_CONTACT_FORCE: f64 = crate::virtual_ur::force::PROTECTIVE_STOP_FORCE;

/// Checks a guarded move's force limit: finite, positive, at most `max` (the cell's
/// `max_contact_force`) and at most [`MAX_CONTACT_FORCE`].
pub fn check_contact_force(force_limit: f64, max: f64) -> Result<(), LimitViolation> {
    let max = max.min(MAX_CONTACT_FORCE);
    if !force_limit.is_finite() {
        return Err(LimitViolation::NonFinite {
            what: "contact force limit",
        });
    }
    if force_limit <= 0.0 {
        return Err(LimitViolation::NotPositive {
            what: "contact force limit",
            value: force_limit,
        });
    }
    if force_limit > max {
        return Err(LimitViolation::ContactForce {
            requested: force_limit,
            max,
        });
    }
    Ok(())
}

/// Points along a joint move's path whose TCP is checked against the workspace box.
pub const JOINT_PATH_SAMPLES: usize = 32;

/// Period a blended path's motion is sampled at by [`check_path`], s (1 ms).
pub const PATH_SAMPLE_PERIOD: f64 = 1e-3;

/// Relative allowance for the rounding of finite differences in the sampled path check.
const SAMPLE_TOLERANCE: f64 = 1e-6;

/// Why the sampled check of a path stopped: a limit, or the arm model refused the path.
enum PathCheck {
    Limit(LimitViolation),
    Arm(ArmError),
}

impl From<ArmError> for PathCheck {
    fn from(e: ArmError) -> Self {
        PathCheck::Arm(e)
    }
}

/// Checks a blended path from joints `from` before it is sent: each via-point as the move to it
/// ([`Limits::check_move_j`] with [`JOINT_PATH_SAMPLES`], [`Limits::check_move_l`]); each blend
/// radius finite, not negative, at most half of either segment it blends (segment lengths between
/// the TCP's via-points) and 0 at the last via-point; then the blended motion as the virtual UR's
/// arm model runs it ([`execute_path`]), every [`PATH_SAMPLE_PERIOD`]: joints in range, every
/// joint's speed and acceleration within the limits, the TCP in the workspace box, and the TCP
/// speed within `max_tcp_speed` while only tool lines move it. Everything it refuses but an empty
/// path is a [`RobotError::LimitViolation`] (the arm model's refusals and unreachable via-points
/// as [`LimitViolation::PathRefused`]), so a caller can tell a refused path, which never moved
/// the arm and may run stop by stop, from a failed one.
pub fn check_path(
    limits: &Limits,
    kinematics: &UrKinematics,
    from: &Joints,
    path: &[Waypoint],
) -> Result<(), RobotError> {
    if path.is_empty() {
        return Err(RobotError::Rejected {
            detail: "a blended path needs at least one via-point".into(),
        });
    }
    if !from.iter().all(|v| v.is_finite()) {
        return Err(LimitViolation::NonFinite {
            what: "joint start",
        }
        .into());
    }
    let mut near = *from;
    for w in path {
        if !w.blend.is_finite() {
            return Err(LimitViolation::NonFinite {
                what: "blend radius",
            }
            .into());
        }
        if w.blend < 0.0 {
            return Err(LimitViolation::NotPositive {
                what: "blend radius",
                value: w.blend,
            }
            .into());
        }
        match w.target {
            WaypointTarget::Joints(q) => {
                let motion = JointMotion {
                    speed: w.speed,
                    acceleration: w.acceleration,
                };
                limits.check_move_j(kinematics, &near, &q, &motion, JOINT_PATH_SAMPLES)?;
                near = q;
            }
            WaypointTarget::Linear(pose) => {
                let motion = LinearMotion {
                    speed: w.speed,
                    acceleration: w.acceleration,
                };
                limits.check_move_l(&pose, &motion)?;
                near = kinematics
                    .inverse_nearest(&pose, &near)
                    .map_err(|e| LimitViolation::PathRefused {
                        detail: format!("a via-point is unreachable: {e}"),
                    })?
                    .joints;
            }
        }
    }
    let moves = waypoint_moves(path);
    let points = via_points(kinematics, from, &moves);
    let length = |i: usize| {
        let (a, b) = (points[i], points[i + 1]);
        ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
    };
    for (index, w) in path.iter().enumerate() {
        let max = if index + 1 == path.len() {
            0.0
        } else {
            0.5 * length(index).min(length(index + 1))
        };
        if w.blend > max {
            return Err(LimitViolation::BlendRadius {
                index,
                radius: w.blend,
                max,
            }
            .into());
        }
    }
    let mut arm = KinematicArm::new(kinematics.clone(), *from);
    let mut previous: Option<PathCycle> = None;
    let speed_max = limits.max_joint_speed * (1.0 + SAMPLE_TOLERANCE);
    let accel_max = limits.max_joint_acceleration * (1.0 + SAMPLE_TOLERANCE);
    let tcp_max = limits.max_tcp_speed * (1.0 + SAMPLE_TOLERANCE);
    let run = execute_path(&mut arm, &moves, PATH_SAMPLE_PERIOD, |c: &PathCycle| {
        let s = &c.state;
        limits.check_joints(&s.q).map_err(PathCheck::Limit)?;
        let tcp = nalgebra::Vector3::new(s.tcp_pose[0], s.tcp_pose[1], s.tcp_pose[2]);
        limits.workspace.check(&tcp).map_err(PathCheck::Limit)?;
        if let Some(v) = s.qd.iter().map(|v| v.abs()).find(|v| *v > speed_max) {
            return Err(PathCheck::Limit(LimitViolation::JointSpeed {
                requested: v,
                max: limits.max_joint_speed,
            }));
        }
        if let Some(a) = s
            .target_qdd
            .iter()
            .map(|a| a.abs())
            .find(|a| *a > accel_max)
        {
            return Err(PathCheck::Limit(LimitViolation::JointAcceleration {
                requested: a,
                max: limits.max_joint_acceleration,
            }));
        }
        if let Some(p) = previous.filter(|_| c.tool_lines) {
            let before = nalgebra::Vector3::new(
                p.state.tcp_pose[0],
                p.state.tcp_pose[1],
                p.state.tcp_pose[2],
            );
            let v = (tcp - before).norm() / PATH_SAMPLE_PERIOD;
            if v > tcp_max {
                return Err(PathCheck::Limit(LimitViolation::TcpSpeed {
                    requested: v,
                    max: limits.max_tcp_speed,
                }));
            }
        }
        previous = Some(*c);
        Ok(())
    });
    match run {
        Ok(_) => Ok(()),
        Err(PathCheck::Limit(v)) => Err(v.into()),
        Err(PathCheck::Arm(e)) => Err(LimitViolation::PathRefused {
            detail: e.to_string(),
        }
        .into()),
    }
}

/// A robot whose every motion is checked against `limits` first.
pub struct Limited<R> {
    inner: R,
    limits: Limits,
    kinematics: UrKinematics,
}

impl<R: Robot> Limited<R> {
    /// Wraps `inner` with `limits` (validated here); `kinematics` (with the robot's TCP) gives the
    /// TCP along joint moves.
    pub fn new(inner: R, limits: Limits, kinematics: UrKinematics) -> Result<Self, InvalidLimits> {
        limits.validate()?;
        Ok(Self {
            inner,
            limits,
            kinematics,
        })
    }

    /// The wrapped robot, for queries outside the [`Robot`] trait.
    pub fn inner(&self) -> &R {
        &self.inner
    }

    /// The wrapped robot, for operations outside the [`Robot`] trait (dashboard, unlocking a
    /// protective stop). Motions sent through it directly are not checked.
    pub fn inner_mut(&mut self) -> &mut R {
        &mut self.inner
    }

    /// The kinematics joint-move paths are checked with.
    pub fn kinematics(&self) -> &UrKinematics {
        &self.kinematics
    }
}

impl<R: Robot> Robot for Limited<R> {
    fn limits(&self) -> &Limits {
        &self.limits
    }

    fn joints(&mut self) -> RobotFuture<'_, Joints> {
        self.inner.joints()
    }

    fn tcp_pose(&mut self) -> RobotFuture<'_, Isometry3<f64>> {
        self.inner.tcp_pose()
    }

    fn move_j(&mut self, target: Joints, motion: JointMotion) -> RobotFuture<'_, ()> {
        Box::pin(async move {
            // Cheap checks first: a refused target costs no round trip to the robot.
            self.limits.check_joints(&target)?;
            let from = self.inner.joints().await?;
            self.limits.check_move_j(
                &self.kinematics,
                &from,
                &target,
                &motion,
                JOINT_PATH_SAMPLES,
            )?;
            self.inner.move_j(target, motion).await
        })
    }

    #[allow(non_snake_case)]
    fn move_l(&mut self, base_T_tcp: Isometry3<f64>, motion: LinearMotion) -> RobotFuture<'_, ()> {
        Box::pin(async move {
            self.limits.check_move_l(&base_T_tcp, &motion)?;
            self.inner.move_l(base_T_tcp, motion).await
        })
    }

    fn move_path(&mut self, path: Vec<Waypoint>) -> RobotFuture<'_, ()> {
        Box::pin(async move {
            let from = self.inner.joints().await?;
            check_path(&self.limits, &self.kinematics, &from, &path)?;
            self.inner.move_path(path).await
        })
    }

    fn open_gripper(&mut self) -> RobotFuture<'_, ()> {
        self.inner.open_gripper()
    }

    fn open_gripper_to(&mut self, width: f64) -> RobotFuture<'_, ()> {
        self.inner.open_gripper_to(width)
    }

    fn close_gripper(&mut self) -> RobotFuture<'_, ()> {
        self.inner.close_gripper()
    }

    fn stop(&mut self) -> RobotFuture<'_, ()> {
        self.inner.stop()
    }

    fn status(&mut self) -> RobotFuture<'_, RobotStatus> {
        self.inner.status()
    }

    #[allow(non_snake_case)]
    fn move_until_contact(
        &mut self,
        base_T_tcp: Isometry3<f64>,
        motion: LinearMotion,
        force_limit: f64,
    ) -> RobotFuture<'_, ContactOutcome> {
        Box::pin(async move {
            check_contact_force(force_limit, self.limits.max_contact_force)?;
            self.limits.check_move_l(&base_T_tcp, &motion)?;
            self.inner
                .move_until_contact(base_T_tcp, motion, force_limit)
                .await
        })
    }

    fn wrench(&mut self) -> RobotFuture<'_, Wrench> {
        self.inner.wrench()
    }
}
