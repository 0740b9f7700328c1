//! The project's CAD meshes split into exact convex pieces (perception::part::convex_pieces):
//! the contact simulation and the stacking check both rely on it.

use nalgebra::Point3;
use parry3d_f64::math::Vector3;
use parry3d_f64::transformation::convex_hull;
use perception::part::convex_pieces;
use sim::cad::usbc;

/// The volume of the convex hull of `points`.
fn hull_volume(points: &[Point3<f64>]) -> f64 {
    let pts: Vec<Vector3> = points.iter().map(|p| Vector3::new(p.x, p.y, p.z)).collect();
    let (vertices, triangles) = convex_hull(&pts);
    triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| vertices[i as usize]);
            a.dot(b.cross(c)) / 6.0
        })
        .sum::<f64>()
        .abs()
}

#[test]
fn usbc_parts_split_into_exact_convex_pieces() {
    // The nest's chamfers merge with the walls below them, its plate cells with each other.
    let nest = usbc::fixture_nest();
    assert!(convex_pieces(&nest).pieces.len() < nest.triangles.len() / 12 / 2);
    for mesh in [
        usbc::main_shell(),
        usbc::insert_mold(),
        usbc::top_shell(),
        usbc::fixture_nest(),
    ] {
        let p = convex_pieces(&mesh);
        assert!(p.exact);
        assert!(p.pieces.len() <= mesh.triangles.len() / 12);
        // The merged hulls hold the solid's volume (up to the twisted mitres of rings with
        // unequal wall thickness, whose hulls overlap a neighbour inside the solid by a few
        // 1e-5).
        let pieces: f64 = p.pieces.iter().map(|q| hull_volume(q)).sum();
        let v = mesh.volume();
        assert!((pieces - v).abs() < 1e-4 * v, "{pieces} vs {v}");
    }
}

#[test]
fn a_non_convex_chunk_falls_back_to_the_hull() {
    // A mesh whose triangles are not whole hexahedra is not cut into pieces.
    let mut mesh = usbc::insert_mold();
    mesh.triangles.truncate(11);
    assert!(!convex_pieces(&mesh).exact);
}
