//! `Limited<R>`: the decorator that checks every commanded target against the cell's [`Limits`]
//! before any [`Robot`] implementation sees it (in the spirit of openrr's limiters), so no
//! implementation checks by hand and none can forget to.
//!
//! A joint move is checked for the joint range, the joint speed and acceleration, and the TCP
//! along its curved joint-space path (sampled from the measured joints to the target) against the
//! workspace box; a linear move for the target in the box (convex, so the straight line stays
//! inside) and the TCP speed and acceleration; a guarded move (`move_until_contact`) as a linear
//! move, and its force limit positive and at most [`MAX_CONTACT_FORCE`]. A refused command fails with
//! [`RobotError::LimitViolation`] and nothing reaches the robot.

use nalgebra::Isometry3;

use crate::kinematics::{Joints, UrKinematics};
use crate::limits::LimitViolation;
use crate::limits::{InvalidLimits, Limits};
use crate::motion::{JointMotion, LinearMotion};
use crate::robot::{ContactOutcome, Robot, RobotFuture, RobotStatus, Wrench};

/// Largest force limit a guarded move may ask for, N: the arm's protective stop force (UR's
/// default safety limit), which would stop it first.
pub const MAX_CONTACT_FORCE: f64 = crate::virtual_ur::force::PROTECTIVE_STOP_FORCE;

/// Checks a guarded move's force limit: finite, positive, at most [`MAX_CONTACT_FORCE`].
pub fn check_contact_force(force_limit: f64) -> Result<(), LimitViolation> {
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
    if force_limit > MAX_CONTACT_FORCE {
        return Err(LimitViolation::ContactForce {
            requested: force_limit,
            max: MAX_CONTACT_FORCE,
        });
    }
    Ok(())
}

/// Points along a joint move's path whose TCP is checked against the workspace box.
pub const JOINT_PATH_SAMPLES: usize = 32;

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
            check_contact_force(force_limit)?;
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
