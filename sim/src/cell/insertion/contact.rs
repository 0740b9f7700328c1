//! The contact simulation: rapier at millimetre scale pushes the held part's real convex pieces
//! into the receivers' pieces through a compliant wrist, so chamfers guide it or it jams.
//!
//! The wrist is a kinematic body descending along the insertion axis; the part hangs on it by a
//! six-axis spring (a remote-centre-compliance device with its centre at the part's leading
//! face): lateral and rotational springs, and an axial spring whose force is capped (the push
//! force). The moving mass is the compliant platform with the fingers and the part. The world is
//! in metres with rapier's length unit set to 0.1 mm (the parts are millimetres, the clearances
//! tens of microns), so contact tolerances are a fraction of a micron, and the contact softness
//! is stiffened (2 kHz) so a 5 N push sinks less than 0.1 µm.
//!
//! Contacts are predicted 30 µm ahead (more than the part travels in a step), recycled contacts
//! are off (they may be microns stale), and penetrations are pushed out at up to 5 cm/s: with
//! rapier's length-unit-scaled defaults a part that grazed a wall stuck to it. Near the capture
//! boundary this scorer seats a few more parts than the analytic model (the compliant wrist
//! lets a corner that landed a few microns onto the rim yaw off it): 2.6 % of boundary samples
//! disagree (`cell scorers`).

use nalgebra::Isometry3;
use rapier3d_f64::prelude::{
    ColliderBuilder, GenericJointBuilder, JointAxesMask, JointAxis, MassProperties, MotorModel,
    PhysicsWorld, RigidBodyBuilder, Vector,
};

pub use super::wrist::WristWrench;
use super::{InsertionResult, Mating, ReceiverPart, Wrist};
use crate::cell::geometry::PartGeometry;
use crate::convert::{isometry_from_pose, pose_from_isometry, vec_from_point};

/// Rapier's solver settings for the insertion (the wrist is shared with the other engines).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactSettings {
    /// The compliant wrist pushing the part in.
    pub wrist: Wrist,
    /// Time step, seconds.
    pub dt: f64,
    /// Natural frequency of the contact constraints' softness, Hz (rapier's default of 30–60 Hz
    /// lets a 5 N push sink tens of microns into the chamfers at this scale).
    pub contact_frequency: f64,
    /// Solver iterations per step.
    pub solver_iterations: usize,
    /// Rapier's length unit, metres: its contact tolerances (allowed penetration 0.5 %,
    /// predictive distance 2 %) scale with it, so it must be well under the clearances.
    pub length_unit: f64,
    /// Gap under which contacts are predicted, metres: more than the part travels in a step, so
    /// it never tunnels into a chamfer before the solver sees the contact.
    pub prediction_distance: f64,
    /// Fastest speed at which the solver pushes out a penetration, m/s (rapier's default of
    /// 3 length units per second is 0.3 mm/s here: a part that grazed a wall would stick to it).
    pub max_corrective_velocity: f64,
    /// Fastest the part may move, m/s: a sanity bound only. (Rapier's default, 400 length units
    /// per second, is 4 cm/s here: barely above the 2.5 cm/s descent.)
    pub max_speed: f64,
}

impl Default for ContactSettings {
    fn default() -> Self {
        Self {
            wrist: Wrist::default(),
            dt: 5e-4,
            contact_frequency: 2000.0,
            solver_iterations: 8,
            length_unit: 1e-4,
            prediction_distance: 3e-5,
            max_corrective_velocity: 0.05,
            max_speed: 1.0,
        }
    }
}

/// The rapier contact simulation as an [`InsertionScorer`](super::InsertionScorer).
#[derive(Debug, Clone, Copy, Default)]
pub struct Rapier {
    /// Solver and wrist settings.
    pub settings: ContactSettings,
}

impl super::InsertionScorer for Rapier {
    fn name(&self) -> &'static str {
        "contact"
    }

    fn check_part(&self, part: &PartGeometry) -> Result<(), super::ScorerError> {
        super::check_pieces(part, "contact")
    }

    fn score(&self, case: &super::InsertionCase<'_>) -> Result<super::Scored, super::ScorerError> {
        self.score_with_wrench(case).map(|(scored, _)| scored)
    }

    fn score_with_wrench(
        &self,
        case: &super::InsertionCase<'_>,
    ) -> Result<(super::Scored, Vec<WristWrench>), super::ScorerError> {
        let run = simulate(
            case.mating,
            case.held,
            case.receivers,
            &case.ins_T_part,
            &self.settings,
        );
        Ok((
            super::Scored {
                result: run.result,
                simulated_time: run.simulated_time,
                steps: run.steps,
            },
            run.wrench,
        ))
    }
}

/// What the simulation did, next to its result.
#[derive(Debug, Clone, PartialEq)]
pub struct ContactRun {
    /// The scored insertion.
    pub result: InsertionResult,
    /// Simulated seconds.
    pub simulated_time: f64,
    /// Physics steps taken.
    pub steps: usize,
    /// The wrist's load through the insertion ([`Wrist::spring_wrench`]), every
    /// [`WRENCH_SAMPLE_PERIOD`] and at the end.
    pub wrench: Vec<WristWrench>,
}

/// How often the engines record the wrist's load, s: the UR controller's 500 Hz, the rate at which
/// a real arm's sensor reading reaches a program.
pub const WRENCH_SAMPLE_PERIOD: f64 = 0.002;

/// Simulates an insertion that starts with the held part at `ins_T_part` (insertion frame,
/// lateral and angular error as given; it is lifted to just clear of the receivers).
#[allow(non_snake_case)]
pub fn simulate(
    mating: &Mating,
    held: &PartGeometry,
    receivers: &[ReceiverPart<'_>],
    ins_T_part: &Isometry3<f64>,
    settings: &ContactSettings,
) -> ContactRun {
    let start = mating.pose_error(ins_T_part);
    let w = &settings.wrist;
    let start_pose = w.start_pose(mating, ins_T_part);

    let mut world = PhysicsWorld::new();
    world.gravity = Vector::ZERO;
    world.integration_parameters.dt = settings.dt;
    world.integration_parameters.length_unit = settings.length_unit;
    world.integration_parameters.num_solver_iterations = settings.solver_iterations.max(1);
    world.integration_parameters.normalized_prediction_distance =
        settings.prediction_distance / settings.length_unit;
    world
        .integration_parameters
        .normalized_max_corrective_velocity =
        settings.max_corrective_velocity / settings.length_unit;
    world.integration_parameters.normalized_max_linear_velocity =
        settings.max_speed / settings.length_unit;
    // Recycled contacts may be a few microns stale: too coarse for tens-of-micron clearances.
    world.integration_parameters.contact_recycling = false;
    for softness in [
        &mut world.integration_parameters.contact_softness,
        &mut world.integration_parameters.static_contact_softness,
    ] {
        softness.natural_frequency = settings.contact_frequency;
    }

    let ins_T_d = mating.destination_T_insertion.inverse();
    let fixed = world.bodies.insert(RigidBodyBuilder::fixed().build());
    for r in receivers {
        let pose = ins_T_d * r.destination_T_part;
        for piece in &r.geometry.pieces.pieces {
            let pts: Vec<Vector> = piece.iter().map(|p| vec_from_point(&(pose * p))).collect();
            if let Some(c) = ColliderBuilder::convex_hull(&pts) {
                world.colliders.insert_with_parent(
                    c.friction(mating.friction).build(),
                    fixed,
                    &mut world.bodies,
                );
            }
        }
    }

    let part = world.bodies.insert(
        RigidBodyBuilder::dynamic()
            .pose(pose_from_isometry(&start_pose))
            .additional_mass_properties(MassProperties::new(
                Vector::ZERO,
                w.mass,
                Vector::splat(w.inertia),
            ))
            .can_sleep(false)
            .build(),
    );
    for piece in &held.pieces.pieces {
        let pts: Vec<Vector> = piece.iter().map(vec_from_point).collect();
        if let Some(c) = ColliderBuilder::convex_hull(&pts) {
            world.colliders.insert_with_parent(
                c.density(0.0).friction(mating.friction).build(),
                part,
                &mut world.bodies,
            );
        }
    }
    let wrist = world.bodies.insert(
        RigidBodyBuilder::kinematic_position_based()
            .pose(pose_from_isometry(&start_pose))
            .build(),
    );
    let centre = pose_from_isometry(&Isometry3::translation(
        mating.lead_point.x,
        mating.lead_point.y,
        mating.lead_point.z,
    ));
    let mut joint = GenericJointBuilder::new(JointAxesMask::empty())
        .local_frame1(centre)
        .local_frame2(centre);
    for (axis, k, m) in [
        (JointAxis::LinX, w.lateral_stiffness, w.mass),
        (JointAxis::LinY, w.lateral_stiffness, w.mass),
        (JointAxis::LinZ, w.axial_stiffness, w.mass),
        (JointAxis::AngX, w.rotational_stiffness, w.inertia),
        (JointAxis::AngY, w.rotational_stiffness, w.inertia),
        (JointAxis::AngZ, w.rotational_stiffness, w.inertia),
    ] {
        joint = joint
            .motor_model(axis, MotorModel::ForceBased)
            .motor_position(axis, 0.0, k, w.damping(k, m));
    }
    joint = joint.motor_max_force(JointAxis::LinZ, w.max_push);
    world
        .impulse_joints
        .insert(wrist, part, joint.build(), true);

    let dt = settings.dt;
    let mut t = 0.0;
    let mut still = 0.0;
    let mut steps = 0;
    let every = ((WRENCH_SAMPLE_PERIOD / dt).round() as usize).max(1);
    let mut wrench = Vec::new();
    let load = |world: &PhysicsWorld, t: f64| {
        w.spring_wrench(
            t,
            &w.pose_at(&start_pose, t),
            &isometry_from_pose(world.bodies[part].position()),
            &mating.lead_point,
        )
    };
    while t < w.max_time {
        t += dt;
        steps += 1;
        world.bodies[wrist]
            .set_next_kinematic_position(pose_from_isometry(&w.pose_at(&start_pose, t)));
        world.step();
        if steps % every == 0 {
            wrench.push(load(&world, t));
        }
        let rb = &world.bodies[part];
        let at_rest = w.is_still(mating, rb.linvel().length(), rb.angvel().length());
        still = if w.bottomed(&start_pose, t) && at_rest {
            still + dt
        } else {
            0.0
        };
        if still >= w.settle {
            break;
        }
    }
    if steps % every != 0 {
        wrench.push(load(&world, t));
    }
    let end_pose = isometry_from_pose(world.bodies[part].position());
    ContactRun {
        result: InsertionResult::ended_at(mating, start, end_pose),
        simulated_time: t,
        steps,
        wrench,
    }
}
