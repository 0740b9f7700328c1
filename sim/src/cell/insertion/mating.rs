//! The geometry of one assembly step that both scorers use.

use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector2, Vector3};
use perception::symmetry::{keeping_axis, nearest_twin, symmetry_group};

use super::pose_error::{PoseError, tilt_of, twist_about_z};
use crate::cell::geometry::{PartGeometry, destination_T_insertion};
use crate::config::{AssemblyStep, Tolerances};

/// Coulomb friction between metal and plastic part surfaces (used by both scorers).
pub const PART_FRICTION: f64 = 0.3;

/// A part already in place that the held part mates with.
#[derive(Debug, Clone, Copy)]
#[allow(non_snake_case)]
pub struct ReceiverPart<'a> {
    /// Its shapes.
    pub geometry: &'a PartGeometry,
    /// Its true pose in the step's destination frame.
    pub destination_T_part: Isometry3<f64>,
}

/// The mating geometry of one step, derived from the real meshes.
#[derive(Debug, Clone)]
#[allow(non_snake_case)]
pub struct Mating {
    /// Name of the held part.
    pub part: String,
    /// Total clearance across the mating features, metres.
    pub clearance: f64,
    /// Lead-in chamfer size, metres.
    pub lead_in: f64,
    /// What counts as seated.
    pub tolerances: Tolerances,
    /// Depth over which the held part engages the destination when seated, metres.
    pub engagement: f64,
    /// Half-widths (x, y) of the mating fit in the insertion frame, metres.
    pub half_width: Vector2<f64>,
    /// The held part's leading point (centre of its leading face), part frame.
    pub lead_point: Point3<f64>,
    /// Rotation of the seated part in the insertion frame.
    pub ins_R_seat: UnitQuaternion<f64>,
    /// The insertion frame in the destination frame.
    pub destination_T_insertion: Isometry3<f64>,
    /// Friction between the parts.
    pub friction: f64,
    /// True when the held part's engaged cross-section turns freely in the fit: it lies within
    /// a circle that still fits the hole at any turn (a round peg), so a yaw error neither
    /// swings its corners nor jams it.
    pub turns_freely: bool,
    /// The held part's twins: part-frame rotations `g` of its exact symmetries that keep the
    /// insertion axis (turns about it, and half turns across it that swap its ends), the
    /// identity first. The part posed `R` is the same solid as posed `R · g`, so every pose is
    /// scored as its twin nearest the seated one: a square peg turned a quarter seats like one
    /// at 0°, a 48-gon turned 7.5° like one at 0°, a peg either end up alike.
    pub twins: Vec<UnitQuaternion<f64>>,
}

impl Mating {
    /// The mating of `held` into `receivers` (the first is the destination itself).
    pub fn new(step: &AssemblyStep, held: &PartGeometry, receivers: &[ReceiverPart<'_>]) -> Self {
        let d_T_ins = destination_T_insertion(step);
        let ins_T_d = d_T_ins.inverse();
        let ins_R_seat = (ins_T_d * step.target.isometry()).rotation;
        let axis_in_part = ins_R_seat.inverse() * -Vector3::z();
        let (_, lead) = held.extent_along(&axis_in_part);
        let lead_point = Point3::from(axis_in_part * lead);
        let seated: Vec<Point3<f64>> = held.mesh.vertices.iter().map(|p| ins_R_seat * p).collect();
        let bottom = seated.iter().map(|p| p.z).fold(f64::INFINITY, f64::min);
        let top_of = |r: &ReceiverPart<'_>| {
            let t = ins_T_d * r.destination_T_part;
            r.geometry
                .mesh
                .vertices
                .iter()
                .map(|p| (t * p).z)
                .fold(f64::NEG_INFINITY, f64::max)
        };
        let engagement = receivers
            .first()
            .map_or(0.0, |r| (top_of(r) - bottom).max(0.0));
        let band = |z: f64| z < bottom + engagement - 1e-7;
        let footprint = |pts: &mut dyn Iterator<Item = Point3<f64>>| {
            pts.filter(|p| band(p.z))
                .fold(Vector2::zeros(), |m: Vector2<f64>, p| {
                    Vector2::new(m.x.max(p.x.abs()), m.y.max(p.y.abs()))
                })
        };
        let held_fp = footprint(&mut seated.iter().copied());
        let turns_freely = turns_freely(
            &seated
                .iter()
                .filter(|p| band(p.z))
                .map(|p| Vector2::new(p.x, p.y))
                .collect::<Vec<_>>(),
            step.clearance,
        );
        let half_width = match receivers.first() {
            Some(r) => {
                let t = ins_T_d * r.destination_T_part;
                let recv_fp = footprint(&mut r.geometry.mesh.vertices.iter().map(|p| t * p));
                Vector2::new(held_fp.x.min(recv_fp.x), held_fp.y.min(recv_fp.y))
            }
            None => held_fp,
        };
        let twins = keeping_axis(&symmetry_group(&held.symmetries), &axis_in_part);
        Self {
            part: step.part.clone(),
            clearance: step.clearance,
            lead_in: step.lead_in,
            tolerances: step.tolerances,
            engagement,
            half_width,
            lead_point,
            ins_R_seat,
            destination_T_insertion: d_T_ins,
            friction: PART_FRICTION,
            turns_freely,
            twins,
        }
    }

    /// The twin `g` (one of [`Self::twins`]) that turns a part posed `rotation` (insertion
    /// frame) nearest to its seated rotation; the identity for a part without twins.
    pub fn twin(&self, rotation: &UnitQuaternion<f64>) -> UnitQuaternion<f64> {
        if self.twins.len() < 2 {
            return UnitQuaternion::identity();
        }
        nearest_twin(&self.ins_R_seat, rotation, &self.twins)
    }

    /// The part's pose `ins_T_part` as its twin nearest seated (`ins_T_part · g`): the same solid
    /// in the same place. Unchanged for a part without twins.
    #[allow(non_snake_case)]
    pub fn nearest_twin(&self, ins_T_part: &Isometry3<f64>) -> Isometry3<f64> {
        if self.twins.len() < 2 {
            return *ins_T_part;
        }
        ins_T_part * self.twin(&ins_T_part.rotation)
    }

    /// Capture half-width: clearance/2 + lead-in.
    pub fn capture(&self) -> f64 {
        self.clearance / 2.0 + self.lead_in
    }

    /// How far the leading face reaches laterally on its worst axis, the yaw's corner swing
    /// included.
    pub fn capture_reach(&self, e: &PoseError) -> f64 {
        if self.turns_freely {
            return e.lateral.x.abs().max(e.lateral.y.abs());
        }
        let s = e.yaw.sin().abs();
        (e.lateral.x.abs() + s * self.half_width.y).max(e.lateral.y.abs() + s * self.half_width.x)
    }

    /// Mating width along a horizontal direction (the tilt's), metres.
    pub fn width_along(&self, dir: &Vector2<f64>) -> f64 {
        if dir.norm() < 1e-12 {
            return 2.0 * self.half_width.x.min(self.half_width.y);
        }
        2.0 * (dir.x.abs() * self.half_width.x + dir.y.abs() * self.half_width.y)
    }

    /// Largest tilt (toward `dir`) at which a rigidly held part still passes the whole engagement
    /// depth: the two-point condition `w cos θ + D tan θ = w + c`.
    pub fn jam_angle(&self, dir: &Vector2<f64>) -> f64 {
        let w = self.width_along(dir);
        let (d, c) = (self.engagement, self.clearance);
        let f = |t: f64| w * t.cos() + d * t.tan() - w - c;
        bisect(f, 0.0, 1.2)
    }

    /// Largest yaw about the insertion axis whose footprint still fits the clearance.
    pub fn yaw_limit(&self) -> f64 {
        if self.turns_freely {
            return std::f64::consts::PI;
        }
        let (a, b, h) = (self.half_width.x, self.half_width.y, self.clearance / 2.0);
        let f = |t: f64| (a * t.cos() + b * t.sin() - a - h).max(b * t.cos() + a * t.sin() - b - h);
        bisect(f, 0.0, 0.7)
    }

    /// The pose error of a part pose given in the insertion frame, measured on its twin nearest
    /// seated ([`Self::nearest_twin`]).
    #[allow(non_snake_case)]
    pub fn pose_error(&self, ins_T_part: &Isometry3<f64>) -> PoseError {
        let twin = self.nearest_twin(ins_T_part);
        let ins_T_part = &twin;
        let r = ins_T_part.rotation * self.ins_R_seat.inverse();
        let (tilt, tilt_direction) = tilt_of(&r);
        let lead = ins_T_part * self.lead_point;
        let lead0 = self.ins_R_seat * self.lead_point;
        PoseError {
            lateral: Vector2::new(lead.x - lead0.x, lead.y - lead0.y),
            height: ins_T_part.translation.z,
            tilt,
            tilt_direction,
            yaw: twist_about_z(&r),
        }
    }

    /// The part pose in the insertion frame with a given error (the inverse of [`Self::pose_error`]
    /// for lateral, height, yaw and tilt about a horizontal axis).
    pub fn pose_with_error(
        &self,
        lateral: Vector2<f64>,
        height: f64,
        yaw: f64,
        tilt: f64,
        tilt_direction: Vector2<f64>,
    ) -> Isometry3<f64> {
        let axis = Vector3::new(-tilt_direction.y, tilt_direction.x, 0.0);
        let tilt_r = match nalgebra::Unit::try_new(axis, 1e-12) {
            Some(a) => UnitQuaternion::from_axis_angle(&a, tilt),
            None => UnitQuaternion::identity(),
        };
        let r = tilt_r * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw) * self.ins_R_seat;
        let lead0 = self.ins_R_seat * self.lead_point;
        let lead_now = r * self.lead_point;
        let t = Vector3::new(
            lateral.x + lead0.x - lead_now.x,
            lateral.y + lead0.y - lead_now.y,
            height,
        );
        Isometry3::from_parts(t.into(), r)
    }
}

/// Whether a cross-section (points about the insertion axis, seated) turns freely in a fit of
/// total clearance `clearance`: its farthest point from the axis lies within the circle that its
/// convex outline contains (its nearest edge's distance from the axis) grown by half the
/// clearance. A hole is the part's outline grown by half the clearance, so it contains that
/// grown circle, and the part turned by any angle stays within it. Holds for a fine polygon
/// standing for a circle; never for a rectangle (its corners lie far outside its inscribed
/// circle).
fn turns_freely(points: &[Vector2<f64>], clearance: f64) -> bool {
    if points.len() < 3 {
        return false;
    }
    let outer = points.iter().map(|p| p.norm()).fold(0.0, f64::max);
    let hull = convex_outline(points);
    if hull.len() < 3 {
        return false;
    }
    let inner = (0..hull.len())
        .map(|i| {
            let (a, b) = (hull[i], hull[(i + 1) % hull.len()]);
            let edge = b - a;
            // Distance of the axis (the origin) from the edge's line.
            (edge.x * a.y - edge.y * a.x).abs() / edge.norm()
        })
        .fold(f64::INFINITY, f64::min);
    outer <= inner + clearance / 2.0
}

/// The convex outline of 2-D points, counter-clockwise (Andrew's monotone chain).
fn convex_outline(points: &[Vector2<f64>]) -> Vec<Vector2<f64>> {
    let mut p: Vec<Vector2<f64>> = points.to_vec();
    p.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    p.dedup_by(|a, b| (*a - *b).norm() < 1e-12);
    if p.len() < 3 {
        return p;
    }
    let cross = |o: Vector2<f64>, a: Vector2<f64>, b: Vector2<f64>| {
        (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x)
    };
    let mut hull: Vec<Vector2<f64>> = Vec::with_capacity(2 * p.len());
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &Vector2<f64>>> = if pass == 0 {
            Box::new(p.iter())
        } else {
            Box::new(p.iter().rev())
        };
        for &q in iter {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0
            {
                hull.pop();
            }
            hull.push(q);
        }
        hull.pop();
    }
    hull
}

/// The first root of `f` on [lo, hi], where `f(lo) ≤ 0`: scanned in steps of 1 mrad, then
/// bisected; `hi` when `f` never rises above zero there.
fn bisect(f: impl Fn(f64) -> f64, lo: f64, hi: f64) -> f64 {
    if f(lo) > 0.0 {
        return lo;
    }
    let step = 1e-3;
    let mut a = lo;
    while a < hi {
        let b = (a + step).min(hi);
        if f(b) > 0.0 {
            let (mut l, mut h) = (a, b);
            for _ in 0..50 {
                let mid = 0.5 * (l + h);
                if f(mid) > 0.0 {
                    h = mid;
                } else {
                    l = mid;
                }
            }
            return 0.5 * (l + h);
        }
        a = b;
    }
    hi
}

#[cfg(test)]
mod tests {
    use nalgebra::Isometry3;

    use super::*;
    use crate::cad::nist::{HOLE_DEPTH_MM, PEGS, PegShape, fixture_plate};
    use crate::cell::insertion::analytic;

    fn geometry(name: &str, mesh: perception::part::TriMesh) -> PartGeometry {
        PartGeometry::from_mesh(name, mesh, 1e-3, vec![], vec![]).unwrap()
    }

    #[test]
    fn a_round_peg_turns_freely_in_its_hole_and_a_square_one_does_not() {
        let plate = geometry("nist_plate", fixture_plate());
        for peg in &PEGS {
            let held = geometry(peg.name, peg.mesh());
            let receivers = [ReceiverPart {
                geometry: &plate,
                destination_T_part: Isometry3::identity(),
            }];
            let m = Mating::new(&peg.insertion_step(), &held, &receivers);
            let round = peg.shape == PegShape::Round;
            assert_eq!(m.turns_freely, round, "{}", peg.name);
            // The whole hole depth engages; the fit is the peg's own width.
            assert!(
                (m.engagement - HOLE_DEPTH_MM * 1e-3).abs() < 1e-12,
                "{}",
                peg.name
            );
            let half = peg.peg_size_mm() / 2.0 * 1e-3;
            assert!((m.half_width.x - half).abs() < 1e-12, "{}", peg.name);
            // Three degrees of yaw: the round peg is seated, the square one jams on its corners
            // (its yaw limit is about half a degree).
            let start = m.pose_with_error(
                Vector2::new(1e-4, 0.0),
                m.engagement + 1e-3,
                3f64.to_radians(),
                0.0,
                Vector2::zeros(),
            );
            let r = analytic::score(&m, &start);
            if round {
                assert_eq!(m.yaw_limit(), std::f64::consts::PI);
                assert_eq!(r.verdict, super::super::Verdict::Seated, "{}", peg.name);
            } else {
                assert!(m.yaw_limit() < 1f64.to_radians(), "{}", m.yaw_limit());
                assert_eq!(r.verdict, super::super::Verdict::Jammed, "{}", peg.name);
            }
        }
    }

    #[test]
    fn only_a_fine_polygon_within_its_clearance_turns_freely() {
        let ring = |n: usize, r: f64| -> Vec<Vector2<f64>> {
            (0..n)
                .map(|k| {
                    let a = std::f64::consts::TAU * k as f64 / n as f64;
                    Vector2::new(r * a.cos(), r * a.sin())
                })
                .collect()
        };
        // A 4 mm 48-gon's flats are 8.6 µm inside its corners: free in a 0.02 mm fit, not in 0.01.
        assert!(turns_freely(&ring(48, 0.004), 2e-5));
        assert!(!turns_freely(&ring(48, 0.004), 1e-5));
        // An octagon's flats are 7.6 % inside: never free in a fit of tens of microns.
        assert!(!turns_freely(&ring(8, 0.004), 1e-4));
        // A rectangle, the USB-C parts' cross-sections.
        let rect = [(-4.2, -4.27), (4.2, -4.27), (4.2, 4.27), (-4.2, 4.27)]
            .map(|(x, y)| Vector2::new(x * 1e-3, y * 1e-3));
        assert!(!turns_freely(&rect, 9e-5));
    }
}
