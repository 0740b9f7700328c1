//! Convex hulls of large, degenerate point sets within bounded memory.
//!
//! parry's quickhull keeps each removed facet's list of outside points, and on points lying
//! many to a circle or a plane (a finely tessellated cylinder: every vertex on one of two
//! circles) those lists grow with the square of the points: an 8 002-point cylinder took
//! 2.3 GB and 3.2 s, a 50 002-point one ran past 24 GB, where 8 000 points on a sphere take
//! 12 MB. Moving every point by a tiny pseudo-random amount first puts them in general position
//! (50 002 cylinder points: 67 MB, 0.35 s); the hull's vertices are then the original points.

use std::collections::HashMap;

use parry3d_f64::math::Vector3;

/// Point sets up to this size go to parry's quickhull as they are (their hulls, and so every
/// drop of the USB-C parts, unchanged); larger ones are put in general position first.
pub const EXACT_HULL_MAX_POINTS: usize = 2048;

/// How far each point is moved for the hull's topology, as a share of the points' extent:
/// a nanometre on a metre-sized part, far under any tolerance a hull is used to.
pub const HULL_JITTER_REL: f64 = 1e-9;

/// [`convex_hull`] as a solid shape for contact and distance queries (parry's
/// `SharedShape::convex_hull` in bounded memory); `None` when the points span no volume.
pub fn convex_hull_shape(points: &[Vector3]) -> Option<parry3d_f64::shape::SharedShape> {
    let (vertices, triangles) = convex_hull(points);
    if triangles.is_empty() {
        return None;
    }
    parry3d_f64::shape::SharedShape::convex_mesh(vertices, &triangles)
}

/// The convex hull of `points` as (vertices, counter-clockwise triangles), vertices among
/// `points`, in memory linear in their number whatever their degeneracy (see the module);
/// parry's own result for up to [`EXACT_HULL_MAX_POINTS`] points. Empty when the points span no
/// volume.
pub fn convex_hull(points: &[Vector3]) -> (Vec<Vector3>, Vec<[u32; 3]>) {
    if points.len() <= EXACT_HULL_MAX_POINTS {
        return parry3d_f64::transformation::try_convex_hull(points)
            .unwrap_or_else(|_| (Vec::new(), Vec::new()));
    }
    // Distinct points only: two copies of a point, moved apart, would make a sliver.
    let mut seen = HashMap::with_capacity(points.len());
    let distinct: Vec<Vector3> = points
        .iter()
        .filter(|p| seen.insert(p.to_array().map(f64::to_bits), ()).is_none())
        .copied()
        .collect();
    let (lo, hi) = distinct.iter().fold(
        (
            Vector3::splat(f64::INFINITY),
            Vector3::splat(f64::NEG_INFINITY),
        ),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let jitter = HULL_JITTER_REL * (hi - lo).length();
    // xorshift64: deterministic, the same hull on every run and platform.
    let mut state: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut unit = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
    };
    let moved: Vec<Vector3> = distinct
        .iter()
        .map(|p| *p + Vector3::new(unit(), unit(), unit()) * jitter)
        .collect();
    let original: HashMap<[u64; 3], usize> = moved
        .iter()
        .enumerate()
        .map(|(i, p)| (p.to_array().map(f64::to_bits), i))
        .collect();
    let Ok((verts, tris)) = parry3d_f64::transformation::try_convex_hull(&moved) else {
        return (Vec::new(), Vec::new());
    };
    let verts = verts
        .iter()
        .map(|p| distinct[original[&p.to_array().map(f64::to_bits)]])
        .collect();
    (verts, tris)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The side and cap vertices of a cylinder of `segments` sides, 10 mm across, 6 mm tall,
    /// and the caps' centres.
    fn cylinder_points(segments: usize) -> Vec<Vector3> {
        let mut points = Vec::new();
        for z in [-0.003, 0.003] {
            for k in 0..segments {
                let a = std::f64::consts::TAU * k as f64 / segments as f64;
                points.push(Vector3::new(0.005 * a.cos(), 0.005 * a.sin(), z));
            }
            points.push(Vector3::new(0.0, 0.0, z));
        }
        points
    }

    /// The peak resident memory of this process so far, bytes (Linux; `None` elsewhere).
    fn peak_rss() -> Option<u64> {
        let status = std::fs::read_to_string("/proc/self/status").ok()?;
        let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
        let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
        Some(kb * 1024)
    }

    /// 8 002 points on two circles (parry alone: 2.3 GB of memory and 3.2 s, both growing with
    /// the square of the points) make their hull of every circle point and 2 n − 4 triangles,
    /// each with every point on or behind its plane, in a few megabytes.
    #[test]
    fn a_fine_cylinders_hull_is_exact_and_cheap() {
        let segments = 4000;
        let points = cylinder_points(segments);
        let (verts, tris) = convex_hull(&points);
        if let Some(peak) = peak_rss() {
            assert!(peak < 1 << 30, "the test process peaked at {peak} bytes");
        }
        assert_eq!(verts.len(), 2 * segments);
        assert_eq!(tris.len(), 4 * segments - 4);
        for p in &verts {
            assert!(points.contains(p), "{p:?} is no input point");
        }
        let mut worst = f64::MIN;
        for t in tris.iter().step_by(97) {
            let [a, b, c] = t.map(|i| verts[i as usize]);
            let n = (b - a).cross(c - a).normalize();
            for p in &points {
                worst = worst.max(n.dot(*p - a));
            }
        }
        assert!(worst < 1e-10, "a point {worst} m outside a face");
    }

    /// Up to [`EXACT_HULL_MAX_POINTS`] points the hull is parry's own, triangle for triangle.
    #[test]
    fn a_small_hull_is_parrys_own() {
        let points = cylinder_points(500);
        assert_eq!(
            convex_hull(&points),
            parry3d_f64::transformation::convex_hull(&points)
        );
    }
}
