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

/// Distance covered `t` seconds into a rest-to-rest trapezoidal (or triangular) profile over
/// `length` ([`trapezoid_time`]'s), clamped to `[0, length]`.
pub fn trapezoid_position(length: f64, speed: f64, accel: f64, t: f64) -> f64 {
    let total = trapezoid_time(length, speed, accel);
    if total <= 0.0 || t >= total {
        return length.max(0.0);
    }
    if t <= 0.0 {
        return 0.0;
    }
    // Cruise speed reached (the triangle's peak when the cruise speed is not).
    let peak = speed.min((length * accel).sqrt());
    let ramp = peak / accel;
    let s = if t < ramp {
        0.5 * accel * t * t
    } else if t <= total - ramp {
        0.5 * accel * ramp * ramp + peak * (t - ramp)
    } else {
        let left = total - t;
        length - 0.5 * accel * left * left
    };
    s.clamp(0.0, length)
}

/// A rest-to-rest trapezoidal profile: its length, cruise speed and acceleration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Profile {
    /// Distance (rad of the lead joint, or the straight line's length), from rest to rest.
    pub length: f64,
    /// Cruise speed.
    pub speed: f64,
    /// Acceleration and deceleration.
    pub accel: f64,
}

impl Profile {
    /// Its duration, s ([`trapezoid_time`]).
    pub fn duration(&self) -> f64 {
        trapezoid_time(self.length, self.speed, self.accel)
    }

    /// The fraction of the way covered `t` seconds in, in `[0, 1]` (1 for a move of no length).
    pub fn fraction(&self, t: f64) -> f64 {
        if self.length.is_nan() || self.length <= 0.0 {
            return 1.0;
        }
        trapezoid_position(self.length, self.speed, self.accel, t) / self.length
    }
}

/// The profile of a synchronised joint move led by the joint that travels furthest.
pub fn move_j_profile(
    from: &Joints,
    to: &Joints,
    motion: &JointMotion,
    limits: &Limits,
) -> Profile {
    let length = from
        .iter()
        .zip(to)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    Profile {
        length,
        speed: motion.speed.min(limits.max_joint_speed),
        accel: motion.acceleration.min(limits.max_joint_acceleration),
    }
}

/// Duration of a synchronised joint move led by the joint that travels furthest.
pub fn move_j_time(from: &Joints, to: &Joints, motion: &JointMotion, limits: &Limits) -> f64 {
    move_j_profile(from, to, motion, limits).duration()
}

/// The profile of a straight-line TCP move (its length: the distance, or a pure
/// reorientation's equivalent).
#[allow(non_snake_case)]
pub fn move_l_profile(
    from: &Isometry3<f64>,
    to: &Isometry3<f64>,
    motion: &LinearMotion,
    limits: &Limits,
) -> Profile {
    let distance = (to.translation.vector - from.translation.vector).norm();
    let angle = from.rotation.angle_to(&to.rotation);
    Profile {
        length: distance.max(angle * ROTATION_PER_METRE),
        speed: motion.speed.min(limits.max_tcp_speed),
        accel: motion.acceleration.min(limits.max_tcp_acceleration),
    }
}

/// Duration of a straight-line TCP move.
#[allow(non_snake_case)]
pub fn move_l_time(
    from: &Isometry3<f64>,
    to: &Isometry3<f64>,
    motion: &LinearMotion,
    limits: &Limits,
) -> f64 {
    move_l_profile(from, to, motion, limits).duration()
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

    #[test]
    fn trapezoid_positions_follow_the_profile() {
        // The trapezoid above: 0.125 m after 0.5 s, cruise at 0.5 m/s, 0.875 m at 2 s.
        let at = |t| trapezoid_position(1.0, 0.5, 1.0, t);
        assert_eq!(at(0.0), 0.0);
        assert!((at(0.5) - 0.125).abs() < 1e-12);
        assert!((at(1.5) - 0.625).abs() < 1e-12);
        assert!((at(2.0) - 0.875).abs() < 1e-12);
        assert!((at(2.25) - (1.0 - 0.5 * 0.25 * 0.25)).abs() < 1e-12);
        assert_eq!(at(3.0), 1.0);
        // The triangle: halfway at half time; speed continuous, rising then falling.
        let total = trapezoid_time(0.1, 0.5, 1.0);
        assert!((trapezoid_position(0.1, 0.5, 1.0, total / 2.0) - 0.05).abs() < 1e-12);
        let mut last = 0.0;
        for k in 1..=100 {
            let s = trapezoid_position(1.0, 0.5, 1.0, k as f64 * 0.025);
            assert!(s >= last && s - last <= 0.5 * 0.025 + 1e-12);
            last = s;
        }
    }
}
