//! Domain randomisation: the documented ranges every scene parameter is drawn from.

use rand::{Rng, RngExt};

/// An inclusive range [lo, hi] a value is drawn uniformly from (lo = hi fixes it).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
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

    /// Whether the range can be drawn from within the domain [min, max]: both bounds finite,
    /// lo ≤ hi, and both inside the domain (the one check of every randomisation, look and
    /// family range).
    pub fn check(&self, min: f64, max: f64) -> Result<(), RangeError> {
        let (lo, hi) = (self.lo, self.hi);
        if !lo.is_finite() || !hi.is_finite() {
            return Err(RangeError::NotFinite { lo, hi });
        }
        if lo > hi {
            return Err(RangeError::Inverted { lo, hi });
        }
        if lo < min || hi > max {
            return Err(RangeError::OutOfDomain { lo, hi, min, max });
        }
        Ok(())
    }
}

/// Why a [`Range`] cannot be drawn from ([`Range::check`]).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum RangeError {
    /// A bound is NaN or infinite.
    #[error("non-finite bound ({lo}, {hi})")]
    NotFinite {
        /// Lower bound given.
        lo: f64,
        /// Upper bound given.
        hi: f64,
    },
    /// lo > hi.
    #[error("inverted: lo = {lo} > hi = {hi}")]
    Inverted {
        /// Lower bound given.
        lo: f64,
        /// Upper bound given.
        hi: f64,
    },
    /// A bound outside the domain.
    #[error("[{lo}, {hi}] is outside the allowed [{min}, {max}]")]
    OutOfDomain {
        /// Lower bound given.
        lo: f64,
        /// Upper bound given.
        hi: f64,
        /// Smallest allowed value.
        min: f64,
        /// Largest allowed value.
        max: f64,
    },
}

impl RandomisationError {
    /// The randomisation parameter `name`'s range error.
    fn of_range(name: &'static str, e: RangeError) -> Self {
        match e {
            RangeError::NotFinite { lo, hi } => Self::NotFinite { name, lo, hi },
            RangeError::Inverted { lo, hi } => Self::Inverted { name, lo, hi },
            RangeError::OutOfDomain { lo, hi, min, max } => Self::OutOfDomain {
                name,
                lo,
                hi,
                min,
                max,
            },
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
/// 1.4–1.9 m, aimed within 5 mm of the target; one or two lights) and its BlenderProc setup
/// (randomised materials, lights, camera effects and clutter), tuned so that at the default
/// exposure no part saturates: clipping appears only as the randomised over-exposure condition.
/// In a TOML file every key is optional (missing keys keep their defaults); a range is written
/// `key = { lo = 0.1, hi = 0.2 }`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
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
    /// Radius of a light's emitting sphere, m (soft shadows, wider highlights).
    pub light_size: Range,
    /// Ambient (sky) radiance.
    pub ambient: Range,
    /// Grey albedo of the table under the board.
    pub table_albedo: Range,
    /// Multiplier of a material's base colour (brightness; each channel also shifts by up to a
    /// tenth of the range's spread, a subtle colour cast).
    pub material_tint: Range,
    /// Multiplier of a material's nominal roughness.
    pub roughness_scale: Range,
    /// Brushing of the metal shells (0 isotropic … 1 strongly brushed highlights).
    pub metal_anisotropy: Range,
    /// Albedo of the board's black print.
    pub board_black: Range,
    /// Amplitude of the board print's smooth albedo variation.
    pub board_grain: Range,
    /// Dust specks on the board per cm².
    pub dust: Range,
    /// Scratches through the board's print per 100 cm².
    pub scratches: Range,
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
    /// Probability that an image is over-exposed (saturated highlights), 0–1.
    pub overexposure_probability: f64,
    /// Extra exposure multiplier of an over-exposed image.
    pub overexposure: Range,
    /// Analogue gain (amplifies signal and noise).
    pub gain: Range,
    /// Gaussian blur sigma, px.
    pub blur_sigma: Range,
    /// Defocus disk radius, px.
    pub defocus_radius: Range,
    /// Motion-blur streak length, px (direction uniform).
    pub motion_length: Range,
    /// Read noise standard deviation (full scale 1).
    pub read_noise: Range,
    /// Shot noise variance per unit signal.
    pub shot_noise: Range,
    /// Probability that an image gets JPEG-like block artefacts, 0–1.
    pub jpeg_probability: f64,
    /// Quality of the JPEG-like compression, 1–100.
    pub jpeg_quality: Range,
}

impl Default for Randomisation {
    fn default() -> Self {
        Self {
            lights: Range::new(1.0, 2.0),
            light_height: Range::new(0.8, 1.6),
            light_radius: Range::new(0.0, 0.8),
            light_intensity: Range::new(0.7, 1.8),
            light_tint: Range::new(0.92, 1.08),
            light_size: Range::new(0.0, 0.15),
            ambient: Range::new(0.04, 0.15),
            table_albedo: Range::new(0.05, 0.6),
            material_tint: Range::new(0.85, 1.15),
            roughness_scale: Range::new(0.7, 1.4),
            metal_anisotropy: Range::new(0.0, 0.7),
            board_black: Range::new(0.015, 0.06),
            board_grain: Range::new(0.0, 0.08),
            dust: Range::new(0.0, 0.5),
            scratches: Range::new(0.0, 4.0),
            camera_xy: Range::new(-0.2, 0.2),
            camera_height: Range::new(1.4, 1.9),
            camera_aim: Range::new(-0.005, 0.005),
            camera_roll: Range::new(-0.1, 0.1),
            exposure: Range::new(0.8, 1.25),
            overexposure_probability: 0.05,
            overexposure: Range::new(1.8, 3.5),
            gain: Range::new(1.0, 1.3),
            blur_sigma: Range::new(0.0, 0.8),
            defocus_radius: Range::new(0.0, 0.7),
            motion_length: Range::new(0.0, 1.0),
            read_noise: Range::new(0.0, 0.01),
            shot_noise: Range::new(0.0, 0.002),
            jpeg_probability: 0.3,
            jpeg_quality: Range::new(60.0, 95.0),
        }
    }
}

impl Randomisation {
    /// The same ranges without the randomised over-exposure: the settings images should look
    /// like by default (no part saturates).
    pub fn without_overexposure(&self) -> Self {
        Self {
            overexposure_probability: 0.0,
            ..self.clone()
        }
    }

    /// Checks every range: finite, lo ≤ hi, within the parameter's physical domain; and every
    /// probability in [0, 1]. The error names the key.
    pub fn validate(&self) -> Result<(), RandomisationError> {
        let inf = f64::INFINITY;
        let pi = std::f64::consts::PI;
        let ranges: [(&'static str, Range, f64, f64); 30] = [
            ("lights", self.lights, 0.0, 8.0),
            ("light_height", self.light_height, 0.05, inf),
            ("light_radius", self.light_radius, 0.0, inf),
            ("light_intensity", self.light_intensity, 0.0, inf),
            ("light_tint", self.light_tint, 0.0, inf),
            ("light_size", self.light_size, 0.0, 1.0),
            ("ambient", self.ambient, 0.0, inf),
            ("table_albedo", self.table_albedo, 0.0, 1.0),
            ("material_tint", self.material_tint, 0.0, inf),
            ("roughness_scale", self.roughness_scale, 0.0, inf),
            ("metal_anisotropy", self.metal_anisotropy, 0.0, 1.0),
            ("board_black", self.board_black, 0.0, 1.0),
            ("board_grain", self.board_grain, 0.0, 1.0),
            ("dust", self.dust, 0.0, 100.0),
            ("scratches", self.scratches, 0.0, 100.0),
            ("camera_xy", self.camera_xy, -inf, inf),
            ("camera_height", self.camera_height, 0.05, inf),
            ("camera_aim", self.camera_aim, -inf, inf),
            ("camera_roll", self.camera_roll, -pi, pi),
            ("exposure", self.exposure, 1e-6, inf),
            (
                "overexposure_probability",
                Range::new(self.overexposure_probability, self.overexposure_probability),
                0.0,
                1.0,
            ),
            ("overexposure", self.overexposure, 1.0, inf),
            ("gain", self.gain, 1e-6, inf),
            ("blur_sigma", self.blur_sigma, 0.0, 10.0),
            ("defocus_radius", self.defocus_radius, 0.0, 10.0),
            ("motion_length", self.motion_length, 0.0, 20.0),
            ("read_noise", self.read_noise, 0.0, 1.0),
            ("shot_noise", self.shot_noise, 0.0, 1.0),
            (
                "jpeg_probability",
                Range::new(self.jpeg_probability, self.jpeg_probability),
                0.0,
                1.0,
            ),
            ("jpeg_quality", self.jpeg_quality, 1.0, 100.0),
        ];
        for (name, r, min, max) in ranges {
            r.check(min, max)
                .map_err(|e| RandomisationError::of_range(name, e))?;
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
