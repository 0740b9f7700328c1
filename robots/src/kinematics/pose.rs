//! UR pose vectors (x, y, z, rx, ry, rz) as spoken by RTDE and URScript, and isometries.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

/// Isometry from a UR pose vector: position in metres, orientation as a rotation vector
/// (axis × angle, radians).
pub fn from_ur_pose(pose: &[f64; 6]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(pose[0], pose[1], pose[2]),
        UnitQuaternion::from_scaled_axis(Vector3::new(pose[3], pose[4], pose[5])),
    )
}

/// UR pose vector of an isometry; the rotation vector has angle in [0, π] like the controller's.
pub fn to_ur_pose(pose: &Isometry3<f64>) -> [f64; 6] {
    let t = pose.translation.vector;
    let r = pose.rotation.scaled_axis();
    [t.x, t.y, t.z, r.x, r.y, r.z]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_preserves_pose() {
        let v = [0.1, -0.2, 0.3, 0.4, -1.2, 2.0];
        let back = to_ur_pose(&from_ur_pose(&v));
        for (a, b) in v.iter().zip(back) {
            assert!((a - b).abs() < 1e-12, "{v:?} vs {back:?}");
        }
    }

    #[test]
    fn small_and_half_turn_rotations() {
        let tiny = [0.0, 0.0, 0.0, 1e-9, 0.0, 0.0];
        assert!((to_ur_pose(&from_ur_pose(&tiny))[3] - 1e-9).abs() < 1e-18);
        let half = [0.0, 0.0, 0.0, 0.0, std::f64::consts::PI, 0.0];
        let back = from_ur_pose(&to_ur_pose(&from_ur_pose(&half)));
        assert!(back.rotation.angle_to(&from_ur_pose(&half).rotation) < 1e-12);
    }
}
