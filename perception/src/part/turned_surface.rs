//! A part's surface about a centre, for measuring how far a turn moves it off itself: the
//! likeness of two stable poses ([`super::alike_stable_poses`]) and the roundness of a symmetry
//! axis ([`super::round_axes`]) both ask that.

use nalgebra::{Point3, UnitQuaternion, Vector3};
use parry3d_f64::math::Vector as DVec3;
use parry3d_f64::query::PointQuery;
use parry3d_f64::shape::TriMesh as ParryMesh;

use super::{TriMesh, farthest_point_sample};

/// Points of a coarse search (farthest-point samples of the points checked).
const COARSE_POINTS: usize = 48;
/// Most points (vertices) of a full check.
const MAX_CHECK_POINTS: usize = 6000;

/// The part's surface about a centre (its centre of mass, or the part origin that symmetries
/// turn about), with the points the checks move.
pub(super) struct Surface {
    mesh: ParryMesh,
    centre: Vector3<f64>,
    /// Vertices (every n-th of a large mesh's), relative to the centre.
    pub(super) points: Vec<Vector3<f64>>,
    /// A spread-out few of `points` for the coarse search.
    pub(super) coarse: Vec<Vector3<f64>>,
    /// Largest distance of a point from the centre.
    pub(super) radius: f64,
}

impl Surface {
    /// The surface of `mesh` about `centre`, checked at its vertices: not at triangle
    /// centroids too, since the inner walls of a mesh of touching bodies (a round peg exported as
    /// a fan of prisms, a pin pressed into a mold) have theirs inside the part, and a turn would
    /// measure them against the outer surface (`None` for a mesh parry refuses).
    pub(super) fn new(mesh: &TriMesh, centre: Point3<f64>) -> Option<Self> {
        let parry = mesh.to_parry()?;
        let stride = mesh.vertices.len().div_ceil(MAX_CHECK_POINTS).max(1);
        let sampled: Vec<Point3<f64>> = mesh.vertices.iter().copied().step_by(stride).collect();
        let coarse = farthest_point_sample(&sampled, COARSE_POINTS, centre);
        let relative = |p: &Point3<f64>| p - centre;
        let points: Vec<Vector3<f64>> = sampled.iter().map(relative).collect();
        let radius = points.iter().map(|p| p.norm()).fold(0.0, f64::max);
        Some(Self {
            mesh: parry,
            centre: centre.coords,
            points,
            coarse: coarse.iter().map(relative).collect(),
            radius,
        })
    }

    /// The largest distance from `points` turned by `turn` to the surface, or `None` once one
    /// is farther than `limit`.
    pub(super) fn deviation(
        &self,
        points: &[Vector3<f64>],
        turn: &UnitQuaternion<f64>,
        limit: f64,
    ) -> Option<f64> {
        let mut worst = 0.0f64;
        for p in points {
            let q = self.centre + turn * p;
            let q = DVec3::new(q.x, q.y, q.z);
            let proj = self
                .mesh
                .project_local_point_with_max_dist(q, false, limit)?;
            let d = (proj.point - q).length();
            if d > limit {
                return None;
            }
            worst = worst.max(d);
        }
        Some(worst)
    }

    /// How far the surface turned by `turn` lies from itself, both ways round (the turned
    /// surface onto the part, and the part onto the turned one), or `None` beyond `limit`.
    pub(super) fn turned_deviation(&self, turn: &UnitQuaternion<f64>, limit: f64) -> Option<f64> {
        let there = self.deviation(&self.points, turn, limit)?;
        let back = self.deviation(&self.points, &turn.inverse(), limit)?;
        Some(there.max(back))
    }
}
