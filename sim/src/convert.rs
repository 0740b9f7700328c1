//! Conversions between the workspace's nalgebra types and the glam types of rapier and parry.

use nalgebra::{Isometry3, Point3, Quaternion, Translation3, UnitQuaternion, Vector3};
use parry3d_f64::math::{Pose, Rotation, Vector};

/// A nalgebra point as a parry/rapier vector.
pub fn vec_from_point(p: &Point3<f64>) -> Vector {
    Vector::new(p.x, p.y, p.z)
}

/// A nalgebra vector as a parry/rapier vector.
pub fn vec_from_vector(v: &Vector3<f64>) -> Vector {
    Vector::new(v.x, v.y, v.z)
}

/// A parry/rapier vector as a nalgebra vector.
pub fn vector_from_vec(v: Vector) -> Vector3<f64> {
    Vector3::new(v.x, v.y, v.z)
}

/// A nalgebra rotation as a parry/rapier rotation.
pub fn rot_from_unit_quaternion(q: &UnitQuaternion<f64>) -> Rotation {
    Rotation::from_xyzw(q.i, q.j, q.k, q.w)
}

/// A parry/rapier rotation as a nalgebra unit quaternion.
pub fn unit_quaternion_from_rot(r: &Rotation) -> UnitQuaternion<f64> {
    UnitQuaternion::new_normalize(Quaternion::new(r.w, r.x, r.y, r.z))
}

/// A nalgebra isometry as a parry/rapier pose.
pub fn pose_from_isometry(iso: &Isometry3<f64>) -> Pose {
    Pose::from_parts(
        vec_from_vector(&iso.translation.vector),
        rot_from_unit_quaternion(&iso.rotation),
    )
}

/// A parry/rapier pose as a nalgebra isometry.
pub fn isometry_from_pose(pose: &Pose) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::from(vector_from_vec(pose.translation)),
        unit_quaternion_from_rot(&pose.rotation),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn isometry_round_trips_through_pose() {
        let iso = Isometry3::new(Vector3::new(0.1, -0.2, 0.3), Vector3::new(0.4, 0.5, -0.6));
        let back = isometry_from_pose(&pose_from_isometry(&iso));
        assert!((back.to_homogeneous() - iso.to_homogeneous()).norm() < 1e-12);
        let p = Point3::new(1.0, 2.0, 3.0);
        let moved = pose_from_isometry(&iso) * vec_from_point(&p);
        assert!((vector_from_vec(moved) - (iso * p).coords).norm() < 1e-12);
    }
}
