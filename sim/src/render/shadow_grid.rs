//! Which parts can shade a point of the board's top from one light: every instance's box,
//! projected from the light onto the board plane, binned on a grid. A shadow ray that leaves the
//! board then tests only the instances binned in its cell, instead of clipping itself against the
//! scene's grid; most of a feeder image is board, and each of its points casts a ray per light.

use nalgebra::Point3;

use super::aabb::box_corners;
use super::light::{PointLight, light_cube};

/// Shadow-ray origins within this height of the board's top (z = 0) may use the grid, metres
/// (shadow rays start a fraction of a micrometre above the surface they shade).
const BAND: f64 = 1e-6;

/// Cells along the longer side of the shadows' box.
const CELLS: f64 = 32.0;

/// Slack around each projected box, metres, against rounding.
const SLACK: f64 = 1e-6;

/// The instances whose boxes a segment from a board point to one light can meet, binned over the
/// board plane (at most 64 instances).
#[derive(Debug, Clone)]
pub(crate) struct ShadowGrid {
    x0: f64,
    y0: f64,
    cell: f64,
    nx: usize,
    ny: usize,
    masks: Vec<u64>,
}

impl ShadowGrid {
    /// The grid for `light` over these table-frame boxes; `None` when
    /// none applies (no boxes, more than 64, or the light not above every box).
    pub(crate) fn new(light: &PointLight, bounds: &[(Point3<f64>, Point3<f64>)]) -> Option<Self> {
        if bounds.is_empty() || bounds.len() > 64 {
            return None;
        }
        // A sphere light lies inside the cube around it; its shadows inside the cube corners'.
        let sources = light_cube(light);
        let mut footprints = Vec::with_capacity(bounds.len());
        for (lo, hi) in bounds {
            if sources.iter().any(|l| l.z.is_nan() || l.z <= hi.z + BAND) {
                return None;
            }
            let mut f = [
                f64::INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::NEG_INFINITY,
            ];
            let mut add = |x: f64, y: f64| {
                f = [f[0].min(x), f[1].min(y), f[2].max(x), f[3].max(y)];
            };
            for c in box_corners(lo, hi) {
                add(c.x, c.y);
                for l in &sources {
                    // The corner's shadow on the lowest and highest receiving planes (it moves
                    // linearly between them); corners below a plane shade nothing on it.
                    for z in [-BAND, BAND] {
                        if c.z > z {
                            let p = l + (c - l) * ((l.z - z) / (l.z - c.z));
                            add(p.x, p.y);
                        }
                    }
                }
            }
            if !f.iter().all(|v| v.is_finite()) {
                return None;
            }
            footprints.push([f[0] - SLACK, f[1] - SLACK, f[2] + SLACK, f[3] + SLACK]);
        }
        let [x0, y0, x1, y1] = footprints.iter().fold(
            [
                f64::INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::NEG_INFINITY,
            ],
            |b, f| {
                [
                    b[0].min(f[0]),
                    b[1].min(f[1]),
                    b[2].max(f[2]),
                    b[3].max(f[3]),
                ]
            },
        );
        let extent = (x1 - x0).max(y1 - y0);
        if !(extent.is_finite() && extent > 0.0) {
            return None;
        }
        let cell = extent / CELLS;
        let nx = (((x1 - x0) / cell).ceil() as usize).clamp(1, CELLS as usize);
        let ny = (((y1 - y0) / cell).ceil() as usize).clamp(1, CELLS as usize);
        let mut grid = Self {
            x0,
            y0,
            cell,
            nx,
            ny,
            masks: vec![0; nx * ny],
        };
        for (i, f) in footprints.iter().enumerate() {
            let (cx0, cy0) = grid.cell_of(f[0], f[1]);
            let (cx1, cy1) = grid.cell_of(f[2], f[3]);
            for y in cy0..=cy1 {
                for x in cx0..=cx1 {
                    grid.masks[y * nx + x] |= 1 << i;
                }
            }
        }
        Some(grid)
    }

    /// The cell holding table point (x, y), clamped to the grid.
    fn cell_of(&self, x: f64, y: f64) -> (usize, usize) {
        // Truncation equals floor for the non-negative values kept; NaN gives 0.
        let index = |v: f64, n: usize| {
            if v > 0.0 { (v as usize).min(n - 1) } else { 0 }
        };
        (
            index((x - self.x0) / self.cell, self.nx),
            index((y - self.y0) / self.cell, self.ny),
        )
    }

    /// The instances (bit i for instance i) whose boxes a segment from `o` to the light can meet;
    /// `None` when `o` is not on the board's top, where the grid says nothing.
    pub(crate) fn candidates(&self, o: &Point3<f64>) -> Option<u64> {
        if o.z.is_nan() || o.z.abs() > BAND {
            return None;
        }
        let (fx, fy) = ((o.x - self.x0) / self.cell, (o.y - self.y0) / self.cell);
        if !(fx >= 0.0 && fy >= 0.0 && fx < self.nx as f64 && fy < self.ny as f64) {
            return Some(0);
        }
        Some(self.masks[fy as usize * self.nx + fx as usize])
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
    use perception::part::{Material, TriMesh};

    use super::*;
    use crate::render::{Appearance, Instance, PointLight, RenderMesh, RenderScene, TagBoard};

    #[test]
    fn board_points_see_the_same_shadows_through_the_grid() {
        // Twenty tilted boxes on the board, a point light and a sphere light.
        let mesh =
            Arc::new(RenderMesh::new(&TriMesh::cuboid(Vector3::new(0.009, 0.004, 0.003))).unwrap());
        let instances = (0..20)
            .map(|i| {
                let f = i as f64;
                let pose = Isometry3::from_parts(
                    Translation3::new(
                        (f * 0.37).sin() * 0.04,
                        0.05 + (f * 0.73).cos() * 0.03,
                        0.0015,
                    ),
                    UnitQuaternion::from_euler_angles(0.2 * (f * 0.5).sin(), 0.0, f),
                );
                Instance::new(
                    mesh.clone(),
                    pose,
                    Appearance::for_material(Material::Metal),
                )
            })
            .collect();
        let lights = vec![
            PointLight {
                position: Point3::new(0.45, 0.3, 1.2),
                intensity: [1.0; 3],
                radius: 0.0,
            },
            PointLight {
                position: Point3::new(-0.4, -0.25, 1.0),
                intensity: [1.0; 3],
                radius: 0.05,
            },
        ];
        let scene = RenderScene::new(instances, Some(TagBoard::default()), None, lights, [0.1; 3]);
        let grids = scene.shadow_grids();
        let mut shaded = 0;
        for k in 0..40_000 {
            let o = Point3::new(
                -0.06 + (k % 200) as f64 * 0.0006,
                (k / 200) as f64 * 0.0006,
                1e-7,
            );
            for (light, grid) in scene.lights.iter().zip(&grids) {
                let grid = grid.as_ref().expect("lights above the parts have a grid");
                let to = light.position - o;
                let (d, max_t) = (to.normalize(), to.norm());
                let direct = scene.occluded(&o, &d, max_t);
                assert_eq!(
                    scene.occluded_towards(Some(grid), &o, &d, max_t),
                    direct,
                    "at {o:?}"
                );
                shaded += usize::from(direct);
            }
        }
        assert!(shaded > 1000, "only {shaded} shadowed rays tested");
    }
}
