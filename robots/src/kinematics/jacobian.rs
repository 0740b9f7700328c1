//! The geometric Jacobian of a UR arm and its manipulability.

use nalgebra::{Isometry3, Matrix6, Vector3};

use super::angles::Joints;
use super::dh::UrDh;

/// Geometric Jacobian at the point `base_T_tcp.translation`, in the base frame: rows 0–2 map
/// joint speeds to the TCP's linear velocity (m/s), rows 3–5 to its angular velocity (rad/s).
#[allow(non_snake_case)]
pub fn jacobian(dh: &UrDh, q: &Joints, flange_T_tcp: &Isometry3<f64>) -> Matrix6<f64> {
    let frames = dh.frames(q);
    let tcp = (frames[5] * flange_T_tcp).translation.vector;
    let mut jac = Matrix6::zeros();
    for i in 0..6 {
        // Joint i+1 turns about z of frame i (frame 0 is the base).
        let (axis, origin) = if i == 0 {
            (Vector3::z(), Vector3::zeros())
        } else {
            let f = &frames[i - 1];
            (f.rotation * Vector3::z(), f.translation.vector)
        };
        let linear = axis.cross(&(tcp - origin));
        jac.fixed_view_mut::<3, 1>(0, i).copy_from(&linear);
        jac.fixed_view_mut::<3, 1>(3, i).copy_from(&axis);
    }
    jac
}

/// |det J|: zero exactly at the wrist, elbow and shoulder singularities. For a UR arm it equals
/// |a2 · a3 · sin q3 · sin q5 · (a2 cos q2 + a3 cos(q2 + q3) + d5 sin(q2 + q3 + q4))| and does
/// not depend on the tool offset.
pub fn manipulability(dh: &UrDh, q: &Joints) -> f64 {
    jacobian(dh, q, &Isometry3::identity()).determinant().abs()
}
