//! Whether a part's convex pieces are its shape: the contact scorers collide pieces, so a part
//! whose mesh fell back to one convex hull (not built from convex pieces) would have its holes,
//! pockets and cavities filled in, and every insertion into them would land on the lid.

use super::ScorerError;
use crate::cell::geometry::PartGeometry;
use crate::convert::vec_from_point;

/// Relative excess of the pieces' volume over the mesh's above which the pieces are refused:
/// well above rounding, far below any hole worth inserting into.
const MAX_EXCESS: f64 = 1e-3;

/// Refuses `part` for a contact scorer named `scorer` when its pieces fill more than the solid:
/// the summed volume of their convex hulls exceeds the mesh's volume.
pub fn check_pieces(part: &PartGeometry, scorer: &'static str) -> Result<(), ScorerError> {
    if part.pieces.exact {
        return Ok(());
    }
    let solid = part.mesh.volume().abs();
    let filled: f64 = part
        .pieces
        .pieces
        .iter()
        .map(|piece| {
            let points: Vec<_> = piece.iter().map(vec_from_point).collect();
            let (vertices, triangles) = perception::part::convex_hull(&points);
            triangles
                .iter()
                .map(|t| {
                    let [a, b, c] = t.map(|i| vertices[i as usize]);
                    a.dot(b.cross(c)) / 6.0
                })
                .sum::<f64>()
                .abs()
        })
        .sum();
    if filled > solid * (1.0 + MAX_EXCESS) {
        return Err(ScorerError::Geometry {
            part: part.name.clone(),
            piece: 0,
            reason: format!(
                "the {scorer} scorer collides convex pieces, and this mesh is not built from \
                 convex pieces (sim::cad's hexahedra): its single convex hull is {:.1} % larger \
                 than the solid, so it would fill the part's holes and pockets. Use the analytic \
                 scorer, or model the part from convex pieces",
                100.0 * (filled / solid.max(f64::MIN_POSITIVE) - 1.0)
            ),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use perception::part::ConvexPieces;

    use super::*;
    use crate::cad::nist::fixture_plate;

    #[test]
    fn a_plate_whose_pieces_are_its_hull_is_refused_and_its_hexahedra_are_not() {
        let mesh = fixture_plate();
        let exact =
            PartGeometry::from_mesh("nist_plate", mesh.clone(), 1.0, vec![], vec![]).unwrap();
        assert!(exact.pieces.exact);
        check_pieces(&exact, "contact").unwrap();
        // The same mesh as one hull (what a mesh not built from convex pieces falls back to).
        let mut filled = exact.clone();
        filled.pieces = ConvexPieces {
            pieces: vec![mesh.vertices.clone()],
            exact: false,
        };
        let err = check_pieces(&filled, "contact").unwrap_err().to_string();
        assert!(
            err.contains("nist_plate") && err.contains("fill the part's holes"),
            "{err}"
        );
        // A convex part that fell back to its hull is its hull: accepted.
        let peg = crate::cad::nist::PEGS[3].mesh();
        let mut block =
            PartGeometry::from_mesh("square_8", peg.clone(), 1.0, vec![], vec![]).unwrap();
        block.pieces = ConvexPieces {
            pieces: vec![peg.vertices.clone()],
            exact: false,
        };
        check_pieces(&block, "mujoco").unwrap();
    }
}
