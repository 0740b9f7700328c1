//! Denavit–Hartenberg description of a UR arm and its forward kinematics.

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use serde::{Deserialize, Serialize};
use std::f64::consts::FRAC_PI_2;

use super::angles::Joints;

/// One row of a standard DH table: `Rz(θ + theta_offset) · Tz(d) · Tx(a) · Rx(alpha)`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DhRow {
    /// Link length along the new x axis (m).
    pub a: f64,
    /// Link offset along the previous z axis (m).
    pub d: f64,
    /// Link twist about the new x axis (rad).
    pub alpha: f64,
}

impl DhRow {
    /// The link transform `frame(i-1)_T_frame(i)` for joint angle `theta`.
    pub fn transform(&self, theta: f64) -> Isometry3<f64> {
        // Rz(θ)·Rx(α) as a quaternion product of the half-angle rotations, and cos θ, sin θ
        // from the half angles: one sin_cos for the joint.
        let (sh, ch) = (0.5 * theta).sin_cos();
        let (sa, ca) = (0.5 * self.alpha).sin_cos();
        let rotation =
            UnitQuaternion::new_unchecked(Quaternion::new(ch * ca, ch * sa, sh * sa, sh * ca));
        let (c, s) = (ch * ch - sh * sh, 2.0 * sh * ch);
        Isometry3::from_parts(Translation3::new(self.a * c, self.a * s, self.d), rotation)
    }
}

/// The six DH lengths of a UR arm; the twists are fixed by the UR structure
/// (π/2, 0, 0, π/2, −π/2, 0) and all other lengths are zero.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct UrDh {
    /// Base to shoulder height (m).
    pub d1: f64,
    /// Upper-arm length (m, negative in UR's table).
    pub a2: f64,
    /// Forearm length (m, negative in UR's table).
    pub a3: f64,
    /// Shoulder offset along the parallel joint axes (m).
    pub d4: f64,
    /// Wrist 1 to wrist 2 offset (m).
    pub d5: f64,
    /// Wrist 2 to flange offset (m).
    pub d6: f64,
}

impl UrDh {
    /// UR5e nominal parameters from Universal Robots' published DH table.
    pub const fn ur5e() -> Self {
        Self {
            d1: 0.1625,
            a2: -0.425,
            a3: -0.3922,
            d4: 0.1333,
            d5: 0.0997,
            d6: 0.0996,
        }
    }

    /// The full DH table, joint 1 first.
    pub fn rows(&self) -> [DhRow; 6] {
        let row = |a, d, alpha| DhRow { a, d, alpha };
        [
            row(0.0, self.d1, FRAC_PI_2),
            row(self.a2, 0.0, 0.0),
            row(self.a3, 0.0, 0.0),
            row(0.0, self.d4, FRAC_PI_2),
            row(0.0, self.d5, -FRAC_PI_2),
            row(0.0, self.d6, 0.0),
        ]
    }

    /// Checks that every length is finite and that the structure is a real UR-like arm.
    pub fn is_valid(&self) -> bool {
        let lengths = [self.d1, self.a2, self.a3, self.d4, self.d5, self.d6];
        lengths.iter().all(|v| v.is_finite()) && self.a2 != 0.0 && self.a3 != 0.0 && self.d6 >= 0.0
    }

    /// `base_T_frame(i)` for i = 1..=6 (the last one is the flange).
    pub fn frames(&self, q: &Joints) -> [Isometry3<f64>; 6] {
        let rows = self.rows();
        let mut frames = [Isometry3::identity(); 6];
        let mut acc = Isometry3::identity();
        for (i, (row, &theta)) in rows.iter().zip(q).enumerate() {
            acc *= row.transform(theta);
            frames[i] = acc;
        }
        frames
    }

    /// Forward kinematics: `base_T_flange`.
    pub fn forward(&self, q: &Joints) -> Isometry3<f64> {
        self.frames(q)[5]
    }

    /// Maximum distance from the shoulder (joint 2 axis) to the wrist centre the arm can reach
    /// in its plane: |a2| + |a3|.
    pub fn planar_reach(&self) -> f64 {
        self.a2.abs() + self.a3.abs()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn row_transform_is_rz_tz_tx_rx() {
        let row = DhRow {
            a: -0.425,
            d: 0.1625,
            alpha: FRAC_PI_2,
        };
        for theta in [-3.0, -1.0, 0.0, 0.4, 2.5] {
            let expected = Isometry3::rotation(Vector3::z() * theta)
                * Isometry3::translation(0.0, 0.0, row.d)
                * Isometry3::translation(row.a, 0.0, 0.0)
                * Isometry3::rotation(Vector3::x() * row.alpha);
            let got = row.transform(theta);
            assert!((got.translation.vector - expected.translation.vector).norm() < 1e-15);
            assert!(got.rotation.angle_to(&expected.rotation) < 1e-15);
        }
    }
}
