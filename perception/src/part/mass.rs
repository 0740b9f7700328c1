//! Mass properties of a part from the union of its bodies.
//!
//! A part exported as several closed bodies (a mold and the pins pushed into it) is one rigid
//! solid: the volume two bodies share is metal once. Its mass properties are computed as the
//! exact surface integrals of every body (the divergence theorem over the triangles, which
//! counts a point inside k bodies k times) minus the excess: the volume integrals of
//! (bodies containing the point − 1) wherever that is positive. The excess is integrated only in
//! the boxes where two bodies' bounding boxes overlap, by casting rays along the box's longest
//! axis on a grid of [`UNION_RAYS`] across its larger side: along each ray the winding number is
//! exact, so the integral is exact along the ray and a midpoint sum across it. Bodies that only
//! touch (or do not meet) give no excess, and the result is then exactly the bodies' sum.

use std::ops::{Add, Sub};

use nalgebra::{Matrix3, Point3, Vector3};

use super::TriMesh;
use super::mesh_bodies::pieces;
use super::mesh_topology::edge_uses;

/// Rays across the larger side of each box where bodies overlap; the other side gets as many
/// per unit length. On a pin pushed into a block this measures the union's volume to about
/// 1e-6 of it (see the tests).
pub const UNION_RAYS: usize = 256;

/// An excess below this share of the bodies' summed volume is rounding, not overlap (faces
/// two bodies share, crossed at x values computed from different triangles), and is dropped: a
/// single 48-gon peg measured 2e-16 of its volume.
pub const UNION_NOISE_REL: f64 = 1e-9;

/// Triangle bins per side over a box's cross-section, so each ray tests only its bin's triangles.
const BINS: usize = 32;

/// Volume integrals of a solid in metres: ∫ 1, ∫ x and ∫ x xᵀ over its volume.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VolumeMoments {
    /// Volume, m³.
    pub volume: f64,
    /// First moment ∫ x dV, m⁴.
    pub first: Vector3<f64>,
    /// Second moment ∫ x xᵀ dV about the origin, m⁵.
    pub second: Matrix3<f64>,
}

impl VolumeMoments {
    /// Nothing: no volume.
    pub const ZERO: Self = Self {
        volume: 0.0,
        first: Vector3::new(0.0, 0.0, 0.0),
        second: Matrix3::new(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    };

    /// The moments enclosed by a mesh's triangles (outward, counter-clockwise), exactly: each
    /// triangle's tetrahedron with the origin, signed. A point inside k closed bodies counts k
    /// times.
    pub fn of_surface(mesh: &TriMesh) -> Self {
        let mut m = Self::ZERO;
        for t in &mesh.triangles {
            let [a, b, c] = t.map(|i| mesh.vertices[i as usize].coords);
            let v = a.dot(&b.cross(&c)) / 6.0;
            let s = a + b + c;
            m.volume += v;
            m.first += s * (v / 4.0);
            // ∫ x xᵀ over the tetrahedron (0, a, b, c) = V/20 (Σ vᵢ vᵢᵀ + s sᵀ).
            m.second +=
                (a * a.transpose() + b * b.transpose() + c * c.transpose() + s * s.transpose())
                    * (v / 20.0);
        }
        m
    }

    /// The centroid (the origin for no volume).
    pub fn centroid(&self) -> Point3<f64> {
        if self.volume != 0.0 {
            Point3::from(self.first / self.volume)
        } else {
            Point3::origin()
        }
    }

    /// Mass at `density` kg/m³.
    pub fn mass(&self, density: f64) -> f64 {
        self.volume * density
    }

    /// Inertia tensor about the centroid at `density`, kg·m².
    pub fn inertia(&self, density: f64) -> Matrix3<f64> {
        let c = self.centroid().coords;
        let central = self.second - c * c.transpose() * self.volume;
        (Matrix3::identity() * central.trace() - central) * density
    }
}

impl Add for VolumeMoments {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        Self {
            volume: self.volume + o.volume,
            first: self.first + o.first,
            second: self.second + o.second,
        }
    }
}

impl Sub for VolumeMoments {
    type Output = Self;
    fn sub(self, o: Self) -> Self {
        Self {
            volume: self.volume - o.volume,
            first: self.first - o.first,
            second: self.second - o.second,
        }
    }
}

/// A part's volume integrals over the union of its bodies, and what the union leaves out of the
/// bodies' sum.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UnionMoments {
    /// Over the union: a point inside several bodies counts once.
    pub union: VolumeMoments,
    /// The excess of the bodies' sum over the union: a point inside k bodies counts k − 1 times.
    /// Zero volume when no two bodies overlap.
    pub excess: VolumeMoments,
}

impl TriMesh {
    /// Volume integrals over the union of the mesh's closed bodies (see the module): exact when
    /// no two bodies overlap (an excess below [`UNION_NOISE_REL`] of the volume is dropped as
    /// rounding), otherwise within about 1e-6 of the union's volume.
    pub fn union_moments(&self) -> UnionMoments {
        let sum = VolumeMoments::of_surface(self);
        let mut excess = overlap_boxes(self)
            .iter()
            .map(|b| excess_in_box(self, b))
            .fold(VolumeMoments::ZERO, Add::add);
        if excess.volume <= UNION_NOISE_REL * sum.volume.abs() {
            excess = VolumeMoments::ZERO;
        }
        UnionMoments {
            union: sum - excess,
            excess,
        }
    }
}

/// An axis-aligned box as (lower, upper) corners.
type Aabb = (Point3<f64>, Point3<f64>);

/// Whether two boxes share a volume (not only a face).
fn overlaps(a: &Aabb, b: &Aabb) -> bool {
    (0..3).all(|k| a.0[k].max(b.0[k]) < a.1[k].min(b.1[k]))
}

/// Boxes, pairwise disjoint, that hold every point inside more than one body: where two pieces'
/// bounding boxes overlap, and the whole box of a piece with an edge used more than twice (bodies
/// sharing vertices, which may overlap within the piece), merged until none overlap.
fn overlap_boxes(mesh: &TriMesh) -> Vec<Aabb> {
    let pieces = pieces(mesh);
    if pieces.is_empty() {
        return Vec::new();
    }
    let mut piece_of_vertex = vec![usize::MAX; mesh.vertices.len()];
    let mut boxes: Vec<Aabb> = Vec::with_capacity(pieces.len());
    for (k, piece) in pieces.iter().enumerate() {
        let mut lo = Point3::from(Vector3::repeat(f64::INFINITY));
        let mut hi = Point3::from(Vector3::repeat(f64::NEG_INFINITY));
        for &t in piece {
            for &i in &mesh.triangles[t] {
                let p = mesh.vertices[i as usize];
                lo = lo.inf(&p);
                hi = hi.sup(&p);
                piece_of_vertex[i as usize] = k;
            }
        }
        boxes.push((lo, hi));
    }
    let mut regions: Vec<Aabb> = Vec::new();
    let mut shared_edges = vec![false; pieces.len()];
    for ((a, _), (f, b)) in edge_uses(&mesh.triangles) {
        if f + b > 2 {
            shared_edges[piece_of_vertex[a as usize]] = true;
        }
    }
    for (k, &shared) in shared_edges.iter().enumerate() {
        if shared {
            regions.push(boxes[k]);
        }
    }
    for i in 0..boxes.len() {
        for j in i + 1..boxes.len() {
            if overlaps(&boxes[i], &boxes[j]) {
                regions.push((boxes[i].0.sup(&boxes[j].0), boxes[i].1.inf(&boxes[j].1)));
            }
        }
    }
    // Merge overlapping regions into their common box until none overlap.
    let mut merged = true;
    while merged {
        merged = false;
        'outer: for i in 0..regions.len() {
            for j in i + 1..regions.len() {
                if overlaps(&regions[i], &regions[j]) {
                    let b = regions.swap_remove(j);
                    regions[i] = (regions[i].0.inf(&b.0), regions[i].1.sup(&b.1));
                    merged = true;
                    break 'outer;
                }
            }
        }
    }
    regions
}

/// A triangle projected for ray casting along axis `a`: its corners' (u, v), counter-clockwise,
/// the plane to find the crossing, and the winding step of a ray along +a through it.
struct Projected {
    corners: [[f64; 2]; 3],
    origin: Vector3<f64>,
    normal: Vector3<f64>,
    step: i32,
}

/// Signed area test of `p` against edge `p0 → p1`, computed the same way whichever way round the
/// edge is given (so two triangles sharing the edge agree exactly).
fn edge_function(p0: [f64; 2], p1: [f64; 2], p: [f64; 2]) -> f64 {
    let (a, b, sign) = if (p0[0], p0[1]) <= (p1[0], p1[1]) {
        (p0, p1, 1.0)
    } else {
        (p1, p0, -1.0)
    };
    sign * ((b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]))
}

/// Whether an edge of a counter-clockwise triangle owns the points exactly on it (the top-left
/// rule: of two triangles sharing the edge, which run it opposite ways, exactly one does).
fn owns_edge(p0: [f64; 2], p1: [f64; 2]) -> bool {
    let (du, dv) = (p1[0] - p0[0], p1[1] - p0[1]);
    dv < 0.0 || (dv == 0.0 && du < 0.0)
}

impl Projected {
    /// Whether the ray at (u, v) passes through the triangle.
    /// Whether the ray at (u, v) passes through the triangle, and whether it grazes one of its
    /// edges or corners (then it may run along a face two bodies share, see [`excess_in_box`]).
    fn contains(&self, p: [f64; 2]) -> (bool, bool) {
        let mut grazes = false;
        let inside = (0..3).all(|k| {
            let (p0, p1) = (self.corners[k], self.corners[(k + 1) % 3]);
            let e = edge_function(p0, p1, p);
            grazes |= e == 0.0;
            e > 0.0 || (e == 0.0 && owns_edge(p0, p1))
        });
        (inside, grazes && inside)
    }
}

/// The excess's moments inside box `region`: rays along its longest axis.
fn excess_in_box(mesh: &TriMesh, region: &Aabb) -> VolumeMoments {
    let (lo, hi) = *region;
    let d = hi - lo;
    let a = d.imax();
    // (a, u, v) a cyclic order of the axes, so the u–v area's sign is the normal's a component.
    let (u, v) = ((a + 1) % 3, (a + 2) % 3);
    let h = d[u].max(d[v]) / UNION_RAYS as f64;
    let n = [u, v].map(|k| ((d[k] / h).round() as usize).clamp(1, UNION_RAYS));
    let cell = [d[u] / n[0] as f64, d[v] / n[1] as f64];
    // Triangles a ray through the region's cross-section crosses before its far end, projected
    // and binned by their u–v bounding box.
    let bins = [n[0].min(BINS), n[1].min(BINS)];
    let bin_of = |k: usize, x: f64| {
        let i = ((x - lo[[u, v][k]]) / d[[u, v][k]] * bins[k] as f64).floor();
        i.clamp(0.0, (bins[k] - 1) as f64) as usize
    };
    let mut triangles: Vec<Projected> = Vec::new();
    let mut binned: Vec<Vec<u32>> = vec![Vec::new(); bins[0] * bins[1]];
    for t in &mesh.triangles {
        let p = t.map(|i| mesh.vertices[i as usize]);
        let min = p[0].inf(&p[1]).inf(&p[2]);
        let max = p[0].sup(&p[1]).sup(&p[2]);
        if max[u] < lo[u] || min[u] > hi[u] || max[v] < lo[v] || min[v] > hi[v] || min[a] > hi[a] {
            continue;
        }
        let normal = (p[1] - p[0]).cross(&(p[2] - p[0]));
        if normal[a] == 0.0 {
            continue;
        }
        let mut corners = p.map(|q| [q[u], q[v]]);
        if normal[a] < 0.0 {
            corners.swap(1, 2);
        }
        let id = triangles.len() as u32;
        triangles.push(Projected {
            corners,
            origin: p[0].coords,
            normal,
            // Outward normals: a ray along +a enters where the normal points against it.
            step: if normal[a] < 0.0 { 1 } else { -1 },
        });
        for i in bin_of(0, min[u])..=bin_of(0, max[u]) {
            for j in bin_of(1, min[v])..=bin_of(1, max[v]) {
                binned[i * bins[1] + j].push(id);
            }
        }
    }
    let area = cell[0] * cell[1];
    let mut m = VolumeMoments::ZERO;
    let mut events: Vec<(f64, i32)> = Vec::new();
    for i in 0..n[0] {
        let pu = lo[u] + (i as f64 + 0.5) * cell[0];
        for j in 0..n[1] {
            let pv = lo[v] + (j as f64 + 0.5) * cell[1];
            // A ray through an edge of the mesh may run along a face two touching bodies share
            // and count as inside both: such a ray is cast again a hair to the side (a millionth
            // of a cell, weighed still at the cell's centre).
            for attempt in 0..4 {
                let nudge = attempt as f64 * 1e-6;
                let p = [pu + nudge * 0.618 * cell[0], pv + nudge * 0.755 * cell[1]];
                events.clear();
                let mut grazed = false;
                for &t in &binned[bin_of(0, p[0]) * bins[1] + bin_of(1, p[1])] {
                    let t = &triangles[t as usize];
                    let (inside, grazes) = t.contains(p);
                    if !inside {
                        continue;
                    }
                    grazed |= grazes;
                    let x = t.origin[a]
                        - (t.normal[u] * (p[0] - t.origin[u]) + t.normal[v] * (p[1] - t.origin[v]))
                            / t.normal[a];
                    events.push((x, t.step));
                }
                if !grazed {
                    break;
                }
            }
            if events.is_empty() {
                continue;
            }
            events.sort_by(|p, q| p.0.total_cmp(&q.0));
            // ∫ e, ∫ e x, ∫ e x² along the ray, e = bodies containing the point − 1 where positive,
            // inside the region.
            let (mut l0, mut l1, mut l2) = (0.0, 0.0, 0.0);
            let mut winding = 0;
            for w in 0..events.len() {
                winding += events[w].1;
                let Some(next) = events.get(w + 1) else {
                    break;
                };
                let excess = f64::from(winding - 1);
                if excess <= 0.0 {
                    continue;
                }
                let (x0, x1) = (events[w].0.max(lo[a]), next.0.min(hi[a]));
                if x1 <= x0 {
                    continue;
                }
                l0 += excess * (x1 - x0);
                l1 += excess * (x1 * x1 - x0 * x0) / 2.0;
                l2 += excess * (x1.powi(3) - x0.powi(3)) / 3.0;
            }
            if l0 == 0.0 {
                continue;
            }
            let (l0, l1, l2) = (l0 * area, l1 * area, l2 * area);
            m.volume += l0;
            m.first[a] += l1;
            m.first[u] += pu * l0;
            m.first[v] += pv * l0;
            m.second[(a, a)] += l2;
            // Each cell's own spread across the ray (h²/12) on top of its sample's square.
            m.second[(u, u)] += (pu * pu + cell[0] * cell[0] / 12.0) * l0;
            m.second[(v, v)] += (pv * pv + cell[1] * cell[1] / 12.0) * l0;
            m.second[(u, v)] += pu * pv * l0;
            m.second[(a, u)] += pu * l1;
            m.second[(a, v)] += pv * l1;
        }
    }
    m.second[(v, u)] = m.second[(u, v)];
    m.second[(u, a)] = m.second[(a, u)];
    m.second[(v, a)] = m.second[(a, v)];
    m
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Isometry3, Translation3, UnitQuaternion};

    /// A box of full size `size` centred at `centre`.
    fn cuboid(size: [f64; 3], centre: [f64; 3]) -> TriMesh {
        TriMesh::cuboid(Vector3::from(size)).transformed(&Isometry3::from_parts(
            Translation3::from(Vector3::from(centre)),
            UnitQuaternion::identity(),
        ))
    }

    /// Analytic volume moments of an axis-aligned box.
    fn box_moments(size: [f64; 3], centre: [f64; 3]) -> VolumeMoments {
        let s = Vector3::from(size);
        let c = Vector3::from(centre);
        let volume = s.x * s.y * s.z;
        let own = Matrix3::from_diagonal(&s.component_mul(&s).map(|x| x / 12.0)) * volume;
        VolumeMoments {
            volume,
            first: c * volume,
            second: own + c * c.transpose() * volume,
        }
    }

    fn joined(bodies: &[TriMesh]) -> TriMesh {
        let mut out = TriMesh {
            vertices: Vec::new(),
            triangles: Vec::new(),
        };
        for b in bodies {
            out.append(b);
        }
        out
    }

    #[test]
    fn surface_moments_of_a_box_are_the_analytic_ones() {
        let (size, centre) = ([0.02, 0.01, 0.004], [0.003, -0.002, 0.001]);
        let m = VolumeMoments::of_surface(&cuboid(size, centre));
        let want = box_moments(size, centre);
        assert!((m.volume - want.volume).abs() < 1e-12 * want.volume);
        assert!((m.first - want.first).norm() < 1e-12 * want.first.norm());
        assert!((m.second - want.second).norm() < 1e-12 * want.second.norm());
    }

    #[test]
    fn bodies_that_only_touch_are_summed_exactly() {
        let mesh = joined(&[
            cuboid([0.01, 0.01, 0.01], [0.0, 0.0, 0.0]),
            cuboid([0.01, 0.01, 0.01], [0.01, 0.0, 0.0]),
        ]);
        let m = mesh.union_moments();
        assert_eq!(m.excess.volume, 0.0);
        assert_eq!(m.union, VolumeMoments::of_surface(&mesh));
    }

    #[test]
    fn a_body_inside_two_others_counts_once() {
        // Three copies of one box, each shifted along x by 2 mm: a middle stretch lies in all
        // three.
        let bodies: Vec<TriMesh> = (0..3)
            .map(|k| cuboid([0.01, 0.004, 0.003], [0.002 * k as f64, 0.0, 0.0]))
            .collect();
        let m = joined(&bodies).union_moments();
        let want = box_moments([0.014, 0.004, 0.003], [0.002, 0.0, 0.0]);
        assert!(
            (m.union.volume - want.volume).abs() < 1e-9 * want.volume,
            "{} mm³",
            m.union.volume * 1e9
        );
        assert!((m.union.centroid() - want.centroid()).norm() < 1e-9);
        let (i, j) = (m.union.inertia(1.0), want.inertia(1.0));
        assert!((i - j).norm() < 1e-6 * j.norm(), "{i} {j}");
    }

    #[test]
    fn a_duplicated_body_counts_once() {
        let block = cuboid([0.01, 0.006, 0.004], [0.001, 0.002, 0.003]);
        let m = joined(&[block.clone(), block.clone()]).union_moments();
        let want = VolumeMoments::of_surface(&block);
        assert!((m.union.volume - want.volume).abs() < 1e-9 * want.volume);
        assert!((m.union.centroid() - want.centroid()).norm() < 1e-9);
    }
    /// A regular `sides`-gon prism of circumradius `r` along z from `z0` to `z1`, on the z axis.
    fn prism(sides: usize, r: f64, z0: f64, z1: f64) -> TriMesh {
        let mut vertices = Vec::new();
        for z in [z0, z1] {
            for i in 0..sides {
                let t = std::f64::consts::TAU * i as f64 / sides as f64;
                vertices.push(Point3::new(r * t.cos(), r * t.sin(), z));
            }
        }
        let n = sides as u32;
        let mut triangles = Vec::new();
        for i in 0..n {
            let j = (i + 1) % n;
            triangles.push([i, j, n + j]);
            triangles.push([i, n + j, n + i]);
            if i > 0 && j > 0 {
                triangles.push([n, n + i, n + j]);
                triangles.push([0, j, i]);
            }
        }
        TriMesh::new(vertices, triangles)
    }

    /// Analytic moments of that prism: area n/2 r² sin θ, polar moment n r⁴ sin θ (2 + cos θ)/12
    /// (θ = 2π/n), half of it about each of x and y.
    fn prism_moments(sides: usize, r: f64, z0: f64, z1: f64) -> VolumeMoments {
        let n = sides as f64;
        let theta = std::f64::consts::TAU / n;
        let area = n / 2.0 * r * r * theta.sin();
        let polar = n * r.powi(4) * theta.sin() * (2.0 + theta.cos()) / 12.0;
        let length = z1 - z0;
        let zc = (z0 + z1) / 2.0;
        let volume = area * length;
        VolumeMoments {
            volume,
            first: Vector3::new(0.0, 0.0, zc * volume),
            second: Matrix3::from_diagonal(&Vector3::new(
                polar / 2.0 * length,
                polar / 2.0 * length,
                volume * (length * length / 12.0 + zc * zc),
            )),
        }
    }

    /// A 20 × 20 × 10 mm block (z from −5 to 5 mm) and a pin of 12 mm pushed 6 mm into its
    /// top: the union is the block and the 6 mm of pin above it.
    #[test]
    fn a_square_pin_pushed_into_a_block_gives_the_unions_moments() {
        let block = cuboid([0.02, 0.02, 0.01], [0.0, 0.0, 0.0]);
        let pin = cuboid([0.004, 0.004, 0.012], [0.003, -0.002, 0.005]);
        let m = joined(&[block, pin]).union_moments();
        let want = box_moments([0.02, 0.02, 0.01], [0.0, 0.0, 0.0])
            + box_moments([0.004, 0.004, 0.006], [0.003, -0.002, 0.008]);
        let overlap = box_moments([0.004, 0.004, 0.006], [0.003, -0.002, 0.002]);
        assert!((m.excess.volume - overlap.volume).abs() < 1e-9 * overlap.volume);
        assert!((m.union.volume - want.volume).abs() < 1e-9 * want.volume);
        assert!((m.union.centroid() - want.centroid()).norm() < 1e-9);
        let (i, j) = (m.union.inertia(7800.0), want.inertia(7800.0));
        assert!((i - j).norm() < 1e-6 * j.norm(), "{i} {j}");
    }

    /// The same with a round (48-gon) pin of 3 mm diameter and the whole part turned and moved
    /// off the axes, against the analytic union turned the same way: volume within 1e-6,
    /// centre of mass within 10 nm, inertia within 1e-6 of its norm.
    #[test]
    fn a_round_pin_in_a_turned_block_gives_the_unions_moments() {
        let block = cuboid([0.02, 0.02, 0.01], [0.0, 0.0, 0.0]);
        let pin = prism(48, 0.0015, -0.001, 0.011);
        let pose = Isometry3::from_parts(
            Translation3::new(0.004, -0.011, 0.023),
            UnitQuaternion::from_scaled_axis(Vector3::new(0.3, -0.7, 1.1)),
        );
        let part = joined(&[block.transformed(&pose), pin.transformed(&pose)]);
        let m = part.union_moments();
        let want = box_moments([0.02, 0.02, 0.01], [0.0, 0.0, 0.0])
            + prism_moments(48, 0.0015, 0.005, 0.011);
        let overlap = prism_moments(48, 0.0015, -0.001, 0.005);
        let density = 7800.0;
        let r = pose.rotation.to_rotation_matrix().into_inner();
        let want_com = pose * want.centroid();
        let want_inertia = r * want.inertia(density) * r.transpose();
        let volume_error = (m.union.volume - want.volume).abs() / want.volume;
        let overlap_error = (m.excess.volume - overlap.volume).abs() / overlap.volume;
        let com_error = (m.union.centroid() - want_com).norm();
        let inertia_error = (m.union.inertia(density) - want_inertia).norm() / want_inertia.norm();
        println!(
            "volume {volume_error:.2e}, overlap {overlap_error:.2e}, centre of mass              {com_error:.2e} m, inertia {inertia_error:.2e}"
        );
        assert!(volume_error < 1e-6, "volume off by {volume_error:.2e}");
        assert!(com_error < 1e-8, "centre of mass off by {com_error:.2e} m");
        assert!(inertia_error < 1e-6, "inertia off by {inertia_error:.2e}");
    }
}
