//! Physical consistency between one frame's estimates: parts that rest on the table cannot
//! interpenetrate.
//!
//! Planar refinement puts every part flat on the table in one of its stable poses. When two such
//! estimates overlap by more than estimation error explains, one part lies on the other (leaning
//! on it, or stacked): a pose that no stable pose describes, so neither estimate is fit for a
//! grasp. The test runs on the parts' convex pieces (their hulls would overlap where one part's
//! tab reaches over another's low wall): parry's GJK says whether two pieces intersect, and the
//! separating-axis theorem how deep (parry's EPA misjudged deep overlaps of pieces with parallel
//! faces); a pair's depth is the smallest translation that separates its deepest-overlapping
//! pieces. The queries work in millimetres: parry's solvers have absolute tolerances that
//! misjudge millimetre parts in metres.

use nalgebra::{Isometry3, Point3};
use parry3d_f64::math::{Pose, Rotation, Vector};
use parry3d_f64::query::intersection_test;
use parry3d_f64::query::sat::support_map_support_map_compute_separation;
use parry3d_f64::shape::ConvexPolyhedron;

use crate::part::{TriMesh, convex_pieces};

/// Millimetres per metre: the unit of the shapes and poses handed to parry.
const MM: f64 = 1000.0;

/// Convex pieces of the detectable parts, to test whether estimates can rest side by side.
pub struct StackingCheck {
    parts: Vec<PartPieces>,
    tolerance: f64,
}

/// One part's convex pieces and the radius about its frame origin that holds them, mm.
struct PartPieces {
    pieces: Vec<Piece>,
    radius: f64,
}

/// One convex piece and the sphere that holds it (part frame, mm).
struct Piece {
    shape: ConvexPolyhedron,
    centre: Point3<f64>,
    radius: f64,
}

/// An estimate that overlaps another one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Overlap {
    /// Index, among the estimates checked, of the one it overlaps most deeply.
    pub other: usize,
    /// Penetration depth of the two parts' deepest-overlapping pieces, metres.
    pub depth: f64,
}

impl StackingCheck {
    /// Pieces of `meshes` (part frames, indexed by class); overlaps up to `tolerance` metres are
    /// put down to estimation error. Pieces without volume are left out.
    pub fn new(meshes: &[TriMesh], tolerance: f64) -> Self {
        let parts = meshes
            .iter()
            .map(|mesh| {
                let pieces: Vec<Piece> = convex_pieces(mesh)
                    .pieces
                    .iter()
                    .filter_map(|points| piece(points))
                    .collect();
                let radius = pieces
                    .iter()
                    .map(|p| p.centre.coords.norm() + p.radius)
                    .fold(0.0, f64::max);
                PartPieces { pieces, radius }
            })
            .collect();
        Self { parts, tolerance }
    }

    /// For each estimate `(class, table_T_part)`, its deepest overlap beyond the tolerance with
    /// another estimate, if it has one.
    pub fn overlaps(&self, estimates: &[(usize, Isometry3<f64>)]) -> Vec<Option<Overlap>> {
        self.overlaps_where(estimates, |_, _| true)
    }

    /// [`Self::overlaps`], counting an overlap of estimate `k` with estimate `other` against `k`
    /// only where `counts(k, other)`: a weak estimate may fall to any overlap and yet bring down
    /// no strong one.
    #[allow(non_snake_case)]
    pub fn overlaps_where(
        &self,
        estimates: &[(usize, Isometry3<f64>)],
        counts: impl Fn(usize, usize) -> bool,
    ) -> Vec<Option<Overlap>> {
        let mut found: Vec<Option<Overlap>> = vec![None; estimates.len()];
        for (i, (ci, table_T_i)) in estimates.iter().enumerate() {
            let Some(pi) = self.parts.get(*ci) else {
                continue;
            };
            for (j, (cj, table_T_j)) in estimates.iter().enumerate().skip(i + 1) {
                let Some(pj) = self.parts.get(*cj) else {
                    continue;
                };
                let apart =
                    MM * (table_T_i.translation.vector - table_T_j.translation.vector).norm();
                if apart > pi.radius + pj.radius {
                    continue;
                }
                let depth = deepest(pi, table_T_i, pj, table_T_j, MM * self.tolerance) / MM;
                if depth <= self.tolerance {
                    continue;
                }
                for (k, other) in [(i, j), (j, i)] {
                    if counts(k, other) && found[k].is_none_or(|o| o.depth < depth) {
                        found[k] = Some(Overlap { other, depth });
                    }
                }
            }
        }
        found
    }
}

/// A convex piece (metres) as a parry shape with its bounding sphere, in millimetres.
fn piece(points: &[Point3<f64>]) -> Option<Piece> {
    let mm: Vec<Point3<f64>> = points.iter().map(|p| p * MM).collect();
    let n = mm.len().max(1) as f64;
    let centre = Point3::from(mm.iter().map(|p| p.coords).sum::<nalgebra::Vector3<f64>>() / n);
    let radius = mm.iter().map(|p| (p - centre).norm()).fold(0.0, f64::max);
    let vertices: Vec<Vector> = mm.iter().map(|p| Vector::new(p.x, p.y, p.z)).collect();
    let shape = ConvexPolyhedron::from_convex_hull(&vertices)?;
    Some(Piece {
        shape,
        centre,
        radius,
    })
}

/// Penetration depth (mm, ≤ 0 when apart) of the deepest-overlapping pair of pieces of two
/// parts at their poses (metres); exact when it exceeds `floor` (mm), and otherwise some value
/// not above it.
#[allow(non_snake_case)]
fn deepest(
    a: &PartPieces,
    table_T_a: &Isometry3<f64>,
    b: &PartPieces,
    table_T_b: &Isometry3<f64>,
    floor: f64,
) -> f64 {
    let (pose_a, pose_b) = (pose(table_T_a), pose(table_T_b));
    let in_mm =
        |iso: &Isometry3<f64>, p: &Point3<f64>| iso.rotation * p + iso.translation.vector * MM;
    let centres_b: Vec<Point3<f64>> = b
        .pieces
        .iter()
        .map(|q| in_mm(table_T_b, &q.centre))
        .collect();
    let mut depth = f64::NEG_INFINITY;
    for p in &a.pieces {
        let ca = in_mm(table_T_a, &p.centre);
        for (q, cb) in b.pieces.iter().zip(&centres_b) {
            if (ca - cb).norm() > p.radius + q.radius {
                continue;
            }
            depth = depth.max(penetration(&pose_a, &p.shape, &pose_b, &q.shape, floor));
        }
    }
    depth
}

/// Penetration depth of two convex pieces at their poses, mm (−∞ when apart; see
/// [`separating_axis_depth`] for `floor`): GJK tells whether they intersect, and the
/// separating-axis depth how deep. (parry's EPA, behind its `contact`, reported two insert molds
/// 2 mm apart at the same yaw as touching, and as apart when it gave up.)
fn penetration(
    pose_a: &Pose,
    a: &ConvexPolyhedron,
    pose_b: &Pose,
    b: &ConvexPolyhedron,
    floor: f64,
) -> f64 {
    if intersection_test(pose_a, a, pose_b, b).is_ok_and(|i| i.intersecting) {
        separating_axis_depth(&pose_a.inv_mul(pose_b), a, b, floor)
    } else {
        f64::NEG_INFINITY
    }
}

/// The least overlap of two convex polyhedra (`b` at `pos_ab` in `a`'s frame) over the axes that
/// can separate them, both faces' normals and the cross products of their edges: their
/// penetration depth, exact for convex polyhedra (negative when some axis separates them). It
/// stops at the first axis that shows the depth is at most `floor` and returns that overlap:
/// slight overlaps, the common case, then cost a few face normals instead of every edge pair.
fn separating_axis_depth(
    pos_ab: &Pose,
    a: &ConvexPolyhedron,
    b: &ConvexPolyhedron,
    floor: f64,
) -> f64 {
    let edges_b: Vec<Vector> = b.edges().iter().map(|e| pos_ab.rotation * e.dir).collect();
    let axes = a
        .faces()
        .iter()
        .map(|f| f.normal)
        .chain(b.faces().iter().map(|f| pos_ab.rotation * f.normal))
        .chain(a.edges().iter().flat_map(|ea| {
            edges_b
                .iter()
                .filter_map(move |eb| ea.dir.cross(*eb).try_normalize())
        }));
    let mut depth = f64::INFINITY;
    for axis in axes {
        for dir in [axis, -axis] {
            depth = depth.min(-support_map_support_map_compute_separation(
                a, b, pos_ab, dir,
            ));
            if depth <= floor {
                return depth;
            }
        }
    }
    depth
}

/// A nalgebra isometry (metres) as a parry pose (millimetres).
fn pose(iso: &Isometry3<f64>) -> Pose {
    let t = iso.translation.vector * MM;
    let q = iso.rotation;
    Pose::from_parts(
        Vector::new(t.x, t.y, t.z),
        Rotation::from_xyzw(q.i, q.j, q.k, q.w),
    )
}

#[cfg(test)]
mod tests {
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    use super::*;

    /// A closed box `[0, sx] × [0, sy] × [0, sz]` metres (the frame at a corner, z up).
    fn block(sx: f64, sy: f64, sz: f64) -> TriMesh {
        let size = Vector3::new(sx, sy, sz);
        let mut mesh = TriMesh::cuboid(size);
        for v in &mut mesh.vertices {
            *v += size / 2.0;
        }
        mesh
    }

    fn at(x: f64, y: f64, yaw: f64) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(x, y, 0.0),
            UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
        )
    }

    #[test]
    fn parts_side_by_side_pass_and_overlapping_ones_are_both_flagged() {
        let check = StackingCheck::new(&[block(0.009, 0.006, 0.003)], 0.0005);
        // Touching along x (0.2 mm of estimation error into each other), and one far away.
        let touching = [
            (0, at(0.0, 0.0, 0.0)),
            (0, at(0.0088, 0.0, 0.0)),
            (0, at(0.05, 0.0, 0.0)),
        ];
        assert_eq!(check.overlaps(&touching), vec![None; 3]);
        // The second one 1.5 mm into the first: both flagged, each naming the other.
        let stacked = [
            (0, at(0.0, 0.0, 0.0)),
            (0, at(0.0075, 0.0, 0.0)),
            (0, at(0.05, 0.0, 0.0)),
        ];
        let found = check.overlaps(&stacked);
        for (k, other) in [(0, 1), (1, 0)] {
            let o = found[k].expect("overlap");
            assert_eq!(o.other, other);
            assert!((o.depth - 0.0015).abs() < 1e-9, "depth {}", o.depth);
        }
        assert_eq!(found[2], None);
    }

    #[test]
    fn a_turned_part_overlaps_by_its_corner() {
        let check = StackingCheck::new(&[block(0.009, 0.009, 0.003)], 0.0005);
        // A square turned −45° about its corner at the origin reaches x = 0 only at that corner;
        // placed with that corner 1 mm inside a neighbour's right face, it overlaps by 1 mm (its
        // other separating directions need more: 2.1 mm along the wedge's edge normal).
        let found = check.overlaps(&[
            (0, at(-0.009, 0.0, 0.0)),
            (0, at(-0.001, 0.002, -std::f64::consts::FRAC_PI_4)),
        ]);
        let o = found[0].expect("overlap");
        assert!((o.depth - 0.001).abs() < 1e-6, "depth {}", o.depth);
    }

    #[test]
    fn insert_molds_overlapping_at_any_yaw_are_flagged() {
        // parry's contact query (EPA) reported these as touching or apart: two insert molds 2 mm
        // apart, at one yaw or nearly.
        let root =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/parts/usbc.toml");
        let catalog = crate::part::Catalog::load(&root).unwrap();
        let mold = catalog.part("insert_mold").unwrap();
        let check = StackingCheck::new(&[catalog.load_mesh(mold).unwrap()], 0.0005);
        for (yaw, turn) in [
            (0.0, 0.0),
            (0.0, 1e-6),
            (0.3, 1e-9),
            (0.3, 0.01),
            (1.0, 0.0),
        ] {
            let resting = |x: f64, yaw: f64| {
                Isometry3::from_parts(
                    Translation3::new(x, 0.0, 0.002075),
                    UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
                )
            };
            let found = check.overlaps(&[(0, resting(0.0, yaw)), (0, resting(0.002, yaw + turn))]);
            let o = found[0].unwrap_or_else(|| panic!("yaw {yaw} + {turn}: apart"));
            assert!(o.depth > 0.002, "yaw {yaw} + {turn}: {} mm", 1e3 * o.depth);
        }
    }

    #[test]
    fn parts_without_volume_and_unknown_classes_are_never_flagged() {
        let flat = TriMesh {
            vertices: vec![Point3::origin(); 3],
            triangles: vec![[0, 1, 2]],
        };
        let check = StackingCheck::new(&[flat], 0.0005);
        assert_eq!(
            check.overlaps(&[
                (0, at(0.0, 0.0, 0.0)),
                (0, at(0.0, 0.0, 0.0)),
                (3, at(0.0, 0.0, 0.0))
            ]),
            vec![None; 3]
        );
    }
}
