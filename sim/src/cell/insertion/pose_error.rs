//! Where the held part is relative to its seated target, in the step's insertion frame: the
//! pose error every scorer starts from and ends at, and the rotation measures it is made of.

use nalgebra::{Vector2, Vector3};
use serde::{Deserialize, Serialize};

/// The pose of a part relative to its seated target, in the insertion frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseError {
    /// Lateral offset of the part's leading point (x, y), metres.
    pub lateral: Vector2<f64>,
    /// Height of the part origin above seated along the insertion frame's z, metres.
    pub height: f64,
    /// Angle between the part's axis and the insertion axis, radians.
    pub tilt: f64,
    /// Horizontal direction the part's axis leans toward (unit, or zero without tilt).
    pub tilt_direction: Vector2<f64>,
    /// Rotation about the insertion axis, radians in (−π, π].
    pub yaw: f64,
}

/// Swing-twist: the twist angle of `r` about `z`.
pub(crate) fn twist_about_z(r: &nalgebra::UnitQuaternion<f64>) -> f64 {
    let q = r.quaternion();
    let yaw = 2.0 * q.k.atan2(q.w);
    nalgebra::RealField::atan2(yaw.sin(), yaw.cos())
}

/// The z axis of a rotation's frame.
pub(crate) fn tilt_of(r: &nalgebra::UnitQuaternion<f64>) -> (f64, Vector2<f64>) {
    let z = r * Vector3::z();
    let tilt = z.z.clamp(-1.0, 1.0).acos();
    let h = Vector2::new(z.x, z.y);
    let dir = if h.norm() > 1e-15 {
        h.normalize()
    } else {
        Vector2::zeros()
    };
    (tilt, dir)
}
