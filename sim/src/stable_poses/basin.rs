//! When a dropped part can no longer leave the hull face it is on: its energy is below the
//! face's tipping barrier, so the drop's outcome is known before it comes to rest.
//!
//! Let `u` be the downward direction seen from the part, and `h(u)` the height of the centre
//! of mass above the table when the part touches it (the hull's support distance along `u`).
//! Call `C_F` the directions whose ray from the centre of mass leaves the hull through face
//! `F`. On the border of `C_F` that ray leaves through an edge `e` of `F`, so `h(u)` is at least
//! the distance `d_e` from the centre of mass to that edge's line. A part whose centre of mass
//! height plus kinetic energy over `m g` stays below the smallest `d_e` never reaches that
//! border: it stays in `C_F`, where the only resting direction is `F`'s own normal (the ray
//! leaves through one face only). Contacts only take energy away, but the solver pushes
//! penetration out at up to 2 cm/s (about 20 µm of height), so a face traps a part only once
//! its energy is below half the barrier and at least [`MIN_MARGIN`] under it.
//!
//! Hull triangles within [`SAME_FACE_RAD`] of each other are one face: CAD exports a flat
//! face as facets a fraction of a milliradian apart (the seed authors' top shell), and such a
//! face's facets all rest in the same stable-pose class.

use std::collections::HashMap;

use nalgebra::{Point3, Vector3};

/// Facets whose normals are this close (radians) to a face's first facet belong to that face.
pub const SAME_FACE_RAD: f64 = 1e-3;

/// Least energy margin (as height of the centre of mass, metres) a face keeps under its
/// barrier before it traps a part: the push-out of contact penetration can add about 20 µm.
pub const MIN_MARGIN: f64 = 5e-5;

/// Share of its barrier a part's energy must be under before a face traps it.
const TRAP_SHARE: f64 = 0.5;

/// One face of the hull: coplanar (within [`SAME_FACE_RAD`]) facets.
#[derive(Debug, Clone)]
struct Face {
    /// Outward unit normal in the part frame (its first facet's).
    normal: Vector3<f64>,
    /// Distance of the centre of mass from the face plane, metres: its height at rest.
    rest: f64,
    /// Least distance of the centre of mass from the line of one of the face's outer edges.
    barrier: f64,
    /// Whether the centre of mass lies over the face, so the part can rest on it.
    stable: bool,
}

/// The faces of a part's hull with the energy each needs to be left, seen from its centre of
/// mass.
#[derive(Debug, Clone)]
pub struct FaceBasins {
    /// Each hull triangle's outward normal and its plane's distance from the centre of mass.
    facets: Vec<(Vector3<f64>, f64)>,
    /// The face each hull triangle belongs to.
    face_of: Vec<usize>,
    faces: Vec<Face>,
    /// The hull's corners relative to the centre of mass.
    corners: Vec<Vector3<f64>>,
}

impl FaceBasins {
    /// The faces of the convex hull `(vertices, triangles)` (part frame, metres, wound either
    /// way) around the centre of mass `com`, which must lie inside it.
    pub fn new(vertices: &[Point3<f64>], triangles: &[[u32; 3]], com: &Point3<f64>) -> Self {
        let inside = vertices.iter().fold(Vector3::zeros(), |s, v| s + v.coords)
            / vertices.len().max(1) as f64;
        let facets: Vec<(Vector3<f64>, f64)> = triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| vertices[i as usize]);
                let mut n = (b - a)
                    .cross(&(c - a))
                    .try_normalize(0.0)
                    .unwrap_or_default();
                if n.dot(&(a.coords - inside)) < 0.0 {
                    n = -n;
                }
                (n, n.dot(&(a - com)))
            })
            .collect();
        // Facets join the face of a neighbour (sharing an edge) when they lie near its first
        // facet.
        let mut by_edge: HashMap<[u32; 2], Vec<usize>> = HashMap::new();
        for (t, tri) in triangles.iter().enumerate() {
            for e in edges(tri) {
                by_edge.entry(e).or_default().push(t);
            }
        }
        let mut face_of = vec![usize::MAX; triangles.len()];
        let mut members: Vec<Vec<usize>> = Vec::new();
        for start in 0..triangles.len() {
            if face_of[start] != usize::MAX {
                continue;
            }
            let face = members.len();
            face_of[start] = face;
            let mut group = vec![start];
            let mut next = 0;
            while let Some(&t) = group.get(next) {
                next += 1;
                for u in edges(&triangles[t]).iter().flat_map(|e| &by_edge[e]) {
                    if face_of[*u] == usize::MAX
                        && facets[*u].0.angle(&facets[start].0) < SAME_FACE_RAD
                    {
                        face_of[*u] = face;
                        group.push(*u);
                    }
                }
            }
            members.push(group);
        }
        let faces = members
            .iter()
            .map(|group| {
                // An outer edge borders one facet of the face only.
                let mut uses: HashMap<[u32; 2], usize> = HashMap::new();
                for e in group.iter().flat_map(|&t| edges(&triangles[t])) {
                    *uses.entry(e).or_default() += 1;
                }
                let barrier = uses
                    .iter()
                    .filter(|(_, n)| **n == 1)
                    .map(|([i, j], _)| {
                        line_distance(com, &vertices[*i as usize], &vertices[*j as usize])
                    })
                    .fold(f64::INFINITY, f64::min);
                let (normal, rest) = facets[group[0]];
                Face {
                    normal,
                    rest,
                    barrier,
                    stable: false,
                }
            })
            .collect();
        let mut basins = Self {
            facets,
            face_of,
            faces,
            corners: vertices.iter().map(|v| v - com).collect(),
        };
        for f in 0..basins.faces.len() {
            basins.faces[f].stable = basins.face_below(&-basins.faces[f].normal) == Some(f);
        }
        basins
    }

    /// The face a part rests on for good, as its outward normal in the part frame, or `None`
    /// while it may still leave it. `up` is the table's up direction seen from the part,
    /// `height` its centre of mass's height above the table and `energy_height` its kinetic
    /// energy over `m g` (metres).
    pub fn trapped(
        &self,
        up: &Vector3<f64>,
        height: f64,
        energy_height: f64,
    ) -> Option<Vector3<f64>> {
        let f = self.face_below(up)?;
        let face = &self.faces[f];
        let excess = height + energy_height - face.rest;
        let barrier = face.barrier - face.rest;
        (face.stable && excess < (TRAP_SHARE * barrier).min(barrier - MIN_MARGIN))
            .then_some(face.normal)
    }

    /// How far the part's lowest corner lies under the table, metres (0 when none does), with
    /// `up` and `height` as in [`Self::trapped`]: a soft contact pressed in holds energy that
    /// the centre of mass's height does not show.
    pub fn sunk(&self, up: &Vector3<f64>, height: f64) -> f64 {
        let reach = self
            .corners
            .iter()
            .map(|v| -v.dot(up))
            .fold(f64::NEG_INFINITY, f64::max);
        (reach - height).max(0.0)
    }

    /// The face the ray from the centre of mass straight down (against `up`) leaves the hull
    /// through.
    fn face_below(&self, up: &Vector3<f64>) -> Option<usize> {
        self.facets
            .iter()
            .enumerate()
            .filter_map(|(t, (n, d))| {
                let along = -n.dot(up);
                (along > 0.0).then(|| (t, d / along))
            })
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(t, _)| self.face_of[t])
    }
}

/// A triangle's three edges, each as its vertex indices in increasing order.
fn edges(t: &[u32; 3]) -> [[u32; 2]; 3] {
    [0, 1, 2].map(|k| {
        let (i, j) = (t[k], t[(k + 1) % 3]);
        [i.min(j), i.max(j)]
    })
}

/// Distance from `p` to the line through `a` and `b`.
fn line_distance(p: &Point3<f64>, a: &Point3<f64>, b: &Point3<f64>) -> f64 {
    let dir = (b - a).try_normalize(0.0).unwrap_or_default();
    let v = p - a;
    (v - dir * v.dot(&dir)).norm()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A box of half-sizes `h` centred on the origin, as 12 triangles.
    fn cuboid(h: [f64; 3]) -> (Vec<Point3<f64>>, Vec<[u32; 3]>) {
        let m = perception::part::TriMesh::cuboid(2.0 * Vector3::from(h));
        (m.vertices, m.triangles)
    }

    #[test]
    fn a_box_has_six_faces_with_their_tipping_barriers() {
        // 10 × 6 × 2 mm, lying on its largest face: it tips over a long edge when its centre
        // of mass rises from 1 mm to √(3² + 1²) mm.
        let (v, t) = cuboid([0.005, 0.003, 0.001]);
        let b = FaceBasins::new(&v, &t, &Point3::origin());
        assert_eq!(b.faces.len(), 6);
        assert!(b.faces.iter().all(|f| f.stable));
        let bottom = b.face_below(&Vector3::z()).unwrap();
        let f = &b.faces[bottom];
        assert!((f.normal + Vector3::z()).norm() < 1e-12);
        assert!((f.rest - 0.001).abs() < 1e-12);
        assert!((f.barrier - (0.003f64.powi(2) + 0.001f64.powi(2)).sqrt()).abs() < 1e-12);
    }

    #[test]
    fn a_part_pressed_into_the_table_is_sunk_by_its_lowest_corner() {
        let (v, t) = cuboid([0.005, 0.003, 0.001]);
        let b = FaceBasins::new(&v, &t, &Point3::origin());
        assert!((b.sunk(&Vector3::z(), 0.0009) - 1e-4).abs() < 1e-12);
        assert_eq!(b.sunk(&Vector3::z(), 0.0011), 0.0);
        // Tilted 10° about x: the lowest edge is 3 sin 10° + 1 cos 10° mm below the centre.
        let up = nalgebra::Rotation3::from_euler_angles(0.17, 0.0, 0.0).inverse() * Vector3::z();
        let reach = 0.003 * 0.17f64.sin() + 0.001 * 0.17f64.cos();
        assert!((b.sunk(&up, reach - 2e-6) - 2e-6).abs() < 1e-12);
    }

    #[test]
    fn a_part_is_trapped_only_below_half_its_barrier() {
        let (v, t) = cuboid([0.005, 0.003, 0.001]);
        let b = FaceBasins::new(&v, &t, &Point3::origin());
        let barrier = (0.003f64.powi(2) + 0.001f64.powi(2)).sqrt() - 0.001;
        let up = Vector3::z();
        assert!(b.trapped(&up, 0.001, 0.45 * barrier).is_some());
        assert!(b.trapped(&up, 0.001, 0.55 * barrier).is_none());
        // Still, 1.5 mm above its rest height (more than half the 2.16 mm barrier), or 1 mm
        // (less: it falls flat and stays).
        assert!(b.trapped(&up, 0.0025, 0.0).is_none());
        assert!(b.trapped(&up, 0.002, 0.0).is_some());
        // Tilted 10° about x, resting on the same face's edge: the ray down still leaves by it.
        let tilted = nalgebra::Rotation3::from_euler_angles(0.17, 0.0, 0.0).inverse() * up;
        assert_eq!(b.trapped(&tilted, 0.0012, 0.0), Some(-Vector3::z()));
    }

    #[test]
    fn a_face_the_centre_of_mass_overhangs_traps_nothing() {
        // A prism of cross-section (0, 0), (10, 0), (12, 2) mm, 2 mm deep: its slanted face from
        // (10, 0) to (12, 2) mm lies beyond the centre of mass, so a part put on it rolls onto
        // its bottom.
        let xz = [(0.0, 0.0), (0.01, 0.0), (0.012, 0.002)];
        let v: Vec<Point3<f64>> = xz
            .iter()
            .flat_map(|&(x, z)| [Point3::new(x, -0.001, z), Point3::new(x, 0.001, z)])
            .collect();
        let t = [
            [0, 2, 3],
            [0, 3, 1],
            [2, 4, 5],
            [2, 5, 3],
            [0, 1, 5],
            [0, 5, 4],
            [0, 4, 2],
            [1, 3, 5],
        ];
        let com = Point3::new(0.022 / 3.0, 0.0, 0.002 / 3.0);
        let b = FaceBasins::new(&v, &t, &com);
        assert_eq!(b.faces.len(), 5);
        let slant = Vector3::new(1.0, 0.0, -1.0).normalize();
        let on_slant = b
            .faces
            .iter()
            .find(|f| (f.normal - slant).norm() < 1e-9)
            .unwrap();
        assert!(!on_slant.stable);
        // Still on the slanted face: the ray down leaves through the bottom, which it is far
        // above.
        let height = slant.dot(&(v[2] - com));
        assert!(b.trapped(&-slant, height, 0.0).is_none());
        // At rest on the bottom it is trapped there.
        assert_eq!(
            b.trapped(&Vector3::z(), 0.002 / 3.0, 0.0),
            Some(-Vector3::z())
        );
    }
}
