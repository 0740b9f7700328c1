//! Stable poses a camera above the table cannot tell apart: the part rests in both as the same
//! shape, only turned, under a turn that is not one of its declared symmetries (a 12 mm square
//! peg 12 mm long is such a near-cube: standing and lying it shows the same square).
//!
//! Vision then reports either pose for both, and a grasp or insertion planned for one is
//! applied to the other. `cell parts prepare` warns of every such pair, so the integrator can
//! declare the turn as a symmetry (when it is exact) or change the part.

use nalgebra::{Point3, Unit, UnitQuaternion, Vector3};

use super::turned_surface::Surface;
use super::{StablePose, Symmetry, TriMesh};
use crate::symmetry::symmetry_group;

/// Default tolerance of [`alike_stable_poses`], as a share of the part's largest extent: 1 %
/// is 0.12 mm on a 12 mm part, under a pixel at the seed's camera (about 7 px/mm).
pub const ALIKE_WITHIN_REL: f64 = 0.01;

/// A pair whose ups a declared symmetry maps within this angle of each other is already known.
const DECLARED_ANGLE_RAD: f64 = 0.05;
/// Steps of the turn about the second pose's up axis searched for a match (0.5° apart).
const YAW_STEPS: usize = 720;

/// Two stable poses in which a part shows the same shape, turned.
#[derive(Debug, Clone, PartialEq)]
pub struct AlikePoses {
    /// Index of the first pose in the poses checked.
    pub first: usize,
    /// Index of the second pose.
    pub second: usize,
    /// Largest distance (m) from a surface point of the part, turned, to the unturned surface,
    /// either way round: how far the two resting shapes differ.
    pub deviation: f64,
    /// The part-frame turn about the centre of mass that takes the first pose's up to the
    /// second's and the part's surface onto itself within `deviation`.
    pub turn: UnitQuaternion<f64>,
}

/// The pairs of `poses` in which the part rests as the same shape within `tolerance` (m),
/// leaving out pairs that the part's declared `symmetries` relate (near ones included: the
/// ambiguities the catalog already names).
///
/// A match is a turn `g` about the centre of mass with `g · up_first = up_second` that maps the
/// surface onto itself: the part resting in the first pose is then the part resting in the
/// second, seen turned about the vertical.
pub fn alike_stable_poses(
    mesh: &TriMesh,
    center_of_mass: Point3<f64>,
    poses: &[StablePose],
    symmetries: &[Symmetry],
    tolerance: f64,
) -> Vec<AlikePoses> {
    let as_exact: Vec<Symmetry> = (symmetries.iter())
        .map(|s| Symmetry {
            exact: true,
            ..s.clone()
        })
        .collect();
    let declared = symmetry_group(&as_exact);
    let Some(surface) = Surface::new(mesh, center_of_mass) else {
        return Vec::new();
    };
    let mut found = Vec::new();
    for first in 0..poses.len() {
        for second in first + 1..poses.len() {
            let up = |i: usize| Vector3::from(poses[i].up_in_part);
            let known = declared
                .iter()
                .any(|h| (h * up(first)).angle(&up(second)) < DECLARED_ANGLE_RAD);
            if known {
                continue;
            }
            if let Some((deviation, turn)) = surface.best_turn(&up(first), &up(second), tolerance) {
                found.push(AlikePoses {
                    first,
                    second,
                    deviation,
                    turn,
                });
            }
        }
    }
    found
}

/// The likeness search on a part's surface about its centre of mass.
impl Surface {
    /// How high the centre of mass stands above the table when the part rests with `up` up.
    fn support_height(&self, up: &Vector3<f64>) -> f64 {
        self.points
            .iter()
            .map(|p| -p.dot(up))
            .fold(f64::NEG_INFINITY, f64::max)
    }

    /// The turn taking `from` to `to` that best maps the surface onto itself, with its
    /// deviation, when that is within `tolerance`.
    fn best_turn(
        &self,
        from: &Vector3<f64>,
        to: &Vector3<f64>,
        tolerance: f64,
    ) -> Option<(f64, UnitQuaternion<f64>)> {
        // Alike shapes rest with their centres of mass equally high.
        if (self.support_height(from) - self.support_height(to)).abs() > tolerance {
            return None;
        }
        let align = UnitQuaternion::rotation_between(from, to).unwrap_or_else(|| {
            // Opposite ups: a half turn about any axis square to them.
            let axis = from.cross(&Vector3::x()).try_normalize(1e-6);
            let axis = axis.unwrap_or_else(|| from.cross(&Vector3::y()).normalize());
            UnitQuaternion::from_axis_angle(&Unit::new_unchecked(axis), std::f64::consts::PI)
        });
        let axis = Unit::new_normalize(*to);
        let at = |yaw: f64| UnitQuaternion::from_axis_angle(&axis, yaw) * align;
        let step = std::f64::consts::TAU / YAW_STEPS as f64;
        // A yaw half a step off moves a point by at most radius · step / 2.
        let slack = tolerance + self.radius * step / 2.0;
        let coarse = |yaw: f64| self.deviation(&self.coarse, &at(yaw), slack);
        let (best_yaw, best) = (0..YAW_STEPS)
            .filter_map(|k| {
                let yaw = k as f64 * step;
                coarse(yaw).map(|d| (yaw, d))
            })
            .min_by(|a, b| a.1.total_cmp(&b.1))?;
        // Golden-section refinement of the yaw within the step either side.
        let (mut lo, mut hi) = (best_yaw - step, best_yaw + step);
        let ratio = (5f64.sqrt() - 1.0) / 2.0;
        let score = |yaw: f64| {
            self.deviation(&self.coarse, &at(yaw), f64::INFINITY)
                .unwrap_or(f64::INFINITY)
        };
        for _ in 0..30 {
            let (a, b) = (hi - ratio * (hi - lo), lo + ratio * (hi - lo));
            if score(a) < score(b) {
                hi = b;
            } else {
                lo = a;
            }
        }
        let refined = (lo + hi) / 2.0;
        let turn = at(if score(refined) < best {
            refined
        } else {
            best_yaw
        });
        Some((self.turned_deviation(&turn, tolerance)?, turn))
    }
}
