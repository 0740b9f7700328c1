//! Dropping a part onto a table with rapier until it rests: the physics half of stable poses.

use std::sync::{Mutex, PoisonError};

use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};
use perception::part::{Catalog, TriMesh};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rapier3d_f64::prelude::{
    ActiveHooks, ColliderBuilder, ColliderHandle, ContactModificationContext, Group,
    InteractionGroups, InteractionTestMode, MassProperties, PhysicsHooks, PhysicsWorld,
    RigidBodyBuilder, SharedShape, Vector,
};

use super::basin::FaceBasins;
use crate::convert::{
    rot_from_unit_quaternion, unit_quaternion_from_rot, vec_from_point, vec_from_vector,
    vector_from_vec,
};

/// How parts are dropped and when they count as resting.
#[derive(Debug, Clone, PartialEq)]
pub struct DropSettings {
    /// Number of drops.
    pub drops: usize,
    /// Seed of the orientation sequence's random shift; the same seed gives the same outcomes.
    pub seed: u64,
    /// Height of the part's lowest point above the table at release, metres: how the parts
    /// arrive on the feeder. The shares depend on it (the seed authors' three meshes, 5 000 drops
    /// each, upright main shell / insert mold / top shell 55.3 / 58.3 / 71.6 % at 15 mm, 57.2 /
    /// 61.9 / 75.1 % at 30 mm). The default, 30 mm, is the seed's own experiment (parts' centres
    /// released 30–40 mm above the board), whose 60 000 BlenderProc drops this then matches
    /// within 2.3 points on every class above 20 %. A catalog records the height its table was
    /// dropped from ([`Self::with_catalog`]).
    pub drop_height: f64,
    /// Coulomb friction coefficient between part and table.
    pub friction: f64,
    /// Restitution (bounciness) of the contact.
    pub restitution: f64,
    /// Physics time step, seconds. The default, 1/2 400 s, is where the class shares stop
    /// moving: at rapier's usual 1/600 s and 4 iterations the insert mold's upright share was
    /// 3 points low and MuJoCo's own shares moved by 5 points; at 1/1 200 s it is 5 points low
    /// whatever the iterations (contacts found half as often).
    pub dt: f64,
    /// Rapier's solver iterations (substeps) per step; MuJoCo's solver runs to its own
    /// tolerance. The default, 16, with one contact per point
    /// ([`Self::one_contact_per_point`]): against 24 on the same 1 000 orientations a part
    /// (main shell, insert mold, top shell), 5, 5 and 16 drops came to rest on another face,
    /// shares within 0.3 points, for 22 % less CPU; MuJoCo's shares stay within 1.8 points on
    /// the cross-check's 3 000 drops. 12 moved 14, 17 and 27 of 2 000 more and saved only 9 %.
    /// With every triangle's contacts, 8 had put the insert mold's upright share 3.0 points
    /// from MuJoCo's, so that default was 24.
    pub solver_iterations: usize,
    /// A drop that has not come to rest after this much simulated time is reported as unsettled.
    pub max_time: f64,
    /// The part is at rest once it stays within this distance of one position, metres ...
    pub rest_displacement: f64,
    /// ... and within this angle of one orientation, radians ...
    pub rest_rotation: f64,
    /// ... for this long, seconds. (A pose criterion, not a velocity one: contact solvers leave
    /// micro-jitter on flat faces whose velocity never quite reaches zero.) The default, 20 ms,
    /// is eight periods of the 400 Hz contact spring. Against 100 ms on the same orientations
    /// (500 drops of each USB-C part), none of the 1 500 drops came to rest on another face (1
    /// at 12.5 ms, 0 at 5 and 25 ms, 1 at 50 ms), and the drops cost 1.8 times less CPU:
    /// `cargo bench -p sim --bench stable_poses -- 500 paired rest_time=0.1`.
    pub rest_time: f64,
    /// Parts simulated side by side in one physics world (rounded to whole crowds).
    pub batch: usize,
    /// Parts dropped together onto one spot, free to collide and lean on each other: 1 drops
    /// each part alone (the stable poses of a single part); more models a crowded feeder.
    pub crowd: usize,
    /// Count each point where the part's hull touches the table once ([`OneContactPerPoint`]):
    /// every hull triangle meeting at a vertex on the table reports it, and the solver's time
    /// grows with the duplicates. Against every triangle's contacts on the same 2 000
    /// orientations a part (with 16 iterations against 24): 2.75 times less CPU; 42, 74 and 95
    /// drops (main shell, insert mold, top shell) came to rest on another face, about as many
    /// as the flight's step phase alone moves (an exact free fall started 1 mm above the table
    /// moved 12, 41 and 33 of 1 000); shares within 0.25 points but the top shell's upright
    /// (26.5 → 25.4 %) and tilted (7.7 → 8.7 %) ones, both nearer MuJoCo's (24.4, 8.3 %).
    pub one_contact_per_point: bool,
    /// End a drop, alone on the table, as soon as its energy can no longer carry it off the
    /// hull face it is on ([`FaceBasins`]): its resting face is then known, and the rest of
    /// the drop only rocks and slides on it.
    pub stop_when_trapped: bool,
}

impl DropSettings {
    /// These settings with the drop height the catalog's stable-pose table was dropped from, if
    /// it records one: the settings that reproduce its table.
    pub fn with_catalog(self, catalog: &Catalog) -> Self {
        Self {
            drop_height: catalog.drop_height.unwrap_or(self.drop_height),
            ..self
        }
    }
}

impl Default for DropSettings {
    fn default() -> Self {
        Self {
            drops: 5000,
            seed: 1,
            drop_height: 0.03,
            friction: 0.4,
            restitution: 0.1,
            dt: 1.0 / 2400.0,
            solver_iterations: 16,
            max_time: 1.5,
            rest_displacement: 2e-6,
            rest_rotation: 2e-4,
            rest_time: 0.02,
            batch: 64,
            crowd: 1,
            one_contact_per_point: true,
            stop_when_trapped: true,
        }
    }
}

/// Where one drop came to rest.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DropOutcome {
    /// `table_R_part` at rest.
    pub rotation: UnitQuaternion<f64>,
    /// Height of the part origin above the table at rest, metres (from physics).
    pub height: f64,
    /// False when the drop was still jittering in place at `max_time` (it is classified by its
    /// final resting face all the same; see [`DropSettings::rest_time`]).
    pub settled: bool,
    /// True when the drop was ended on the face it could no longer leave
    /// ([`DropSettings::stop_when_trapped`]): its rotation is laid flat on that face and its
    /// height is the geometric rest height, not physics'.
    pub trapped: bool,
    /// Simulated seconds until rest.
    pub time: f64,
}

/// A world in metres with gravity for dropping millimetre parts onto a table and each other:
/// length unit 1 mm; stiff contacts (400 Hz) against the table and between parts alike; and
/// penetrations pushed out at up to 2 cm/s instead of 3 mm/s, so parts settle at their
/// geometric rest height instead of sinking into the contact's softness. Rapier's default
/// springs are 60 Hz against fixed bodies, which sags g/ω² ≈ 70 µm under gravity (more than the
/// 10 µm a rest height must agree with geometry; 400 Hz sags 1.6 µm), and 30 Hz between moving
/// bodies, which let parts heaped on each other sink in: in 48 scene drops of 12 parts, 319
/// pairs of hulls ended more than 0.1 mm inside each other (up to 3 mm), against 12 at 400 Hz.
///
/// Rapier also caps every body's speed at 400 length units per second, 0.4 m/s with a 1 mm unit.
/// Stable-pose drops lift that cap ([`stable_pose_world`]); scene drops (rendered scenes, the
/// feeder's `drop` placement) keep it, see the README's known gaps.
pub(crate) fn drop_world(dt: f64) -> PhysicsWorld {
    let mut world = PhysicsWorld::new();
    world.gravity = Vector::Z * -GRAVITY;
    let p = &mut world.integration_parameters;
    p.dt = dt;
    p.length_unit = 1e-3;
    p.normalized_max_corrective_velocity = 20.0;
    p.static_contact_softness.natural_frequency = CONTACT_HZ;
    p.contact_softness = p.static_contact_softness;
    world
}

/// The world of the stable-pose drops: [`drop_world`] with `settings`' solver iterations,
/// without rapier's speed cap, and without contact clustering.
///
/// At 0.4 m/s the cap slowed a part dropped 15 mm, which lands at √(2 g h) = 0.54 m/s, in
/// mid-air: it hit the table with half its kinetic energy, and the class shares followed
/// (MuJoCo, which has no cap, disagreed by up to 6 points).
///
/// Clustering merges the contact manifolds of a collider pair whose normals nearly agree and
/// keeps four points of the merged set. A resting face that CAD exported as facets a fraction
/// of a milliradian apart (the seed authors' top shell: its skirts end at −1.003 and −1.002 mm,
/// the file's micrometre rounding) is one cluster, and which four points survive changed from
/// step to step as the part rocked micrometres: 44 % of that shell's drops still jittered at
/// the time limit, 0.1° off their face and 3 µm off their rest height. Every facet keeping its
/// own contacts, all of them rest, within 0.3 µm of the geometric height.
fn stable_pose_world(settings: &DropSettings) -> PhysicsWorld {
    let mut world = drop_world(settings.dt);
    let p = &mut world.integration_parameters;
    p.num_solver_iterations = settings.solver_iterations.max(1);
    p.normalized_max_linear_velocity = MAX_DROP_SPEED / p.length_unit;
    p.contact_clustering = false;
    world
}

/// Keeps one solver contact per point where a part's hull triangles touch the table.
///
/// Rapier gives each hull triangle near the table its own manifold (clustering is off, see
/// [`stable_pose_world`]), so a hull vertex on the table is reported once by every triangle
/// that meets there, and an edge by both its triangles. Those duplicates are one physical
/// contact: the solver splits the same impulse between them. This hook, called manifold after
/// manifold for one collider pair, drops a solver contact whose point (within
/// [`SAME_POINT`]) an earlier manifold of the pair already holds in this step.
#[derive(Default)]
pub(crate) struct OneContactPerPoint {
    held: Mutex<(Option<[ColliderHandle; 2]>, Vec<Vector>)>,
}

/// Two contact points closer than this, metres, are one (hull vertices are far further apart).
const SAME_POINT: f64 = 1e-8;

impl OneContactPerPoint {
    /// Forgets the points held, before a step.
    pub(crate) fn reset(&self) {
        let mut held = self.held.lock().unwrap_or_else(PoisonError::into_inner);
        held.0 = None;
        held.1.clear();
    }
}

impl PhysicsHooks for OneContactPerPoint {
    fn modify_solver_contacts(&self, context: &mut ContactModificationContext) {
        let pair = [context.collider1, context.collider2];
        let Some(manifold) = context.rigid_mut() else {
            return;
        };
        let mut held = self.held.lock().unwrap_or_else(PoisonError::into_inner);
        let (owner, points) = &mut *held;
        if *owner != Some(pair) {
            *owner = Some(pair);
            points.clear();
        }
        manifold.solver_contacts.retain(|c| {
            let p = (c.anchor1 + c.anchor2) * 0.5;
            if points
                .iter()
                .any(|q| (*q - p).length_squared() < SAME_POINT * SAME_POINT)
            {
                return false;
            }
            points.push(p);
            true
        });
    }
}

/// Standard gravity, m/s², of every drop world.
pub const GRAVITY: f64 = 9.81;

/// Natural frequency of the drop worlds' contacts, Hz ([`drop_world`]).
const CONTACT_HZ: f64 = 400.0;

/// [`CONTACT_HZ`] as an angular frequency, rad/s.
const CONTACT_OMEGA: f64 = std::f64::consts::TAU * CONTACT_HZ;

/// Fastest a part dropped for its stable poses may move, m/s: only a sanity bound (a fall from
/// 0.5 m lands at 3.1 m/s).
pub const MAX_DROP_SPEED: f64 = 10.0;

/// A uniformly distributed random rotation (Shoemake's method).
pub fn random_rotation(rng: &mut impl rand::Rng) -> UnitQuaternion<f64> {
    rotation_from_unit_cube(rng.random(), rng.random(), rng.random())
}

/// Rotation `index` of a low-discrepancy sequence covering SO(3) evenly: Roberts' R3 additive
/// recurrence, randomly shifted by `shift` (one shift per seed), through Shoemake's map. Class
/// probabilities estimated from it vary far less between seeds than with independent draws.
pub fn stratified_rotation(index: usize, shift: [f64; 3]) -> UnitQuaternion<f64> {
    // g is the unique positive root of x⁴ = x + 1; (1/g, 1/g², 1/g³) is R3's generator.
    const G: f64 = 1.220_744_084_605_759_6;
    let n = (index + 1) as f64;
    let u = |k: i32, s: f64| (s + n / G.powi(k)).fract();
    rotation_from_unit_cube(u(1, shift[0]), u(2, shift[1]), u(3, shift[2]))
}

/// Shoemake's map from the unit cube onto unit quaternions (uniform in, uniform out).
fn rotation_from_unit_cube(u1: f64, u2: f64, u3: f64) -> UnitQuaternion<f64> {
    let tau = std::f64::consts::TAU;
    let (a, b) = ((1.0 - u1).sqrt(), u1.sqrt());
    UnitQuaternion::new_normalize(nalgebra::Quaternion::new(
        b * (tau * u3).cos(),
        a * (tau * u2).sin(),
        a * (tau * u2).cos(),
        b * (tau * u3).sin(),
    ))
}

/// Height of the part origin when the mesh, rotated by `rotation`, rests on z = 0: the
/// geometric rest height.
pub fn geometric_rest_height(mesh: &TriMesh, rotation: &UnitQuaternion<f64>) -> f64 {
    -mesh
        .vertices
        .iter()
        .map(|p| (rotation * p).z)
        .fold(f64::INFINITY, f64::min)
}

/// Collision group of the table.
const TABLE: Group = Group::GROUP_1;
/// Collision group of the parts' triangulated convex hulls, which touch only the table.
const FACETS: Group = Group::GROUP_2;
/// Collision group of the parts' convex hulls (solid), which touch the table and each other.
const PARTS: Group = Group::GROUP_3;

/// The physics body shared by every drop: contact shapes and the true mass properties of the
/// (possibly hollow) solid.
///
/// Each part carries its convex hull twice. As a convex polyhedron it is solid (parts in a crowd
/// cannot pass through each other) and parry merges nearly coplanar hull triangles into one
/// face, but its contact keeps only four corners of a face with more (a TODO in parry's
/// `local_support_feature`): the main shell's floor with its tabs has eight, so alone it stood
/// on a sliver of the floor, tipped a corner 26 µm into the table and slid for ever (58 % of all
/// its drops never came to rest). As a triangle mesh touching only the table it adds per-triangle
/// contacts, which rapier clusters into one manifold per plane, so the whole face carries the
/// part. A part dropped alone touches only the table and carries the triangles alone: without
/// contact clustering ([`stable_pose_world`]) each keeps its own contacts, so nearly coplanar
/// facets no longer trade a four-point cluster between them (with clustering, the triangles
/// alone had let the insert mold rock between hull triangles 0.4° apart). A vertex the
/// triangles share is one contact point, kept once ([`OneContactPerPoint`]).
#[derive(Debug, Clone)]
pub struct DropBody {
    hull: Option<SharedShape>,
    facets: (Vec<parry3d_f64::math::Vector>, Vec<[u32; 3]>),
    /// Mass properties of the part itself, not of its filled hull: a hollow shell's centre of
    /// mass, and with it the face it comes to rest on, differ from its hull's. Several
    /// overlapping bodies weigh as their union.
    pub(crate) mass: MassProperties,
    pub(super) mesh: TriMesh,
    pub(super) diameter: f64,
    /// The contact hull's faces with their tipping barriers, for ending a drop early.
    basins: FaceBasins,
}

impl DropBody {
    /// Prepares a mesh (metres, part frame) of the given density for dropping, its contact hull
    /// simplified within [`HULL_TOLERANCE`] when it has more than [`SIMPLIFY_HULL_ABOVE`]
    /// triangles ([`contact_hull`]).
    pub fn new(mesh: &TriMesh, density: f64) -> Self {
        Self::with_hull_tolerance(mesh, density, HULL_TOLERANCE)
    }

    /// [`Self::new`] with the contact hull simplified within `tolerance` metres (0: the full
    /// hull); the mass properties are the full mesh's either way.
    pub fn with_hull_tolerance(mesh: &TriMesh, density: f64, tolerance: f64) -> Self {
        let verts: Vec<_> = mesh.vertices.iter().map(vec_from_point).collect();
        let mass = union_mass(mesh, density, &verts);
        let (lo, hi) = mesh.aabb();
        // Our hull, not parry's: a finely tessellated cylinder's points on two circles took
        // parry memory quadratic in them (see perception::part::convex_hull).
        let full = perception::part::convex_hull(&verts);
        let facets = if tolerance > 0.0 && full.1.len() > SIMPLIFY_HULL_ABOVE {
            contact_hull(&full.0, tolerance)
        } else {
            full
        };
        // The solid from the hull just built (parry's `convex_hull` would build it again).
        let hull = (!facets.1.is_empty())
            .then(|| SharedShape::convex_mesh(facets.0.clone(), &facets.1))
            .flatten();
        let corners: Vec<Point3<f64>> = facets
            .0
            .iter()
            .map(|v| Point3::new(v.x, v.y, v.z))
            .collect();
        let c = mass.local_com;
        let basins = FaceBasins::new(&corners, &facets.1, &Point3::new(c.x, c.y, c.z));
        Self {
            facets,
            hull,
            basins,
            mass,
            mesh: mesh.clone(),
            diameter: (hi - lo).norm(),
        }
    }

    /// Vertices and triangles of the hull the part touches the table with.
    pub fn contact_hull_size(&self) -> (usize, usize) {
        (self.facets.0.len(), self.facets.1.len())
    }

    /// The convex hull it collides by as a solid, `None` when the mesh spans no volume.
    pub fn hull(&self) -> Option<&SharedShape> {
        self.hull.as_ref()
    }

    /// Whether physics can shape and weigh the part: its mesh spans a volume of positive mass.
    pub fn has_volume(&self) -> bool {
        self.hull.is_some() && self.mass.mass() > 0.0 && self.mass.mass().is_finite()
    }

    /// Mass in kg and centre of mass in the part frame.
    pub fn mass_and_com(&self) -> (f64, Point3<f64>) {
        let c = self.mass.local_com;
        (self.mass.mass(), Point3::new(c.x, c.y, c.z))
    }
}

/// Hulls of more triangles than this are simplified for the drops ([`contact_hull`]); the
/// USB-C parts' hulls have 28 to 36 and are dropped as they are.
pub const SIMPLIFY_HULL_ABOVE: usize = 1000;

/// How far, metres, a hull vertex may lie outside the simplified contact hull's face planes:
/// 0.01 mm, the chordal tolerance STEP parts are tessellated to, so the simplified hull is as
/// near the CAD surface as the tessellation is.
pub const HULL_TOLERANCE: f64 = 1e-5;

/// A convex hull of `points` (metres) with vertices among theirs and every point within
/// `tolerance` of each of its face planes, as few as a tolerance-stopped quickhull finds: start
/// from the points extreme along 26 directions, then round after round add, for each face, the
/// point farthest outside it if that is more than `tolerance`, until none is.
///
/// A part rests on a face of its hull: on a face of this one, its true lowest point lies at most
/// `tolerance` below it, so rest heights move by at most `tolerance` and a curved surface's
/// thousands of facets become the few that chordal error allows. Each round costs points ×
/// faces; a round's points are the ones outside the last round's hull, and a last pass over all
/// of them confirms the bound.
pub fn contact_hull(
    points: &[parry3d_f64::math::Vector],
    tolerance: f64,
) -> (Vec<parry3d_f64::math::Vector>, Vec<[u32; 3]>) {
    use parry3d_f64::math::Vector as V;
    let hull_of = |chosen: &[usize]| {
        let pts: Vec<V> = chosen.iter().map(|&i| points[i]).collect();
        perception::part::convex_hull(&pts)
    };
    let mut chosen: Vec<usize> = Vec::new();
    for x in -1..=1 {
        for y in -1..=1 {
            for z in -1..=1 {
                if (x, y, z) == (0, 0, 0) {
                    continue;
                }
                let d = V::new(f64::from(x), f64::from(y), f64::from(z));
                let best = (0..points.len())
                    .max_by(|&a, &b| points[a].dot(d).total_cmp(&points[b].dot(d)));
                if let Some(i) = best.filter(|i| !chosen.contains(i)) {
                    chosen.push(i);
                }
            }
        }
    }
    let mut candidates: Vec<usize> = (0..points.len()).collect();
    let mut confirming = false;
    loop {
        let (verts, faces) = hull_of(&chosen);
        if faces.is_empty() {
            return perception::part::convex_hull(points);
        }
        let planes: Vec<(V, f64)> = faces
            .iter()
            .filter_map(|f| {
                let [a, b, c] = f.map(|i| verts[i as usize]);
                let n = (b - a).cross(c - a);
                let len = n.length();
                (len > 0.0).then(|| (n / len, (n / len).dot(a)))
            })
            .collect();
        // Per face, the farthest point outside it by more than the tolerance.
        let mut farthest: Vec<Option<(f64, usize)>> = vec![None; planes.len()];
        let mut outside = Vec::new();
        for &i in &candidates {
            let p = points[i];
            let (face, distance) = planes
                .iter()
                .enumerate()
                .map(|(f, (n, d))| (f, n.dot(p) - d))
                .max_by(|a, b| a.1.total_cmp(&b.1))
                .unwrap_or((0, 0.0));
            if distance > tolerance {
                outside.push(i);
                if farthest[face].is_none_or(|(best, _)| distance > best) {
                    farthest[face] = Some((distance, i));
                }
            }
        }
        let added: Vec<usize> = farthest.into_iter().flatten().map(|(_, i)| i).collect();
        if added.is_empty() {
            if confirming {
                return (verts, faces);
            }
            confirming = true;
            candidates = (0..points.len()).collect();
            continue;
        }
        confirming = false;
        chosen.extend(
            added
                .iter()
                .filter(|i| !chosen.contains(i))
                .collect::<Vec<_>>(),
        );
        candidates = outside;
    }
}

/// An overlap of bodies under this share of the part's volume leaves the part's mass to rapier's
/// own integral: it moves the mass a hundred times less than a material's density is known to
/// (about 1 %), and so the drops and the catalog's mass of a part with such a sliver stay as they
/// were (our main shell has one of 9e-6 of its volume near its top).
pub const NEGLIGIBLE_OVERLAP: f64 = 1e-4;

/// Mass properties of the union of the mesh's bodies at `density`: rapier's own integral of the
/// triangles when no two bodies overlap (a single body, bodies that only touch, or an overlap
/// under [`NEGLIGIBLE_OVERLAP`]), otherwise the union's ([`TriMesh::union_moments`]), where a
/// volume two bodies share counts once.
pub(crate) fn union_mass(mesh: &TriMesh, density: f64, verts: &[Vector]) -> MassProperties {
    let moments = mesh.union_moments();
    if moments.excess.volume <= NEGLIGIBLE_OVERLAP * moments.union.volume {
        return MassProperties::from_trimesh(density, verts, &mesh.triangles);
    }
    let union = moments.union;
    MassProperties::with_inertia_matrix(
        vec_from_point(&union.centroid()),
        union.mass(density),
        mat_from_matrix(&union.inertia(density)),
    )
}

/// A 3 × 3 matrix in rapier's math types.
fn mat_from_matrix(m: &nalgebra::Matrix3<f64>) -> parry3d_f64::math::Matrix {
    let col = |k: usize| vec_from_vector(&m.column(k).into_owned());
    parry3d_f64::math::Matrix::from_cols(col(0), col(1), col(2))
}

/// How a body moved in the last step, by the rest criterion of [`DropSettings`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Motion {
    /// It left the pose it was holding (which it now holds instead).
    Moved,
    /// It holds its pose, not yet for [`DropSettings::rest_time`].
    Still,
    /// It has held its pose for [`DropSettings::rest_time`]: at rest.
    Rested,
}

/// The rest criterion both engines judge their drops by: a body is at rest once it has stayed
/// within [`DropSettings::rest_displacement`] and [`DropSettings::rest_rotation`] of one pose
/// for [`DropSettings::rest_time`].
pub(super) struct RestClock {
    anchor: Vec<Isometry3<f64>>,
    calm: Vec<f64>,
}

impl RestClock {
    /// A clock for bodies starting at `poses`.
    pub(super) fn new(poses: Vec<Isometry3<f64>>) -> Self {
        Self {
            calm: vec![0.0; poses.len()],
            anchor: poses,
        }
    }

    /// Body `k` is at `pose` after a step of `settings.dt`.
    pub(super) fn tick(
        &mut self,
        k: usize,
        pose: &Isometry3<f64>,
        settings: &DropSettings,
    ) -> Motion {
        let anchor = &self.anchor[k];
        let still = (pose.translation.vector - anchor.translation.vector).norm()
            < settings.rest_displacement
            && pose.rotation.angle_to(&anchor.rotation) < settings.rest_rotation;
        if !still {
            self.calm[k] = 0.0;
            self.anchor[k] = *pose;
            return Motion::Moved;
        }
        self.calm[k] += settings.dt;
        if self.calm[k] >= settings.rest_time {
            Motion::Rested
        } else {
            Motion::Still
        }
    }
}

/// The collider of `body`'s hull triangles, which touch only the table and carry the part's mass,
/// `None` when they make no triangle mesh.
fn facets_collider(body: &DropBody, settings: &DropSettings) -> Option<ColliderBuilder> {
    let facets = ColliderBuilder::trimesh(body.facets.0.clone(), body.facets.1.clone()).ok()?;
    Some(
        facets
            .mass_properties(body.mass)
            .friction(settings.friction)
            .restitution(settings.restitution)
            .collision_groups(InteractionGroups::new(
                FACETS,
                TABLE,
                InteractionTestMode::And,
            ))
            .active_hooks(if settings.one_contact_per_point {
                ActiveHooks::MODIFY_SOLVER_CONTACTS
            } else {
                ActiveHooks::empty()
            }),
    )
}

/// Simulates drops `first..first + count` of the sequence defined by `settings` in one world.
///
/// Drops are released in groups of [`DropSettings::crowd`] (by global index, so `first` should
/// be a multiple of it): a group falls together onto one spot, its parts stacked at release so
/// none overlap, and may come to rest touching or leaning on each other. Groups are far enough
/// apart never to meet. A part counts as at rest once it has stayed still for
/// [`DropSettings::rest_time`]; if a neighbour knocks it before its whole group rests, it is
/// watched again.
pub fn simulate_batch(
    body: &DropBody,
    settings: &DropSettings,
    first: usize,
    count: usize,
) -> Vec<DropOutcome> {
    let mut world = stable_pose_world(settings);
    let crowd = settings.crowd.max(1);
    // Parts of a group are released over a square about as wide as the group lying side by side.
    let scatter = if crowd > 1 {
        0.5 * body.diameter * (crowd as f64).sqrt()
    } else {
        0.0
    };
    let spacing = 3.0 * body.diameter + 2.0 * scatter + 0.01;
    let group_of = |k: usize| (first + k) / crowd - first / crowd;
    let groups = if count == 0 {
        0
    } else {
        group_of(count - 1) + 1
    };
    let side = (groups as f64).sqrt().ceil() as usize;
    let half = spacing * side as f64;
    let ground = ColliderBuilder::cuboid(half, half, 0.01)
        .translation(Vector::new(half / 2.0, half / 2.0, -0.01))
        .friction(settings.friction)
        .restitution(settings.restitution)
        .collision_groups(InteractionGroups::new(
            TABLE,
            FACETS | PARTS,
            InteractionTestMode::And,
        ))
        .build();
    world.colliders.insert(ground);
    let Some(hull) = body.hull.clone().map(ColliderBuilder::new) else {
        return Vec::new();
    };
    let Some(facets) = facets_collider(body, settings) else {
        return Vec::new();
    };
    let mut seed_rng = ChaCha8Rng::seed_from_u64(settings.seed);
    let shift: [f64; 3] = [seed_rng.random(), seed_rng.random(), seed_rng.random()];
    let mut handles = Vec::with_capacity(count);
    for k in 0..count {
        let index = first + k;
        let rotation = stratified_rotation(index, shift);
        let g = group_of(k);
        let in_group = index % crowd;
        // Each part of a group starts one diameter (plus 0.5 mm) above the one before it.
        let lift = in_group as f64 * (body.diameter + 5e-4);
        let z = geometric_rest_height(&body.mesh, &rotation) + settings.drop_height + lift;
        let mut offset = Vector3::zeros();
        if crowd > 1 {
            let mut rng = ChaCha8Rng::seed_from_u64(settings.seed);
            rng.set_stream(1 + index as u64);
            offset.x = rng.random_range(-scatter..=scatter);
            offset.y = rng.random_range(-scatter..=scatter);
        }
        let (i, j) = (g % side, g / side);
        let centre = Vector3::new(
            (i as f64 + 0.5) * spacing + offset.x,
            (j as f64 + 0.5) * spacing + offset.y,
            z,
        );
        let rb = RigidBodyBuilder::dynamic()
            .translation(vec_from_vector(&centre))
            .rotation(rot_from_unit_quaternion(&rotation).to_scaled_axis())
            .can_sleep(false)
            .build();
        let h = world.bodies.insert(rb);
        let on_table = facets.clone().build();
        world
            .colliders
            .insert_with_parent(on_table, h, &mut world.bodies);
        if crowd == 1 {
            // Alone, a part touches only the table, which its facets meet face by face.
            handles.push(h);
            continue;
        }
        let solid = hull
            .clone()
            .density(0.0)
            .friction(settings.friction)
            .restitution(settings.restitution)
            .collision_groups(InteractionGroups::new(
                PARTS,
                TABLE | PARTS,
                InteractionTestMode::And,
            ))
            .build();
        world
            .colliders
            .insert_with_parent(solid, h, &mut world.bodies);
        handles.push(h);
    }
    let mut outcomes: Vec<Option<DropOutcome>> = vec![None; count];
    let mut removed = vec![false; count];
    let mut restless = vec![0usize; groups];
    for k in 0..count {
        restless[group_of(k)] += 1;
    }
    let pose_of = |world: &PhysicsWorld, k: usize| {
        let rb = &world.bodies[handles[k]];
        Isometry3::from_parts(
            vector_from_vec(rb.translation()).into(),
            unit_quaternion_from_rot(rb.rotation()),
        )
    };
    let mut clock = RestClock::new((0..count).map(|k| pose_of(&world, k)).collect());
    let mut remaining = groups;
    let mut t = 0.0;
    let hooks = OneContactPerPoint::default();
    // Alone on the table a part's energy decides its face; in a crowd neighbours push it.
    let trap = settings.stop_when_trapped && crowd == 1;
    while remaining > 0 && t < settings.max_time {
        hooks.reset();
        world.step_with_events(&hooks, &());
        t += settings.dt;
        for k in 0..count {
            if removed[k] {
                continue;
            }
            let pose = pose_of(&world, k);
            if trap && outcomes[k].is_none() {
                let rb = &world.bodies[handles[k]];
                let up = pose.rotation.inverse() * Vector3::z();
                let height = rb.center_of_mass().z;
                // A contact pressed in by δ holds ½ m ω² δ² like a spring (rapier's soft
                // contacts); on landing that is most of the energy, and it comes back.
                let sunk = CONTACT_OMEGA * body.basins.sunk(&up, height);
                let energy_height =
                    rb.kinetic_energy() / (rb.mass() * GRAVITY) + sunk * sunk / (2.0 * GRAVITY);
                if let Some(face) = body.basins.trapped(&up, height, energy_height) {
                    let flat =
                        UnitQuaternion::rotation_between(&(pose.rotation * face), &-Vector3::z())
                            .unwrap_or_else(UnitQuaternion::identity)
                            * pose.rotation;
                    outcomes[k] = Some(DropOutcome {
                        rotation: flat,
                        height: geometric_rest_height(&body.mesh, &flat),
                        settled: true,
                        trapped: true,
                        time: t,
                    });
                    restless[group_of(k)] -= 1;
                    continue;
                }
            }
            match clock.tick(k, &pose, settings) {
                Motion::Moved => {
                    if outcomes[k].take().is_some() {
                        restless[group_of(k)] += 1;
                    }
                }
                Motion::Rested if outcomes[k].is_none() => {
                    outcomes[k] = Some(DropOutcome {
                        rotation: pose.rotation,
                        height: pose.translation.z,
                        settled: true,
                        trapped: false,
                        time: t,
                    });
                    restless[group_of(k)] -= 1;
                }
                Motion::Rested | Motion::Still => {}
            }
        }
        // A group whose parts all rest leaves the world, so later steps cost less.
        for k in 0..count {
            if !removed[k] && restless[group_of(k)] == 0 {
                removed[k] = true;
                world.bodies.remove(
                    handles[k],
                    &mut world.islands,
                    &mut world.colliders,
                    &mut world.impulse_joints,
                    &mut world.multibody_joints,
                    &mut world.soft_bodies,
                    true,
                );
            }
        }
        remaining = restless.iter().filter(|&&r| r > 0).count();
    }
    outcomes
        .into_iter()
        .enumerate()
        .map(|(k, o)| {
            o.unwrap_or_else(|| {
                let rb = &world.bodies[handles[k]];
                DropOutcome {
                    rotation: unit_quaternion_from_rot(rb.rotation()),
                    height: rb.translation().z,
                    settled: false,
                    trapped: false,
                    time: t,
                }
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 10 × 10 × 4 mm block (z from −2 to 2 mm) and a 2 × 2 × 6 mm pin from z = −1 to 5 mm
    /// through its top: 400 + 12 mm³ of union, the 12 mm³ the pin shares with the block once.
    #[test]
    fn overlapping_bodies_weigh_as_their_union() {
        let mut part = TriMesh::cuboid(Vector3::new(0.01, 0.01, 0.004));
        part.append(
            &TriMesh::cuboid(Vector3::new(0.002, 0.002, 0.006))
                .transformed(&Isometry3::translation(0.0, 0.0, 0.002)),
        );
        let (mass, com) = DropBody::new(&part, 1000.0).mass_and_com();
        let volume = 412e-9;
        assert!((mass - volume * 1000.0).abs() < 1e-9 * mass, "{mass} kg");
        // The 12 mm³ of pin above the block, centred 3.5 mm up.
        let want = 12e-9 * 0.0035 / volume;
        assert!((com - Point3::new(0.0, 0.0, want)).norm() < 1e-10, "{com}");
    }

    /// Bodies that overlap by a sliver (1e-5 of the volume: a pin 1 µm into a block) weigh
    /// exactly as rapier integrates them.
    #[test]
    fn a_negligible_overlap_keeps_rapiers_integral() {
        let mut part = TriMesh::cuboid(Vector3::new(0.01, 0.01, 0.004));
        part.append(
            &TriMesh::cuboid(Vector3::new(0.002, 0.002, 0.002))
                .transformed(&Isometry3::translation(0.0, 0.0, 0.002999)),
        );
        let moments = part.union_moments();
        let share = moments.excess.volume / moments.union.volume;
        assert!(share > 0.0 && share < NEGLIGIBLE_OVERLAP, "{share}");
        let verts: Vec<_> = part.vertices.iter().map(vec_from_point).collect();
        assert_eq!(
            DropBody::new(&part, 1000.0).mass,
            MassProperties::from_trimesh(1000.0, &verts, &part.triangles)
        );
    }

    /// A closed cylinder of `segments` sides around z, 10 mm across and 6 mm tall.
    fn cylinder(segments: u32) -> TriMesh {
        let mut vertices = Vec::new();
        for z in [-0.003, 0.003] {
            for k in 0..segments {
                let a = std::f64::consts::TAU * f64::from(k) / f64::from(segments);
                vertices.push(Point3::new(0.005 * a.cos(), 0.005 * a.sin(), z));
            }
        }
        vertices.push(Point3::new(0.0, 0.0, -0.003));
        vertices.push(Point3::new(0.0, 0.0, 0.003));
        let n = segments;
        let mut triangles = Vec::new();
        for k in 0..n {
            let next = (k + 1) % n;
            triangles.push([2 * n, next, k]);
            triangles.push([2 * n + 1, n + k, n + next]);
            triangles.push([k, next, n + next]);
            triangles.push([k, n + next, n + k]);
        }
        TriMesh::new(vertices, triangles)
    }

    /// A cylinder of 2 000 sides (a hull of 8 000 triangles) is dropped on a hull of a few
    /// hundred, whose vertices are the part's, with every part vertex within the tolerance of
    /// its face planes and its rest height in any orientation within the tolerance of the
    /// part's; the mass stays the full mesh's.
    #[test]
    fn a_fine_hull_is_simplified_within_the_tolerance() {
        let mesh = cylinder(2000);
        let body = DropBody::new(&mesh, 1000.0);
        let verts: Vec<_> = mesh.vertices.iter().map(vec_from_point).collect();
        let full = perception::part::convex_hull(&verts);
        assert!(full.1.len() > 7000, "{} hull triangles", full.1.len());
        let (v, f) = body.contact_hull_size();
        // A 5 mm radius within 0.01 mm takes about 50 sides: 100 vertices, 200 triangles.
        assert!(v < 160 && f < 320, "{v} vertices, {f} triangles");
        let (hv, hf) = &body.facets;
        for p in hv {
            assert!(verts.contains(p), "{p:?} is no vertex of the part");
        }
        let worst = hf
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| hv[i as usize]);
                let n = (b - a).cross(c - a).normalize();
                verts.iter().map(|p| n.dot(*p - a)).fold(f64::MIN, f64::max)
            })
            .fold(f64::MIN, f64::max);
        assert!(worst <= HULL_TOLERANCE, "a vertex {worst} m outside a face");
        assert!(worst > 0.5 * HULL_TOLERANCE, "simplified to {worst} m only");
        let simplified = TriMesh::new(
            hv.iter().map(|p| Point3::new(p.x, p.y, p.z)).collect(),
            hf.clone(),
        );
        let shift = [0.1, 0.2, 0.3];
        for i in 0..500 {
            let r = stratified_rotation(i, shift);
            let error = geometric_rest_height(&mesh, &r) - geometric_rest_height(&simplified, &r);
            assert!(
                (0.0..=HULL_TOLERANCE).contains(&error),
                "rest height {error} m off in drop {i}"
            );
        }
        assert_eq!(
            body.mass,
            MassProperties::from_trimesh(1000.0, &verts, &mesh.triangles)
        );
    }

    /// A hull of no more than [`SIMPLIFY_HULL_ABOVE`] triangles (the USB-C parts' have 28 to
    /// 36) is dropped exactly as it is, and a tolerance of 0 keeps any hull.
    #[test]
    fn a_coarse_hull_is_dropped_as_it_is() {
        for (mesh, tolerance) in [(cylinder(64), HULL_TOLERANCE), (cylinder(400), 0.0)] {
            let verts: Vec<_> = mesh.vertices.iter().map(vec_from_point).collect();
            let full = parry3d_f64::transformation::convex_hull(&verts);
            let body = DropBody::with_hull_tolerance(&mesh, 1000.0, tolerance);
            assert_eq!(body.facets, full);
        }
    }

    /// A 100 000-triangle cylinder (50 002 points on two circles and the caps' centres) is
    /// prepared for dropping in bounded memory and time: parry's own hull of its points grew
    /// past 24 GB before its first drop. Its contact hull is simplified as a coarse one's is.
    #[test]
    fn a_100_000_triangle_cylinder_is_prepared_in_bounded_memory() {
        let mesh = cylinder(25_000);
        let start = std::time::Instant::now();
        let body = DropBody::new(&mesh, 1000.0);
        let spent = start.elapsed().as_secs_f64();
        let (v, f) = body.contact_hull_size();
        assert!(v < 160 && f < 320, "{v} vertices, {f} triangles");
        assert!(body.has_volume());
        assert!(spent < 30.0, "{spent} s");
    }

    /// A single body (or bodies that do not overlap) weighs exactly as rapier integrates it.
    #[test]
    fn a_single_body_weighs_as_rapier_integrates_it() {
        let part = TriMesh::cuboid(Vector3::new(0.01, 0.006, 0.004));
        let verts: Vec<_> = part.vertices.iter().map(vec_from_point).collect();
        assert_eq!(
            DropBody::new(&part, 1000.0).mass,
            MassProperties::from_trimesh(1000.0, &verts, &part.triangles)
        );
    }

    /// A cube resting on a face touches the table at its four bottom corners: one solver
    /// contact each with [`OneContactPerPoint`], where without it every hull triangle meeting
    /// at a corner (or along a bottom edge) reports its own.
    #[test]
    fn a_resting_cube_holds_one_contact_per_corner() {
        let contacts = |one_per_point: bool| {
            let settings = DropSettings {
                one_contact_per_point: one_per_point,
                ..DropSettings::default()
            };
            let mut world = stable_pose_world(&settings);
            world.colliders.insert(
                ColliderBuilder::cuboid(0.05, 0.05, 0.01)
                    .translation(Vector::new(0.0, 0.0, -0.01))
                    .collision_groups(InteractionGroups::new(
                        TABLE,
                        FACETS,
                        InteractionTestMode::And,
                    ))
                    .build(),
            );
            let body = DropBody::new(&TriMesh::cuboid(Vector3::new(0.004, 0.004, 0.004)), 1000.0);
            let h = world.bodies.insert(
                RigidBodyBuilder::dynamic()
                    .translation(Vector::new(0.0, 0.0, 0.002))
                    .build(),
            );
            let facets = facets_collider(&body, &settings).unwrap().build();
            world
                .colliders
                .insert_with_parent(facets, h, &mut world.bodies);
            let hooks = OneContactPerPoint::default();
            for _ in 0..100 {
                hooks.reset();
                world.step_with_events(&hooks, &());
            }
            let points: Vec<Vector> = world
                .narrow_phase
                .contact_pairs()
                .flat_map(|pair| pair.manifolds())
                .flat_map(|m| m.data.solver_contacts.iter())
                .map(|c| (c.anchor1 + c.anchor2) * 0.5)
                .collect();
            let z = world.bodies[h].translation().z;
            assert!((z - 0.002).abs() < 1e-5, "the cube rests at {z} m");
            points.len()
        };
        assert_eq!(contacts(true), 4);
        let every_triangle = contacts(false);
        assert!(every_triangle > 8, "{every_triangle} contacts");
    }

    /// A part dropped 15 mm lands at √(2 g h), not at rapier's default speed cap (0.4 m/s with
    /// a 1 mm length unit).
    #[test]
    fn a_dropped_part_falls_freely_to_the_table() {
        let mut world = stable_pose_world(&DropSettings::default());
        world.colliders.insert(
            ColliderBuilder::cuboid(0.05, 0.05, 0.01)
                .translation(Vector::new(0.0, 0.0, -0.01))
                .build(),
        );
        let h = 0.015;
        let body = world.bodies.insert(
            RigidBodyBuilder::dynamic()
                .translation(Vector::new(0.0, 0.0, h + 0.001))
                .build(),
        );
        let part = ColliderBuilder::cuboid(0.004, 0.004, 0.001)
            .density(1400.0)
            .build();
        world
            .colliders
            .insert_with_parent(part, body, &mut world.bodies);
        let mut fastest = 0.0f64;
        for _ in 0..240 {
            world.step();
            fastest = fastest.max(-world.bodies[body].linvel().z);
        }
        let free_fall = (2.0 * 9.81 * h).sqrt();
        assert!(
            (fastest - free_fall).abs() < 0.01 * free_fall,
            "landed at {fastest:.3} m/s, free fall gives {free_fall:.3} m/s"
        );
    }
}
