//! Surface keypoints by farthest-point sampling, as PVNet defines them.

use nalgebra::Point3;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::TriMesh;

/// `n` points uniformly distributed over the mesh surface (area-weighted), reproducible by `seed`.
pub fn sample_surface(mesh: &TriMesh, n: usize, seed: u64) -> Vec<Point3<f64>> {
    let areas: Vec<f64> = (0..mesh.triangles.len())
        .map(|i| {
            let [a, b, c] = mesh.triangle(i);
            0.5 * (b - a).cross(&(c - a)).norm()
        })
        .collect();
    let total: f64 = areas.iter().sum();
    if n == 0 || total <= 0.0 {
        return Vec::new();
    }
    let mut cumulative = Vec::with_capacity(areas.len());
    let mut acc = 0.0;
    for a in &areas {
        acc += a / total;
        cumulative.push(acc);
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            let u: f64 = rng.random();
            let i = cumulative.partition_point(|&c| c < u).min(areas.len() - 1);
            let [a, b, c] = mesh.triangle(i);
            let (mut s, mut t): (f64, f64) = (rng.random(), rng.random());
            if s + t > 1.0 {
                (s, t) = (1.0 - s, 1.0 - t);
            }
            a + (b - a) * s + (c - a) * t
        })
        .collect()
}

/// Picks `k` of `points` greedily, each the farthest from those chosen so far, starting from the
/// set {`seed_point`} (PVNet seeds with the object centre, which is not itself returned).
pub fn farthest_point_sample(
    points: &[Point3<f64>],
    k: usize,
    seed_point: Point3<f64>,
) -> Vec<Point3<f64>> {
    let mut dist: Vec<f64> = points
        .iter()
        .map(|p| (p - seed_point).norm_squared())
        .collect();
    let mut chosen = Vec::with_capacity(k.min(points.len()));
    for _ in 0..k.min(points.len()) {
        // Ties go to the lowest index, so the result depends only on the input order.
        let (best, _) = dist
            .iter()
            .enumerate()
            .fold(
                (0, f64::NEG_INFINITY),
                |acc, (i, &d)| if d > acc.1 { (i, d) } else { acc },
            );
        let p = points[best];
        chosen.push(p);
        for (d, q) in dist.iter_mut().zip(points) {
            *d = d.min((q - p).norm_squared());
        }
    }
    chosen
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::part::mesh::tests::cube;

    #[test]
    fn surface_samples_lie_on_the_surface_and_repeat_by_seed() {
        let c = cube(0.01);
        let a = sample_surface(&c, 2000, 3);
        assert_eq!(a, sample_surface(&c, 2000, 3));
        assert_ne!(a, sample_surface(&c, 2000, 4));
        for p in &a {
            let m = p.coords.abs().max();
            assert!((m - 0.005).abs() < 1e-12, "point {p} is not on a cube face");
        }
    }

    #[test]
    fn fps_on_a_cube_picks_the_eight_corners_region() {
        let c = cube(0.01);
        let pts = sample_surface(&c, 20_000, 1);
        let kp = farthest_point_sample(&pts, 8, Point3::origin());
        assert_eq!(kp.len(), 8);
        // Eight well-spread points on a cube sit near its corners: every pair is far apart.
        let mut min_pair = f64::INFINITY;
        for i in 0..8 {
            for j in i + 1..8 {
                min_pair = min_pair.min((kp[i] - kp[j]).norm());
            }
        }
        assert!(
            min_pair > 0.0085,
            "keypoints are not spread: closest pair {min_pair}"
        );
        // Each lands within 1 mm of a distinct corner.
        let mut corners: Vec<bool> = vec![false; 8];
        for p in &kp {
            let idx =
                (p.x > 0.0) as usize | ((p.y > 0.0) as usize) << 1 | ((p.z > 0.0) as usize) << 2;
            let corner = Point3::new(
                if p.x > 0.0 { 0.005 } else { -0.005 },
                if p.y > 0.0 { 0.005 } else { -0.005 },
                if p.z > 0.0 { 0.005 } else { -0.005 },
            );
            assert!((p - corner).norm() < 1e-3, "{p} is not near a corner");
            assert!(!corners[idx], "two keypoints near the same corner");
            corners[idx] = true;
        }
    }

    #[test]
    fn fps_is_deterministic_and_handles_small_inputs() {
        let pts = vec![Point3::new(0.0, 0.0, 0.0), Point3::new(1.0, 0.0, 0.0)];
        assert_eq!(farthest_point_sample(&pts, 5, Point3::origin()).len(), 2);
        assert!(farthest_point_sample(&[], 3, Point3::origin()).is_empty());
        let c = cube(0.02);
        let p = sample_surface(&c, 5000, 9);
        assert_eq!(
            farthest_point_sample(&p, 8, Point3::origin()),
            farthest_point_sample(&p, 8, Point3::origin())
        );
    }
}
