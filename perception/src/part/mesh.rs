//! Triangle meshes in the part frame, in metres.

use std::collections::HashMap;

use nalgebra::{Isometry3, Point3, Vector3};

use super::mesh_topology::{Edge, EdgeUses, edge_uses, find, union};

/// A connected group of open edges: where a mesh is open, in the mesh's own unit (metres once
/// loaded), shown in millimetres.
#[derive(Debug, Clone, PartialEq)]
pub struct OpenRegion {
    /// Open edges in the group.
    pub edges: usize,
    /// Lower corner of the group's bounding box.
    pub min: Point3<f64>,
    /// Upper corner of the group's bounding box.
    pub max: Point3<f64>,
    /// One of its open edges.
    pub example: (Point3<f64>, Point3<f64>),
}

impl OpenRegion {
    /// Centre of the group's bounding box.
    pub fn centre(&self) -> Point3<f64> {
        nalgebra::center(&self.min, &self.max)
    }
}

impl std::fmt::Display for OpenRegion {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mm = |p: Point3<f64>| format!("({:.4}, {:.4}, {:.4})", p.x * 1e3, p.y * 1e3, p.z * 1e3);
        let size = (self.max - self.min) * 1e3;
        write!(
            f,
            "{} edge{} around {} mm spanning {:.4} × {:.4} × {:.4} mm, e.g. from {} to {} mm",
            self.edges,
            if self.edges == 1 { "" } else { "s" },
            mm(self.centre()),
            size.x,
            size.y,
            size.z,
            mm(self.example.0),
            mm(self.example.1)
        )
    }
}

/// A triangle mesh in metres, counter-clockwise triangles seen from outside.
#[derive(Debug, Clone, PartialEq)]
pub struct TriMesh {
    /// Vertex positions in metres.
    pub vertices: Vec<Point3<f64>>,
    /// Triangles as indices into `vertices`, counter-clockwise seen from outside.
    pub triangles: Vec<[u32; 3]>,
}

/// Why a mesh is not a closed, consistently oriented surface.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MeshDefect {
    /// A triangle index points past the vertex list.
    #[error("triangle {triangle} uses vertex {index} but there are {count} vertices")]
    IndexOutOfRange {
        /// Triangle number.
        triangle: usize,
        /// The offending index.
        index: u32,
        /// Number of vertices.
        count: usize,
    },
    /// Edges are used a different number of times in each direction: holes (boundary edges) or
    /// flipped triangles (an edge used twice the same way), located so the user can find them.
    #[error(
        "{} open edges ({boundary} on a boundary, {misoriented} between inconsistently oriented \
         triangles) in {} place{}: {}",
        boundary + misoriented,
        regions.len(),
        if regions.len() == 1 { "" } else { "s" },
        regions.iter().take(3).map(ToString::to_string).collect::<Vec<_>>().join("; ")
    )]
    Open {
        /// Edges used an odd number of times: the rim of a hole.
        boundary: usize,
        /// Edges used an even number of times but not equally in each direction: a flipped
        /// triangle.
        misoriented: usize,
        /// Connected groups of open edges, the largest first.
        regions: Vec<OpenRegion>,
    },
    /// A vertex coordinate is NaN or infinite.
    #[error("vertex {0} has a non-finite coordinate")]
    NonFinite(usize),
}

impl TriMesh {
    /// An axis-aligned box of the given full size centred on the origin, outward triangles:
    /// the simplest closed part, for fixtures, placeholders and tests.
    pub fn cuboid(size: Vector3<f64>) -> Self {
        let h = size / 2.0;
        let vertices = (0..8)
            .map(|i| {
                Point3::new(
                    if i & 1 == 0 { -h.x } else { h.x },
                    if i & 2 == 0 { -h.y } else { h.y },
                    if i & 4 == 0 { -h.z } else { h.z },
                )
            })
            .collect();
        let quads = [
            [0, 2, 3, 1],
            [4, 5, 7, 6],
            [0, 1, 5, 4],
            [2, 6, 7, 3],
            [0, 4, 6, 2],
            [1, 3, 7, 5],
        ];
        let triangles = quads
            .iter()
            .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
            .collect();
        Self::new(vertices, triangles)
    }

    /// A closed prism of `sides` sides (a cylinder for many) of `diameter` and `height`, standing on
    /// z = 0: a round part for tests, a distractor for renders.
    pub fn prism(sides: usize, diameter: f64, height: f64) -> Self {
        let r = diameter / 2.0;
        let mut vertices = Vec::with_capacity(2 * sides + 2);
        for z in [0.0, height] {
            for k in 0..sides {
                let a = std::f64::consts::TAU * k as f64 / sides as f64;
                vertices.push(Point3::new(r * a.cos(), r * a.sin(), z));
            }
        }
        vertices.push(Point3::new(0.0, 0.0, 0.0));
        vertices.push(Point3::new(0.0, 0.0, height));
        let (n, bottom, top) = (sides as u32, 2 * sides as u32, 2 * sides as u32 + 1);
        let mut triangles = Vec::with_capacity(4 * sides);
        for k in 0..n {
            let k1 = (k + 1) % n;
            triangles.push([k, k1, n + k1]);
            triangles.push([k, n + k1, n + k]);
            triangles.push([bottom, k1, k]);
            triangles.push([top, n + k, n + k1]);
        }
        Self::new(vertices, triangles)
    }

    /// A mesh from vertices and triangles, merging vertices at bit-identical positions.
    pub fn new(vertices: Vec<Point3<f64>>, triangles: Vec<[u32; 3]>) -> Self {
        let mut mesh = Self {
            vertices,
            triangles,
        };
        mesh.weld();
        mesh
    }

    /// Merges vertices with bit-identical coordinates (STL stores every triangle's corners apart).
    fn weld(&mut self) {
        let mut first: HashMap<[u64; 3], u32> = HashMap::new();
        let mut remap = Vec::with_capacity(self.vertices.len());
        let mut kept = Vec::new();
        for p in &self.vertices {
            let key = [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()];
            let id = *first.entry(key).or_insert_with(|| {
                kept.push(*p);
                (kept.len() - 1) as u32
            });
            remap.push(id);
        }
        for t in &mut self.triangles {
            for i in t.iter_mut() {
                if let Some(&r) = remap.get(*i as usize) {
                    *i = r;
                }
            }
        }
        self.vertices = kept;
    }

    /// Checks that the surface is closed: every edge is used equally often in both directions.
    ///
    /// Solids built from touching closed pieces (a shell on a plate, several bodies, edges shared
    /// by four triangles) pass; holes and flipped triangles do not, and the error locates them.
    pub fn check_closed(&self) -> Result<(), MeshDefect> {
        if let Some(i) = self
            .vertices
            .iter()
            .position(|p| !p.coords.iter().all(|c| c.is_finite()))
        {
            return Err(MeshDefect::NonFinite(i));
        }
        for (ti, t) in self.triangles.iter().enumerate() {
            for &index in t {
                if index as usize >= self.vertices.len() {
                    return Err(MeshDefect::IndexOutOfRange {
                        triangle: ti,
                        index,
                        count: self.vertices.len(),
                    });
                }
            }
        }
        let mut open: Vec<(Edge, EdgeUses)> = edge_uses(&self.triangles)
            .into_iter()
            .filter(|(_, (f, b))| f != b)
            .collect();
        if open.is_empty() {
            return Ok(());
        }
        open.sort_unstable();
        let boundary = open.iter().filter(|(_, (f, b))| (f + b) % 2 == 1).count();
        Err(MeshDefect::Open {
            boundary,
            misoriented: open.len() - boundary,
            regions: self.open_regions(&open),
        })
    }

    /// Groups open edges into connected regions (edges sharing a vertex), largest first.
    fn open_regions(&self, open: &[(Edge, EdgeUses)]) -> Vec<OpenRegion> {
        let mut parent: Vec<u32> = (0..self.vertices.len() as u32).collect();
        for &((a, b), _) in open {
            union(&mut parent, a, b);
        }
        let mut by_root: HashMap<u32, OpenRegion> = HashMap::new();
        let mut order = Vec::new();
        for &((a, b), _) in open {
            let root = find(&mut parent, a);
            let (pa, pb) = (self.vertices[a as usize], self.vertices[b as usize]);
            let region = by_root.entry(root).or_insert_with(|| {
                order.push(root);
                OpenRegion {
                    edges: 0,
                    min: pa.inf(&pb),
                    max: pa.sup(&pb),
                    example: (pa, pb),
                }
            });
            region.edges += 1;
            region.min = region.min.inf(&pa.inf(&pb));
            region.max = region.max.sup(&pa.sup(&pb));
        }
        let mut regions: Vec<OpenRegion> = order
            .into_iter()
            .filter_map(|r| by_root.remove(&r))
            .collect();
        regions.sort_by_key(|r| std::cmp::Reverse(r.edges));
        regions
    }

    /// The mesh as parry's triangle mesh with its BVH, for distance and ray queries; `None` when
    /// parry refuses it (no triangles, an index out of range).
    pub fn to_parry(&self) -> Option<parry3d_f64::shape::TriMesh> {
        let vertices = (self.vertices.iter())
            .map(|p| parry3d_f64::math::Vector::new(p.x, p.y, p.z))
            .collect();
        parry3d_f64::shape::TriMesh::new(vertices, self.triangles.clone()).ok()
    }

    /// Axis-aligned bounding box as (min, max) corners.
    pub fn aabb(&self) -> (Point3<f64>, Point3<f64>) {
        let mut lo = Point3::from(Vector3::repeat(f64::INFINITY));
        let mut hi = Point3::from(Vector3::repeat(f64::NEG_INFINITY));
        for p in &self.vertices {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        (lo, hi)
    }

    /// Size of the bounding box along x, y and z.
    pub fn extents(&self) -> Vector3<f64> {
        let (lo, hi) = self.aabb();
        hi - lo
    }

    /// The three corners of triangle `i`.
    pub fn triangle(&self, i: usize) -> [Point3<f64>; 3] {
        let t = self.triangles[i];
        [
            self.vertices[t[0] as usize],
            self.vertices[t[1] as usize],
            self.vertices[t[2] as usize],
        ]
    }

    /// Total surface area in square metres.
    pub fn area(&self) -> f64 {
        (0..self.triangles.len())
            .map(|i| {
                let [a, b, c] = self.triangle(i);
                0.5 * (b - a).cross(&(c - a)).norm()
            })
            .sum()
    }

    /// Enclosed volume in cubic metres (positive for outward-facing triangles).
    pub fn volume(&self) -> f64 {
        (0..self.triangles.len())
            .map(|i| {
                let [a, b, c] = self.triangle(i);
                a.coords.dot(&b.coords.cross(&c.coords)) / 6.0
            })
            .sum()
    }

    /// The mesh with every vertex mapped through `pose`.
    pub fn transformed(&self, pose: &Isometry3<f64>) -> Self {
        Self {
            vertices: self.vertices.iter().map(|p| pose * p).collect(),
            triangles: self.triangles.clone(),
        }
    }

    /// The mesh with every vertex multiplied by `factor` (a unit conversion).
    pub fn scaled(&self, factor: f64) -> Self {
        Self {
            vertices: self.vertices.iter().map(|p| p * factor).collect(),
            triangles: self.triangles.clone(),
        }
    }

    /// Appends another mesh's triangles (a separate closed piece) to this one.
    pub fn append(&mut self, other: &TriMesh) {
        let offset = self.vertices.len() as u32;
        self.vertices.extend_from_slice(&other.vertices);
        self.triangles.extend(
            other
                .triangles
                .iter()
                .map(|t| [t[0] + offset, t[1] + offset, t[2] + offset]),
        );
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A cube of the given side, outward triangles.
    pub(crate) fn cube(side: f64) -> TriMesh {
        TriMesh::cuboid(Vector3::repeat(side))
    }

    #[test]
    fn cube_is_closed_with_exact_volume_and_area() {
        let c = cube(0.01);
        c.check_closed().unwrap();
        assert!((c.volume() - 1e-6).abs() < 1e-18);
        assert!((c.area() - 6e-4).abs() < 1e-15);
    }

    #[test]
    fn removing_a_triangle_opens_the_mesh() {
        let mut c = cube(0.01);
        c.triangles.pop();
        assert!(matches!(c.check_closed(), Err(MeshDefect::Open { .. })));
    }

    #[test]
    fn flipping_a_triangle_is_an_orientation_defect() {
        let mut c = cube(0.01);
        c.triangles[0].swap(1, 2);
        assert!(c.check_closed().is_err());
    }

    #[test]
    fn bad_index_is_reported_not_panicked() {
        let mut c = cube(0.01);
        c.triangles[0][0] = 99;
        assert!(matches!(
            c.check_closed(),
            Err(MeshDefect::IndexOutOfRange { .. })
        ));
    }
}
