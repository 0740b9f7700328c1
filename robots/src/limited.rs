//! `Limited<R>`: the decorator that checks every commanded target against the cell's [`Limits`]
//! before any [`Robot`] implementation sees it (in the spirit of openrr's limiters), so no
//! implementation checks by hand and none can forget to.
//!
//! A joint move is checked for the joint range, the joint speed and acceleration, and the TCP
//! along its curved joint-space path (sampled from the measured joints to the target) against the
//! workspace box; a linear move for the target in the box (convex, so the straight line stays
//! inside) and the TCP speed and acceleration. A refused command fails with
//! [`RobotError::LimitViolation`] and nothing reaches the robot.

use nalgebra::Isometry3;

use crate::kinematics::{Joints, UrKinematics};
use crate::limits::{InvalidLimits, Limits};
use crate::motion::{JointMotion, LinearMotion};
use crate::robot::{Robot, RobotFuture, RobotStatus};

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
}
