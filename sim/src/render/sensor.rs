//! The image sensor: exposure, optical blur, shot and read noise, sRGB encoding to 8 bits.

use image::RgbImage;
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

use super::RenderOutput;

/// A sensor parameter out of its valid range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("sensor parameter {name} = {value} is invalid: {why}")]
pub struct SensorError {
    /// The parameter.
    pub name: &'static str,
    /// Its value.
    pub value: f64,
    /// What it must be.
    pub why: &'static str,
}

/// How radiance becomes 8-bit pixel values.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorModel {
    /// Multiplier from radiance to normalised exposure (1 = nominal).
    pub exposure: f64,
    /// Standard deviation of the Gaussian optical blur, pixels (0 for none).
    pub blur_sigma: f64,
    /// Read noise standard deviation, in normalised linear units (full scale 1).
    pub read_noise: f64,
    /// Shot noise: variance per unit of normalised linear signal.
    pub shot_noise: f64,
}

impl Default for SensorModel {
    fn default() -> Self {
        Self {
            exposure: 1.0,
            blur_sigma: 0.0,
            read_noise: 0.0,
            shot_noise: 0.0,
        }
    }
}

impl SensorModel {
    /// Checks every parameter is finite and in range.
    pub fn validate(&self) -> Result<(), SensorError> {
        let checks = [
            (
                "exposure",
                self.exposure,
                self.exposure > 0.0,
                "finite and > 0",
            ),
            (
                "blur_sigma",
                self.blur_sigma,
                self.blur_sigma >= 0.0,
                "finite and ≥ 0",
            ),
            (
                "read_noise",
                self.read_noise,
                self.read_noise >= 0.0,
                "finite and ≥ 0",
            ),
            (
                "shot_noise",
                self.shot_noise,
                self.shot_noise >= 0.0,
                "finite and ≥ 0",
            ),
        ];
        for (name, value, ok, why) in checks {
            if !ok || !value.is_finite() {
                return Err(SensorError { name, value, why });
            }
        }
        Ok(())
    }

    /// The 8-bit sRGB image of a render; noise draws come from `rng`.
    pub fn capture(&self, out: &RenderOutput, rng: &mut impl Rng) -> Result<RgbImage, SensorError> {
        self.validate()?;
        let (w, h) = (out.window.width as usize, out.window.height as usize);
        let mut lin: Vec<[f64; 3]> = out
            .radiance
            .iter()
            .map(|c| c.map(|x| x as f64 * self.exposure))
            .collect();
        if self.blur_sigma > 0.0 {
            lin = gaussian_blur(&lin, w, h, self.blur_sigma);
        }
        let noisy = self.read_noise > 0.0 || self.shot_noise > 0.0;
        let mut img = RgbImage::new(w as u32, h as u32);
        for (px, c) in img.pixels_mut().zip(&lin) {
            for (k, &channel) in c.iter().enumerate().take(3) {
                let mut x = channel;
                if noisy {
                    let sd =
                        (self.read_noise * self.read_noise + self.shot_noise * x.max(0.0)).sqrt();
                    let z: f64 = StandardNormal.sample(rng);
                    x += sd * z;
                }
                px.0[k] = encode_srgb(x);
            }
        }
        Ok(img)
    }
}

/// Linear value (0–1) to an 8-bit sRGB code: the number of code thresholds at or below `x`, the
/// same code as [`encode_srgb_exact`] without a `powf` per channel.
fn encode_srgb(x: f64) -> u8 {
    static THRESHOLDS: std::sync::OnceLock<Vec<f64>> = std::sync::OnceLock::new();
    let t = THRESHOLDS.get_or_init(|| (1..=255).map(srgb_threshold).collect());
    t.partition_point(|&t| t <= x) as u8
}

/// The sRGB transfer function, linear 0–1 to the nearest 8-bit code.
fn encode_srgb_exact(x: f64) -> u8 {
    let x = x.clamp(0.0, 1.0);
    let s = if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5).floor() as u8
}

/// The smallest non-negative linear value whose code is at least `code` (bisection over the
/// ordered bit patterns of positive doubles, so exact).
fn srgb_threshold(code: u8) -> f64 {
    let (mut lo, mut hi) = (0u64, 1f64.to_bits());
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if encode_srgb_exact(f64::from_bits(mid)) >= code {
            hi = mid;
        } else {
            lo = mid + 1;
        }
    }
    f64::from_bits(lo)
}

/// Separable Gaussian blur with clamped edges.
fn gaussian_blur(src: &[[f64; 3]], w: usize, h: usize, sigma: f64) -> Vec<[f64; 3]> {
    let r = (3.0 * sigma).ceil() as isize;
    let kernel: Vec<f64> = (-r..=r)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp())
        .collect();
    let sum: f64 = kernel.iter().sum();
    let kernel: Vec<f64> = kernel.iter().map(|k| k / sum).collect();
    let pass = |src: &[[f64; 3]], horizontal: bool| -> Vec<[f64; 3]> {
        let mut dst = vec![[0.0; 3]; src.len()];
        for y in 0..h {
            for x in 0..w {
                let mut acc = [0.0; 3];
                for (k, kv) in kernel.iter().enumerate() {
                    let o = k as isize - r;
                    let (sx, sy) = if horizontal {
                        ((x as isize + o).clamp(0, w as isize - 1) as usize, y)
                    } else {
                        (x, (y as isize + o).clamp(0, h as isize - 1) as usize)
                    };
                    let s = src[sy * w + sx];
                    for c in 0..3 {
                        acc[c] += kv * s[c];
                    }
                }
                dst[y * w + x] = acc;
            }
        }
        dst
    };
    pass(&pass(src, true), false)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_threshold_encoder_matches_the_transfer_function() {
        for i in 0..=200_000 {
            let x = i as f64 / 180_000.0 - 0.05;
            assert_eq!(encode_srgb(x), encode_srgb_exact(x), "at {x}");
        }
        assert_eq!(encode_srgb(f64::NAN), 0);
    }
}
