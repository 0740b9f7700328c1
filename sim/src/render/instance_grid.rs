//! A 2-D grid over the table of the instances' bounding boxes: a ray first clips itself to the
//! box around all instances, then tests only the instances registered in the cells its clipped
//! segment crosses. Most camera and shadow rays of a feeder or overview pass near one part, not
//! all of them. Candidates come out as a bit set in ascending instance order, so the nearest hit
//! (and ties) is exactly what testing every instance in order gives.

use nalgebra::{Point3, Vector3};

/// Cells along the longer side of the instances' box.
const CELLS: f64 = 32.0;

/// Up to this many instances, a ray that enters the shared box tests each one directly.
const FEW: u32 = 4;

/// Slack added around a ray segment's footprint, metres, against rounding at cell borders.
const SLACK: f64 = 1e-7;

/// Instance boxes binned on a grid over the table plane (at most 64 instances).
#[derive(Debug, Clone)]
pub(crate) struct InstanceGrid {
    lo: Point3<f64>,
    hi: Point3<f64>,
    cell: f64,
    nx: usize,
    ny: usize,
    masks: Vec<u64>,
    /// Every instance, for scenes too small for the grid to pay off.
    all: u64,
}

impl InstanceGrid {
    /// The grid of these table-frame boxes; `None` when there are none or more than 64.
    pub(crate) fn new(bounds: &[(Point3<f64>, Point3<f64>)]) -> Option<Self> {
        if bounds.is_empty() || bounds.len() > 64 {
            return None;
        }
        let (lo, hi) = bounds
            .iter()
            .copied()
            .reduce(|(alo, ahi), (lo, hi)| (alo.inf(&lo), ahi.sup(&hi)))?;
        let extent = (hi.x - lo.x).max(hi.y - lo.y);
        if !(extent.is_finite() && extent > 0.0) {
            return None;
        }
        let cell = extent / CELLS;
        let nx = (((hi.x - lo.x) / cell).ceil() as usize).clamp(1, CELLS as usize);
        let ny = (((hi.y - lo.y) / cell).ceil() as usize).clamp(1, CELLS as usize);
        let mut grid = Self {
            lo,
            hi,
            cell,
            nx,
            ny,
            masks: vec![0; nx * ny],
            all: u64::MAX >> (64 - bounds.len()),
        };
        for (i, (blo, bhi)) in bounds.iter().enumerate() {
            let (x0, x1, y0, y1) = grid.cells(blo.x, bhi.x, blo.y, bhi.y);
            for y in y0..=y1 {
                for x in x0..=x1 {
                    grid.masks[y * nx + x] |= 1 << i;
                }
            }
        }
        Some(grid)
    }

    /// Inclusive cell ranges covering the table rectangle [x0, x1] × [y0, y1].
    fn cells(&self, x0: f64, x1: f64, y0: f64, y1: f64) -> (usize, usize, usize, usize) {
        // Truncation equals floor for the non-negative values kept (no libm call); NaN gives 0.
        let index = |v: f64, n: usize| {
            if v > 0.0 { (v as usize).min(n - 1) } else { 0 }
        };
        let ix = |x: f64| index((x - self.lo.x) / self.cell, self.nx);
        let iy = |y: f64| index((y - self.lo.y) / self.cell, self.ny);
        (ix(x0), ix(x1), iy(y0), iy(y1))
    }

    /// The instances whose boxes the ray from `o` along `d` may enter before `max_t`, bit i for
    /// instance i.
    pub(crate) fn candidates(&self, o: &Point3<f64>, d: &Vector3<f64>, max_t: f64) -> u64 {
        let Some((t0, t1)) = slab_range(&self.lo, &self.hi, o, d) else {
            return 0;
        };
        if t0 >= max_t {
            return 0;
        }
        if self.all.count_ones() <= FEW {
            return self.all;
        }
        let t1 = t1.min(max_t);
        let (a, b) = (o + d * t0, o + d * t1);
        let (x0, x1, y0, y1) = self.cells(
            a.x.min(b.x) - SLACK,
            a.x.max(b.x) + SLACK,
            a.y.min(b.y) - SLACK,
            a.y.max(b.y) + SLACK,
        );
        let mut m = 0;
        for y in y0..=y1 {
            for x in x0..=x1 {
                m |= self.masks[y * self.nx + x];
            }
        }
        m
    }
}

/// Entry and exit distances of a ray through a box (entry 0 when it starts inside); `None` when
/// it misses.
pub(crate) fn slab_range(
    lo: &Point3<f64>,
    hi: &Point3<f64>,
    o: &Point3<f64>,
    d: &Vector3<f64>,
) -> Option<(f64, f64)> {
    let mut t0 = 0.0f64;
    let mut t1 = f64::INFINITY;
    for a in 0..3 {
        let inv = 1.0 / d[a];
        let (mut near, mut far) = ((lo[a] - o[a]) * inv, (hi[a] - o[a]) * inv);
        if near > far {
            std::mem::swap(&mut near, &mut far);
        }
        // NaN (a zero direction component on a slab face) compares false and keeps the bound.
        if near > t0 {
            t0 = near;
        }
        if far < t1 {
            t1 = far;
        }
        if t0 > t1 {
            return None;
        }
    }
    Some((t0, t1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn candidates_include_every_box_a_ray_enters() {
        // A row of unit-millimetre boxes; rays at many angles: a box the ray enters is a candidate.
        let bounds: Vec<_> = (0..20)
            .map(|i| {
                let x = i as f64 * 0.004 - 0.04;
                let y = ((i * 7) % 5) as f64 * 0.003;
                (
                    Point3::new(x, y, 0.0),
                    Point3::new(x + 0.002, y + 0.002, 0.003),
                )
            })
            .collect();
        let grid = InstanceGrid::new(&bounds).unwrap();
        let mut entered = 0;
        for k in 0..4000 {
            let f = k as f64;
            let o = Point3::new(
                (f * 0.37).sin() * 0.05,
                (f * 0.73).cos() * 0.02,
                0.001 + (f * 0.11).sin().abs() * 0.5,
            );
            // Aim near a box corner, so that rays graze, enter and miss boxes.
            let (lo, hi) = bounds[k % bounds.len()];
            let target = lo + (hi - lo) * (0.5 + 0.7 * (f * 0.91).sin());
            let d = (target - o).normalize();
            let m = grid.candidates(&o, &d, 1.0);
            for (i, (lo, hi)) in bounds.iter().enumerate() {
                if slab_range(lo, hi, &o, &d).is_some_and(|(t0, _)| t0 < 1.0) {
                    entered += 1;
                    assert!(
                        m & (1 << i) != 0,
                        "ray {k} enters box {i} but it is no candidate"
                    );
                }
            }
        }
        assert!(entered > 2000, "only {entered} box entries tested");
    }
}
