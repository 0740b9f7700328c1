//! The joint torques and motor currents the virtual arm reports: the torque each joint needs to
//! hold its links and the payload against gravity, from the robot description's link inertials,
//! and the current a motor draws for it through a per-joint torque constant.
//!
//! Model limits, stated: gravity only (no inertial, Coriolis or friction torques: the kinematic
//! arm tracks its trajectory perfectly, so at rest, where these figures are read, they are zero
//! anyway); the torque constants are modelled values, not Universal Robots data (see
//! [`MODEL_PEAK_CURRENT`]).

use super::registers::Payload;
use crate::description::{DescriptionError, RobotDescription};
use crate::kinematics::{Joints, UrDh};
use crate::ur_arm::{BASE_LINK, FLANGE_LINK};
use nalgebra::{Isometry3, Point3, Vector3};

/// Gravity (m/s²) along −z of the base frame: URScript's default gravity vector
/// (`set_gravity([0, 0, 9.82])`).
pub const GRAVITY: f64 = 9.82;

/// The modelled motor current (A) at which a joint delivers its rated torque (the URDF joint's
/// `effort`): the torque constants are `effort / MODEL_PEAK_CURRENT`, 10 N·m/A for a UR5e's
/// 150 N·m joints and 1.87 N·m/A for its 28 N·m wrists. A modelled value, not UR data.
pub const MODEL_PEAK_CURRENT: f64 = 15.0;

/// One link's mass and centre of mass.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkInertial {
    /// Mass (kg).
    pub mass: f64,
    /// Centre of mass in the link's joint frame: DH frame i−1 turned by q_i about its z axis
    /// (for link i, the child of joint i; frame 0 is the base). For UR descriptions this is the
    /// URDF link frame itself.
    pub com: Vector3<f64>,
}

/// Gravity model of a UR arm: the six moving links' inertials and the joints' torque constants.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmDynamics {
    /// Links 1–6 (shoulder to wrist 3), the child of each joint.
    pub links: [LinkInertial; 6],
    /// Joint torque per motor ampere (N·m/A), joint 1 first.
    pub torque_constants: Joints,
}

impl ArmDynamics {
    /// The UR5e of `scenarios/robots/ur5e.urdf`: masses from UR's published table, centres of
    /// mass of its link geometry, torque constants from its joint efforts (150, 150, 150, 28, 28,
    /// 28 N·m) and [`MODEL_PEAK_CURRENT`]. `robots/tests/virtual_ur_dynamics.rs` checks this table
    /// against the URDF.
    pub fn ur5e() -> ArmDynamics {
        let link = |mass, x, y, z| LinkInertial {
            mass,
            com: Vector3::new(x, y, z),
        };
        let big = 150.0 / MODEL_PEAK_CURRENT;
        let small = 28.0 / MODEL_PEAK_CURRENT;
        ArmDynamics {
            links: [
                link(3.761, 0.0, 0.0, 0.12),
                link(8.058, -0.2125, 0.0, 0.138),
                link(2.846, -0.1961, 0.0, 0.01),
                link(1.37, 0.0, 0.0, 0.1233),
                link(1.3, 0.0, 0.0, 0.0897),
                link(0.365, 0.0, 0.0, 0.0746),
            ],
            torque_constants: [big, big, big, small, small, small],
        }
    }

    /// The built-in model for an arm with these DH lengths: the UR5e's, or none.
    pub fn for_dh(dh: &UrDh) -> Option<ArmDynamics> {
        (*dh == UrDh::ur5e()).then(ArmDynamics::ur5e)
    }

    /// Reads the model from a UR robot description (chain `base` → `tool0`, as
    /// [`crate::ur_arm::UrArm`]): each moving link's `<inertial>` mass and origin, and each
    /// joint's `effort` over [`MODEL_PEAK_CURRENT`]. `dh` must be the arm's derived DH lengths
    /// (`UrArm::from_description(..).kinematics.dh`). `None` when a link carries no inertial or a
    /// joint no positive effort.
    pub fn from_description(
        description: &RobotDescription,
        dh: &UrDh,
    ) -> Result<Option<ArmDynamics>, DescriptionError> {
        let chain = description.chain(BASE_LINK, FLANGE_LINK)?;
        let zero = [0.0; 6];
        let poses = chain.link_poses(&zero)?;
        if poses.len() != 6 || chain.limits().len() != 6 {
            return Ok(None);
        }
        let joint_frames = joint_frames(dh, &zero);
        let mut links = [LinkInertial {
            mass: 0.0,
            com: Vector3::zeros(),
        }; 6];
        let mut torque_constants = [0.0; 6];
        for (i, (name, pose)) in poses.iter().enumerate() {
            let Some(link) = description.link(name) else {
                return Ok(None);
            };
            let inertial = &link.inertial;
            let mass = inertial.mass.value;
            if !(mass.is_finite() && mass > 0.0) {
                return Ok(None);
            }
            let [x, y, z] = inertial.origin.xyz.0;
            let com_base = pose * Point3::new(x, y, z);
            let com = joint_frames[i].inverse_transform_point(&com_base).coords;
            links[i] = LinkInertial { mass, com };
            let effort = chain.limits()[i].effort;
            if !(effort.is_finite() && effort > 0.0) {
                return Ok(None);
            }
            torque_constants[i] = effort / MODEL_PEAK_CURRENT;
        }
        Ok(Some(ArmDynamics {
            links,
            torque_constants,
        }))
    }

    /// The torque (N·m) each joint applies to hold the arm and `payload` still at `q` against
    /// gravity: `τ = ∂V/∂q` with `V = Σ m g z`, positive about the joint's axis (the sign of
    /// `M(q) q̈ + C(q, q̇) q̇ + g(q) = τ`).
    pub fn gravity_torques(&self, dh: &UrDh, q: &Joints, payload: &Payload) -> Joints {
        let frames = joint_frames(dh, q);
        let flange = dh.forward(q);
        // Every mass point in the base frame, with the first joint that moves it.
        let mut masses: Vec<(usize, f64, Vector3<f64>)> = self
            .links
            .iter()
            .enumerate()
            .map(|(i, l)| (i, l.mass, (frames[i] * Point3::from(l.com)).coords))
            .collect();
        if payload.mass > 0.0 {
            let cog = Point3::from(Vector3::from(payload.cog));
            masses.push((5, payload.mass, (flange * cog).coords));
        }
        std::array::from_fn(|j| {
            let axis = frames[j].rotation * Vector3::z();
            let origin = frames[j].translation.vector;
            masses
                .iter()
                .filter(|(link, _, _)| *link >= j)
                .map(|(_, m, c)| m * GRAVITY * axis.cross(&(c - origin)).z)
                .sum()
        })
    }

    /// The motor current (A) for each joint torque: `τ / k`.
    pub fn currents(&self, torques: &Joints) -> Joints {
        std::array::from_fn(|i| torques[i] / self.torque_constants[i])
    }
}

/// Each joint's frame at `q`: DH frame i−1 (the base for joint 1) turned by q_i about its z.
fn joint_frames(dh: &UrDh, q: &Joints) -> [Isometry3<f64>; 6] {
    let dh_frames = dh.frames(q);
    std::array::from_fn(|i| {
        let before = if i == 0 {
            Isometry3::identity()
        } else {
            dh_frames[i - 1]
        };
        before * Isometry3::rotation(Vector3::z() * q[i])
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    #[test]
    fn a_vertical_arm_needs_no_shoulder_torque_and_a_horizontal_one_does() {
        let d = ArmDynamics::ur5e();
        let dh = UrDh::ur5e();
        // Straight up: q2 = −π/2, q3 = 0 (the upper arm and forearm along +z).
        let up = [0.0, -FRAC_PI_2, 0.0, -FRAC_PI_2, 0.0, 0.0];
        let t = d.gravity_torques(&dh, &up, &Payload::default());
        assert!(t[0].abs() < 1e-12, "{t:?}");
        assert!(t[1].abs() < 0.5, "shoulder nearly unloaded upright: {t:?}");
        // Stretched out horizontally: the shoulder carries every link's moment.
        let flat = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let t = d.gravity_torques(&dh, &flat, &Payload::default());
        assert!(t[1].abs() > 40.0, "{t:?}");
        // A payload at the flange adds m g times its horizontal reach to the shoulder.
        let kg = Payload {
            mass: 1.0,
            ..Payload::default()
        };
        let with = d.gravity_torques(&dh, &flat, &kg);
        let reach = dh.forward(&flat).translation.vector.x.abs();
        assert!(((with[1] - t[1]).abs() - GRAVITY * reach).abs() < 1e-9);
        // Joint 1 (vertical axis) never holds gravity.
        assert!(with[0].abs() < 1e-12);
    }
}
