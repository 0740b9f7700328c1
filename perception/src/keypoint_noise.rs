//! The one keypoint-noise model: Gaussian pixel noise along x, y or both, plus gross outliers.
//! The simulation's keypoint-noise perception and the Figure 5 ablation both draw from it, so the
//! noise a scenario names is the noise the ablation studied.

use nalgebra::{Point2, Vector2};
use rand::{Rng, RngExt};
use serde::{Deserialize, Serialize};

/// Along which image axis Gaussian keypoint noise is added.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum NoiseAxis {
    /// Columns only.
    X,
    /// Rows only.
    Y,
    /// Both, independently (isotropic).
    Iso,
}

impl NoiseAxis {
    /// Every axis mode.
    pub const ALL: [NoiseAxis; 3] = [NoiseAxis::X, NoiseAxis::Y, NoiseAxis::Iso];

    /// Short name: "x", "y", "iso".
    pub fn name(self) -> &'static str {
        match self {
            NoiseAxis::X => "x",
            NoiseAxis::Y => "y",
            NoiseAxis::Iso => "iso",
        }
    }
}

/// Keypoint noise: σ px of Gaussian noise along `axis`, and a fraction of keypoints replaced by
/// outliers drawn uniformly in a box of half size `outlier_radius_px` around the true keypoint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KeypointNoiseModel {
    /// Standard deviation per noisy axis, pixels.
    pub noise_px: f64,
    /// Which axes get Gaussian noise.
    pub axis: NoiseAxis,
    /// Fraction of keypoints replaced by gross outliers, in [0, 1].
    pub outlier_fraction: f64,
    /// Half size of the box an outlier lands in, pixels.
    pub outlier_radius_px: f64,
}

impl KeypointNoiseModel {
    /// Isotropic noise of `noise_px` with `outlier_fraction` outliers in a 40 px box.
    pub fn new(noise_px: f64, outlier_fraction: f64) -> Self {
        Self {
            noise_px,
            axis: NoiseAxis::Iso,
            outlier_fraction,
            outlier_radius_px: 40.0,
        }
    }

    /// Checks the settings; the error says which one is wrong.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.noise_px.is_finite() && self.noise_px >= 0.0) {
            return Err(format!(
                "keypoint noise must be ≥ 0 px, got {}",
                self.noise_px
            ));
        }
        if !(0.0..=1.0).contains(&self.outlier_fraction) {
            return Err(format!(
                "outlier fraction must be in [0, 1], got {}",
                self.outlier_fraction
            ));
        }
        if !(self.outlier_radius_px.is_finite() && self.outlier_radius_px >= 0.0) {
            return Err(format!(
                "outlier radius must be ≥ 0 px, got {}",
                self.outlier_radius_px
            ));
        }
        Ok(())
    }

    /// The observed pixel of a keypoint whose true pixel is `truth`. Every call draws the same
    /// number of random values, whatever the axis, so streams stay aligned across settings.
    pub fn perturb(&self, truth: Point2<f64>, rng: &mut impl Rng) -> Point2<f64> {
        if rng.random::<f64>() < self.outlier_fraction {
            let r = self.outlier_radius_px;
            return Point2::new(
                truth.x + rng.random_range(-r..=r),
                truth.y + rng.random_range(-r..=r),
            );
        }
        let (nx, ny) = (gauss(rng), gauss(rng));
        let s = self.noise_px;
        truth
            + match self.axis {
                NoiseAxis::X => Vector2::new(s * nx, 0.0),
                NoiseAxis::Y => Vector2::new(0.0, s * ny),
                NoiseAxis::Iso => Vector2::new(s * nx, s * ny),
            }
    }
}

/// A standard normal draw (Box–Muller from two uniforms in (0, 1]).
fn gauss(rng: &mut impl Rng) -> f64 {
    let u1: f64 = 1.0 - rng.random::<f64>();
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn noise_has_the_named_spread_on_the_named_axes() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let truth = Point2::new(100.0, 50.0);
        for axis in [NoiseAxis::X, NoiseAxis::Y, NoiseAxis::Iso] {
            let model = KeypointNoiseModel {
                axis,
                ..KeypointNoiseModel::new(2.0, 0.0)
            };
            let n = 20_000;
            let (mut sx, mut sy) = (0.0, 0.0);
            for _ in 0..n {
                let d = model.perturb(truth, &mut rng) - truth;
                sx += d.x * d.x;
                sy += d.y * d.y;
            }
            let (sx, sy) = ((sx / n as f64).sqrt(), (sy / n as f64).sqrt());
            let want = |on: bool| if on { 2.0 } else { 0.0 };
            assert!(
                (sx - want(axis != NoiseAxis::Y)).abs() < 0.05,
                "{axis:?} x {sx}"
            );
            assert!(
                (sy - want(axis != NoiseAxis::X)).abs() < 0.05,
                "{axis:?} y {sy}"
            );
        }
    }

    #[test]
    fn outliers_land_in_their_box_at_their_rate() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let model = KeypointNoiseModel::new(0.0, 0.25);
        let truth = Point2::new(0.0, 0.0);
        let moved = (0..10_000)
            .map(|_| model.perturb(truth, &mut rng))
            .inspect(|p| assert!(p.x.abs() <= 40.0 && p.y.abs() <= 40.0))
            .filter(|p| p.coords.norm() > 0.0)
            .count();
        assert!((moved as f64 / 10_000.0 - 0.25).abs() < 0.015, "{moved}");
    }

    #[test]
    fn bad_settings_are_named() {
        assert!(
            KeypointNoiseModel::new(-1.0, 0.0)
                .validate()
                .unwrap_err()
                .contains("noise")
        );
        assert!(
            KeypointNoiseModel::new(1.0, 1.5)
                .validate()
                .unwrap_err()
                .contains("outlier")
        );
    }
}
