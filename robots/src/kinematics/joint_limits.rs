//! Joint position limits and choosing the 2π-equivalent of an angle that fits them.

use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

use super::angles::Joints;

/// Lower and upper position limit of each joint (rad).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct JointLimits {
    /// Lower limits, joint 1 first.
    pub lower: Joints,
    /// Upper limits, joint 1 first.
    pub upper: Joints,
}

impl Default for JointLimits {
    /// ±2π on every joint, the UR5e's controller range.
    fn default() -> Self {
        Self::symmetric(TAU)
    }
}

impl JointLimits {
    /// The same symmetric range ±`limit` on all joints.
    pub fn symmetric(limit: f64) -> Self {
        Self {
            lower: [-limit; 6],
            upper: [limit; 6],
        }
    }

    /// True when every joint lies within its limits.
    pub fn contains(&self, q: &Joints) -> bool {
        (0..6).all(|i| q[i] >= self.lower[i] && q[i] <= self.upper[i])
    }

    /// The first joint outside its limits, if any, as (index, value).
    pub fn first_violation(&self, q: &Joints) -> Option<(usize, f64)> {
        (0..6)
            .find(|&i| !(q[i] >= self.lower[i] && q[i] <= self.upper[i]))
            .map(|i| (i, q[i]))
    }

    /// Among `angle + 2πk`, the value within joint `joint`'s limits nearest `reference`, if any.
    pub fn wrap_nearest(&self, joint: usize, angle: f64, reference: f64) -> Option<f64> {
        let (lower, upper) = (self.lower[joint], self.upper[joint]);
        let centred = angle + TAU * ((reference - angle) / TAU).round();
        // `centred` is the equivalent nearest the reference; the next ones out bracket it.
        let mut best: Option<f64> = None;
        for candidate in [centred, centred - TAU, centred + TAU] {
            if candidate >= lower && candidate <= upper {
                let better =
                    best.is_none_or(|b| (candidate - reference).abs() < (b - reference).abs());
                if better {
                    best = Some(candidate);
                }
            }
        }
        if best.is_some() {
            return best;
        }
        // Reference far outside the range: take the in-range equivalent closest to it.
        let k_low = ((lower - angle) / TAU).ceil();
        let k_high = ((upper - angle) / TAU).floor();
        if k_low > k_high {
            return None;
        }
        let low = angle + TAU * k_low;
        let high = angle + TAU * k_high;
        Some(if (low - reference).abs() <= (high - reference).abs() {
            low
        } else {
            high
        })
    }

    /// Every joint of `q` moved by multiples of 2π to fit the limits and lie nearest `reference`.
    pub fn wrap_nearest_all(&self, q: &Joints, reference: &Joints) -> Option<Joints> {
        let mut out = [0.0; 6];
        for i in 0..6 {
            out[i] = self.wrap_nearest(i, q[i], reference[i])?;
        }
        Some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn wrap_picks_equivalent_nearest_reference_within_limits() {
        let limits = JointLimits::default();
        let q = limits.wrap_nearest(0, 3.0, -3.0).unwrap();
        assert!((q - (3.0 - TAU)).abs() < 1e-12);
        let q = limits.wrap_nearest(0, -3.0, 6.0).unwrap();
        assert!((q - (-3.0 + TAU)).abs() < 1e-12);
        // Nearest equivalent of 0.5 to 6.2 would be 0.5 + 2π = 6.78, beyond 2π: take 0.5.
        let q = limits.wrap_nearest(0, 0.5, 6.2).unwrap();
        assert!((q - 0.5).abs() < 1e-12);
    }

    #[test]
    fn wrap_respects_narrow_limits_and_reports_impossible() {
        let mut limits = JointLimits::symmetric(PI);
        limits.lower[2] = -0.5;
        limits.upper[2] = 0.5;
        assert_eq!(limits.wrap_nearest(2, 1.0, 1.0), None);
        let q = limits.wrap_nearest(2, 0.2 + TAU, 5.0).unwrap();
        assert!((q - 0.2).abs() < 1e-12);
        assert!(
            limits
                .wrap_nearest_all(&[0.0, 0.0, 1.0, 0.0, 0.0, 0.0], &[0.0; 6])
                .is_none()
        );
    }
}
