//! Convex pieces of a part mesh, for contact simulation and for testing whether parts overlap.
//!
//! The project's meshes are built by the simulator's CAD (`sim::cad::solid::Solid`) from hexahedra (12 consecutive
//! triangles each, in order, also after an OBJ round trip). The union of their convex hulls is
//! the solid, chamfers and clearances included: a hexahedron's only non-planar faces are the
//! mitres where two wall pieces of a ring meet, and the hull fills those inside the solid. A mesh
//! not made of closed 12-triangle pieces falls back to its single convex hull (flagged so callers
//! can tell).
//!
//! Touching pieces whose union is convex (a chamfer above its straight wall, neighbouring cells
//! of a plate) are merged: a face between two pieces is inside the solid, but a contact solver
//! sees it as a surface, and a part sliding down a wall a micron inside the tolerance would stop
//! on the seam where the chamfer meets the wall.

use super::TriMesh;
use super::hull::convex_hull;
use nalgebra::Point3;
use parry3d_f64::math::Vector3;

/// Triangles per hexahedron in a `Solid`-built mesh.
const HEX_TRIANGLES: usize = 12;

/// A mesh cut into convex pieces.
#[derive(Debug, Clone)]
pub struct ConvexPieces {
    /// Vertices of each convex piece (part frame, metres).
    pub pieces: Vec<Vec<Point3<f64>>>,
    /// True when the pieces are exact; false when the mesh fell back to one convex hull.
    pub exact: bool,
}

/// Splits `mesh` into its convex hexahedra, or returns its single hull when it is not built
/// from convex hexahedra.
pub fn convex_pieces(mesh: &TriMesh) -> ConvexPieces {
    if let Some(pieces) = hexahedra(mesh) {
        return ConvexPieces {
            pieces: merge_convex_unions(pieces),
            exact: true,
        };
    }
    ConvexPieces {
        pieces: vec![mesh.vertices.clone()],
        exact: false,
    }
}

fn hexahedra(mesh: &TriMesh) -> Option<Vec<Vec<Point3<f64>>>> {
    if mesh.triangles.is_empty() || !mesh.triangles.len().is_multiple_of(HEX_TRIANGLES) {
        return None;
    }
    let mut pieces = Vec::with_capacity(mesh.triangles.len() / HEX_TRIANGLES);
    for chunk in mesh.triangles.chunks(HEX_TRIANGLES) {
        let mut ids: Vec<u32> = chunk.iter().flatten().copied().collect();
        ids.sort_unstable();
        ids.dedup();
        if ids.len() < 4 || ids.len() > 8 || !closed(chunk) {
            return None;
        }
        let points: Vec<Point3<f64>> = ids
            .iter()
            .map(|&i| mesh.vertices.get(i as usize).copied())
            .collect::<Option<_>>()?;
        pieces.push(points);
    }
    Some(pieces)
}

/// Merges pairs of pieces that share a face (at least three vertices) while their union is
/// convex: the hull of the union has the volume of the two pieces (which never overlap).
fn merge_convex_unions(mut pieces: Vec<Vec<Point3<f64>>>) -> Vec<Vec<Point3<f64>>> {
    let mut volumes: Vec<f64> = pieces.iter().map(|p| hull(p).1).collect();
    let mut i = 0;
    while i < pieces.len() {
        let mut merged = false;
        for j in i + 1..pieces.len() {
            let shared = pieces[j].iter().filter(|p| pieces[i].contains(p)).count();
            if shared < 3 {
                continue;
            }
            let union: Vec<Point3<f64>> = pieces[i].iter().chain(&pieces[j]).copied().collect();
            let (points, volume) = hull(&union);
            let parts = volumes[i] + volumes[j];
            if (volume - parts).abs() <= 1e-9 * parts.max(f64::MIN_POSITIVE) {
                pieces[i] = points;
                volumes[i] = volume;
                pieces.swap_remove(j);
                volumes.swap_remove(j);
                merged = true;
                break;
            }
        }
        if !merged {
            i += 1;
        }
    }
    pieces
}

/// The vertices of the convex hull of `points` and its volume.
fn hull(points: &[Point3<f64>]) -> (Vec<Point3<f64>>, f64) {
    let pts: Vec<Vector3> = points.iter().map(|p| Vector3::new(p.x, p.y, p.z)).collect();
    let (vertices, triangles) = convex_hull(&pts);
    let volume = triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| vertices[i as usize]);
            a.dot(b.cross(c)) / 6.0
        })
        .sum::<f64>()
        .abs();
    let vertices = vertices
        .iter()
        .map(|v| Point3::new(v.x, v.y, v.z))
        .collect();
    (vertices, volume)
}

/// Whether the triangles form a closed surface on their own: every directed edge is matched by
/// its reverse.
fn closed(triangles: &[[u32; 3]]) -> bool {
    let mut edges: Vec<(u32, u32)> = triangles
        .iter()
        .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
        .collect();
    edges.sort_unstable();
    edges
        .iter()
        .all(|&(a, b)| a == b || edges.binary_search(&(b, a)).is_ok())
}
