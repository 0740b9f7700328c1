//! Joint vectors and angle arithmetic with the ±2π wrap.

use std::f64::consts::{PI, TAU};

/// Joint angles of a six-axis arm, base to wrist 3, in radians.
pub type Joints = [f64; 6];

/// Wraps an angle into (−π, π].
pub fn normalize_angle(angle: f64) -> f64 {
    let wrapped = angle - TAU * (angle / TAU).round();
    if wrapped <= -PI {
        wrapped + TAU
    } else {
        wrapped
    }
}

/// Euclidean distance between two joint vectors in radians (no wrapping).
pub fn joint_distance(a: &Joints, b: &Joints) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f64>()
        .sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalize_maps_into_half_open_interval() {
        assert_eq!(normalize_angle(PI), PI);
        assert!((normalize_angle(-PI) - PI).abs() < 1e-15);
        assert!((normalize_angle(3.0 * TAU + 0.25) - 0.25).abs() < 1e-12);
        assert!((normalize_angle(-TAU - 0.5) + 0.5).abs() < 1e-12);
        assert!((normalize_angle(1.5 * PI) + 0.5 * PI).abs() < 1e-12);
    }
}
