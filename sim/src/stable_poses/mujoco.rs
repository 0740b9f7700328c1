//! Stable poses with MuJoCo as a cross-check of rapier's: the same drop sequence (stratified
//! orientations, the same heights), the same convex hull, true mass properties, friction and
//! rest criterion, dropped onto a plane in MuJoCo, then clustered the same way.
//!
//! Contact settings with their physical reason: a part resting on the table must sit on its
//! geometric rest height within microns, so the contact time constant is two time steps and the
//! impedance 0.99 (MuJoCo's defaults sink a gram-scale part tens of microns under gravity).
//!
//! Restitution has no MuJoCo parameter, and how much a soft contact bounces depends on its
//! damping ratio *and* on the time step: with critical damping a part landing flat rebounds
//! with 9 % of its impact speed at 1/600 s but 20 % at 1/2 400 s. (Nor is it the linear
//! spring-damper's `e = exp(−π ζ / √(1 − ζ²))`.) So the damping ratio is calibrated: before the
//! drops, [`restitution_dampratio`] bisects it until the part, landing flat at the drop's impact
//! speed, rebounds with [`DropSettings::restitution`] of it, the coefficient rapier applies. That
//! ties both engines to the same physical quantity instead of tuning one towards the other.

use indicatif::ProgressBar;
use perception::part::TriMesh;
use rayon::prelude::*;

use super::drop::GRAVITY;
use super::{DropBody, DropOutcome, DropSettings, StablePoseReport};
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
    let body = DropBody::new(mesh, density);
    let (mass, center_of_mass) = body.mass_and_com();
    let model = DropModel {
        part,
        body: &body,
        settings,
        dampratio: restitution_dampratio(part, &body, settings)?,
    };
    let batch = settings.batch.max(1);
    let starts: Vec<usize> = (0..settings.drops).step_by(batch).collect();
    let batches: Vec<Vec<DropOutcome>> = starts
        .par_iter()
        .map(|&first| {
            let count = batch.min(settings.drops - first);
            let out = model.simulate_batch(first, count);
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

/// Bounds of the damping-ratio search: critically damped up to heavily overdamped.
const DAMPRATIO_RANGE: (f64, f64) = (1.0, 8.0);

/// The contact damping ratio at which `part` (its drop `body`), landing flat in its modelled
/// orientation (part z up) at the drop's impact speed `√(2 g h)`, rebounds with
/// `settings.restitution` of that speed at `settings.dt` (see the module docs). Bisection over
/// [`DAMPRATIO_RANGE`]: the rebound falls as damping rises. A restitution the range cannot reach
/// gives the nearer end.
pub fn restitution_dampratio(
    part: &str,
    body: &DropBody,
    settings: &DropSettings,
) -> Result<f64, MujocoError> {
    crate::mujoco::ensure_available()?;
    let mut model = DropModel {
        part,
        body,
        settings,
        dampratio: 0.0,
    };
    let (mut lo, mut hi) = DAMPRATIO_RANGE;
    for _ in 0..20 {
        model.dampratio = 0.5 * (lo + hi);
        if model.flat_rebound()? > settings.restitution {
            lo = model.dampratio;
        } else {
            hi = model.dampratio;
        }
    }
    Ok(0.5 * (lo + hi))
}

/// One MuJoCo drop model's inputs: the part, its drop body and settings, the contact damping.
#[cfg_attr(not(feature = "mujoco"), allow(dead_code))]
struct DropModel<'a> {
    part: &'a str,
    body: &'a DropBody,
    settings: &'a DropSettings,
    dampratio: f64,
}

#[cfg(not(feature = "mujoco"))]
impl DropModel<'_> {
    fn flat_rebound(&self) -> Result<f64, MujocoError> {
        crate::mujoco::ensure_available().map(|()| 0.0)
    }

    fn simulate_batch(
        &self,
        _first: usize,
        _count: usize,
    ) -> Result<Vec<DropOutcome>, MujocoError> {
        crate::mujoco::ensure_available().map(|()| Vec::new())
    }
}

#[cfg(feature = "mujoco")]
impl DropModel<'_> {
    /// The compiled model of one free body per pose in `starts`, spaced so they never touch,
    /// above one plane.
    fn compile(
        &self,
        starts: &[nalgebra::Isometry3<f64>],
    ) -> Result<crate::mujoco::Compiled, MujocoError> {
        use nalgebra::{Isometry3, Vector3};

        use crate::mujoco::mjcf::{Mjcf, Options, pose_attrs};

        let props = &self.body.mass;
        let com = props.local_com;
        let frame = crate::convert::unit_quaternion_from_rot(&props.principal_inertia_local_frame);
        let inertia = props.principal_inertia();
        // The whole mesh is one convex piece, as rapier's drop uses the hull of every vertex.
        let hull = [self.body.mesh.vertices.clone()];
        let mut mjcf = Mjcf::new(Options {
            timestep: self.settings.dt,
            gravity: Vector3::new(0.0, 0.0, -GRAVITY),
            friction: self.settings.friction,
            contact_timeconst: 2.0 * self.settings.dt,
            contact_dampratio: self.dampratio,
            contact_impedance: 0.99,
            iterations: 50,
            noslip_iterations: 0,
        });
        let geoms = mjcf.piece_geoms(self.part, &hull, &Isometry3::identity())?;
        let spacing = 3.0 * self.body.diameter + 0.01;
        let side = (starts.len() as f64).sqrt().ceil() as usize;
        let half = spacing * side as f64;
        let mut world = format!(
            "    <geom type=\"plane\" size=\"{half} {half} 0.01\" pos=\"{} {} 0\"/>\n",
            half / 2.0,
            half / 2.0
        );
        let q = frame.quaternion();
        for (k, start) in starts.iter().enumerate() {
            let (i, j) = (k % side, k / side);
            let offset = Vector3::new((i as f64 + 0.5) * spacing, (j as f64 + 0.5) * spacing, 0.0);
            let pose =
                Isometry3::from_parts((start.translation.vector + offset).into(), start.rotation);
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
        crate::mujoco::compile(&mjcf, xml)
    }

    /// Rebound over impact speed of the part released 0.1 mm above the table in its modelled
    /// orientation (part z up), moving down at the drop's impact speed.
    fn flat_rebound(&self) -> Result<f64, MujocoError> {
        use mujoco_rs::prelude::MjData;
        use nalgebra::{Isometry3, UnitQuaternion, Vector3};

        use super::geometric_rest_height;

        let rotation = UnitQuaternion::identity();
        let z = geometric_rest_height(&self.body.mesh, &rotation) + 1e-4;
        let start = Isometry3::from_parts(Vector3::new(0.0, 0.0, z).into(), rotation);
        let compiled = self.compile(&[start])?;
        let mut data = MjData::new(&compiled.model);
        let impact = (2.0 * GRAVITY * self.settings.drop_height).sqrt();
        data.qvel_mut()[2] = -impact;
        let mut rebound = 0.0f64;
        let mut t = 0.0;
        while t < 0.02 {
            data.step();
            t += self.settings.dt;
            rebound = rebound.max(data.qvel()[2]);
        }
        Ok(rebound / impact)
    }

    /// Simulates drops `first..first + count` of the sequence in one model.
    fn simulate_batch(&self, first: usize, count: usize) -> Result<Vec<DropOutcome>, MujocoError> {
        use mujoco_rs::prelude::{MjData, MjtObjBase};
        use nalgebra::{Isometry3, Vector3};
        use rand::{RngExt, SeedableRng};
        use rand_chacha::ChaCha8Rng;

        use super::drop::{Motion, RestClock};
        use super::{geometric_rest_height, stratified_rotation};
        use crate::mujoco::mjcf::pose_from;

        let settings = self.settings;
        let mut seed_rng = ChaCha8Rng::seed_from_u64(settings.seed);
        let shift: [f64; 3] = [seed_rng.random(), seed_rng.random(), seed_rng.random()];
        let starts: Vec<Isometry3<f64>> = (0..count)
            .map(|k| {
                let rotation = stratified_rotation(first + k, shift);
                let z = geometric_rest_height(&self.body.mesh, &rotation) + settings.drop_height;
                Isometry3::from_parts(Vector3::new(0.0, 0.0, z).into(), rotation)
            })
            .collect();
        let compiled = self.compile(&starts)?;
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
        let mut clock = RestClock::new(ids.iter().map(|&id| pose_of(&data, id)).collect());
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
                if clock.tick(k, &p, settings) == Motion::Rested {
                    outcomes[k] = Some(DropOutcome {
                        rotation: p.rotation,
                        height: p.translation.z,
                        settled: true,
                        trapped: false,
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
                        trapped: false,
                        time: t,
                    }
                })
            })
            .collect())
    }
}
