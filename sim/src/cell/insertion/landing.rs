//! Where a held part that misses its target lands: the heights above seated at which the held
//! part, coming straight down beside the capture band, first meets the parts already in place.
//!
//! A part whose leading face is beyond the capture band (clearance/2 + lead-in) does not enter
//! the fit: it lands on whatever is under it, the receiver's rim at the engagement depth, but
//! also lower faces where the receiver is narrower than the held part's outline (a top shell
//! offset across its open sides meets the shell it covers 1.35 mm above seated, not its 2.74 mm
//! engagement depth). These heights are the rim-miss signature the force-guided strategy reads
//! a guarded descent's first contact against: [`RimLandings::of`] sweeps the held part, rigid
//! and level, down at offsets beyond the band in every direction, and keeps the heights at which
//! it first touches, merged into bands.
//!
//! The sweep is exact for convex pieces: the held piece `P` moved by `s` touches the receiver's
//! piece `Q` when `s` lies in their Minkowski difference `Q − P`, the convex hull of the
//! differences of their vertices; coming down at lateral offset `(x, y)`, `P` first touches `Q`
//! at the top of that hull's vertical line through `(x, y)`.

use nalgebra::{Isometry3, Point3, Vector2};
use parry3d_f64::math::Vector;
use serde::Serialize;

use crate::cell::geometry::PartGeometry;

/// Directions swept around the target.
const DIRECTIONS: u32 = 72;
/// Offsets swept in each direction, as multiples of the capture band: just beyond it to twice
/// it (a spiral probe's first ring steps one band off a miss).
const OFFSETS: [f64; 5] = [1.02, 1.15, 1.3, 1.6, 2.0];

/// The Minkowski difference of a held piece and a receiver's piece, as the triangles of its hull
/// with their plan-view bounds.
struct Difference {
    lo: Vector2<f64>,
    hi: Vector2<f64>,
    triangles: Vec<[Point3<f64>; 3]>,
}

impl Difference {
    fn new(held: &[Point3<f64>], receiver: &[Point3<f64>]) -> Option<Self> {
        let pts: Vec<Vector> = receiver
            .iter()
            .flat_map(|q| {
                held.iter()
                    .map(move |p| Vector::new(q.x - p.x, q.y - p.y, q.z - p.z))
            })
            .collect();
        let (verts, tris) = parry3d_f64::transformation::try_convex_hull(&pts).ok()?;
        let v: Vec<Point3<f64>> = verts.iter().map(|p| Point3::new(p.x, p.y, p.z)).collect();
        let triangles: Vec<[Point3<f64>; 3]> = tris
            .iter()
            .map(|t| [v[t[0] as usize], v[t[1] as usize], v[t[2] as usize]])
            .collect();
        if triangles.is_empty() {
            return None;
        }
        let (mut lo, mut hi) = (
            Vector2::repeat(f64::INFINITY),
            Vector2::repeat(f64::NEG_INFINITY),
        );
        for p in &v {
            lo = lo.inf(&Vector2::new(p.x, p.y));
            hi = hi.sup(&Vector2::new(p.x, p.y));
        }
        Some(Self { lo, hi, triangles })
    }

    /// The top of the hull's vertical line through `at`, if the line meets it.
    fn top(&self, at: &Vector2<f64>) -> Option<f64> {
        if at.x < self.lo.x || at.y < self.lo.y || at.x > self.hi.x || at.y > self.hi.y {
            return None;
        }
        self.triangles
            .iter()
            .filter_map(|[a, b, c]| {
                // Barycentric coordinates of `at` in the triangle's plan view.
                let d = (b.x - a.x) * (c.y - a.y) - (c.x - a.x) * (b.y - a.y);
                if d.abs() < 1e-24 {
                    return None;
                }
                let u = ((at.x - a.x) * (c.y - a.y) - (c.x - a.x) * (at.y - a.y)) / d;
                let v = ((b.x - a.x) * (at.y - a.y) - (at.x - a.x) * (b.y - a.y)) / d;
                let eps = 1e-9;
                (u >= -eps && v >= -eps && u + v <= 1.0 + eps)
                    .then(|| a.z + u * (b.z - a.z) + v * (c.z - a.z))
            })
            .reduce(f64::max)
    }
}

/// A held part's rigid shape against what is in place, in the step's insertion frame.
pub struct Sweep {
    differences: Vec<Difference>,
    /// How far above seated the held part first reaches the top of what it goes into, metres.
    engagement: f64,
}

impl Sweep {
    /// The held part seated at `ins_T_held` against `receivers` (each part at its pose; the
    /// first is what it goes into), all in the insertion frame (z out of the hole).
    #[allow(non_snake_case)]
    pub fn new(
        held: &PartGeometry,
        ins_T_held: &Isometry3<f64>,
        receivers: &[(&PartGeometry, Isometry3<f64>)],
    ) -> Self {
        let held_pieces: Vec<Vec<Point3<f64>>> = held
            .pieces
            .pieces
            .iter()
            .map(|p| p.iter().map(|v| ins_T_held * v).collect())
            .collect();
        let bottom = held
            .mesh
            .vertices
            .iter()
            .map(|v| (ins_T_held * v).z)
            .fold(f64::INFINITY, f64::min);
        let engagement = receivers.first().map_or(0.0, |(g, t)| {
            let top = g
                .mesh
                .vertices
                .iter()
                .map(|v| (t * v).z)
                .fold(f64::NEG_INFINITY, f64::max);
            (top - bottom).max(0.0)
        });
        let mut differences = Vec::new();
        for (g, ins_T_part) in receivers {
            for q in &g.pieces.pieces {
                let q: Vec<Point3<f64>> = q.iter().map(|v| ins_T_part * v).collect();
                for p in &held_pieces {
                    differences.extend(Difference::new(p, &q));
                }
            }
        }
        Self {
            differences,
            engagement,
        }
    }

    /// How far above seated the held part first reaches the top of what it goes into (the
    /// first receiver), metres: its engagement depth, as [`super::Mating`] measures it.
    pub fn engagement(&self) -> f64 {
        self.engagement
    }

    /// How far above seated the held part, level and moved sideways by `offset` (insertion
    /// frame x, y), first touches what is in place coming straight down; `None` when nothing
    /// is under it.
    pub fn landing(&self, offset: &Vector2<f64>) -> Option<f64> {
        self.differences
            .iter()
            .filter_map(|d| d.top(offset))
            .reduce(f64::max)
    }
}

/// Where first contact reads as a miss on a rim: at or above the top of what the part goes
/// into, and at the heights at which a part beyond the capture band lands, merged into bands.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct RimLandings {
    /// First contact at least this high above seated is on the receiver's top: its engagement
    /// depth less the tolerance, metres.
    pub rim: f64,
    /// Bands `[low, high]` of landing heights above seated, metres, lowest first; each is
    /// widened by the tolerance it was made with.
    pub bands: Vec<[f64; 2]>,
}

impl RimLandings {
    /// Only the receiver's top: first contact at least `tolerance` below `engagement` (metres
    /// above seated) is a miss.
    pub fn at_engagement(engagement: f64, tolerance: f64) -> Self {
        Self {
            rim: engagement - tolerance,
            bands: Vec::new(),
        }
    }

    /// Sweeps the held part down at offsets just beyond `capture` to twice it, in every
    /// direction ([`Sweep::landing`]), and merges the landing heights above `seated` (a part
    /// that comes down that far is not on a rim) into bands, each widened by `tolerance` on
    /// either side; bands that then overlap are one. The receiver's top is its engagement
    /// depth ([`Sweep::engagement`]) less `tolerance`.
    pub fn of(sweep: &Sweep, capture: f64, seated: f64, tolerance: f64) -> Self {
        let mut heights: Vec<f64> = (0..DIRECTIONS)
            .flat_map(|k| {
                let a = std::f64::consts::TAU * f64::from(k) / f64::from(DIRECTIONS);
                OFFSETS
                    .iter()
                    .map(move |m| Vector2::new(a.cos(), a.sin()) * (m * capture))
            })
            .filter_map(|at| sweep.landing(&at))
            .filter(|h| *h > seated)
            .collect();
        heights.sort_by(f64::total_cmp);
        let mut bands: Vec<[f64; 2]> = Vec::new();
        for h in heights {
            let (lo, hi) = (h - tolerance, h + tolerance);
            match bands.last_mut() {
                Some(b) if lo <= b[1] => b[1] = b[1].max(hi),
                _ => bands.push([lo, hi]),
            }
        }
        Self {
            rim: sweep.engagement - tolerance,
            bands,
        }
    }

    /// Whether first contact `height` above seated reads as a miss on a rim: at or above the
    /// receiver's top, or where a part beyond the band lands.
    pub fn contains(&self, height: f64) -> bool {
        height >= self.rim || self.bands.iter().any(|b| (b[0]..=b[1]).contains(&height))
    }

    /// The lowest height above seated at which first contact reads as a miss, metres.
    pub fn lowest(&self) -> f64 {
        self.bands.first().map_or(self.rim, |b| b[0].min(self.rim))
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::{Isometry3, Vector2};

    use super::*;
    use crate::cad::solid::{Rect, Solid};

    /// A part from boxes `(x0, x1, y0, y1, z0, z1)` in millimetres, and where its part frame (the
    /// bounding box's centre) lies in the boxes' frame, metres.
    fn part(name: &str, boxes: &[[f64; 6]]) -> (PartGeometry, Isometry3<f64>) {
        let mut s = Solid::new();
        let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for b in boxes {
            s.cuboid(Rect::new(b[0], b[1], b[2], b[3]), b[4], b[5]);
            for i in 0..3 {
                lo[i] = lo[i].min(b[2 * i]);
                hi[i] = hi[i].max(b[2 * i + 1]);
            }
        }
        let centre = Isometry3::translation(
            (lo[0] + hi[0]) / 2e3,
            (lo[1] + hi[1]) / 2e3,
            (lo[2] + hi[2]) / 2e3,
        );
        let g = PartGeometry::from_mesh(name, s.into_part_mesh(), 1e-3, vec![], vec![]).unwrap();
        (g, centre)
    }

    /// A top-shell-like step: a cap whose skirts hang 1.5 mm down the ±x sides of a 4 mm block
    /// and whose +y skirt, 1 mm deep, rests on a low ledge; seated, its roof lies on the block.
    fn cap_over_block() -> Sweep {
        let (cap, at_cap) = part(
            "cap",
            &[
                [-2.15, 2.15, -2.15, 2.15, 2.0, 2.2],
                [-2.15, -2.05, -2.15, 2.15, 0.5, 2.0],
                [2.05, 2.15, -2.15, 2.15, 0.5, 2.0],
                [-2.05, 2.05, 2.05, 2.15, 1.0, 2.0],
            ],
        );
        let (block, at_block) = part(
            "block",
            &[
                [-2.0, 2.0, -2.0, 2.0, 0.0, 2.0],
                [-2.0, 2.0, 2.0, 2.6, 0.0, 1.0],
            ],
        );
        Sweep::new(&cap, &at_cap, &[(&block, at_block)])
    }

    #[test]
    fn a_cap_beside_its_block_lands_on_the_rim_or_lower_where_a_skirt_is_shorter() {
        let sweep = cap_over_block();
        let at = |x: f64, y: f64| sweep.landing(&Vector2::new(x * 1e-3, y * 1e-3));
        let near = |h: Option<f64>, mm: f64| h.is_some_and(|h| (h - mm * 1e-3).abs() < 1e-9);
        // Seated, and off towards the ledge: the roof on the block, nothing higher.
        assert!(near(at(0.0, 0.0), 0.0), "{:?}", at(0.0, 0.0));
        assert!(near(at(0.0, 0.2), 0.0), "{:?}", at(0.0, 0.2));
        // Off along x, a side skirt lands on the block's top: 1.5 mm up, the engagement depth.
        assert!(near(at(0.2, 0.0), 1.5), "{:?}", at(0.2, 0.0));
        assert!(near(at(-0.3, 0.05), 1.5), "{:?}", at(-0.3, 0.05));
        // Off along −y, only the shorter +y skirt lands: 1.0 mm up, below the engagement depth.
        assert!(near(at(0.0, -0.2), 1.0), "{:?}", at(0.0, -0.2));
        // Far beside it nothing is under the cap.
        assert_eq!(at(5.0, 0.0), None);

        // Beyond a 0.15 mm band, every direction: the two rims, each ±0.05 mm.
        assert!((sweep.engagement() - 1.5e-3).abs() < 1e-9);
        let rims = RimLandings::of(&sweep, 1.5e-4, 2e-4, 5e-5);
        assert!((rims.rim - 1.45e-3).abs() < 1e-9);
        assert!((rims.lowest() - 0.95e-3).abs() < 1e-9);
        assert_eq!(rims.bands.len(), 2, "{:?}", rims.bands);
        for (band, mm) in rims.bands.iter().zip([1.0, 1.5]) {
            assert!((band[0] - (mm - 0.05) * 1e-3).abs() < 1e-9, "{band:?}");
            assert!((band[1] - (mm + 0.05) * 1e-3).abs() < 1e-9, "{band:?}");
        }
        assert!(rims.contains(1.02e-3) && rims.contains(1.47e-3) && rims.contains(3e-3));
        assert!(!rims.contains(1.25e-3) && !rims.contains(0.5e-3));
    }
}
