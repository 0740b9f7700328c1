//! Symmetry axes about which a part is round: a turn symmetry of so high an order (a round peg
//! modelled as a 48-gon) that turning the part by any angle about its axis moves its surface
//! less than a tolerance. Pose metrics let such a part turn freely about the axis, as BOP treats
//! continuous symmetries: neither a camera nor a hole can tell those turns apart. (Whether a
//! held part turns freely in a given fit is the insertion's question, `sim`'s
//! `Mating::turns_freely`, from its cross-section and the step's clearance.)

use nalgebra::{Point3, Unit, UnitQuaternion, Vector3};

use super::turned_surface::Surface;
use super::{Symmetry, TriMesh};

/// Default tolerance of [`round_axes`], metres: 0.02 mm, a fifth of the 0.1 mm an
/// assembly-grade pose may be off and under a sixth of a pixel at the seed's camera. A 48-gon
/// of 16 mm turned half a facet deviates 0.017 mm; a square peg turned at all, millimetres.
pub const ROUND_WITHIN_M: f64 = 2e-5;

/// Turns checked within half a symmetry step (the worst of a regular polygon's is the half).
const CHECKED_TURNS: usize = 4;

/// The axes (part frame, through its origin) of the exact `symmetries` about which the part
/// `mesh` turned by any angle stays within `tolerance` (metres) of itself, its vertices
/// checked (a turn of a polygon's vertex to mid-facet is its largest deviation).
pub fn round_axes(
    mesh: &TriMesh,
    symmetries: &[Symmetry],
    tolerance: f64,
) -> Vec<Unit<Vector3<f64>>> {
    let candidates: Vec<(Unit<Vector3<f64>>, u32)> = (symmetries.iter())
        .filter(|s| s.exact && s.order > 1)
        .filter_map(|s| Some((Unit::try_new(Vector3::from(s.axis), 1e-12)?, s.order)))
        .collect();
    if candidates.is_empty() {
        return Vec::new();
    }
    let Some(surface) = Surface::new(mesh, Point3::origin()) else {
        return Vec::new();
    };
    candidates
        .into_iter()
        .filter(|(axis, order)| {
            let half_step = std::f64::consts::PI / f64::from(*order);
            (1..=CHECKED_TURNS).all(|k| {
                let angle = half_step * k as f64 / CHECKED_TURNS as f64;
                let turn = UnitQuaternion::from_axis_angle(axis, angle);
                surface.turned_deviation(&turn, tolerance).is_some()
            })
        })
        .map(|(axis, _)| axis)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A prism of `sides` sides around z, `radius` to its corners, 10 mm long, centred.
    fn prism(sides: usize, radius: f64) -> TriMesh {
        let standing = TriMesh::prism(sides, 2.0 * radius, 0.01);
        standing.transformed(&nalgebra::Isometry3::translation(0.0, 0.0, -0.005))
    }

    fn about_z(order: u32, exact: bool) -> Symmetry {
        Symmetry {
            axis: [0.0, 0.0, 2.0],
            order,
            exact,
        }
    }

    #[test]
    fn a_48_gon_is_round_and_a_square_is_not() {
        // Half a facet of a 48-gon of 8 mm radius: 8 · (1 − cos 3.75°) = 0.017 mm.
        let round = round_axes(&prism(48, 0.008), &[about_z(48, true)], ROUND_WITHIN_M);
        assert_eq!(round.len(), 1);
        assert!((round[0].into_inner() - Vector3::z()).norm() < 1e-12);
        let square = round_axes(&prism(4, 0.008), &[about_z(4, true)], ROUND_WITHIN_M);
        assert!(square.is_empty(), "a square turned 45° is millimetres off");
    }

    #[test]
    fn a_tolerance_below_the_facets_sagitta_keeps_the_48_gon_discrete() {
        assert!(round_axes(&prism(48, 0.008), &[about_z(48, true)], 1.5e-5).is_empty());
        assert_eq!(
            round_axes(&prism(48, 0.008), &[about_z(48, true)], 1.8e-5).len(),
            1
        );
    }

    #[test]
    fn a_near_symmetry_or_a_half_turn_end_over_end_is_no_round_axis() {
        let mesh = prism(48, 0.008);
        assert!(round_axes(&mesh, &[about_z(48, false)], ROUND_WITHIN_M).is_empty());
        let end_over_end = Symmetry {
            axis: [1.0, 0.0, 0.0],
            order: 2,
            exact: true,
        };
        assert!(round_axes(&mesh, &[end_over_end], ROUND_WITHIN_M).is_empty());
    }
}
