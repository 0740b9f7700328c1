//! Repairing meshes as CAD exports them: near-duplicate vertices, zero-area and duplicate
//! triangles, T-junctions, several touching bodies. Every repair keeps the surface where it is
//! (nothing moves by more than the weld tolerance) and is counted, so a user can be warned.

use std::collections::{HashMap, HashSet};

use nalgebra::Point3;

use super::TriMesh;
use super::mesh_bodies::{is_closed, pieces, sub_mesh};
use super::mesh_topology::{edge_uses, find, union};

/// Vertices closer than this fraction of the bounding-box diagonal are one vertex, and a triangle
/// whose third corner lies closer than it to its longest edge has zero area: 0.1 µm on a 10 mm
/// part, a few float32 steps of a millimetre export and 450 times below our finest fit (45 µm).
pub const WELD_TOLERANCE_REL: f64 = 1e-5;

/// Rounds of T-junction splitting; each round closes one vertex deep of a sliver chain.
const MAX_SPLIT_ROUNDS: usize = 16;

/// What [`TriMesh::repair`] changed or found, with counts for the user's warnings.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MeshRepairs {
    /// Weld tolerance used, metres (or the mesh's unit).
    pub tolerance: f64,
    /// Vertices merged into a neighbour within the tolerance.
    pub welded_vertices: usize,
    /// Triangles dropped because two corners became one vertex.
    pub collapsed_triangles: usize,
    /// Triangles dropped because their three distinct corners lie on one line (slivers).
    pub zero_area_triangles: usize,
    /// Extra copies of a triangle (same corners, same orientation) dropped.
    pub duplicate_triangles: usize,
    /// Triangles split at a vertex lying on one of their edges (T-junctions, and the far side of
    /// a dropped sliver), so the surface stays closed.
    pub split_triangles: usize,
    /// Vertices no triangle uses any more, dropped.
    pub unused_vertices: usize,
    /// Edges shared by more than two triangles (bodies touching along an edge or face): kept,
    /// since the solid is still closed when they are used equally often each way.
    pub non_manifold_edges: usize,
    /// Bodies: closed pieces as the file gives them (connected through its vertex indices),
    /// each repaired and checked on its own, and the pieces of what was repaired together.
    pub bodies: usize,
    /// Closed bodies kept exactly as the file gives them because repairing them would have
    /// opened them.
    pub kept_as_given: usize,
    /// Summed volume of the bodies, cubic metres.
    pub body_volume: f64,
    /// Volume the bodies' sum holds beyond their union (a volume inside k bodies counted k − 1
    /// times), cubic metres: left out of the mass, which is the union's
    /// ([`TriMesh::union_moments`]).
    pub overlap_volume: f64,
    /// Small planar holes capped while loading (see [`TriMesh::fill_small_holes`]).
    pub filled_holes: usize,
    /// Bounding-box diagonal of the largest capped hole, metres.
    pub largest_filled_hole: f64,
    /// The largest hole size capped, metres (the bound the loader used).
    pub hole_bound: f64,
}

impl MeshRepairs {
    /// Whether anything was changed (non-manifold edges and bodies are findings, not changes).
    pub fn changed(&self) -> bool {
        self.welded_vertices
            + self.collapsed_triangles
            + self.zero_area_triangles
            + self.duplicate_triangles
            + self.split_triangles
            + self.unused_vertices
            + self.filled_holes
            > 0
    }

    /// Adds another piece's repair counts to these.
    fn add(&mut self, o: &MeshRepairs) {
        self.welded_vertices += o.welded_vertices;
        self.collapsed_triangles += o.collapsed_triangles;
        self.zero_area_triangles += o.zero_area_triangles;
        self.duplicate_triangles += o.duplicate_triangles;
        self.split_triangles += o.split_triangles;
        self.unused_vertices += o.unused_vertices;
    }

    /// Share of the summed body volume that two bodies share (0 for one body).
    pub fn overlap_share(&self) -> f64 {
        if self.body_volume > 0.0 {
            self.overlap_volume / self.body_volume
        } else {
            0.0
        }
    }

    /// One line per repair, with its count; empty for a clean mesh.
    pub fn warnings(&self) -> Vec<String> {
        let tol_um = self.tolerance * 1e6;
        let mut out = Vec::new();
        let mut say = |n: usize, text: String| {
            if n > 0 {
                out.push(text);
            }
        };
        say(
            self.welded_vertices,
            format!(
                "welded {} vertices lying within {tol_um:.3} µm of another",
                self.welded_vertices
            ),
        );
        say(
            self.collapsed_triangles,
            format!(
                "dropped {} triangles collapsed onto an edge or point by the weld",
                self.collapsed_triangles
            ),
        );
        say(
            self.zero_area_triangles,
            format!(
                "dropped {} zero-area triangles (corners on one line within {tol_um:.3} µm)",
                self.zero_area_triangles
            ),
        );
        say(
            self.duplicate_triangles,
            format!("dropped {} duplicate triangles", self.duplicate_triangles),
        );
        say(
            self.split_triangles,
            format!(
                "split {} triangles at vertices lying on their edges (T-junctions)",
                self.split_triangles
            ),
        );
        say(
            self.unused_vertices,
            format!("dropped {} unused vertices", self.unused_vertices),
        );
        say(
            self.filled_holes,
            format!(
                "capped {} small planar holes (the largest {:.3} mm across; holes up to {:.3} mm \
                 are capped)",
                self.filled_holes,
                self.largest_filled_hole * 1e3,
                self.hole_bound * 1e3
            ),
        );
        out
    }

    /// What was accepted as it is but is worth knowing (edges shared by more than two
    /// triangles, several bodies); empty for a simple closed mesh.
    pub fn notes(&self) -> Vec<String> {
        let mut out = Vec::new();
        if self.non_manifold_edges > 0 {
            out.push(format!(
                "{} edges are shared by more than two triangles (touching bodies); the solid is \
                 closed, so they are kept",
                self.non_manifold_edges
            ));
        }
        if self.bodies > 1 {
            out.push(format!(
                "the file holds {} bodies, each closed, treated as one rigid part; mass and inertia \
                 are the union's",
                self.bodies,
            ));
        }
        if self.overlap_volume > 0.0 {
            out.push(format!(
                "the bodies overlap by {:.4} mm³, {:.2} % of their summed volume {:.3} mm³; the \
                 mass counts the overlap once",
                self.overlap_volume * 1e9,
                100.0 * self.overlap_share(),
                self.body_volume * 1e9
            ));
        }
        if self.kept_as_given > 0 {
            out.push(format!(
                "{} closed bodies were kept as the file gives them (repairing them would open them)",
                self.kept_as_given
            ));
        }
        out
    }
}

impl TriMesh {
    /// Repairs what CAD exports commonly contain, with the tolerance [`WELD_TOLERANCE_REL`] of
    /// the bounding-box diagonal; see [`TriMesh::repair_with`].
    pub fn repair(&mut self) -> MeshRepairs {
        let (lo, hi) = self.aabb();
        self.repair_with(WELD_TOLERANCE_REL * (hi - lo).norm())
    }

    /// Finds the bodies (pieces connected through the mesh's vertex indices); repairs each closed
    /// one alone and the open ones together: welds vertices within `tolerance`, drops collapsed,
    /// duplicate and zero-area triangles, splits triangles at T-junctions and drops unused
    /// vertices, in that order; counts non-manifold edges and bodies, and measures how much the
    /// bodies overlap (the excess of [`TriMesh::union_moments`]). A mesh that needs no repair is left exactly as it was; a repaired one is
    /// rebuilt body after body. A mesh with non-finite coordinates or out-of-range indices is left
    /// alone for [`TriMesh::check_closed`] to report.
    pub fn repair_with(&mut self, tolerance: f64) -> MeshRepairs {
        let mut r = MeshRepairs {
            tolerance,
            ..MeshRepairs::default()
        };
        let n = self.vertices.len();
        let valid = tolerance.is_finite()
            && tolerance > 0.0
            && self
                .vertices
                .iter()
                .all(|p| p.coords.iter().all(|c| c.is_finite()))
            && self.triangles.iter().flatten().all(|&i| (i as usize) < n);
        if !valid {
            return r;
        }
        let used = {
            let mut used = vec![false; n];
            for &i in self.triangles.iter().flatten() {
                used[i as usize] = true;
            }
            used.iter().filter(|&&u| u).count()
        };
        r.unused_vertices = n - used;
        // Bodies as the file gives them: pieces connected through its own vertex indices. A
        // closed piece is a body, repaired alone so nothing welds or splits it against a body it
        // touches, and kept as given when its own repair would open it. Open pieces (a body
        // stored face by face, or with stray vertex copies) are repaired together.
        let mut bodies = Vec::new();
        let mut open = Vec::new();
        for piece in pieces(self) {
            let body = sub_mesh(self, &piece);
            if !is_closed(&body.triangles) {
                open.extend(piece);
                continue;
            }
            let mut repaired = body.clone();
            let mut counts = MeshRepairs::default();
            repaired.repair_piece(tolerance, &mut counts);
            if is_closed(&repaired.triangles) {
                r.add(&counts);
                bodies.push(repaired);
            } else {
                r.kept_as_given += 1;
                bodies.push(body);
            }
        }
        if !open.is_empty() {
            open.sort_unstable();
            let mut pool = sub_mesh(self, &open);
            pool.repair_piece(tolerance, &mut r);
            bodies.extend(pieces(&pool).iter().map(|p| sub_mesh(&pool, p)));
        }
        if r.changed() {
            let mut joined = TriMesh {
                vertices: Vec::new(),
                triangles: Vec::new(),
            };
            for b in &bodies {
                joined.append(b);
            }
            *self = joined;
        }
        r.non_manifold_edges = edge_uses(&self.triangles)
            .values()
            .filter(|(f, b)| f + b > 2)
            .count();
        r.bodies = bodies.len();
        if bodies.len() > 1 {
            r.body_volume = bodies.iter().map(|b| b.volume().abs()).sum();
            r.overlap_volume = self.union_moments().excess.volume;
        }
        r
    }

    /// Welds vertices within `tolerance`, drops collapsed, duplicate and zero-area triangles,
    /// splits T-junctions and drops unused vertices, adding the counts to `r`.
    fn repair_piece(&mut self, tolerance: f64, r: &mut MeshRepairs) {
        r.welded_vertices += self.weld_within(tolerance);
        let before = self.triangles.len();
        self.triangles
            .retain(|t| t[0] != t[1] && t[1] != t[2] && t[2] != t[0]);
        r.collapsed_triangles += before - self.triangles.len();
        r.duplicate_triangles += self.drop_duplicates();
        let before = self.triangles.len();
        let vertices = &self.vertices;
        self.triangles
            .retain(|t| thickness(vertices, t) >= tolerance);
        r.zero_area_triangles += before - self.triangles.len();
        r.split_triangles += self.split_t_junctions(tolerance);
        r.unused_vertices += self.drop_unused_vertices();
    }

    /// Merges each vertex into the first earlier vertex within `tolerance` (a spatial hash on a
    /// grid of that size); returns how many were merged.
    fn weld_within(&mut self, tolerance: f64) -> usize {
        let cell = |p: &Point3<f64>| [p.x, p.y, p.z].map(|c| (c / tolerance).floor() as i64);
        let mut grid: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
        let mut kept: Vec<Point3<f64>> = Vec::with_capacity(self.vertices.len());
        let mut remap = Vec::with_capacity(self.vertices.len());
        for p in &self.vertices {
            let c = cell(p);
            let mut found = None;
            'search: for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        let key = [c[0] + dx, c[1] + dy, c[2] + dz];
                        for &k in grid.get(&key).map(Vec::as_slice).unwrap_or_default() {
                            if (kept[k as usize] - p).norm() < tolerance {
                                found = Some(k);
                                break 'search;
                            }
                        }
                    }
                }
            }
            let id = found.unwrap_or_else(|| {
                kept.push(*p);
                let id = (kept.len() - 1) as u32;
                grid.entry(c).or_default().push(id);
                id
            });
            remap.push(id);
        }
        let merged = self.vertices.len() - kept.len();
        for t in &mut self.triangles {
            *t = t.map(|i| remap[i as usize]);
        }
        self.vertices = kept;
        merged
    }

    /// Drops later copies of a triangle with the same corners in the same cyclic order.
    fn drop_duplicates(&mut self) -> usize {
        let mut seen = HashSet::new();
        let before = self.triangles.len();
        self.triangles.retain(|t| seen.insert(canonical(t)));
        before - self.triangles.len()
    }

    /// Splits triangles whose edge is open and passes through a vertex of another open edge
    /// (within `tolerance`): a T-junction, as left by a dropped sliver or a finer tessellation on
    /// the other side. Returns the number of triangles split.
    fn split_t_junctions(&mut self, tolerance: f64) -> usize {
        let mut split = 0;
        for _ in 0..MAX_SPLIT_ROUNDS {
            let uses = edge_uses(&self.triangles);
            let open: Vec<(u32, u32)> = uses
                .iter()
                .filter(|(_, (f, b))| f != b)
                .map(|(e, _)| *e)
                .collect();
            if open.is_empty() {
                break;
            }
            let mut candidates: Vec<u32> = open.iter().flat_map(|&(a, b)| [a, b]).collect();
            candidates.sort_unstable();
            candidates.dedup();
            let open: HashSet<(u32, u32)> = open.into_iter().collect();
            let mut out = Vec::with_capacity(self.triangles.len());
            let mut changed = false;
            for t in &self.triangles {
                let mut done = false;
                for k in 0..3 {
                    let (u, v, x) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
                    if done || !open.contains(&(u.min(v), u.max(v))) {
                        continue;
                    }
                    let on_edge = self.vertices_on_segment(&candidates, u, v, tolerance);
                    if on_edge.is_empty() {
                        continue;
                    }
                    let mut chain = vec![u];
                    chain.extend(on_edge);
                    chain.push(v);
                    out.extend(chain.windows(2).map(|w| [w[0], w[1], x]));
                    done = true;
                }
                if done {
                    split += 1;
                    changed = true;
                } else {
                    out.push(*t);
                }
            }
            self.triangles = out;
            if !changed {
                break;
            }
        }
        split
    }

    /// Vertices among `candidates` lying strictly inside segment u–v within `tolerance`, ordered
    /// from u to v.
    fn vertices_on_segment(&self, candidates: &[u32], u: u32, v: u32, tolerance: f64) -> Vec<u32> {
        let (a, b) = (self.vertices[u as usize], self.vertices[v as usize]);
        let d = b - a;
        let len2 = d.norm_squared();
        let mut on: Vec<(f64, u32)> = candidates
            .iter()
            .filter(|&&w| w != u && w != v)
            .filter_map(|&w| {
                let p = self.vertices[w as usize];
                let s = (p - a).dot(&d) / len2;
                let inside = s * len2.sqrt() > tolerance && (1.0 - s) * len2.sqrt() > tolerance;
                (inside && (a + d * s - p).norm() < tolerance).then_some((s, w))
            })
            .collect();
        on.sort_by(|x, y| x.0.total_cmp(&y.0));
        on.into_iter().map(|(_, w)| w).collect()
    }

    /// Drops vertices no triangle uses, keeping the others' order; returns how many.
    fn drop_unused_vertices(&mut self) -> usize {
        let mut used = vec![false; self.vertices.len()];
        for &i in self.triangles.iter().flatten() {
            used[i as usize] = true;
        }
        let mut remap = vec![0u32; self.vertices.len()];
        let mut kept = Vec::with_capacity(self.vertices.len());
        for (i, p) in self.vertices.iter().enumerate() {
            if used[i] {
                remap[i] = kept.len() as u32;
                kept.push(*p);
            }
        }
        let dropped = self.vertices.len() - kept.len();
        if dropped > 0 {
            for t in &mut self.triangles {
                *t = t.map(|i| remap[i as usize]);
            }
            self.vertices = kept;
        }
        dropped
    }

    /// Number of connected pieces (triangles sharing a vertex are connected).
    pub fn bodies(&self) -> usize {
        let mut parent: Vec<u32> = (0..self.vertices.len() as u32).collect();
        for t in &self.triangles {
            union(&mut parent, t[0], t[1]);
            union(&mut parent, t[1], t[2]);
        }
        let roots: HashSet<u32> = self
            .triangles
            .iter()
            .map(|t| find(&mut parent, t[0]))
            .collect();
        roots.len()
    }
}

/// The triangle rotated so its smallest index comes first (same orientation).
fn canonical(t: &[u32; 3]) -> [u32; 3] {
    let k = (0..3).min_by_key(|&k| t[k]).unwrap_or(0);
    [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
}

/// Distance of a triangle's corner from the line through its longest edge: zero for a sliver.
fn thickness(vertices: &[Point3<f64>], t: &[u32; 3]) -> f64 {
    let [a, b, c] = t.map(|i| vertices[i as usize]);
    let twice_area = (b - a).cross(&(c - a)).norm();
    let longest = (b - a).norm().max((c - b).norm()).max((a - c).norm());
    if longest > 0.0 {
        twice_area / longest
    } else {
        0.0
    }
}
