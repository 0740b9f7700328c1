//! The image sensor: exposure, optical blur, defocus and motion blur, shot and read noise, gain,
//! sRGB encoding to 8 bits and optional JPEG-like block artefacts.

use image::RgbImage;
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

use super::RenderOutput;
use super::kernels::{convolve, disk_kernel, gaussian_blur, jpeg_like, line_kernel};

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
    /// Analogue gain after the noise sources: amplifies signal and noise alike (1 = none).
    pub gain: f64,
    /// Radius of the defocus disk (circle of confusion), pixels (0 for sharp focus).
    pub defocus_radius: f64,
    /// Length of the linear motion-blur streak, pixels (0 for none).
    pub motion_length: f64,
    /// Direction of the motion streak in the image, radians from the +x axis.
    pub motion_angle: f64,
    /// JPEG-like 8 × 8 block compression quality, 1–100 (0 for none).
    pub jpeg_quality: f64,
}

impl Default for SensorModel {
    fn default() -> Self {
        Self {
            exposure: 1.0,
            blur_sigma: 0.0,
            read_noise: 0.0,
            shot_noise: 0.0,
            gain: 1.0,
            defocus_radius: 0.0,
            motion_length: 0.0,
            motion_angle: 0.0,
            jpeg_quality: 0.0,
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
                (0.0..=10.0).contains(&self.blur_sigma),
                "finite and in [0, 10]",
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
            ("gain", self.gain, self.gain > 0.0, "finite and > 0"),
            (
                "defocus_radius",
                self.defocus_radius,
                (0.0..=10.0).contains(&self.defocus_radius),
                "finite and in [0, 10]",
            ),
            (
                "motion_length",
                self.motion_length,
                (0.0..=20.0).contains(&self.motion_length),
                "finite and in [0, 20]",
            ),
            (
                "motion_angle",
                self.motion_angle,
                self.motion_angle.is_finite(),
                "finite",
            ),
            (
                "jpeg_quality",
                self.jpeg_quality,
                self.jpeg_quality == 0.0 || (1.0..=100.0).contains(&self.jpeg_quality),
                "0 (off) or in [1, 100]",
            ),
        ];
        for (name, value, ok, why) in checks {
            if !ok || !value.is_finite() {
                return Err(SensorError { name, value, why });
            }
        }
        Ok(())
    }

    /// Highlight-priority metering: this sensor with its exposure lowered (never raised) so that
    /// all but a `share` of the parts' visible pixels in `out` stay below `target` of full scale
    /// after exposure and gain, keeping the edges and openings of shiny shells out of saturation.
    /// Unchanged when no part is visible.
    pub fn metered(&self, out: &RenderOutput, target: f64, share: f64) -> SensorModel {
        let mut peaks: Vec<f32> = out
            .visible
            .iter()
            .zip(&out.radiance)
            .filter(|(v, _)| **v != 0)
            .map(|(_, c)| c[0].max(c[1]).max(c[2]))
            .collect();
        if peaks.is_empty() {
            return *self;
        }
        let k =
            (((1.0 - share.clamp(0.0, 1.0)) * peaks.len() as f64) as usize).min(peaks.len() - 1);
        let (_, peak, _) = peaks.select_nth_unstable_by(k, f32::total_cmp);
        let level = *peak as f64 * self.exposure * self.gain;
        let mut metered = *self;
        if level > target && level.is_finite() {
            metered.exposure *= target / level;
        }
        metered
    }

    /// The 8-bit sRGB image of a render; noise draws come from `rng`.
    ///
    /// Order: exposure, optics (Gaussian blur, defocus disk, motion streak), shot and read noise,
    /// gain, clipping and sRGB encoding, then optional JPEG-like block compression.
    pub fn capture(&self, out: &RenderOutput, rng: &mut impl Rng) -> Result<RgbImage, SensorError> {
        self.capture_balanced(out, [1.0; 3], rng)
    }

    /// [`SensorModel::capture`] with a white balance: per-channel multipliers (red, green,
    /// blue) applied with the gain, after the noise, as a camera's processing applies them
    /// (`[1, 1, 1]` is `capture`, byte for byte).
    pub fn capture_balanced(
        &self,
        out: &RenderOutput,
        balance: [f64; 3],
        rng: &mut impl Rng,
    ) -> Result<RgbImage, SensorError> {
        self.validate()?;
        for b in balance {
            if !(b.is_finite() && b > 0.0) {
                return Err(SensorError {
                    name: "white_balance",
                    value: b,
                    why: "finite and > 0",
                });
            }
        }
        let (w, h) = (out.window.width as usize, out.window.height as usize);
        let mut lin: Vec<[f64; 3]> = out
            .radiance
            .iter()
            .map(|c| c.map(|x| x as f64 * self.exposure))
            .collect();
        if self.blur_sigma > 0.0 {
            lin = gaussian_blur(&lin, w, h, self.blur_sigma);
        }
        if self.defocus_radius > 0.0 {
            lin = convolve(&lin, w, h, &disk_kernel(self.defocus_radius));
        }
        if self.motion_length > 0.0 {
            lin = convolve(
                &lin,
                w,
                h,
                &line_kernel(self.motion_length, self.motion_angle),
            );
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
                px.0[k] = encode_srgb(x * self.gain * balance[k]);
            }
        }
        if self.jpeg_quality > 0.0 {
            jpeg_like(&mut img, self.jpeg_quality);
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
