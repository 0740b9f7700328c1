//! Convex pieces of a part mesh for contact simulation.
//!
//! The project's meshes are built by [`crate::cad::solid::Solid`] from hexahedra (12 consecutive
//! triangles each, in order, also after an OBJ round trip). The union of their convex hulls is
//! the solid, chamfers and clearances included: a hexahedron's only non-planar faces are the
//! mitres where two wall pieces of a ring meet, and the hull fills those inside the solid. A mesh
//! not made of closed 12-triangle pieces falls back to its single convex hull (flagged so callers
//! can tell).

use nalgebra::Point3;
use perception::part::TriMesh;

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
            pieces,
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cad::usbc;

    #[test]
    fn usbc_parts_split_into_exact_convex_pieces() {
        for mesh in [
            usbc::main_shell(),
            usbc::insert_mold(),
            usbc::top_shell(),
            usbc::fixture_nest(),
        ] {
            let p = convex_pieces(&mesh);
            assert!(p.exact);
            assert_eq!(p.pieces.len(), mesh.triangles.len() / 12);
        }
    }

    #[test]
    fn a_non_convex_chunk_falls_back_to_the_hull() {
        // A mesh whose triangles are not whole hexahedra is not cut into pieces.
        let mut mesh = usbc::insert_mold();
        mesh.triangles.truncate(11);
        assert!(!convex_pieces(&mesh).exact);
    }
}
