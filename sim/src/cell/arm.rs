//! The simulated cell as the virtual UR controller's arm model: the production client drives it
//! over loopback RTDE.
//!
//! [`SimArm`] steps the motion like the kinematic arm (joint and straight-line trajectories with
//! trapezoidal profiles at the control period, the cell's speed and acceleration limits) and, when
//! a motion completes, hands the final joints and the elapsed time to the shared [`SimCell`]:
//! repeatability, insertions and the simulated clock then work exactly as in-process. The gripper
//! follows the controller's tool digital output through [`SimArm::set_tool_output`].

use std::sync::{Arc, Mutex, MutexGuard};

use robots::kinematics::Joints;
use robots::virtual_ur::arm::{ArmCommand, ArmError, ArmModel, ArmState, KinematicArm};

use super::SimCell;

/// The tool digital output pin that drives the gripper (closed when high), as
/// `robots::ur_robot`'s default gripper configuration.
pub const GRIPPER_TOOL_PIN: u32 = 0;

/// A [`SimCell`] behind the virtual controller's [`ArmModel`] trait.
pub struct SimArm {
    cell: Arc<Mutex<SimCell>>,
    arm: KinematicArm,
    elapsed: f64,
    was_moving: bool,
}

impl SimArm {
    /// Wraps a shared cell; the arm starts at the cell's joints.
    pub fn new(cell: Arc<Mutex<SimCell>>) -> Self {
        let (q, limits) = {
            let c = lock(&cell);
            (c.joints_now(), c.model().spec.limits.clone())
        };
        let mut arm = KinematicArm::ur5e(q);
        arm.max_joint_speed = limits.max_joint_speed;
        arm.max_joint_accel = limits.max_joint_acceleration;
        arm.max_tool_speed = limits.max_tcp_speed;
        arm.max_tool_accel = limits.max_tcp_acceleration;
        Self {
            cell,
            arm,
            elapsed: 0.0,
            was_moving: false,
        }
    }

    /// The shared cell (to read outcomes while the controller drives it).
    pub fn cell(&self) -> Arc<Mutex<SimCell>> {
        self.cell.clone()
    }

    /// The controller's tool digital output changed: pin [`GRIPPER_TOOL_PIN`] high closes the
    /// gripper, low opens it.
    pub fn set_tool_output(&mut self, pin: u32, level: bool) {
        if pin == GRIPPER_TOOL_PIN {
            lock(&self.cell).set_gripper(level);
        }
    }
}

fn lock(cell: &Arc<Mutex<SimCell>>) -> MutexGuard<'_, SimCell> {
    cell.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

impl ArmModel for SimArm {
    fn command(&mut self, cmd: ArmCommand) -> Result<(), ArmError> {
        if let Some(e) = lock(&self.cell).status_now().safety.motion_error() {
            return Err(ArmError::Unreachable(e.to_string()));
        }
        self.arm.command(cmd)?;
        self.elapsed = 0.0;
        self.was_moving = self.arm.is_moving();
        Ok(())
    }

    fn step(&mut self, dt: f64, speed_fraction: f64) -> Result<(), ArmError> {
        let result = self.arm.step(dt, speed_fraction);
        if self.was_moving {
            self.elapsed += dt;
        }
        let moving = self.arm.is_moving();
        if self.was_moving && !moving {
            let q = self.arm.state().q;
            lock(&self.cell).set_joints_after_motion(q, self.elapsed);
            self.elapsed = 0.0;
        }
        self.was_moving = moving;
        result
    }

    fn state(&self) -> ArmState {
        self.arm.state()
    }

    fn is_moving(&self) -> bool {
        self.arm.is_moving()
    }

    fn forward(&self, q: &Joints) -> [f64; 6] {
        robots::kinematics::to_ur_pose(&lock(&self.cell).model().kinematics.forward_tcp(q))
    }

    fn inverse(&self, pose: &[f64; 6], near: &Joints) -> Result<Joints, ArmError> {
        lock(&self.cell)
            .model()
            .kinematics
            .inverse_nearest(&robots::kinematics::from_ur_pose(pose), near)
            .map(|s| s.joints)
            .map_err(|e| ArmError::Unreachable(e.to_string()))
    }
}
