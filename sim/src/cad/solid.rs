//! Building closed solids from hexahedra that touch but never overlap, so the union is watertight,
//! its volume is the sum of the pieces, and every feature is exact to the micrometre.

use nalgebra::Point3;
use perception::part::TriMesh;

/// An axis-aligned rectangle in the xy plane, millimetres: (x min, x max, y min, y max).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rect {
    /// Smallest x.
    pub x0: f64,
    /// Largest x.
    pub x1: f64,
    /// Smallest y.
    pub y0: f64,
    /// Largest y.
    pub y1: f64,
}

impl Rect {
    /// A rectangle from its bounds.
    pub const fn new(x0: f64, x1: f64, y0: f64, y1: f64) -> Self {
        Self { x0, x1, y0, y1 }
    }

    /// A rectangle centred on the origin with the given full width (x) and depth (y).
    pub fn centred(width: f64, depth: f64) -> Self {
        Self::new(-width / 2.0, width / 2.0, -depth / 2.0, depth / 2.0)
    }

    /// The rectangle grown by `d` on every side (shrunk for negative `d`).
    pub fn grown(&self, d: f64) -> Self {
        Self::new(self.x0 - d, self.x1 + d, self.y0 - d, self.y1 + d)
    }

    /// Corners counter-clockwise seen from +z, starting at (x0, y0).
    fn corners(&self) -> [(f64, f64); 4] {
        [
            (self.x0, self.y0),
            (self.x1, self.y0),
            (self.x1, self.y1),
            (self.x0, self.y1),
        ]
    }

    fn contains_open(&self, x: f64, y: f64) -> bool {
        x > self.x0 && x < self.x1 && y > self.y0 && y < self.y1
    }
}

/// A solid under construction, in millimetres.
#[derive(Debug, Default, Clone)]
pub struct Solid {
    vertices: Vec<Point3<f64>>,
    triangles: Vec<[u32; 3]>,
}

impl Solid {
    /// An empty solid.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a hexahedron from its bottom and top quads, each counter-clockwise seen from +z.
    pub fn hexahedron(&mut self, bottom: [Point3<f64>; 4], top: [Point3<f64>; 4]) -> &mut Self {
        let base = self.vertices.len() as u32;
        self.vertices.extend(bottom);
        self.vertices.extend(top);
        let b = |i: u32| base + i;
        let t = |i: u32| base + 4 + i;
        let mut quad = |a: u32, bq: u32, c: u32, d: u32| {
            self.triangles.push([a, bq, c]);
            self.triangles.push([a, c, d]);
        };
        quad(b(0), b(3), b(2), b(1));
        quad(t(0), t(1), t(2), t(3));
        for i in 0..4 {
            let j = (i + 1) % 4;
            quad(b(i), b(j), t(j), t(i));
        }
        self
    }

    /// Adds a box over `rect` from height `z0` to `z1`.
    pub fn cuboid(&mut self, rect: Rect, z0: f64, z1: f64) -> &mut Self {
        self.frustum(rect, z0, rect, z1)
    }

    /// Adds a solid whose cross-section goes linearly from `bottom` at `z0` to `top` at `z1`.
    pub fn frustum(&mut self, bottom: Rect, z0: f64, top: Rect, z1: f64) -> &mut Self {
        let at = |r: Rect, z: f64| r.corners().map(|(x, y)| Point3::new(x, y, z));
        self.hexahedron(at(bottom, z0), at(top, z1))
    }

    /// Adds a rectangular wall ring between an outer and an inner rectangle, each of which may
    /// differ between bottom and top (a lead-in chamfer widens the inner one at the top). The four
    /// walls meet on mitred diagonals, so the ring is watertight.
    pub fn ring(
        &mut self,
        z0: f64,
        z1: f64,
        (outer0, inner0): (Rect, Rect),
        (outer1, inner1): (Rect, Rect),
    ) -> &mut Self {
        let (o0, i0, o1, i1) = (
            outer0.corners(),
            inner0.corners(),
            outer1.corners(),
            inner1.corners(),
        );
        for k in 0..4 {
            let n = (k + 1) % 4;
            let p = |c: (f64, f64), z: f64| Point3::new(c.0, c.1, z);
            self.hexahedron(
                [p(o0[k], z0), p(o0[n], z0), p(i0[n], z0), p(i0[k], z0)],
                [p(o1[k], z1), p(o1[n], z1), p(i1[n], z1), p(i1[k], z1)],
            );
        }
        self
    }

    /// Adds a plate over `outer` from `z0` to `z1` with rectangular through-holes, as a grid of
    /// boxes cut at every hole edge. `chamfer` (size, the hole it applies to) bevels that hole's
    /// top edge by moving the top inner edge of each bordering cell outward, so no other hole
    /// may cut the plate within `size` of that hole (asserted).
    pub fn plate_with_holes(
        &mut self,
        outer: Rect,
        z0: f64,
        z1: f64,
        holes: &[Rect],
        chamfer: Option<(f64, Rect)>,
    ) -> &mut Self {
        let mut xs = vec![outer.x0, outer.x1];
        let mut ys = vec![outer.y0, outer.y1];
        for h in holes {
            xs.extend([h.x0, h.x1]);
            ys.extend([h.y0, h.y1]);
        }
        let clamp_sort = |v: &mut Vec<f64>, lo: f64, hi: f64| {
            v.retain(|c| *c >= lo && *c <= hi);
            v.sort_by(f64::total_cmp);
            v.dedup();
        };
        clamp_sort(&mut xs, outer.x0, outer.x1);
        clamp_sort(&mut ys, outer.y0, outer.y1);
        for wx in xs.windows(2) {
            for wy in ys.windows(2) {
                let cell = Rect::new(wx[0], wx[1], wy[0], wy[1]);
                let (cx, cy) = ((cell.x0 + cell.x1) / 2.0, (cell.y0 + cell.y1) / 2.0);
                if holes.iter().any(|h| h.contains_open(cx, cy)) {
                    continue;
                }
                let mut top = cell;
                if let Some((c, hole)) = chamfer {
                    let overlaps_y = cell.y0 < hole.y1 && cell.y1 > hole.y0;
                    let overlaps_x = cell.x0 < hole.x1 && cell.x1 > hole.x0;
                    if overlaps_y && cell.x1 == hole.x0 {
                        top.x1 -= c;
                    }
                    if overlaps_y && cell.x0 == hole.x1 {
                        top.x0 += c;
                    }
                    if overlaps_x && cell.y1 == hole.y0 {
                        top.y1 -= c;
                    }
                    if overlaps_x && cell.y0 == hole.y1 {
                        top.y0 += c;
                    }
                }
                assert!(
                    top.x0 < top.x1 && top.y0 < top.y1,
                    "a chamfered cell {cell:?} is narrower than the chamfer"
                );
                if top == cell {
                    self.cuboid(cell, z0, z1);
                } else {
                    let zc = z1 - chamfer.map_or(0.0, |(c, _)| c);
                    self.cuboid(cell, z0, zc);
                    self.frustum(cell, zc, top, z1);
                }
            }
        }
        self
    }

    /// The finished mesh, converted from millimetres to metres and translated so the origin is the
    /// centre of the bounding box (the part frame convention).
    pub fn into_part_mesh(self) -> TriMesh {
        let mesh = TriMesh::new(self.vertices, self.triangles);
        let (lo, hi) = mesh.aabb();
        let centre = nalgebra::center(&lo, &hi);
        let centred = TriMesh {
            vertices: mesh
                .vertices
                .iter()
                .map(|p| Point3::from(p - centre))
                .collect(),
            triangles: mesh.triangles,
        };
        centred.scaled(1e-3)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pieces_are_watertight_with_additive_volume() {
        let mut s = Solid::new();
        s.cuboid(Rect::centred(10.0, 10.0), 0.0, 1.0);
        let r = Rect::centred(10.0, 10.0);
        let i = r.grown(-1.0);
        s.ring(1.0, 3.0, (r, i), (r, i.grown(0.5)));
        let m = s.into_part_mesh();
        m.check_closed().unwrap();
        // Plate 100 mm³ + ring: frustum-walled ring volume = outer prism − inner frustum.
        let inner_frustum = 2.0 / 3.0 * (64.0 + 81.0 + (64.0f64 * 81.0).sqrt());
        let expect = 100.0 + 200.0 - inner_frustum;
        assert!(
            (m.volume() * 1e9 - expect).abs() < 1e-6,
            "{}",
            m.volume() * 1e9
        );
    }

    #[test]
    fn plate_with_holes_subtracts_the_holes() {
        let mut s = Solid::new();
        let hole = Rect::new(-1.0, 1.0, -2.0, 2.0);
        s.plate_with_holes(Rect::centred(10.0, 10.0), 0.0, 2.0, &[hole], None);
        let m = s.into_part_mesh();
        m.check_closed().unwrap();
        assert!((m.volume() * 1e9 - (200.0 - 16.0)).abs() < 1e-6);
    }
}
