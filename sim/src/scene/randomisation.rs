//! Domain randomisation: the documented ranges every scene parameter is drawn from.

use rand::{Rng, RngExt};

/// An inclusive range [lo, hi] a value is drawn uniformly from (lo = hi fixes it).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Range {
    /// Lower bound.
    pub lo: f64,
    /// Upper bound.
    pub hi: f64,
}

impl Range {
    /// The range [lo, hi].
    pub const fn new(lo: f64, hi: f64) -> Self {
        Self { lo, hi }
    }

    /// A uniform draw.
    pub fn sample(&self, rng: &mut impl Rng) -> f64 {
        if self.hi > self.lo {
            rng.random_range(self.lo..=self.hi)
        } else {
            self.lo
        }
    }
}

/// A randomisation range that cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RandomisationError {
    /// lo > hi.
    #[error("randomisation range {name} is inverted: lo = {lo} > hi = {hi}")]
    Inverted {
        /// The parameter.
        name: &'static str,
        /// Lower bound given.
        lo: f64,
        /// Upper bound given.
        hi: f64,
    },
    /// A bound is NaN or infinite.
    #[error("randomisation range {name} has a non-finite bound ({lo}, {hi})")]
    NotFinite {
        /// The parameter.
        name: &'static str,
        /// Lower bound given.
        lo: f64,
        /// Upper bound given.
        hi: f64,
    },
    /// A bound outside what the parameter can physically take.
    #[error("randomisation range {name} = [{lo}, {hi}] is outside the allowed [{min}, {max}]")]
    OutOfDomain {
        /// The parameter.
        name: &'static str,
        /// Lower bound given.
        lo: f64,
        /// Upper bound given.
        hi: f64,
        /// Smallest allowed value.
        min: f64,
        /// Largest allowed value.
        max: f64,
    },
    /// A count range that allows no parts at all, or no lights.
    #[error("randomisation range {name} is empty: it allows no {what}")]
    Empty {
        /// The parameter.
        name: &'static str,
        /// What is missing.
        what: &'static str,
    },
}

/// Ranges for every randomised scene parameter. Lengths in metres, angles in radians.
///
/// Defaults follow the seed's synthetic data (camera x, y within ±0.2 m of nominal, height
/// 1.4–1.9 m, aimed within 5 mm of the target; two point lights) and a lit lab cell.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Randomisation {
    /// Number of point lights (rounded draw).
    pub lights: Range,
    /// Light height above the table, m.
    pub light_height: Range,
    /// Horizontal distance of a light from the board centre, m.
    pub light_radius: Range,
    /// Light intensity: irradiance at 1 m in linear sensor units (radiance 1 is full scale).
    pub light_intensity: Range,
    /// Per-channel colour variation of a light (multiplier).
    pub light_tint: Range,
    /// Ambient (sky) radiance.
    pub ambient: Range,
    /// Grey albedo of the table under the board.
    pub table_albedo: Range,
    /// Per-channel multiplier of a material's base colour.
    pub material_tint: Range,
    /// Multiplier of a material's nominal roughness.
    pub roughness_scale: Range,
    /// Camera offset from nominal along table x and y, m.
    pub camera_xy: Range,
    /// Camera height above the table, m.
    pub camera_height: Range,
    /// Offset of the aim point from the target along x and y, m.
    pub camera_aim: Range,
    /// Rotation about the optical axis, rad.
    pub camera_roll: Range,
    /// Exposure multiplier.
    pub exposure: Range,
    /// Gaussian blur sigma, px.
    pub blur_sigma: Range,
    /// Read noise standard deviation (full scale 1).
    pub read_noise: Range,
    /// Shot noise variance per unit signal.
    pub shot_noise: Range,
}

impl Default for Randomisation {
    fn default() -> Self {
        Self {
            lights: Range::new(1.0, 2.0),
            light_height: Range::new(0.8, 1.6),
            light_radius: Range::new(0.0, 0.8),
            light_intensity: Range::new(0.7, 1.8),
            light_tint: Range::new(0.92, 1.08),
            ambient: Range::new(0.04, 0.15),
            table_albedo: Range::new(0.05, 0.6),
            material_tint: Range::new(0.85, 1.15),
            roughness_scale: Range::new(0.7, 1.4),
            camera_xy: Range::new(-0.2, 0.2),
            camera_height: Range::new(1.4, 1.9),
            camera_aim: Range::new(-0.005, 0.005),
            camera_roll: Range::new(-0.1, 0.1),
            exposure: Range::new(0.8, 1.25),
            blur_sigma: Range::new(0.0, 0.8),
            read_noise: Range::new(0.0, 0.01),
            shot_noise: Range::new(0.0, 0.002),
        }
    }
}

impl Randomisation {
    /// Checks every range: finite, lo ≤ hi, within the parameter's physical domain.
    pub fn validate(&self) -> Result<(), RandomisationError> {
        let inf = f64::INFINITY;
        let ranges: [(&'static str, Range, f64, f64); 17] = [
            ("lights", self.lights, 0.0, 8.0),
            ("light_height", self.light_height, 0.05, inf),
            ("light_radius", self.light_radius, 0.0, inf),
            ("light_intensity", self.light_intensity, 0.0, inf),
            ("light_tint", self.light_tint, 0.0, inf),
            ("ambient", self.ambient, 0.0, inf),
            ("table_albedo", self.table_albedo, 0.0, 1.0),
            ("material_tint", self.material_tint, 0.0, inf),
            ("roughness_scale", self.roughness_scale, 0.0, inf),
            ("camera_xy", self.camera_xy, -inf, inf),
            ("camera_height", self.camera_height, 0.05, inf),
            ("camera_aim", self.camera_aim, -inf, inf),
            (
                "camera_roll",
                self.camera_roll,
                -std::f64::consts::PI,
                std::f64::consts::PI,
            ),
            ("exposure", self.exposure, 1e-6, inf),
            ("blur_sigma", self.blur_sigma, 0.0, 10.0),
            ("read_noise", self.read_noise, 0.0, 1.0),
            ("shot_noise", self.shot_noise, 0.0, 1.0),
        ];
        for (name, r, min, max) in ranges {
            if !r.lo.is_finite() || !r.hi.is_finite() {
                return Err(RandomisationError::NotFinite {
                    name,
                    lo: r.lo,
                    hi: r.hi,
                });
            }
            if r.lo > r.hi {
                return Err(RandomisationError::Inverted {
                    name,
                    lo: r.lo,
                    hi: r.hi,
                });
            }
            if r.lo < min || r.hi > max {
                return Err(RandomisationError::OutOfDomain {
                    name,
                    lo: r.lo,
                    hi: r.hi,
                    min,
                    max,
                });
            }
        }
        if self.lights.hi.round() < 1.0 && self.ambient.hi <= 0.0 {
            return Err(RandomisationError::Empty {
                name: "lights",
                what: "light at all (no lights and no ambient)",
            });
        }
        Ok(())
    }
}
