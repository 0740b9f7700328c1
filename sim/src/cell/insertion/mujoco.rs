//! The MuJoCo contact simulation: the same convex pieces, friction and compliant [`Wrist`] as
//! the rapier scorer, in an independent engine.
//!
//! Generated model (see [`crate::mujoco::mjcf`]): the receivers' pieces are static world geoms;
//! the wrist is a carriage sliding down the axis of a mocap body that holds the start
//! orientation, its position and velocity set to the commanded path every step; the part hangs
//! on it by three slide joints and a ball joint whose anchors sit at the part's leading point
//! (the compliance centre), so the joint coordinates are exactly the wrist spring's deflections.
//! The lateral and rotational springs are joint stiffness and damping; the axial spring is a
//! position actuator whose force is clamped to the push force. The part starts at rest in the
//! world, as in rapier. `implicitfast` integrates the damping implicitly (the 5 kHz rotational
//! mode would be unstable explicitly at this step).
//!
//! The wrist does not move by the mocap body alone: MuJoCo gives mocap bodies no velocity, so a
//! part carried by one moved with the wrist only by being put somewhere new each step. It met
//! the rim at zero approach speed in MuJoCo's eyes, so the contact's damping never acted and the
//! part sank about two steps' travel (5 µm at 0.1 ms) into the rim's edge before it was pushed
//! out, sideways into the chamfer when the overlap was smaller than that: MuJoCo seated parts
//! that landed up to 5 µm beyond the capture band, where rapier (and geometry) leave them on the
//! rim. With the carriage's real velocity the contact brakes the landing and the band lies
//! within 1.6 µm of rapier's on every step and side (`cell scorers`). (The mocap still moves
//! sideways by the carriage's drift along its tilted axis, at most 16 µm over a descent, at
//! 0.1 mm/s: too slow to matter.)
//!
//! Contact settings, each with its physical reason (not tuned toward rapier): the parts are
//! rigid metal and plastic, so they must not sink into each other by more than a small part of
//! the tens-of-micron capture margins. MuJoCo's soft contacts sink by `(1 − d)/d · a / k` with
//! `k = 1/(τ² ζ²)` under a steady push, and by about `v τ / e` when the part lands at speed `v`;
//! the defaults (τ = 20 ms, d = 0.9) sink millimetres. So τ is two time steps (MuJoCo's floor)
//! and d = 0.99 (about 1 µm under the 5 N push), and the step is 0.1 ms so a part landing at
//! 25 mm/s sinks under 2 µm. Flat faces touch over an area, so multi-point convex contacts are on
//! (`multiccd`); friction is the parts' Coulomb friction with an elliptic cone (sliding only,
//! like rapier).

use super::wrist::WristWrench;
use super::{InsertionCase, InsertionScorer, Scored, ScorerError, Wrist};
use crate::mujoco::MujocoError;
use crate::mujoco::mjcf::Options;

/// MuJoCo's settings for the insertion (the wrist is shared with the other engines).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MujocoSettings {
    /// The compliant wrist pushing the part in.
    pub wrist: Wrist,
    /// Time step, seconds.
    pub dt: f64,
    /// Contact time constant, seconds (at least two time steps).
    pub contact_timeconst: f64,
    /// Contact impedance: the share of a push the contact resists at once.
    pub contact_impedance: f64,
    /// Solver iterations per step.
    pub iterations: usize,
    /// Iterations of the no-slip pass that removes soft friction's creep.
    pub noslip_iterations: usize,
}

impl Default for MujocoSettings {
    fn default() -> Self {
        Self {
            wrist: Wrist::default(),
            dt: 1e-4,
            contact_timeconst: 2e-4,
            contact_impedance: 0.99,
            iterations: 50,
            noslip_iterations: 0,
        }
    }
}

impl MujocoSettings {
    /// The generated model's options for a mating with this friction (no gravity: the wrist
    /// carries the part, as in the rapier scorer).
    pub fn options(&self, friction: f64) -> Options {
        Options {
            timestep: self.dt,
            gravity: nalgebra::Vector3::zeros(),
            friction,
            contact_timeconst: self.contact_timeconst,
            contact_dampratio: 1.0,
            contact_impedance: self.contact_impedance,
            iterations: self.iterations,
            noslip_iterations: self.noslip_iterations,
        }
    }
}

/// The MuJoCo contact simulation as an [`InsertionScorer`].
#[derive(Debug, Clone, Default)]
pub struct Mujoco {
    /// Engine and wrist settings.
    pub settings: MujocoSettings,
    /// Compiled models by their MJCF: the start pose is set at run time, so every insertion
    /// of a step with the same parts in the same places reuses one model.
    #[cfg(feature = "mujoco")]
    models: ModelCache,
}

impl Mujoco {
    /// A MuJoCo scorer with these settings.
    pub fn new(settings: MujocoSettings) -> Self {
        Self {
            settings,
            ..Self::default()
        }
    }
}

/// Compiled models shared by the threads scoring with one scorer.
#[cfg(feature = "mujoco")]
type ModelCache = std::sync::Arc<
    std::sync::Mutex<
        std::collections::HashMap<String, std::sync::Arc<mujoco_rs::prelude::MjModel>>,
    >,
>;

/// Mass and inertia of the wrist's carriage, kg and kg·m²: heavy enough that the 5 N push moves
/// it a few nanometres within a step before it is put back on its commanded path, light enough
/// to keep the contact solve well conditioned (at 1 kg the reset fed seated parts' chatter, and
/// at 1 000 kg the 2·10⁴ mass ratio did: either kept some parts from ever coming to rest).
#[cfg(feature = "mujoco")]
const WRIST_MASS: f64 = 10.0;

/// Most models kept: the agreement check has one per step, a simulated run one per step and
/// arrangement of the parts already placed.
#[cfg(feature = "mujoco")]
const CACHED_MODELS: usize = 16;

/// The MuJoCo scorer when this build has MuJoCo and the library is the right version.
pub(super) fn build() -> Result<std::sync::Arc<dyn InsertionScorer>, ScorerError> {
    crate::mujoco::ensure_available().map_err(|e| to_scorer_error(e, "mujoco"))?;
    Ok(std::sync::Arc::new(Mujoco::default()))
}

fn to_scorer_error(e: MujocoError, scorer: &'static str) -> ScorerError {
    match e {
        MujocoError::Unavailable(reason) => ScorerError::Unavailable { scorer, reason },
        MujocoError::Piece {
            part,
            piece,
            reason,
        } => ScorerError::Geometry {
            part,
            piece,
            reason,
        },
        MujocoError::Compile(reason) | MujocoError::Simulation(reason) => {
            ScorerError::Engine { scorer, reason }
        }
    }
}

impl InsertionScorer for Mujoco {
    fn name(&self) -> &'static str {
        "mujoco"
    }

    fn check_part(&self, part: &crate::cell::geometry::PartGeometry) -> Result<(), ScorerError> {
        super::check_pieces(part, "mujoco")?;
        check_part(part, &self.settings).map_err(|e| to_scorer_error(e, "mujoco"))
    }

    fn score(&self, case: &InsertionCase<'_>) -> Result<Scored, ScorerError> {
        self.simulate(case, false)
            .map(|(scored, _)| scored)
            .map_err(|e| to_scorer_error(e, "mujoco"))
    }

    fn score_with_wrench(
        &self,
        case: &InsertionCase<'_>,
    ) -> Result<(Scored, Vec<WristWrench>), ScorerError> {
        Mujoco::score_with_wrench(self, case)
    }
}

impl Mujoco {
    /// Scores one insertion and records the wrist's load through it
    /// ([`Wrist::spring_wrench`], every [`super::contact::WRENCH_SAMPLE_PERIOD`] and at the end),
    /// as the rapier simulation's [`super::contact::ContactRun::wrench`].
    pub fn score_with_wrench(
        &self,
        case: &InsertionCase<'_>,
    ) -> Result<(Scored, Vec<WristWrench>), ScorerError> {
        self.simulate(case, true)
            .map_err(|e| to_scorer_error(e, "mujoco"))
    }
}

#[cfg(not(feature = "mujoco"))]
fn check_part(
    _part: &crate::cell::geometry::PartGeometry,
    _settings: &MujocoSettings,
) -> Result<(), MujocoError> {
    crate::mujoco::ensure_available()
}

#[cfg(not(feature = "mujoco"))]
impl Mujoco {
    fn simulate(
        &self,
        _case: &InsertionCase<'_>,
        _record: bool,
    ) -> Result<(Scored, Vec<WristWrench>), MujocoError> {
        Err(crate::mujoco::ensure_available()
            .err()
            .unwrap_or_else(|| MujocoError::Unavailable("no MuJoCo in this build".into())))
    }
}

/// Compiles a model of `part` alone, so a piece MuJoCo rejects is found before a run.
#[cfg(feature = "mujoco")]
fn check_part(
    part: &crate::cell::geometry::PartGeometry,
    settings: &MujocoSettings,
) -> Result<(), MujocoError> {
    let mut mjcf = crate::mujoco::mjcf::Mjcf::new(settings.options(0.3));
    let geoms = mjcf.part_geoms(part, &nalgebra::Isometry3::identity())?;
    let body = format!(
        "    <body name=\"part\">\n      <freejoint/>\n      <inertial pos=\"0 0 0\" mass=\"1\" \
         diaginertia=\"1 1 1\"/>\n{geoms}    </body>\n"
    );
    let xml = mjcf.document(&body, "");
    crate::mujoco::compile(&mjcf, xml).map(|_| ())
}

/// Simulates one insertion: the wrist descends, the part settles or the time runs out.
#[cfg(feature = "mujoco")]
impl Mujoco {
    /// The compiled model of `xml`, from the cache or compiled now.
    fn model(
        &self,
        mjcf: &crate::mujoco::mjcf::Mjcf,
        xml: String,
    ) -> Result<std::sync::Arc<mujoco_rs::prelude::MjModel>, MujocoError> {
        let cached = self
            .models
            .lock()
            .map_err(|_| MujocoError::Simulation("the model cache is poisoned".into()))?
            .get(&xml)
            .cloned();
        if let Some(model) = cached {
            return Ok(model);
        }
        let compiled = crate::mujoco::compile(mjcf, xml)?;
        let model = std::sync::Arc::new(compiled.model);
        if let Ok(mut cache) = self.models.lock() {
            if cache.len() >= CACHED_MODELS {
                cache.clear();
            }
            cache.insert(compiled.xml, model.clone());
        }
        Ok(model)
    }

    #[allow(non_snake_case)]
    fn simulate(
        &self,
        case: &InsertionCase<'_>,
        record: bool,
    ) -> Result<(Scored, Vec<WristWrench>), MujocoError> {
        use mujoco_rs::prelude::{MjData, MjtObjBase};

        use super::InsertionResult;
        use crate::mujoco::mjcf::{Mjcf, pose_from};

        let settings = &self.settings;
        let mating = case.mating;
        let w = &settings.wrist;
        let start = mating.pose_error(&case.ins_T_part);
        let start_pose = w.start_pose(mating, &case.ins_T_part);

        let mut mjcf = Mjcf::new(settings.options(mating.friction));
        let ins_T_d = mating.destination_T_insertion.inverse();
        let mut world = String::new();
        for r in case.receivers {
            world += &mjcf.part_geoms(r.geometry, &(ins_T_d * r.destination_T_part))?;
        }
        let held = mjcf.part_geoms(case.held, &nalgebra::Isometry3::identity())?;
        let c = mating.lead_point;
        let lead = format!("{} {} {}", c.x, c.y, c.z);
        let (kl, kr, ka) = (
            w.lateral_stiffness,
            w.rotational_stiffness,
            w.axial_stiffness,
        );
        let (cl, cr, ca) = (
            w.damping(kl, w.mass),
            w.damping(kr, w.inertia),
            w.damping(ka, w.mass),
        );
        world += &format!(
            "    <body name=\"wrist\" mocap=\"true\">\n      <body name=\"carriage\">\n      \
         <joint name=\"descent\" type=\"slide\" axis=\"0 0 1\"/>\n      \
         <inertial pos=\"0 0 0\" mass=\"{WRIST_MASS}\" diaginertia=\"{WRIST_MASS} {WRIST_MASS} \
         {WRIST_MASS}\"/>\n      <body name=\"part\">\n        \
         <inertial pos=\"0 0 0\" mass=\"{}\" diaginertia=\"{i} {i} {i}\"/>\n        \
         <joint name=\"x\" type=\"slide\" axis=\"1 0 0\" pos=\"{lead}\" stiffness=\"{kl}\" \
         damping=\"{cl}\"/>\n        <joint name=\"y\" type=\"slide\" axis=\"0 1 0\" \
         pos=\"{lead}\" stiffness=\"{kl}\" damping=\"{cl}\"/>\n        <joint name=\"z\" \
         type=\"slide\" axis=\"0 0 1\" pos=\"{lead}\"/>\n        <joint name=\"r\" \
         type=\"ball\" pos=\"{lead}\" stiffness=\"{kr}\" damping=\"{cr}\"/>\n{held}      \
         </body>\n    </body>\n    </body>\n",
            w.mass,
            i = w.inertia,
        );
        let actuator = format!(
            "    <position joint=\"z\" kp=\"{ka}\" kv=\"{ca}\" forcerange=\"{} {}\"/>\n",
            -w.max_push, w.max_push
        );
        let xml = mjcf.document(&world, &actuator);
        let model = self.model(&mjcf, xml)?;
        let model = model.as_ref();
        let part = model
            .name_to_id(MjtObjBase::mjOBJ_BODY, "part")
            .ok_or_else(|| MujocoError::Compile("the generated model has no part body".into()))?;
        let joint = |name: &str| {
            model
                .name_to_id(MjtObjBase::mjOBJ_JOINT, name)
                .map(|id| {
                    (
                        model.jnt_qposadr()[id] as usize,
                        model.jnt_dofadr()[id] as usize,
                    )
                })
                .ok_or_else(|| {
                    MujocoError::Compile(format!("the generated model has no joint {name:?}"))
                })
        };
        let (descent_q, descent_v) = joint("descent")?;
        let mut data = MjData::new(model);
        // The wrist follows its commanded path exactly, with its velocity (set here, not in the
        // MJCF, so models are reused): the mocap body holds the start orientation, the carriage
        // slides down its axis at the descent speed, and the mocap is moved by the carriage's
        // sideways drift (its axis is tilted with the start pose) so the wrist stays on its
        // vertical path. The part starts at rest in the world, as in rapier.
        let axis = start_pose.rotation * nalgebra::Vector3::z();
        let q = start_pose.rotation.quaternion();
        data.mocap_quat_mut()[0] = [q.w, q.i, q.j, q.k];
        let set_wrist = |data: &mut MjData<&mujoco_rs::prelude::MjModel>, t: f64| {
            let path = w.pose_at(&start_pose, t).translation.vector;
            let s = path.z - start_pose.translation.z;
            let mocap = path - axis * s;
            data.mocap_pos_mut()[0] = [mocap.x, mocap.y, mocap.z];
            data.qpos_mut()[descent_q] = s;
            data.qvel_mut()[descent_v] = if w.bottomed(&start_pose, t) {
                0.0
            } else {
                -w.speed
            };
        };
        set_wrist(&mut data, 0.0);
        let (_, z_dof) = joint("z")?;
        data.qvel_mut()[z_dof] = w.speed;

        let dt = settings.dt;
        let mut t = 0.0;
        let mut still = 0.0;
        let mut steps = 0;
        let every = ((super::contact::WRENCH_SAMPLE_PERIOD / dt).round() as usize).max(1);
        let mut wrench = Vec::new();
        let load = |data: &MjData<&mujoco_rs::prelude::MjModel>, t: f64| {
            w.spring_wrench(
                t,
                &w.pose_at(&start_pose, t),
                &pose_from(&data.xpos()[part], &data.xquat()[part]),
                &mating.lead_point,
            )
        };
        while t < w.max_time {
            t += dt;
            steps += 1;
            data.step();
            set_wrist(&mut data, t);
            if record && steps % every == 0 {
                wrench.push(load(&data, t));
            }
            let v = data.object_velocity(MjtObjBase::mjOBJ_BODY, part, false);
            let angular = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            let linear = (v[3] * v[3] + v[4] * v[4] + v[5] * v[5]).sqrt();
            if !(linear.is_finite() && angular.is_finite()) {
                return Err(MujocoError::Simulation(format!(
                    "the part's velocity diverged after {steps} steps"
                )));
            }
            still = if w.bottomed(&start_pose, t) && w.is_still(mating, linear, angular) {
                still + dt
            } else {
                0.0
            };
            if still >= w.settle {
                break;
            }
        }
        if record && steps % every != 0 {
            wrench.push(load(&data, t));
        }
        let end_pose = pose_from(&data.xpos()[part], &data.xquat()[part]);
        let scored = Scored {
            result: InsertionResult::ended_at(mating, start, end_pose),
            simulated_time: t,
            steps,
        };
        Ok((scored, wrench))
    }
}
