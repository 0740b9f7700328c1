//! What stays the same across episodes of a scenario: specs, shapes, kinematics, home pose.

use std::sync::{Arc, OnceLock};

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use perception::part::Catalog;
use robots::kinematics::{IkError, Joints, UrKinematics, joint_distance};
use robots::limited::Limited;
use robots::limits::InvalidLimits;
use robots::robot::Robot;
use robots::ur_arm::UrArm;

use super::error::CellError;
use super::feasible::check_feasible;
use super::feeder_window::calibrated_feeder_window;
use super::geometry::{CellGeometry, PartGeometry, destination_T_insertion};
use super::insertion::{InsertionScorer, Scorer};
use crate::config::{AssemblyStep, CellSpec, Destination, NoiseSpec};
use crate::render::CentreRays;
use crate::scene::PartModel;

/// Height of the home TCP above the feeder centre, metres.
const HOME_HEIGHT: f64 = 0.15;
/// A UR elbow-up, wrist-down configuration used to pick the home IK branch.
const HOME_REFERENCE: Joints = [
    -std::f64::consts::FRAC_PI_2,
    -std::f64::consts::FRAC_PI_2,
    std::f64::consts::FRAC_PI_2,
    -std::f64::consts::FRAC_PI_2,
    -std::f64::consts::FRAC_PI_2,
    0.0,
];

/// The IK solution for `base_T_tcp` that keeps the arm highest above the table (elbow up: the
/// lowest of the elbow, wrist and flange frames as high as it can be); among those within 1 cm
/// of the highest, the one nearest [`HOME_REFERENCE`].
#[allow(non_snake_case)]
fn elbow_up(
    kinematics: &UrKinematics,
    base_T_table: &Isometry3<f64>,
    base_T_tcp: &Isometry3<f64>,
) -> Result<Joints, IkError> {
    let dh = &kinematics.dh;
    let table_T_base = base_T_table.inverse();
    let lowest = |q: &Joints| {
        dh.frames(q)[1..]
            .iter()
            .map(|f| (table_T_base * f).translation.z)
            .fold(f64::INFINITY, f64::min)
    };
    let all = kinematics.inverse_all(base_T_tcp, HOME_REFERENCE[5])?;
    let highest = all
        .iter()
        .map(|s| lowest(&s.joints))
        .fold(f64::NEG_INFINITY, f64::max);
    let best = all
        .iter()
        .filter(|s| lowest(&s.joints) >= highest - 0.01)
        .min_by(|a, b| {
            joint_distance(&a.joints, &HOME_REFERENCE)
                .total_cmp(&joint_distance(&b.joints, &HOME_REFERENCE))
        });
    match best {
        Some(s) => Ok(s.joints),
        None => kinematics
            .inverse_nearest(base_T_tcp, &HOME_REFERENCE)
            .map(|s| s.joints),
    }
}

/// The fixed part of a simulated cell, shared (behind an `Arc`) by every episode.
#[derive(Debug)]
pub struct CellModel {
    /// The cell as the scenario describes it.
    pub spec: CellSpec,
    /// The assembly steps in order.
    pub steps: Vec<AssemblyStep>,
    /// The error sources.
    pub noise: NoiseSpec,
    /// Which scorer decides insertions.
    pub scorer: Scorer,
    /// That scorer, built with its default settings.
    pub insertion: Arc<dyn InsertionScorer>,
    /// Frames and part shapes.
    pub geometry: CellGeometry,
    /// The arm's kinematics (from the scenario's robot description) with the gripper's TCP.
    pub kinematics: UrKinematics,
    /// Joints at the start of every episode: TCP pointing down above the feeder.
    pub home: Joints,
    /// Render and physics models of the feeder's parts (dropped placement, rendered captures).
    pub part_models: Vec<PartModel>,
    /// Render model of the fixture (a seat check's view of the nest); `None` when the catalog
    /// part has none.
    pub fixture_model: Option<PartModel>,
    /// The camera's centre rays over the feeder window, computed by the first rendered capture
    /// and shared by every episode's.
    feeder_rays: OnceLock<Option<CentreRays>>,
}

impl CellModel {
    /// Checks the scenario and builds the shared model for the arm `arm` (the scenario's
    /// `cell.robot`, loaded with [`UrArm::from_file`]).
    pub fn new(
        spec: &CellSpec,
        arm: &UrArm,
        steps: &[AssemblyStep],
        noise: &NoiseSpec,
        catalog: &Catalog,
        scorer: Scorer,
    ) -> Result<Arc<Self>, CellError> {
        let mut problems = check_feasible(spec, arm, steps, noise, catalog);
        if let Some(problem) = spec.gripper.actuation_time_problem() {
            problems.push(("cell.gripper.actuation_time".into(), problem));
        }
        if !problems.is_empty() {
            return Err(CellError::Infeasible(problems));
        }
        let geometry = CellGeometry::new(spec, steps, catalog)?;
        let insertion = scorer.build()?;
        for part in geometry.parts.values() {
            insertion.check_part(part)?;
        }
        let kinematics = arm.kinematics.clone().with_tcp(Isometry3::translation(
            0.0,
            0.0,
            spec.gripper.tcp_offset,
        ));
        let [cx, cy] = spec.feeder.center;
        let home_tcp = geometry.base_T_table
            * Isometry3::from_parts(
                Translation3::new(cx, cy, HOME_HEIGHT),
                UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
            );
        let home = elbow_up(&kinematics, &geometry.base_T_table, &home_tcp)
            .map_err(|e| CellError::Home(e.to_string()))?;
        let names: Vec<String> = spec.feeder.parts.keys().cloned().collect();
        let part_models =
            PartModel::from_catalog(catalog, &names).map_err(|e| CellError::Drop(e.to_string()))?;
        let fixture_model =
            PartModel::from_catalog(catalog, std::slice::from_ref(&spec.fixture.part))
                .ok()
                .and_then(|mut m| m.pop());
        Ok(Arc::new(Self {
            spec: spec.clone(),
            steps: steps.to_vec(),
            noise: noise.clone(),
            scorer,
            insertion,
            geometry,
            kinematics,
            home,
            part_models,
            fixture_model,
            feeder_rays: OnceLock::new(),
        }))
    }

    /// `robot` (the simulated cell, or a handle on it) wrapped with the cell's limits and
    /// kinematics, so every commanded target is checked: how the cell is driven as a robot.
    pub fn limited<R: Robot>(&self, robot: R) -> Result<Limited<R>, InvalidLimits> {
        Limited::new(robot, self.spec.limits.clone(), self.kinematics.clone())
    }

    /// The centre rays of the window a rendered capture covers (see [`calibrated_feeder_window`]);
    /// `None` when the feeder is not in the calibrated camera's view.
    pub fn feeder_rays(&self) -> Option<&CentreRays> {
        self.feeder_rays
            .get_or_init(|| {
                calibrated_feeder_window(&self.spec)
                    .map(|w| CentreRays::new(&self.spec.camera.intrinsics, w))
            })
            .as_ref()
    }

    /// The shapes of a part.
    pub fn part(&self, name: &str) -> Result<&PartGeometry, CellError> {
        self.geometry.part(name)
    }

    /// The nominal seated pose of step `step`'s part in the base frame, with every earlier part
    /// seated exactly (what a planner knows before anything is measured).
    pub fn nominal_target(&self, step: usize) -> Option<Isometry3<f64>> {
        let s = self.steps.get(step)?;
        let dest = match &s.into {
            Destination::Fixture => self.geometry.base_T_fixture,
            Destination::Part(name) => {
                let earlier = self.steps[..step].iter().rposition(|e| &e.part == name)?;
                self.nominal_target(earlier)?
            }
        };
        Some(dest * s.target.isometry())
    }

    /// The insertion frame of step `step` for a destination at `base_T_destination`.
    pub fn insertion_frame(
        &self,
        step: usize,
        base_T_destination: &Isometry3<f64>,
    ) -> Option<Isometry3<f64>> {
        Some(base_T_destination * destination_T_insertion(self.steps.get(step)?))
    }

    /// A top-down TCP pose that grasps a part lying at `base_T_part` with the catalog grasp of its
    /// stable pose: TCP over the part centre at the grip height, z down, closing (TCP y) along
    /// the part's closing axis. `None` when the part's pose has no grasp.
    pub fn grasp_tcp(&self, part: &str, base_T_part: &Isometry3<f64>) -> Option<Isometry3<f64>> {
        let g = self.geometry.parts.get(part)?;
        let table_T_part = self.geometry.base_T_table.inverse() * base_T_part;
        let pose = g.stable_pose_of(&table_T_part)?;
        let grasp = g.grasps.iter().find(|gr| gr.stable_pose == pose.name)?;
        let closing = table_T_part.rotation * Vector3::from(grasp.closing_axis);
        let y = Vector3::new(closing.x, closing.y, 0.0).try_normalize(1e-9)?;
        let z = -Vector3::z();
        let x = y.cross(&z);
        let r = nalgebra::Rotation3::from_basis_unchecked(&[x, y, z]);
        let t = table_T_part.translation.vector;
        let table_T_tcp = Isometry3::from_parts(
            Translation3::new(t.x, t.y, grasp.grip_height),
            UnitQuaternion::from_rotation_matrix(&r),
        );
        Some(self.geometry.base_T_table * table_T_tcp)
    }
}
