//! Stable poses with MuJoCo as a cross-check of rapier's: the same drop sequence (stratified
//! orientations, the same heights), the same convex hull, true mass properties, friction and
//! rest criterion, dropped onto a plane in MuJoCo, then clustered the same way.
//!
//! Contact settings with their physical reason: a part resting on the table must sit on its
//! geometric rest height within microns, so the contact time constant is two time steps and the
//! impedance 0.99 (MuJoCo's defaults sink a gram-scale part tens of microns under gravity).
//! Restitution has no direct MuJoCo parameter: the contact is critically damped (damping ratio
//! 1), which bounces little, as rapier's restitution of 0.1 does. (Matching the bounce of a
//! linear spring-damper, `e = exp(−π ζ / √(1 − ζ²))`, ζ ≈ 0.59, moved the main shell's flat
//! share 9 points away from rapier's: MuJoCo's soft contact is not that linear spring.)

use indicatif::ProgressBar;
use perception::part::TriMesh;
use rayon::prelude::*;

use super::{DropOutcome, DropSettings, StablePoseReport};
use crate::mujoco::MujocoError;

/// Which physics engine drops the parts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DropEngine {
    /// Rapier (the reference).
    #[default]
    Rapier,
    /// MuJoCo (needs sim's `mujoco` feature).
    Mujoco,
}

impl DropEngine {
    /// The engine called `name` (`rapier` or `mujoco`).
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "rapier" => Some(Self::Rapier),
            "mujoco" => Some(Self::Mujoco),
            _ => None,
        }
    }
}

/// Drops `mesh` (of the part called `part`, for error messages) with `engine` and clusters the
/// rests (see [`super::stable_poses`]).
pub fn stable_poses_with(
    engine: DropEngine,
    part: &str,
    mesh: &TriMesh,
    density: f64,
    settings: &DropSettings,
    progress: Option<&ProgressBar>,
) -> Result<StablePoseReport, MujocoError> {
    match engine {
        DropEngine::Rapier => Ok(super::stable_poses(mesh, density, settings, progress)),
        DropEngine::Mujoco => stable_poses_mujoco(part, mesh, density, settings, progress),
    }
}

/// Drops `mesh` (of the part called `part`) `settings.drops` times in MuJoCo, in parallel
/// batches, and clusters the rests.
pub fn stable_poses_mujoco(
    part: &str,
    mesh: &TriMesh,
    density: f64,
    settings: &DropSettings,
    progress: Option<&ProgressBar>,
) -> Result<StablePoseReport, MujocoError> {
    crate::mujoco::ensure_available()?;
    let body = super::DropBody::new(mesh, density);
    let (mass, center_of_mass) = body.mass_and_com();
    let batch = settings.batch.max(1);
    let starts: Vec<usize> = (0..settings.drops).step_by(batch).collect();
    let batches: Vec<Vec<DropOutcome>> = starts
        .par_iter()
        .map(|&first| {
            let count = batch.min(settings.drops - first);
            let out = simulate_batch(part, mesh, density, settings, first, count);
            if let Some(p) = progress {
                p.inc(count as u64);
            }
            out
        })
        .collect::<Result<_, _>>()?;
    let outcomes: Vec<DropOutcome> = batches.into_iter().flatten().collect();
    Ok(super::report(
        &outcomes,
        mesh,
        settings,
        mass,
        center_of_mass,
    ))
}

#[cfg(not(feature = "mujoco"))]
fn simulate_batch(
    _part: &str,
    _mesh: &TriMesh,
    _density: f64,
    _settings: &DropSettings,
    _first: usize,
    _count: usize,
) -> Result<Vec<DropOutcome>, MujocoError> {
    crate::mujoco::ensure_available().map(|()| Vec::new())
}

/// Simulates drops `first..first + count` of the sequence in one MuJoCo model: one free body
/// per drop, spaced so they never touch, above one plane.
#[cfg(feature = "mujoco")]
fn simulate_batch(
    part: &str,
    mesh: &TriMesh,
    density: f64,
    settings: &DropSettings,
    first: usize,
    count: usize,
) -> Result<Vec<DropOutcome>, MujocoError> {
    use mujoco_rs::prelude::{MjData, MjtObjBase};
    use nalgebra::{Isometry3, Vector3};
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rapier3d_f64::prelude::MassProperties;

    use super::{geometric_rest_height, stratified_rotation};
    use crate::convert::vec_from_point;
    use crate::mujoco::mjcf::{Mjcf, Options, pose_attrs, pose_from};

    let verts: Vec<_> = mesh.vertices.iter().map(vec_from_point).collect();
    let props = MassProperties::from_trimesh(density, &verts, &mesh.triangles);
    let com = props.local_com;
    let frame = crate::convert::unit_quaternion_from_rot(&props.principal_inertia_local_frame);
    let inertia = props.principal_inertia();
    let (lo, hi) = mesh.aabb();
    let spacing = 3.0 * (hi - lo).norm() + 0.01;
    let side = (count as f64).sqrt().ceil() as usize;

    // The whole mesh is one convex piece, as rapier's drop uses the hull of every vertex.
    let hull = [mesh.vertices.clone()];
    let mut mjcf = Mjcf::new(Options {
        timestep: settings.dt,
        gravity: Vector3::new(0.0, 0.0, -9.81),
        friction: settings.friction,
        contact_timeconst: 2.0 * settings.dt,
        contact_dampratio: 1.0,
        contact_impedance: 0.99,
        iterations: 50,
        noslip_iterations: 0,
    });
    let geoms = mjcf.piece_geoms(part, &hull, &Isometry3::identity())?;
    let mut seed_rng = ChaCha8Rng::seed_from_u64(settings.seed);
    let shift: [f64; 3] = [seed_rng.random(), seed_rng.random(), seed_rng.random()];
    let half = spacing * side as f64;
    let mut world = format!(
        "    <geom type=\"plane\" size=\"{half} {half} 0.01\" pos=\"{} {} 0\"/>\n",
        half / 2.0,
        half / 2.0
    );
    for k in 0..count {
        let rotation = stratified_rotation(first + k, shift);
        let z = geometric_rest_height(mesh, &rotation) + settings.drop_height;
        let (i, j) = (k % side, k / side);
        let pose = Isometry3::from_parts(
            Vector3::new((i as f64 + 0.5) * spacing, (j as f64 + 0.5) * spacing, z).into(),
            rotation,
        );
        let q = frame.quaternion();
        world += &format!(
            "    <body name=\"d{k}\" {}>\n      <freejoint/>\n      <inertial pos=\"{} {} {}\" \
             quat=\"{} {} {} {}\" mass=\"{}\" diaginertia=\"{} {} {}\"/>\n{geoms}    </body>\n",
            pose_attrs(&pose),
            com.x,
            com.y,
            com.z,
            q.w,
            q.i,
            q.j,
            q.k,
            props.mass(),
            inertia.x,
            inertia.y,
            inertia.z,
        );
    }
    let xml = mjcf.document(&world, "");
    let compiled = crate::mujoco::compile(&mjcf, xml)?;
    let model = &compiled.model;
    let ids: Vec<usize> = (0..count)
        .map(|k| {
            model
                .name_to_id(MjtObjBase::mjOBJ_BODY, &format!("d{k}"))
                .ok_or_else(|| MujocoError::Compile(format!("no body d{k}")))
        })
        .collect::<Result<_, _>>()?;
    let mut data = MjData::new(model);
    data.forward();
    let pose_of = |data: &MjData<&mujoco_rs::prelude::MjModel>, id: usize| {
        pose_from(&data.xpos()[id], &data.xquat()[id])
    };
    let mut outcomes: Vec<Option<DropOutcome>> = vec![None; count];
    let mut calm = vec![0.0f64; count];
    let mut anchor: Vec<Isometry3<f64>> = ids.iter().map(|&id| pose_of(&data, id)).collect();
    let mut remaining = count;
    let mut t = 0.0;
    while remaining > 0 && t < settings.max_time {
        data.step();
        t += settings.dt;
        for k in 0..count {
            if outcomes[k].is_some() {
                continue;
            }
            let p = pose_of(&data, ids[k]);
            if !p.translation.vector.iter().all(|c| c.is_finite()) {
                return Err(MujocoError::Simulation(format!(
                    "drop {} diverged at {t:.3} s",
                    first + k
                )));
            }
            let still = (p.translation.vector - anchor[k].translation.vector).norm()
                < settings.rest_displacement
                && p.rotation.angle_to(&anchor[k].rotation) < settings.rest_rotation;
            if still {
                calm[k] += settings.dt;
            } else {
                calm[k] = 0.0;
                anchor[k] = p;
            }
            if calm[k] >= settings.rest_time {
                outcomes[k] = Some(DropOutcome {
                    rotation: p.rotation,
                    height: p.translation.z,
                    settled: true,
                    time: t,
                });
                remaining -= 1;
            }
        }
    }
    Ok(outcomes
        .into_iter()
        .enumerate()
        .map(|(k, o)| {
            o.unwrap_or_else(|| {
                let p = pose_of(&data, ids[k]);
                DropOutcome {
                    rotation: p.rotation,
                    height: p.translation.z,
                    settled: false,
                    time: t,
                }
            })
        })
        .collect())
}
