//! Procedural albedo textures for the table under the feeder plate: smooth value noise (a
//! mottled laminate or a rubber mat) or stripes bent by noise (wood grain, brushed sheet), as a
//! multiplier of the table's base colour at each point.

use nalgebra::Point3;

/// The pattern of a [`TableTexture`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TexturePattern {
    /// Two octaves of smooth value noise.
    Noise,
    /// Stripes along a direction, bent by value noise.
    Stripes,
}

/// A procedural texture multiplying the table's albedo by `1 + contrast · p(x, y)` with the
/// pattern `p` in [−1, 1], clamped to [0, 1] albedo.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TableTexture {
    /// The pattern.
    pub pattern: TexturePattern,
    /// Feature size (noise cell, stripe period), metres.
    pub scale: f64,
    /// Amplitude of the albedo modulation, 0–1.
    pub contrast: f64,
    /// Direction of the stripes in the table plane, radians.
    pub angle: f64,
    /// Seed of the noise lattice.
    pub seed: u64,
}

impl TableTexture {
    /// The albedo multiplier at table-frame point `p` (only x and y matter).
    pub fn factor(&self, p: &Point3<f64>) -> f64 {
        let s = self.scale.max(1e-6);
        let (x, y) = (p.x / s, p.y / s);
        let v = match self.pattern {
            TexturePattern::Noise => {
                (2.0 * value_noise(x, y, self.seed) + value_noise(2.0 * x, 2.0 * y, self.seed ^ 1))
                    / 3.0
            }
            TexturePattern::Stripes => {
                let (c, sn) = (self.angle.cos(), self.angle.sin());
                let u = c * x + sn * y;
                let bend = value_noise(0.25 * x, 0.25 * y, self.seed);
                (std::f64::consts::TAU * (u + 0.6 * bend)).sin()
            }
        };
        (1.0 + self.contrast * v).max(0.0)
    }
}

/// Smooth value noise in [−1, 1]: hashed lattice values blended with a smoothstep.
fn value_noise(x: f64, y: f64, seed: u64) -> f64 {
    let (xf, yf) = (x.floor(), y.floor());
    let (fx, fy) = (x - xf, y - yf);
    let (ix, iy) = (xf as i64, yf as i64);
    let smooth = |t: f64| t * t * (3.0 - 2.0 * t);
    let (sx, sy) = (smooth(fx), smooth(fy));
    let v = |i: i64, j: i64| lattice(ix + i, iy + j, seed);
    let top = v(0, 0) + (v(1, 0) - v(0, 0)) * sx;
    let bottom = v(0, 1) + (v(1, 1) - v(0, 1)) * sx;
    top + (bottom - top) * sy
}

/// A pseudo-random value in [−1, 1] at lattice point (i, j) (splitmix64 of the coordinates).
fn lattice(i: i64, j: i64, seed: u64) -> f64 {
    let mut z = seed
        ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (j as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 52) as f64 - 1.0
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The factor stays within 1 ± contrast, averages near 1 and varies over the table.
    #[test]
    fn the_factor_is_bounded_and_varies() {
        for pattern in [TexturePattern::Noise, TexturePattern::Stripes] {
            let t = TableTexture {
                pattern,
                scale: 0.01,
                contrast: 0.4,
                angle: 0.3,
                seed: 5,
            };
            let f: Vec<f64> = (0..10_000)
                .map(|k| {
                    t.factor(&Point3::new(
                        (k % 100) as f64 * 1e-3,
                        (k / 100) as f64 * 1e-3,
                        0.0,
                    ))
                })
                .collect();
            let (lo, hi) = f
                .iter()
                .fold((f64::MAX, f64::MIN), |(a, b), x| (a.min(*x), b.max(*x)));
            let mean = f.iter().sum::<f64>() / f.len() as f64;
            assert!(
                lo >= 0.6 - 1e-12 && hi <= 1.4 + 1e-12,
                "{pattern:?}: {lo} {hi}"
            );
            assert!(hi - lo > 0.3, "{pattern:?}: {lo} {hi}");
            assert!((mean - 1.0).abs() < 0.1, "{pattern:?}: {mean}");
        }
    }
}
