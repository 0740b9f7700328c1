//! Arm motion time: trapezoidal velocity profiles under the commanded and the cell's limits,
//! the simulated clock's increments for cycle-time figures.

use nalgebra::Isometry3;
use robots::kinematics::Joints;
use robots::limits::Limits;
use robots::robot::{JointMotion, LinearMotion};

/// Rotation speed used to time a pure reorientation in a linear move, rad/s per m/s of TCP speed
/// (UR controllers lead with translation; 1 m/s ↔ 10 rad/s as in the virtual controller).
const ROTATION_PER_METRE: f64 = 0.1;

/// Duration of a rest-to-rest trapezoidal (or triangular) profile over `length`.
pub fn trapezoid_time(length: f64, speed: f64, accel: f64) -> f64 {
    if length.is_nan()
        || speed.is_nan()
        || accel.is_nan()
        || length <= 0.0
        || speed <= 0.0
        || accel <= 0.0
    {
        return 0.0;
    }
    let d_accel = speed * speed / accel;
    if d_accel >= length {
        2.0 * (length / accel).sqrt()
    } else {
        2.0 * speed / accel + (length - d_accel) / speed
    }
}

/// Duration of a synchronised joint move led by the joint that travels furthest.
pub fn move_j_time(from: &Joints, to: &Joints, motion: &JointMotion, limits: &Limits) -> f64 {
    let length = from
        .iter()
        .zip(to)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    trapezoid_time(
        length,
        motion.speed.min(limits.max_joint_speed),
        motion.acceleration.min(limits.max_joint_acceleration),
    )
}

/// Duration of a straight-line TCP move.
#[allow(non_snake_case)]
pub fn move_l_time(
    from: &Isometry3<f64>,
    to: &Isometry3<f64>,
    motion: &LinearMotion,
    limits: &Limits,
) -> f64 {
    let distance = (to.translation.vector - from.translation.vector).norm();
    let angle = from.rotation.angle_to(&to.rotation);
    trapezoid_time(
        distance.max(angle * ROTATION_PER_METRE),
        motion.speed.min(limits.max_tcp_speed),
        motion.acceleration.min(limits.max_tcp_acceleration),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn trapezoid_and_triangle_times() {
        // 1 m at 0.5 m/s, 1 m/s²: 0.5 s up and 0.5 s down (0.125 m each way), then 0.75 m of
        // cruise at 0.5 m/s in 1.5 s: 2.5 s in all.
        assert!((trapezoid_time(1.0, 0.5, 1.0) - 2.5).abs() < 1e-12);
        // 0.1 m never reaches 0.5 m/s: 2 sqrt(0.1) s.
        assert!((trapezoid_time(0.1, 0.5, 1.0) - 2.0 * 0.1f64.sqrt()).abs() < 1e-12);
        assert_eq!(trapezoid_time(0.0, 0.5, 1.0), 0.0);
    }
}
