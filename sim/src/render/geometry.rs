//! The scene the renderer sees: part instances (triangle meshes with a parry BVH each), the tag
//! board, the table plane and the lights, with the ray queries the renderer needs.

use std::sync::Arc;

use nalgebra::{Isometry3, Point3, Vector3};
use parry3d_f64::math::Vector as DVec3;
use parry3d_f64::partitioning::BvhNode;
use parry3d_f64::query::{Ray, RayCast};
use parry3d_f64::shape::TriMesh as ParryMesh;

use super::aabb::box_corners;
use super::instance_grid::{InstanceGrid, slab_range};
use super::light::PointLight;
use super::shadow_grid::ShadowGrid;
use super::{Appearance, Environment, TableTexture, TagBoard};

/// A part mesh ready for ray casting, in the part frame (metres), shared by its instances.
#[derive(Clone)]
pub struct RenderMesh {
    mesh: ParryMesh,
    lo: Point3<f64>,
    hi: Point3<f64>,
    /// Per triangle: whether it shows the instance's accent material (e.g. gold pins).
    accent: Vec<bool>,
}

impl std::fmt::Debug for RenderMesh {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RenderMesh")
            .field("triangles", &self.mesh.indices().len())
            .finish()
    }
}

impl RenderMesh {
    /// Builds the BVH of a part mesh; `None` for a mesh without triangles.
    pub fn new(mesh: &perception::part::TriMesh) -> Option<Self> {
        if mesh.triangles.is_empty() {
            return None;
        }
        let parry = mesh.to_parry()?;
        let (lo, hi) = mesh.aabb();
        Some(Self {
            mesh: parry,
            lo,
            hi,
            accent: Vec::new(),
        })
    }

    /// Marks the triangles (by index) that show the instance's accent material.
    pub fn with_accent(mut self, accent: Vec<bool>) -> Self {
        self.accent = accent;
        self
    }

    /// Number of triangles with the accent material.
    pub fn accent_triangles(&self) -> usize {
        self.accent.iter().filter(|a| **a).count()
    }

    /// Corners of the part-frame bounding box.
    pub fn aabb(&self) -> (Point3<f64>, Point3<f64>) {
        (self.lo, self.hi)
    }

    /// First hit of a part-frame ray: distance, part-frame unit normal, accent material.
    fn cast(
        &self,
        o: &Point3<f64>,
        d: &Vector3<f64>,
        max_t: f64,
    ) -> Option<(f64, Vector3<f64>, bool)> {
        let ray = BoxRay::new(o, d);
        let (triangle, hit) = self.mesh.bvh().find_best(
            max_t,
            |node, best| ray.entry(node, best),
            |triangle, best| {
                self.mesh
                    .triangle(triangle)
                    .cast_local_ray_and_get_normal(&ray.ray, best, false)
            },
        )?;
        let n = self.mesh.triangle(triangle).normal().unwrap_or(hit.normal);
        let accent = self.accent.get(triangle as usize).copied().unwrap_or(false);
        Some((hit.time_of_impact, Vector3::new(n.x, n.y, n.z), accent))
    }

    /// Whether a part-frame ray hits the mesh before `max_t`.
    fn hits(&self, o: &Point3<f64>, d: &Vector3<f64>, max_t: f64) -> bool {
        let ray = BoxRay::new(o, d);
        self.mesh
            .bvh()
            .leaves(|node| ray.entry(node, max_t) < f64::MAX)
            .any(|triangle| {
                self.mesh
                    .triangle(triangle)
                    .intersects_local_ray(&ray.ray, max_t)
            })
    }
}

/// A ray with its direction's reciprocals, for the many box tests of a BVH traversal: parry's own
/// box test (the same arithmetic, so the same hits and order), without its three divisions per box.
struct BoxRay {
    ray: Ray,
    inv: [f64; 3],
}

impl BoxRay {
    fn new(o: &Point3<f64>, d: &Vector3<f64>) -> Self {
        Self {
            ray: Ray::new(DVec3::new(o.x, o.y, o.z), DVec3::new(d.x, d.y, d.z)),
            inv: [1.0 / d.x, 1.0 / d.y, 1.0 / d.z],
        }
    }

    /// Where the ray enters a BVH node's box before `max_t` (0 when it starts inside), or
    /// `f64::MAX` when it does not.
    fn entry(&self, node: &BvhNode, max_t: f64) -> f64 {
        let (lo, hi) = (node.mins(), node.maxs());
        let (o, d) = (self.ray.origin, self.ray.dir);
        let mut tmin: f64 = 0.0;
        let mut tmax = max_t;
        for (i, inv) in self.inv.iter().enumerate() {
            if d[i] == 0.0 {
                if o[i] < lo[i] || o[i] > hi[i] {
                    return f64::MAX;
                }
            } else {
                let mut near = (lo[i] - o[i]) * inv;
                let mut far = (hi[i] - o[i]) * inv;
                if near > far {
                    std::mem::swap(&mut near, &mut far);
                }
                tmin = tmin.max(near);
                tmax = tmax.min(far);
                if tmin > tmax {
                    return f64::MAX;
                }
            }
        }
        tmin
    }
}

/// One part placed in the scene.
#[derive(Debug, Clone)]
pub struct Instance {
    /// The part's mesh.
    pub mesh: Arc<RenderMesh>,
    /// Pose of the part in the table (world) frame.
    #[allow(non_snake_case)]
    pub table_T_part: Isometry3<f64>,
    /// How its surface looks.
    pub appearance: Appearance,
    /// How the mesh's accent triangles look (gold pins on the insert); `None` for the main one.
    pub accent: Option<Appearance>,
}

impl Instance {
    /// A part of one material at a pose.
    #[allow(non_snake_case)]
    pub fn new(
        mesh: Arc<RenderMesh>,
        table_T_part: Isometry3<f64>,
        appearance: Appearance,
    ) -> Self {
        Self {
            mesh,
            table_T_part,
            appearance,
            accent: None,
        }
    }
}

/// The table under the board: an infinite plane at z = `height` in the table frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Table {
    /// Height of the table surface in the table frame, metres (minus the board thickness).
    pub height: f64,
    /// How the table looks.
    pub appearance: Appearance,
}

/// What a ray hit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SurfaceKind {
    /// Part instance number `i` (index into `RenderScene::instances`).
    Part(usize),
    /// The tag board.
    Board,
    /// The table.
    Table,
}

/// A ray hit: distance along the (unit) ray, unit normal facing the ray, what was hit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Distance along the ray, metres.
    pub t: f64,
    /// Unit surface normal in the table frame, facing against the ray.
    pub normal: Vector3<f64>,
    /// The surface.
    pub kind: SurfaceKind,
    /// Whether a part's accent triangle was hit (its instance's accent material).
    pub accent: bool,
}

/// Everything the renderer draws, in the table frame (z up; an unposed board's top at z = 0).
#[derive(Debug, Clone)]
pub struct RenderScene {
    /// The parts.
    pub instances: Vec<Instance>,
    /// The tag board, if any (on the table, or at its [`TagBoard::pose`]).
    pub board: Option<TagBoard>,
    /// The table plane, if any.
    pub table: Option<Table>,
    /// Point lights (shadows are cast from each).
    pub lights: Vec<PointLight>,
    /// Uniform ambient (sky) radiance per channel (unused where [`RenderScene::environment`]
    /// is set).
    pub ambient: [f64; 3],
    /// The room around the cell as prefiltered image-based lighting, replacing the uniform
    /// ambient when set (none by default).
    pub environment: Option<Arc<Environment>>,
    /// Radiance the board's top face emits per channel when the feeder plate is backlit (its
    /// print passes the share its albedo has of the white's); none by default.
    pub backlight: Option<[f64; 3]>,
    /// A procedural texture modulating the table's albedo (none by default: a uniform table).
    pub table_texture: Option<TableTexture>,
    bounds: Vec<(Point3<f64>, Point3<f64>)>,
    /// `part_T_table` of each instance, inverted once instead of per ray.
    inverses: Vec<Isometry3<f64>>,
    /// The instances binned over the table (up to 64 instances; beyond, every one is tested).
    grid: Option<InstanceGrid>,
}

impl RenderScene {
    /// A scene from its parts, board, table and lights.
    pub fn new(
        instances: Vec<Instance>,
        board: Option<TagBoard>,
        table: Option<Table>,
        lights: Vec<PointLight>,
        ambient: [f64; 3],
    ) -> Self {
        let bounds: Vec<_> = instances.iter().map(world_aabb).collect();
        let grid = InstanceGrid::new(&bounds);
        let inverses = instances.iter().map(|i| i.table_T_part.inverse()).collect();
        Self {
            instances,
            board,
            table,
            lights,
            ambient,
            environment: None,
            backlight: None,
            table_texture: None,
            bounds,
            inverses,
            grid,
        }
    }

    /// Table-frame bounding box of instance `i`.
    pub fn instance_bounds(&self, i: usize) -> (Point3<f64>, Point3<f64>) {
        self.bounds[i]
    }

    /// The instances a ray may hit before `max_t`, in ascending order.
    fn candidates(
        &self,
        o: &Point3<f64>,
        d: &Vector3<f64>,
        max_t: f64,
    ) -> impl Iterator<Item = usize> + use<> {
        let (mask, all) = match &self.grid {
            Some(g) => (g.candidates(o, d, max_t), 0),
            None => (0, self.instances.len()),
        };
        (0..all).chain(Bits(mask))
    }

    /// Nearest hit of a unit ray from `o` along `d` before `max_t`.
    pub fn intersect(&self, o: &Point3<f64>, d: &Vector3<f64>, max_t: f64) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let mut limit = max_t;
        for i in self.candidates(o, d, max_t) {
            if let Some(hit) = self.intersect_instance(i, o, d, limit) {
                limit = hit.t;
                best = Some(hit);
            }
        }
        if let Some(board) = &self.board
            && let Some((t, n)) = board_hit(board, o, d, limit)
        {
            limit = t;
            best = Some(Hit {
                t,
                normal: n,
                kind: SurfaceKind::Board,
                accent: false,
            });
        }
        if let Some(table) = &self.table
            && d.z.abs() > 1e-12
        {
            let t = (table.height - o.z) / d.z;
            if t > 0.0 && t < limit {
                best = Some(Hit {
                    t,
                    normal: Vector3::new(0.0, 0.0, -d.z.signum()),
                    kind: SurfaceKind::Table,
                    accent: false,
                });
            }
        }
        best
    }

    /// Nearest hit of a unit ray with instance `i` alone, before `max_t`.
    pub fn intersect_instance(
        &self,
        i: usize,
        o: &Point3<f64>,
        d: &Vector3<f64>,
        max_t: f64,
    ) -> Option<Hit> {
        let (lo, hi) = self.bounds[i];
        let entry = slab(&lo, &hi, o, d)?;
        if entry >= max_t {
            return None;
        }
        let inst = &self.instances[i];
        let inv = &self.inverses[i];
        let (t, n, accent) = inst.mesh.cast(&(inv * o), &(inv * d), max_t)?;
        let mut normal = inst.table_T_part * n;
        if normal.dot(d) > 0.0 {
            normal = -normal;
        }
        Some(Hit {
            t,
            normal,
            kind: SurfaceKind::Part(i),
            accent,
        })
    }

    /// Whether anything blocks the unit ray from `o` along `d` before `max_t` (shadow rays).
    pub fn occluded(&self, o: &Point3<f64>, d: &Vector3<f64>, max_t: f64) -> bool {
        self.occluded_among(self.candidates(o, d, max_t), o, d, max_t)
    }

    /// [`Self::occluded`] for a shadow ray towards the light whose [`ShadowGrid`] is `grid`: from
    /// the board's top it tests only the instances the grid holds for its cell.
    pub(crate) fn occluded_towards(
        &self,
        grid: Option<&ShadowGrid>,
        o: &Point3<f64>,
        d: &Vector3<f64>,
        max_t: f64,
    ) -> bool {
        match grid.and_then(|g| g.candidates(o)) {
            Some(mask) => self.occluded_among(Bits(mask), o, d, max_t),
            None => self.occluded(o, d, max_t),
        }
    }

    /// Whether one of the `candidates` (instances a ray may meet) or the board blocks the ray.
    fn occluded_among(
        &self,
        candidates: impl Iterator<Item = usize>,
        o: &Point3<f64>,
        d: &Vector3<f64>,
        max_t: f64,
    ) -> bool {
        for i in candidates {
            let inst = &self.instances[i];
            let (lo, hi) = self.bounds[i];
            if slab(&lo, &hi, o, d).is_some_and(|e| e < max_t) {
                let inv = &self.inverses[i];
                if inst.mesh.hits(&(inv * o), &(inv * d), max_t) {
                    return true;
                }
            }
        }
        if let Some(board) = &self.board
            && board_hit(board, o, d, max_t).is_some()
        {
            return true;
        }
        false
    }

    /// The shadow grid of each light (`None` where none applies), for one render.
    pub(crate) fn shadow_grids(&self) -> Vec<Option<ShadowGrid>> {
        self.lights
            .iter()
            .map(|l| ShadowGrid::new(l, &self.bounds))
            .collect()
    }
}

/// The set bits of a mask, lowest first.
struct Bits(u64);

impl Iterator for Bits {
    type Item = usize;

    fn next(&mut self) -> Option<usize> {
        if self.0 == 0 {
            return None;
        }
        let i = self.0.trailing_zeros() as usize;
        self.0 &= self.0 - 1;
        Some(i)
    }
}

/// Table-frame bounding box of an instance (the part box's corners, transformed).
fn world_aabb(inst: &Instance) -> (Point3<f64>, Point3<f64>) {
    let (lo, hi) = inst.mesh.aabb();
    let mut wlo = Point3::from(Vector3::repeat(f64::INFINITY));
    let mut whi = Point3::from(Vector3::repeat(f64::NEG_INFINITY));
    for c in box_corners(&lo, &hi) {
        let w = inst.table_T_part * c;
        wlo = wlo.inf(&w);
        whi = whi.sup(&w);
    }
    let pad = Vector3::repeat(1e-9);
    (wlo - pad, whi + pad)
}

/// Entry distance of a ray into a box (0 when it starts inside); `None` when it misses.
fn slab(lo: &Point3<f64>, hi: &Point3<f64>, o: &Point3<f64>, d: &Vector3<f64>) -> Option<f64> {
    slab_range(lo, hi, o, d).map(|(entry, _)| entry)
}

/// Hit of a table-frame ray with the board box: distance and table-frame normal. The ray is
/// carried into the board frame for a posed board (distances are the same in both frames).
fn board_hit(
    board: &TagBoard,
    o: &Point3<f64>,
    d: &Vector3<f64>,
    max_t: f64,
) -> Option<(f64, Vector3<f64>)> {
    let (o, d) = board.ray_to_board(o, d);
    board_hit_local(board, &o, &d, max_t).map(|(t, n)| (t, board.normal_to_table(n)))
}

/// Hit of a board-frame ray with the board box (top face at z = 0, bottom at −thickness).
fn board_hit_local(
    board: &TagBoard,
    o: &Point3<f64>,
    d: &Vector3<f64>,
    max_t: f64,
) -> Option<(f64, Vector3<f64>)> {
    let [hx, hy] = board.half_extents();
    let lo = Point3::new(-hx, -hy, -board.thickness());
    let hi = Point3::new(hx, hy, 0.0);
    // Exact top-face hit first: the common case, and the one depth must be exact for.
    if d.z < 0.0 && o.z > 0.0 {
        let t = -o.z / d.z;
        let (x, y) = (o.x + t * d.x, o.y + t * d.y);
        if x.abs() <= hx && y.abs() <= hy {
            return (t < max_t).then_some((t, Vector3::z()));
        }
    }
    let t = slab(&lo, &hi, o, d)?;
    if t <= 0.0 || t >= max_t {
        return None;
    }
    let p = o + t * d;
    let eps = 1e-9;
    let n = if (p.x - hx).abs() < eps {
        Vector3::x()
    } else if (p.x + hx).abs() < eps {
        -Vector3::x()
    } else if (p.y - hy).abs() < eps {
        Vector3::y()
    } else if (p.y + hy).abs() < eps {
        -Vector3::y()
    } else if p.z.abs() < eps {
        Vector3::z()
    } else {
        -Vector3::z()
    };
    Some((t, n))
}
