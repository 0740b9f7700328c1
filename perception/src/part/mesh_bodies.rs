//! Several bodies in one mesh file: the pieces a file gives (triangles connected through the
//! file's own vertex indices) and small planar holes capped.
//!
//! A part exported as several closed bodies (a mold and its pins) is one rigid part. Its mass
//! properties are the union's, a volume two bodies share counted once (see
//! [`TriMesh::union_moments`]).

use std::collections::HashMap;

use nalgebra::{Point3, Vector3};

use super::TriMesh;
use super::mesh_topology::{edge_uses, find, union};

/// Largest hole, across its boundary loop's bounding box in metres, that loading caps: 0.5 mm, a
/// missing end cap of a pin or a fillet, well below any face a part rests or is gripped on.
pub const MAX_FILLED_HOLE_M: f64 = 0.5e-3;

/// A hole's boundary loop is planar when no vertex lies farther from its best plane than this
/// fraction of the loop's size.
pub const HOLE_PLANARITY_REL: f64 = 0.01;

/// Triangle indices of each connected piece (triangles sharing a vertex index), pieces in the
/// order of their first triangle, triangles in mesh order.
pub(crate) fn pieces(mesh: &TriMesh) -> Vec<Vec<usize>> {
    let mut parent: Vec<u32> = (0..mesh.vertices.len() as u32).collect();
    for t in &mesh.triangles {
        union(&mut parent, t[0], t[1]);
        union(&mut parent, t[1], t[2]);
    }
    let mut index: HashMap<u32, usize> = HashMap::new();
    let mut out: Vec<Vec<usize>> = Vec::new();
    for (i, t) in mesh.triangles.iter().enumerate() {
        let root = find(&mut parent, t[0]);
        let k = *index.entry(root).or_insert_with(|| {
            out.push(Vec::new());
            out.len() - 1
        });
        out[k].push(i);
    }
    out
}

/// The mesh of some of `mesh`'s triangles, with only the vertices they use (in index order).
pub(crate) fn sub_mesh(mesh: &TriMesh, triangles: &[usize]) -> TriMesh {
    let mut used = vec![false; mesh.vertices.len()];
    for &t in triangles {
        for &i in &mesh.triangles[t] {
            used[i as usize] = true;
        }
    }
    let mut remap = vec![0u32; mesh.vertices.len()];
    let mut vertices = Vec::new();
    for (i, p) in mesh.vertices.iter().enumerate() {
        if used[i] {
            remap[i] = vertices.len() as u32;
            vertices.push(*p);
        }
    }
    TriMesh {
        vertices,
        triangles: triangles
            .iter()
            .map(|&t| mesh.triangles[t].map(|i| remap[i as usize]))
            .collect(),
    }
}

/// Whether every edge is used equally often in both directions.
pub(crate) fn is_closed(triangles: &[[u32; 3]]) -> bool {
    edge_uses(triangles).values().all(|(f, b)| f == b)
}

/// Capped holes: how many, and the largest one's size in metres.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FilledHoles {
    /// Holes capped.
    pub count: usize,
    /// Bounding-box diagonal of the largest capped hole's rim, metres.
    pub largest: f64,
}

impl TriMesh {
    /// Caps each hole whose rim is one simple loop of boundary edges, planar (within
    /// [`HOLE_PLANARITY_REL`] of its size) and at most `max_size` across its bounding box, with
    /// a fan from the rim's centroid, oriented to close the surface. Other holes are left for
    /// [`TriMesh::check_closed`] to report.
    pub fn fill_small_holes(&mut self, max_size: f64) -> FilledHoles {
        let mut out = FilledHoles::default();
        let uses = edge_uses(&self.triangles);
        // Boundary edges as the mesh uses them (a → b), each used once in all.
        let mut next: HashMap<u32, Vec<u32>> = HashMap::new();
        for (&(lo, hi), &(f, b)) in &uses {
            match (f, b) {
                (1, 0) => next.entry(lo).or_default().push(hi),
                (0, 1) => next.entry(hi).or_default().push(lo),
                _ => {}
            }
        }
        let mut starts: Vec<u32> = next.keys().copied().collect();
        starts.sort_unstable();
        let mut seen: HashMap<u32, bool> = HashMap::new();
        for start in starts {
            if seen.contains_key(&start) {
                continue;
            }
            let mut rim = vec![start];
            let mut simple = true;
            let mut at = start;
            loop {
                seen.insert(at, true);
                let Some(n) = next.get(&at) else {
                    simple = false;
                    break;
                };
                if n.len() != 1 {
                    simple = false;
                    break;
                }
                at = n[0];
                if at == start {
                    break;
                }
                if seen.contains_key(&at) || rim.len() > next.len() {
                    simple = false;
                    break;
                }
                rim.push(at);
            }
            if !simple || rim.len() < 3 {
                continue;
            }
            let points: Vec<Point3<f64>> = rim.iter().map(|&i| self.vertices[i as usize]).collect();
            let (lo, hi) = points
                .iter()
                .fold((points[0], points[0]), |(l, h), p| (l.inf(p), h.sup(p)));
            let size = (hi - lo).norm();
            if size > max_size || size <= 0.0 {
                continue;
            }
            let centre = Point3::from(
                points.iter().map(|p| p.coords).sum::<Vector3<f64>>() / points.len() as f64,
            );
            // Newell's normal of the rim; its plane through the centroid.
            let mut normal = Vector3::zeros();
            for k in 0..points.len() {
                let (a, b) = (points[k], points[(k + 1) % points.len()]);
                normal += (a - centre).cross(&(b - centre));
            }
            let Some(n) = normal.try_normalize(1e-30) else {
                continue;
            };
            let off_plane = points
                .iter()
                .map(|p| (p - centre).dot(&n).abs())
                .fold(0.0, f64::max);
            if off_plane > HOLE_PLANARITY_REL * size {
                continue;
            }
            // The mesh runs a → b along the rim; the cap runs b → a.
            if rim.len() == 3 {
                self.triangles.push([rim[0], rim[2], rim[1]]);
            } else {
                self.vertices.push(centre);
                let c = (self.vertices.len() - 1) as u32;
                for k in 0..rim.len() {
                    self.triangles.push([rim[(k + 1) % rim.len()], rim[k], c]);
                }
            }
            out.count += 1;
            out.largest = out.largest.max(size);
        }
        out
    }
}
