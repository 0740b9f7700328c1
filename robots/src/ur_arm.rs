//! A Universal Robots arm read from its robot description: the UR kinematic parameters derived
//! from the URDF joint chain, its joint position limits and its joint speed limits.
//!
//! The chain runs from link `base` (the controller base frame) to link `tool0` (the flange), the
//! frames UR's own descriptions and ROS-Industrial use. Its six revolute joints must have the UR
//! structure (joint 1 vertical, joints 2–4 parallel, wrist axes meeting pairwise): the six DH
//! lengths are read off the joint axes at zero, and the derived model is accepted only when its
//! forward kinematics reproduces the URDF chain's (within [`FK_TOLERANCE`]) on spread-out joint
//! values, so the analytic inverse kinematics is exact for the described arm.

use nalgebra::{Point3, Vector3};
use std::f64::consts::TAU;
use std::path::Path;

use crate::description::{DescriptionError, RobotDescription, SerialChain};
use crate::kinematics::{Joints, SingularityPolicy, SingularityThresholds, UrDh, UrKinematics};

/// Largest difference (m, and rad for orientation) allowed between the URDF chain's forward
/// kinematics and the derived UR parameters'.
pub const FK_TOLERANCE: f64 = 1e-9;

/// Resolution the derived DH lengths are rounded to (m): far below any arm's accuracy, far above
/// the rounding of the joint-axis arithmetic.
pub const LENGTH_RESOLUTION: f64 = 1e-10;

/// Link the UR chain starts at (the controller base frame).
pub const BASE_LINK: &str = "base";
/// Link the UR chain ends at (the tool flange, UR's tool0).
pub const FLANGE_LINK: &str = "tool0";

/// Direction of each joint axis at zero joint values in a UR arm's base frame.
const AXES_AT_ZERO: [[f64; 3]; 6] = [
    [0.0, 0.0, 1.0],
    [0.0, -1.0, 0.0],
    [0.0, -1.0, 0.0],
    [0.0, -1.0, 0.0],
    [0.0, 0.0, -1.0],
    [0.0, -1.0, 0.0],
];

/// Joint values the derived model is compared with the URDF chain at.
const CHECK_SAMPLES: usize = 64;

/// A UR arm from its URDF: kinematics (TCP at the flange) and joint limits.
#[derive(Clone, Debug, PartialEq)]
pub struct UrArm {
    /// The robot's name in the URDF (e.g. `ur10e`).
    pub name: String,
    /// The derived kinematics: DH lengths, the URDF's joint position limits, TCP at the flange.
    pub kinematics: UrKinematics,
    /// The URDF's joint speed limits (rad/s), joint 1 first.
    pub max_joint_speeds: Joints,
}

impl UrArm {
    /// Loads a URDF file and derives the UR arm it describes.
    pub fn from_file(path: impl AsRef<Path>) -> Result<Self, DescriptionError> {
        Self::from_description(&RobotDescription::from_file(path)?)
    }

    /// Derives the UR arm of a loaded description.
    pub fn from_description(description: &RobotDescription) -> Result<Self, DescriptionError> {
        let origin = description.origin();
        let not_ur = |reason: String| DescriptionError::NotUrArm {
            origin: origin.to_owned(),
            reason,
        };
        let chain = description.chain(BASE_LINK, FLANGE_LINK)?;
        if chain.dof() != 6 {
            return Err(not_ur(format!(
                "the chain has {} movable joints ({}), a UR arm has six",
                chain.dof(),
                chain.joint_names().join(", ")
            )));
        }
        if let Some(i) = chain.revolute().iter().position(|r| !r) {
            return Err(not_ur(format!(
                "joint `{}` slides; a UR arm's joints all turn",
                chain.joint_names()[i]
            )));
        }
        let dh = derive_dh(&chain).map_err(&not_ur)?;
        check_forward_kinematics(&chain, &dh).map_err(&not_ur)?;
        let limits = chain
            .joint_limits6()
            .ok_or_else(|| not_ur("the chain does not have six joint limits".into()))?;
        let mut max_joint_speeds = [0.0; 6];
        for (i, limit) in chain.limits().iter().enumerate() {
            if !(limit.velocity.is_finite() && limit.velocity > 0.0) {
                return Err(not_ur(format!(
                    "joint `{}` has no positive speed limit (velocity = {})",
                    chain.joint_names()[i],
                    limit.velocity
                )));
            }
            max_joint_speeds[i] = limit.velocity;
        }
        Ok(Self {
            name: description.name().to_owned(),
            kinematics: UrKinematics {
                dh,
                flange_T_tcp: nalgebra::Isometry3::identity(),
                joint_limits: limits,
                singularity_thresholds: SingularityThresholds::default(),
                singularity_policy: SingularityPolicy::Report,
            },
            max_joint_speeds,
        })
    }

    /// The slowest joint's speed limit (rad/s): the most a joint move may ask of its leading
    /// joint whichever joint leads.
    pub fn slowest_joint_speed(&self) -> f64 {
        self.max_joint_speeds
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min)
    }
}

/// Reads the six UR lengths off the joint axes at zero (see the module documentation).
fn derive_dh(chain: &SerialChain) -> Result<UrDh, String> {
    let axes = chain
        .joint_axes(&[0.0; 6])
        .map_err(|e| format!("cannot evaluate the chain: {e}"))?;
    for (i, ((_, axis), expected)) in axes.iter().zip(AXES_AT_ZERO).enumerate() {
        let expected = Vector3::from(expected);
        if (axis.into_inner() - expected).norm() > 1e-9 {
            return Err(format!(
                "joint {} `{}` turns about ({:.4}, {:.4}, {:.4}) in `{BASE_LINK}` at zero; a UR \
                 arm's turns about ({}, {}, {})",
                i + 1,
                chain.joint_names()[i],
                axis.x,
                axis.y,
                axis.z,
                expected.x,
                expected.y,
                expected.z
            ));
        }
    }
    let point = |i: usize| -> Point3<f64> { axes[i].0 };
    let flange = chain
        .forward(&[0.0; 6])
        .map_err(|e| format!("cannot evaluate the chain: {e}"))?
        .translation
        .vector;
    // Joint 2's axis runs along −y through (0, 0, d1); joint 3's through (a2, ·, d1); joint 4's
    // through (a2 + a3, ·, d1); joint 5's along −z through (a2 + a3, −d4, ·); joint 6's along −y
    // through (·, ·, d1 − d5); the flange sits at (a2 + a3, −d4 − d6, d1 − d5).
    let d1 = point(1).z;
    let a2 = point(2).x;
    let a3 = point(3).x - a2;
    let d4 = -point(4).y;
    let d5 = d1 - point(5).z;
    let d6 = -flange.y - d4;
    // The differences above carry ~1e-16 m of rounding; lengths written in decimal (as UR
    // publishes them) come out exactly when snapped to LENGTH_RESOLUTION.
    let snap = |v: f64| (v / LENGTH_RESOLUTION).round() / LENGTH_RESOLUTION.recip();
    let dh = UrDh {
        d1: snap(d1),
        a2: snap(a2),
        a3: snap(a3),
        d4: snap(d4),
        d5: snap(d5),
        d6: snap(d6),
    };
    if !dh.is_valid() {
        return Err(format!(
            "the derived lengths {dh:?} are not a UR arm's (a2 and a3 must be non-zero, d6 ≥ 0)"
        ));
    }
    Ok(dh)
}

/// Compares the chain's forward kinematics with the derived model's on spread-out joint values.
fn check_forward_kinematics(chain: &SerialChain, dh: &UrDh) -> Result<(), String> {
    let mut worst = (0.0, [0.0; 6]);
    for k in 0..CHECK_SAMPLES {
        // A Kronecker sequence over [−2π, 2π)⁶: spread evenly, deterministic.
        let q: Joints = std::array::from_fn(|i| {
            let alpha = [0.5698, 0.7548, 0.8191, 0.6180, 0.4142, 0.7321][i];
            ((k as f64 + 0.5) * alpha).fract().mul_add(2.0 * TAU, -TAU)
        });
        let urdf = chain
            .forward(&q)
            .map_err(|e| format!("cannot evaluate the chain: {e}"))?;
        let ur = dh.forward(&q);
        let error = (urdf.translation.vector - ur.translation.vector)
            .norm()
            .max(urdf.rotation.angle_to(&ur.rotation));
        if error.is_nan() || error > worst.0 {
            worst = (error, q);
        }
    }
    if worst.0 <= FK_TOLERANCE {
        return Ok(());
    }
    let q = worst.1;
    Err(format!(
        "the UR parameters read from its joint axes ({dh:?}) reproduce its forward kinematics \
         only to {:.3e} (m or rad; at q = [{:.3}, {:.3}, {:.3}, {:.3}, {:.3}, {:.3}] rad), more \
         than {FK_TOLERANCE:e}: the joints are not placed as in a UR arm (the analytic inverse \
         kinematics needs its exact structure)",
        worst.0, q[0], q[1], q[2], q[3], q[4], q[5]
    ))
}
