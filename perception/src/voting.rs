//! PVNet keypoint voting: from a foreground mask and per-pixel unit vectors pointing at each
//! keypoint, RANSAC over line-intersection hypotheses, a least-squares keypoint over the inlier
//! lines, and a 2×2 covariance from the spread of inlier-weighted hypotheses.
//!
//! Coordinates are pixels of the crop the field was computed on (centres at integers, x = column,
//! y = row). Every random draw comes from a generator seeded by [`VotingConfig::seed`] and the
//! keypoint index, so results repeat exactly. A [`Voter`] keeps its buffers between calls.

use nalgebra::{Matrix2, Point2, Vector2};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Why voting could not produce keypoints.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum VoteError {
    /// A buffer's length does not match the declared field shape.
    #[error("{what} has {got} values, expected {expected}")]
    ShapeMismatch {
        /// Which buffer.
        what: &'static str,
        /// Length implied by width, height and keypoint count.
        expected: usize,
        /// Its actual length.
        got: usize,
    },
    /// The field declares zero keypoints, or a zero width or height.
    #[error("the vector field is empty ({width} × {height} px, {keypoints} keypoints)")]
    EmptyField {
        /// Width in pixels.
        width: usize,
        /// Height in pixels.
        height: usize,
        /// Keypoints.
        keypoints: usize,
    },
    /// No pixel of the mask is foreground.
    #[error("the foreground mask is empty")]
    EmptyMask,
    /// A vector component at a foreground pixel is NaN or infinite.
    #[error("non-finite vector for keypoint {keypoint} at pixel ({x}, {y})")]
    NonFinite {
        /// Keypoint index.
        keypoint: usize,
        /// Column.
        x: usize,
        /// Row.
        y: usize,
    },
    /// Fewer than two foreground pixels carry a usable (non-zero) vector for this keypoint.
    #[error("keypoint {keypoint}: only {usable} foreground pixels have a usable vector")]
    TooFewPixels {
        /// Keypoint index.
        keypoint: usize,
        /// Usable pixels.
        usable: usize,
    },
    /// Every sampled pair of lines was parallel or met behind its pixels: no hypothesis.
    #[error("keypoint {keypoint}: the vectors do not converge on any point")]
    NoHypothesis {
        /// Keypoint index.
        keypoint: usize,
    },
    /// The configuration is unusable.
    #[error("invalid voting configuration: {0}")]
    InvalidConfig(&'static str),
}

/// Voting parameters; the defaults are the seed's (PVNet's).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VotingConfig {
    /// Hypotheses generated per RANSAC round.
    pub hypotheses_per_round: usize,
    /// Upper bound on rounds.
    pub max_rounds: usize,
    /// Stop once the best hypothesis would have been found with this probability.
    pub confidence: f64,
    /// A pixel votes for a hypothesis when the cosine between its vector and the direction to the
    /// hypothesis exceeds this.
    pub inlier_cosine: f32,
    /// Least-squares re-estimations with the inliers of the previous estimate.
    pub refine_iterations: usize,
    /// Hypotheses sampled from inlier pairs for the covariance (0 disables it).
    pub covariance_hypotheses: usize,
    /// Foreground pixels (at most) that weigh each covariance hypothesis.
    pub covariance_voters: usize,
    /// Floor added to the covariance diagonal, px², so that a perfect field still gives a
    /// usable (invertible) weight.
    pub covariance_floor: f64,
    /// Seed of the random generator (mixed with the keypoint index).
    pub seed: u64,
}

impl Default for VotingConfig {
    fn default() -> Self {
        Self {
            hypotheses_per_round: 128,
            max_rounds: 20,
            confidence: 0.99,
            inlier_cosine: 0.99,
            refine_iterations: 2,
            covariance_hypotheses: 256,
            covariance_voters: 512,
            covariance_floor: 1e-4,
            seed: 0,
        }
    }
}

/// A network's output for one crop: foreground mask and 2K vector channels, row-major.
#[derive(Debug, Clone, Copy)]
pub struct VectorField<'a> {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Number of keypoints K.
    pub keypoints: usize,
    /// Foreground mask, `width × height`, non-zero for the object.
    pub mask: &'a [u8],
    /// Vectors, channel-major `[2K][height][width]`: channel 2k is the x component for keypoint
    /// k, 2k + 1 the y component (PVNet's layout). Need not be unit length.
    pub vectors: &'a [f32],
}

/// One voted keypoint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KeypointVote {
    /// Least-squares intersection of the inlier lines, pixels.
    pub position: Point2<f64>,
    /// Covariance of the position from the spread of inlier-weighted hypotheses, px².
    pub covariance: Matrix2<f64>,
    /// Pixels whose vector agrees with the final position.
    pub inliers: usize,
    /// Inliers over usable foreground pixels.
    pub inlier_ratio: f64,
    /// Hypotheses tested by RANSAC.
    pub hypotheses: usize,
}

/// Reusable voting state: configuration and scratch buffers.
#[derive(Debug, Clone, Default)]
pub struct Voter {
    config: VotingConfig,
    xs: Vec<f32>,
    ys: Vec<f32>,
    idx: Vec<usize>,
    ux: Vec<f32>,
    uy: Vec<f32>,
    usable: Vec<u32>,
    inliers: Vec<u32>,
    voters: [Vec<f32>; 4],
}

impl Voter {
    /// A voter with this configuration.
    pub fn new(config: VotingConfig) -> Self {
        Self {
            config,
            ..Self::default()
        }
    }

    /// Its configuration.
    pub fn config(&self) -> &VotingConfig {
        &self.config
    }

    /// Votes every keypoint of the field.
    pub fn vote(&mut self, field: &VectorField<'_>) -> Result<Vec<KeypointVote>, VoteError> {
        self.check(field)?;
        self.gather_foreground(field);
        if self.idx.is_empty() {
            return Err(VoteError::EmptyMask);
        }
        (0..field.keypoints)
            .map(|k| self.vote_keypoint(field, k))
            .collect()
    }

    fn check(&self, field: &VectorField<'_>) -> Result<(), VoteError> {
        let c = &self.config;
        if c.hypotheses_per_round == 0 || c.max_rounds == 0 {
            return Err(VoteError::InvalidConfig("no hypotheses would be tested"));
        }
        if !(c.confidence > 0.0 && c.confidence < 1.0) {
            return Err(VoteError::InvalidConfig("confidence must lie in (0, 1)"));
        }
        if !(c.inlier_cosine > 0.0 && c.inlier_cosine < 1.0) {
            return Err(VoteError::InvalidConfig("inlier cosine must lie in (0, 1)"));
        }
        if !(c.covariance_floor.is_finite() && c.covariance_floor >= 0.0) {
            return Err(VoteError::InvalidConfig("covariance floor must be ≥ 0"));
        }
        if field.width == 0 || field.height == 0 || field.keypoints == 0 {
            return Err(VoteError::EmptyField {
                width: field.width,
                height: field.height,
                keypoints: field.keypoints,
            });
        }
        let pixels = field.width.checked_mul(field.height);
        let channels = pixels.and_then(|p| p.checked_mul(2 * field.keypoints));
        let (Some(pixels), Some(channels)) = (pixels, channels) else {
            return Err(VoteError::InvalidConfig("field dimensions overflow"));
        };
        if field.mask.len() != pixels {
            return Err(VoteError::ShapeMismatch {
                what: "mask",
                expected: pixels,
                got: field.mask.len(),
            });
        }
        if field.vectors.len() != channels {
            return Err(VoteError::ShapeMismatch {
                what: "vectors",
                expected: channels,
                got: field.vectors.len(),
            });
        }
        Ok(())
    }

    fn gather_foreground(&mut self, field: &VectorField<'_>) {
        self.xs.clear();
        self.ys.clear();
        self.idx.clear();
        for (i, _) in field.mask.iter().enumerate().filter(|(_, m)| **m != 0) {
            self.idx.push(i);
            self.xs.push((i % field.width) as f32);
            self.ys.push((i / field.width) as f32);
        }
    }

    /// Loads keypoint k's vectors for the foreground pixels, normalised (the network's need not
    /// be); zero vectors stay zero (they never vote and never make hypotheses).
    fn load_vectors(&mut self, field: &VectorField<'_>, k: usize) -> Result<(), VoteError> {
        let plane = field.width * field.height;
        let (cx, cy) = (
            &field.vectors[2 * k * plane..(2 * k + 1) * plane],
            &field.vectors[(2 * k + 1) * plane..(2 * k + 2) * plane],
        );
        self.ux.clear();
        self.uy.clear();
        self.usable.clear();
        for (j, &i) in self.idx.iter().enumerate() {
            let (x, y) = (cx[i], cy[i]);
            if !(x.is_finite() && y.is_finite()) {
                return Err(VoteError::NonFinite {
                    keypoint: k,
                    x: i % field.width,
                    y: i / field.width,
                });
            }
            let n = (x * x + y * y).sqrt();
            if n > 1e-6 {
                self.ux.push(x / n);
                self.uy.push(y / n);
                self.usable.push(j as u32);
            } else {
                self.ux.push(0.0);
                self.uy.push(0.0);
            }
        }
        Ok(())
    }

    fn vote_keypoint(
        &mut self,
        field: &VectorField<'_>,
        k: usize,
    ) -> Result<KeypointVote, VoteError> {
        self.load_vectors(field, k)?;
        let usable = self.usable.len();
        if usable < 2 {
            return Err(VoteError::TooFewPixels {
                keypoint: k,
                usable,
            });
        }
        let c = self.config;
        let mut rng =
            ChaCha8Rng::seed_from_u64(c.seed ^ (k as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15));
        let mut best: Option<(Vector2<f64>, usize)> = None;
        let mut tested = 0usize;
        for _ in 0..c.max_rounds {
            for _ in 0..c.hypotheses_per_round {
                let Some(h) = self.random_hypothesis(&mut rng) else {
                    continue;
                };
                tested += 1;
                let count = self.count_inliers(h.x as f32, h.y as f32);
                if best.is_none_or(|(_, b)| count > b) {
                    best = Some((h, count));
                }
            }
            if let Some((_, count)) = best {
                let w = count as f64 / usable as f64;
                let needed = required_hypotheses(w, c.confidence);
                if tested as f64 >= needed {
                    break;
                }
            }
        }
        let Some((mut estimate, _)) = best else {
            return Err(VoteError::NoHypothesis { keypoint: k });
        };
        // Least squares over the inliers, re-selected around each new estimate.
        for _ in 0..=c.refine_iterations {
            self.collect_inliers(estimate.x as f32, estimate.y as f32);
            match self.least_squares() {
                Some(p) => estimate = p,
                None => break,
            }
        }
        self.collect_inliers(estimate.x as f32, estimate.y as f32);
        let inliers = self.inliers.len();
        let covariance = self.covariance(&mut rng, estimate);
        Ok(KeypointVote {
            position: Point2::from(estimate),
            covariance,
            inliers,
            inlier_ratio: inliers as f64 / usable as f64,
            hypotheses: tested,
        })
    }

    /// The intersection of the lines of two random usable pixels, if they meet ahead of both.
    fn random_hypothesis(&self, rng: &mut ChaCha8Rng) -> Option<Vector2<f64>> {
        let n = self.usable.len();
        let a = self.usable[rng.random_range(0..n)] as usize;
        let b = self.usable[rng.random_range(0..n)] as usize;
        self.intersect(a, b)
    }

    fn intersect(&self, a: usize, b: usize) -> Option<Vector2<f64>> {
        let pa = Vector2::new(f64::from(self.xs[a]), f64::from(self.ys[a]));
        let pb = Vector2::new(f64::from(self.xs[b]), f64::from(self.ys[b]));
        let da = Vector2::new(f64::from(self.ux[a]), f64::from(self.uy[a]));
        let db = Vector2::new(f64::from(self.ux[b]), f64::from(self.uy[b]));
        let cross = da.x * db.y - da.y * db.x;
        if cross.abs() < 1e-3 {
            return None;
        }
        let d = pb - pa;
        let s = (d.x * db.y - d.y * db.x) / cross;
        let t = (d.x * da.y - d.y * da.x) / cross;
        // Vectors point at the keypoint: it lies ahead of both pixels.
        (s >= 0.0 && t >= 0.0).then(|| pa + da * s)
    }

    /// Pixels whose vector points at `(hx, hy)` within the cosine threshold (branch-free, so the
    /// loop vectorises).
    fn count_inliers(&self, hx: f32, hy: f32) -> usize {
        let t2 = self.config.inlier_cosine * self.config.inlier_cosine;
        count_votes([&self.xs, &self.ys, &self.ux, &self.uy], hx, hy, t2)
    }

    /// The pixels whose vector points at `(hx, hy)`, in order ([`votes_for`]; every
    /// index is written and the count advances only for inliers, so the loop has no branch).
    fn collect_inliers(&mut self, hx: f32, hy: f32) {
        let t2 = self.config.inlier_cosine * self.config.inlier_cosine;
        let n = self.xs.len();
        self.inliers.resize(n, 0);
        let mut count = 0;
        let pixels = self.xs.iter().zip(&self.ys).zip(&self.ux).zip(&self.uy);
        for (j, (((&x, &y), &ux), &uy)) in pixels.enumerate() {
            self.inliers[count] = j as u32;
            count += usize::from(votes_for([x, y, ux, uy], hx, hy, t2));
        }
        self.inliers.truncate(count);
    }

    /// The point closest (in squared perpendicular distance) to every inlier line.
    fn least_squares(&self) -> Option<Vector2<f64>> {
        let mut a = Matrix2::zeros();
        let mut b = Vector2::zeros();
        for &j in &self.inliers {
            let j = j as usize;
            let d = Vector2::new(f64::from(self.ux[j]), f64::from(self.uy[j]));
            let p = Vector2::new(f64::from(self.xs[j]), f64::from(self.ys[j]));
            let proj = Matrix2::identity() - d * d.transpose();
            a += proj;
            b += proj * p;
        }
        // Parallel inlier lines leave A singular: keep the RANSAC hypothesis then.
        let eig = a.symmetric_eigenvalues();
        if eig.min() <= 1e-9 * eig.max().max(1e-300) {
            return None;
        }
        a.try_inverse().map(|inv| inv * b)
    }

    /// PVNet's uncertainty: hypotheses from random inlier pairs, each weighted by the votes it
    /// gets from (a subset of) the foreground, then their weighted covariance.
    fn covariance(&mut self, rng: &mut ChaCha8Rng, estimate: Vector2<f64>) -> Matrix2<f64> {
        let c = self.config;
        let floor = Matrix2::identity() * c.covariance_floor;
        let n = self.inliers.len();
        if c.covariance_hypotheses == 0 || n < 2 {
            return floor;
        }
        // The voters, gathered into contiguous arrays once so that counting vectorises.
        let mut voters = std::mem::take(&mut self.voters);
        for v in voters.iter_mut() {
            v.clear();
        }
        let take = self.usable.len().min(c.covariance_voters);
        for i in 0..take {
            let j = if self.usable.len() <= c.covariance_voters {
                self.usable[i] as usize
            } else {
                self.usable[rng.random_range(0..self.usable.len())] as usize
            };
            voters[0].push(self.xs[j]);
            voters[1].push(self.ys[j]);
            voters[2].push(self.ux[j]);
            voters[3].push(self.uy[j]);
        }
        let t2 = c.inlier_cosine * c.inlier_cosine;
        let (mut wsum, mut mean, mut second) = (0.0, Vector2::zeros(), Matrix2::zeros());
        for _ in 0..c.covariance_hypotheses {
            let a = self.inliers[rng.random_range(0..n)] as usize;
            let b = self.inliers[rng.random_range(0..n)] as usize;
            let Some(h) = self.intersect(a, b) else {
                continue;
            };
            let votes = count_votes(
                [&voters[0], &voters[1], &voters[2], &voters[3]],
                h.x as f32,
                h.y as f32,
                t2,
            ) as f64;
            // Centre on the estimate for numerical stability; shifted back below.
            let d = h - estimate;
            wsum += votes;
            mean += d * votes;
            second += d * d.transpose() * votes;
        }
        self.voters = voters;
        if wsum <= 0.0 {
            return floor;
        }
        let mean = mean / wsum;
        let cov = second / wsum - mean * mean.transpose();
        let cov = (cov + cov.transpose()) * 0.5;
        if cov.iter().all(|v| v.is_finite()) {
            cov + floor
        } else {
            floor
        }
    }
}

/// Pixels of `[xs, ys, ux, uy]` whose vector points at `(hx, hy)` within cosine √`t2`
/// (branch-free, so the loop vectorises; 8 lanes where the CPU has AVX2, with the same
/// arithmetic, so the count is the same on every CPU).
#[multiversion::multiversion(targets("x86_64+avx2"))]
fn count_votes(pixels: [&[f32]; 4], hx: f32, hy: f32, t2: f32) -> usize {
    let [xs, ys, uxs, uys] = pixels;
    let mut count = 0u32;
    for (((&x, &y), &ux), &uy) in xs.iter().zip(ys).zip(uxs).zip(uys) {
        count += u32::from(votes_for([x, y, ux, uy], hx, hy, t2));
    }
    count as usize
}

/// Whether the pixel at (x, y) with unit vector (ux, uy) points at `(hx, hy)` within cosine
/// √`t2` (no branch, so the loops that use it vectorise).
#[inline(always)]
fn votes_for([x, y, ux, uy]: [f32; 4], hx: f32, hy: f32, t2: f32) -> bool {
    let dx = hx - x;
    let dy = hy - y;
    let dot = dx * ux + dy * uy;
    (dot > 0.0) & (dot * dot > t2 * (dx * dx + dy * dy))
}

/// Hypotheses needed to draw one all-inlier pair with probability `confidence` at inlier ratio `w`.
fn required_hypotheses(w: f64, confidence: f64) -> f64 {
    let p_pair = (w * w).clamp(0.0, 1.0);
    if p_pair >= 1.0 {
        return 1.0;
    }
    if p_pair <= 0.0 {
        return f64::INFINITY;
    }
    (1.0 - confidence).ln() / (1.0 - p_pair).ln()
}

/// Convenience: votes a field once with a fresh [`Voter`].
pub fn vote_keypoints(
    field: &VectorField<'_>,
    config: VotingConfig,
) -> Result<Vec<KeypointVote>, VoteError> {
    Voter::new(config).vote(field)
}

/// Ground-truth vector labels for a mask and keypoints (what a dataset stores and the network
/// learns): unit vectors from each foreground pixel to each keypoint, in [`VectorField`]'s
/// channel-major layout, zero outside the mask.
pub fn keypoint_vector_labels(
    width: usize,
    height: usize,
    mask: &[u8],
    keypoints: &[Point2<f64>],
) -> Vec<f32> {
    let plane = width * height;
    let mut out = vec![0.0f32; 2 * keypoints.len() * plane];
    for (k, kp) in keypoints.iter().enumerate() {
        for (i, _) in mask
            .iter()
            .enumerate()
            .take(plane)
            .filter(|(_, m)| **m != 0)
        {
            let d = Vector2::new(kp.x - (i % width) as f64, kp.y - (i / width) as f64);
            let n = d.norm();
            if n > 0.0 {
                out[2 * k * plane + i] = (d.x / n) as f32;
                out[(2 * k + 1) * plane + i] = (d.y / n) as f32;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The dispatched count (8 lanes where the CPU has AVX2) equals a count taken one pixel at a
    /// time, for every remainder of the lane width and for hypotheses on the pixel grid as well
    /// as off it.
    #[test]
    fn vote_counts_equal_a_one_pixel_at_a_time_count() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let t2 = 0.99f32 * 0.99;
        for n in [0, 1, 7, 8, 9, 15, 16, 17, 31, 517] {
            let xs: Vec<f32> = (0..n).map(|_| rng.random_range(0..64) as f32).collect();
            let ys: Vec<f32> = (0..n).map(|_| rng.random_range(0..64) as f32).collect();
            let (ux, uy): (Vec<f32>, Vec<f32>) = (0..n)
                .map(|_| {
                    let a = rng.random_range(0.0..std::f32::consts::TAU);
                    (a.cos(), a.sin())
                })
                .unzip();
            for h in 0..64 {
                let (hx, hy) = if h % 2 == 0 {
                    (
                        rng.random_range(0..64) as f32,
                        rng.random_range(0..64) as f32,
                    )
                } else {
                    (rng.random_range(-8.0..72.0), rng.random_range(-8.0..72.0))
                };
                let one_at_a_time = (0..n)
                    .filter(|&i| {
                        let (dx, dy) = (hx - xs[i], hy - ys[i]);
                        let dot = dx * ux[i] + dy * uy[i];
                        dot > 0.0 && dot * dot > t2 * (dx * dx + dy * dy)
                    })
                    .count();
                assert_eq!(
                    count_votes([&xs, &ys, &ux, &uy], hx, hy, t2),
                    one_at_a_time,
                    "{n} pixels, hypothesis ({hx}, {hy})"
                );
            }
        }
    }
}
