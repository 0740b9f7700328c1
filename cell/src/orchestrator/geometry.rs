//! What the orchestrator knows about the cell for planning: frames, nominal targets, part shapes,
//! the gripper's fingers and the arm's kinematics, and parry collision queries among them.

use std::sync::Arc;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use parry3d_f64::query::distance;
use parry3d_f64::shape::{Cuboid, Shape};
use robots::kinematics::{Joints, SingularityPolicy, UrDh, UrKinematics, joint_distance};
use sim::cell::geometry::{CellGeometry, PartGeometry, destination_T_insertion};
use sim::config::{AssemblyStep, CellSpec, Destination, GripperSpec, NoiseSpec};
use sim::convert::pose_from_isometry;

use crate::scenario::Scenario;

/// Why the planning model of a cell could not be built.
#[derive(Debug, thiserror::Error)]
pub enum KnowledgeError {
    /// Part shapes could not be loaded.
    #[error("cell geometry: {0}")]
    Geometry(String),
    /// A step's target cannot be computed (its destination is not placed earlier).
    #[error("step {0}: its destination is not placed by an earlier step")]
    Target(usize),
}

/// The orchestrator's model of the cell (nominal: calibrated frames, exact targets).
#[allow(non_snake_case)]
pub struct CellKnowledge {
    /// The cell as the scenario describes it.
    pub spec: CellSpec,
    /// The assembly steps.
    pub steps: Vec<AssemblyStep>,
    /// Frames and shapes.
    pub geometry: CellGeometry,
    /// The scenario's arm kinematics with the gripper TCP (fingertip centre, `tcp_offset` below the flange).
    pub kinematics: UrKinematics,
    /// Nominal seated pose of each step's part in the base frame.
    pub base_T_targets: Vec<Isometry3<f64>>,
    /// Nominal insertion frame of each step (z out of the hole), base frame.
    pub base_T_insertions: Vec<Isometry3<f64>>,
    /// The cell's stated error model (the scenario's `[noise]`, which `cell check` holds the
    /// tolerances to): what the planner knows of how far a held part sits from its estimate.
    pub noise: NoiseSpec,
    dh: UrDh,
    finger: Arc<Cuboid>,
    palm: Arc<Cuboid>,
}

/// Height of the gripper body above the fingertips (the palm box starts there), metres.
const PALM_HEIGHT: f64 = 0.06;

/// Standard deviations of the stated errors the planner allows for where a held part truly
/// sits ([`CellKnowledge::held_drop`]): at 5, one insertion in about 3.5 million comes lower.
pub const HELD_ERROR_SIGMAS: f64 = 5.0;

impl CellKnowledge {
    /// The planning model of a scenario's cell.
    #[allow(non_snake_case)]
    pub fn new(scenario: &Scenario) -> Result<Arc<Self>, KnowledgeError> {
        let spec = &scenario.spec;
        let geometry = CellGeometry::new(&spec.cell, &spec.assembly, &scenario.catalog)
            .map_err(|e| KnowledgeError::Geometry(e.to_string()))?;
        let kinematics = scenario
            .robot
            .kinematics
            .clone()
            .with_tcp(Isometry3::translation(
                0.0,
                0.0,
                spec.cell.gripper.tcp_offset,
            ));
        let mut base_T_targets: Vec<Isometry3<f64>> = Vec::new();
        let mut base_T_insertions = Vec::new();
        for (i, s) in spec.assembly.iter().enumerate() {
            let dest = match &s.into {
                Destination::Fixture => geometry.base_T_fixture,
                Destination::Part(name) => {
                    let earlier = spec.assembly[..i]
                        .iter()
                        .rposition(|e| &e.part == name)
                        .ok_or(KnowledgeError::Target(i))?;
                    base_T_targets[earlier]
                }
            };
            base_T_targets.push(dest * s.target.isometry());
            base_T_insertions.push(dest * destination_T_insertion(s));
        }
        let g = &spec.cell.gripper;
        let finger = Arc::new(Cuboid::new(sim::convert::vec_from_vector(&Vector3::new(
            g.finger_width / 2.0,
            g.finger_thickness / 2.0,
            g.finger_length / 2.0,
        ))));
        let palm = Arc::new(Cuboid::new(sim::convert::vec_from_vector(&Vector3::new(
            0.02,
            g.stroke / 2.0 + g.finger_thickness,
            0.02,
        ))));
        Ok(Arc::new(Self {
            spec: spec.cell.clone(),
            steps: spec.assembly.clone(),
            geometry,
            kinematics,
            base_T_targets,
            base_T_insertions,
            noise: spec.noise.clone(),
            dh: scenario.robot.kinematics.dh,
            finger,
            palm,
        }))
    }

    /// The gripper spec.
    pub fn gripper(&self) -> &GripperSpec {
        &self.spec.gripper
    }

    /// Shapes of a part.
    pub fn part(&self, name: &str) -> Option<&PartGeometry> {
        self.geometry.parts.get(name)
    }

    /// How far apart the fingers open to grasp `part` closing along `closing_axis` (part
    /// frame): its width across the jaws plus the scenario's opening margins, at most the
    /// stroke ([`sim::config::GripperSpec::opening_for`]).
    pub fn grasp_opening(&self, part: &str, closing_axis: &Vector3<f64>) -> f64 {
        let g = &self.spec.gripper;
        let Some(p) = self.part(part) else {
            return g.stroke;
        };
        let axis = closing_axis.try_normalize(0.0).unwrap_or_else(Vector3::y);
        g.opening_for(sim::cell::gripper::width_across(&p.mesh.vertices, &axis))
    }

    /// Poses (base frame) of the two fingers `opening` metres apart for a TCP pose.
    #[allow(non_snake_case)]
    pub fn finger_poses(&self, base_T_tcp: &Isometry3<f64>, opening: f64) -> [Isometry3<f64>; 2] {
        let g = &self.spec.gripper;
        let y = opening.min(g.stroke) / 2.0 + g.finger_thickness / 2.0;
        let z = -g.finger_length / 2.0;
        [
            base_T_tcp * Isometry3::translation(0.0, -y, z),
            base_T_tcp * Isometry3::translation(0.0, y, z),
        ]
    }

    /// Smallest distance from the fingers at `base_T_tcp`, `opening` metres apart, to a shape at
    /// `base_T_shape` (zero when they touch or overlap).
    #[allow(non_snake_case)]
    pub fn finger_distance(
        &self,
        base_T_tcp: &Isometry3<f64>,
        opening: f64,
        shape: &dyn Shape,
        base_T_shape: &Isometry3<f64>,
    ) -> f64 {
        let other = pose_from_isometry(base_T_shape);
        self.finger_poses(base_T_tcp, opening)
            .iter()
            .map(|f| {
                distance(&pose_from_isometry(f), self.finger.as_ref(), &other, shape)
                    .map_or(0.0, |d| d.distance)
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// Smallest distance from the gripper (fingers and palm) and the held part at `base_T_tcp`
    /// to an obstacle.
    #[allow(non_snake_case)]
    pub fn gripper_distance(
        &self,
        base_T_tcp: &Isometry3<f64>,
        held: Option<(&PartGeometry, &Isometry3<f64>)>,
        obstacle: &dyn Shape,
        base_T_obstacle: &Isometry3<f64>,
    ) -> f64 {
        let other = pose_from_isometry(base_T_obstacle);
        let palm_pose = base_T_tcp
            * Isometry3::translation(0.0, 0.0, -(self.spec.gripper.finger_length + 0.02));
        let mut d = self
            .finger_distance(
                base_T_tcp,
                self.spec.gripper.stroke,
                obstacle,
                base_T_obstacle,
            )
            .min(
                distance(
                    &pose_from_isometry(&palm_pose),
                    self.palm.as_ref(),
                    &other,
                    obstacle,
                )
                .map_or(0.0, |d| d.distance),
            );
        if let Some((g, tcp_T_part)) = held {
            let p = pose_from_isometry(&(base_T_tcp * tcp_T_part));
            d = d.min(distance(&p, g.hull.as_ref(), &other, obstacle).map_or(0.0, |d| d.distance));
        }
        d
    }

    /// An upper bound on how far any point of the gripper (fingers, palm) or the held part lies
    /// from any joint axis of the arm, metres: the arm's link lengths and offsets, the TCP
    /// offset and [`Self::gripper_reach`]. A joint move's points travel at most this far per
    /// radian of summed joint travel.
    pub fn arm_reach(&self, held: Option<(&PartGeometry, &Isometry3<f64>)>) -> f64 {
        let d = &self.dh;
        [d.d1, d.a2, d.a3, d.d4, d.d5, d.d6]
            .iter()
            .map(|v| v.abs())
            .sum::<f64>()
            + self.spec.gripper.tcp_offset.abs()
            + self.gripper_reach(held)
    }

    /// How far from the TCP any point of the gripper (fingers at full stroke, palm) or the held
    /// part (`tcp_T_part`) lies, metres.
    #[allow(non_snake_case)]
    pub fn gripper_reach(&self, held: Option<(&PartGeometry, &Isometry3<f64>)>) -> f64 {
        let g = &self.spec.gripper;
        // The palm box spans up to finger_length + 0.04 above the fingertips, ±0.02 across.
        let gripper = (g.finger_length + 0.04)
            .hypot(0.02)
            .hypot(g.stroke / 2.0 + g.finger_thickness)
            .max(
                g.finger_length
                    .hypot(g.stroke / 2.0 + g.finger_thickness)
                    .hypot(g.finger_width),
            );
        held.map_or(gripper, |(p, tcp_T_part)| {
            p.mesh
                .vertices
                .iter()
                .map(|v| (tcp_T_part * v).coords.norm())
                .fold(gripper, f64::max)
        })
    }

    /// The highest point above the table (table z) of `shapes` at their poses (base frame),
    /// from their meshes; `None` when there are none.
    #[allow(non_snake_case)]
    pub fn highest_top(&self, shapes: &[(&PartGeometry, Isometry3<f64>)]) -> Option<f64> {
        let table_T_base = self.geometry.base_T_table.inverse();
        shapes
            .iter()
            .flat_map(|(g, t)| {
                let table_T_part = table_T_base * t;
                g.mesh.vertices.iter().map(move |v| (table_T_part * v).z)
            })
            .reduce(f64::max)
    }

    /// How far below its estimate (`tcp_T_part`) the lowest point of a held part can truly
    /// be, metres: [`HELD_ERROR_SIGMAS`] standard deviations of the cell's stated errors that
    /// move it along the tool axis: the grasp's residual offset (`noise.grasp_offset`), the
    /// arm's repeatability at the grasp and again at the insertion
    /// (`noise.robot_repeatability`), and the grasp's residual tilt (`noise.grasp_rotation`)
    /// about the part's centre times the farthest the part reaches across the tool axis from
    /// it. The part's pose on the table is snapped onto its stable pose, so perception adds
    /// nothing along it.
    #[allow(non_snake_case)]
    pub fn held_drop(&self, held: (&PartGeometry, &Isometry3<f64>)) -> f64 {
        let (g, tcp_T_part) = held;
        let centre = nalgebra::center(&g.aabb.0, &g.aabb.1);
        let across = g
            .mesh
            .vertices
            .iter()
            .map(|v| (tcp_T_part.rotation * (v - centre)).xy().norm())
            .fold(0.0, f64::max);
        let n = &self.noise;
        let variance = n.grasp_offset.powi(2)
            + 2.0 * n.robot_repeatability.powi(2)
            + (n.grasp_rotation * across).powi(2);
        HELD_ERROR_SIGMAS * variance.sqrt()
    }

    /// Lowest height above the table (table z) of the fingertips and the held part at a TCP pose.
    #[allow(non_snake_case)]
    pub fn lowest_height(
        &self,
        base_T_tcp: &Isometry3<f64>,
        held: Option<(&PartGeometry, &Isometry3<f64>)>,
    ) -> f64 {
        let table_T_base = self.geometry.base_T_table.inverse();
        let tip = (table_T_base * base_T_tcp).translation.z;
        let part = held.map(|(g, tcp_T_part)| {
            let t = table_T_base * base_T_tcp * tcp_T_part;
            g.mesh
                .vertices
                .iter()
                .map(|p| (t * p).z)
                .fold(f64::INFINITY, f64::min)
        });
        part.map_or(tip, |p| p.min(tip))
    }

    /// Lowest height above the table of the arm's joint frames (shoulder to flange) and the
    /// gripper body at joints `q`.
    pub fn arm_lowest_height(&self, q: &Joints) -> f64 {
        let table_T_base = self.geometry.base_T_table.inverse();
        let frames = self.dh.frames(q);
        // Frames 2.. are elbow, wrists and flange (the shoulder is fixed on the base).
        let mut low = frames[1..]
            .iter()
            .map(|f| (table_T_base * f).translation.z)
            .fold(f64::INFINITY, f64::min);
        let palm = self.kinematics.forward_tcp(q)
            * Isometry3::translation(0.0, 0.0, -(self.spec.gripper.finger_length + PALM_HEIGHT));
        low = low.min((table_T_base * palm).translation.z);
        low
    }

    /// The IK solutions for `base_T_tcp` within the joint limits (each joint at its
    /// 2π-equivalent nearest `near`), most preferred first: those on the same arm branch as
    /// `near` (elbow and wrist on the same side), so a joint move between them does not swing
    /// the wrist or elbow over, then the rest; nearest `near` first within each group. Never
    /// empty.
    #[allow(non_snake_case)]
    pub fn ik_solutions(
        &self,
        base_T_tcp: &Isometry3<f64>,
        near: &Joints,
    ) -> Result<Vec<Joints>, robots::kinematics::IkError> {
        let k = &self.kinematics;
        if !near.iter().all(|v| v.is_finite()) {
            // No current joints to be near: the kinematics say why.
            return k.inverse_nearest(base_T_tcp, near).map(|s| vec![s.joints]);
        }
        let reject_singular = k.singularity_policy == SingularityPolicy::Reject;
        let branch = |q: &Joints| (q[2].sin() >= 0.0, q[4].sin() >= 0.0);
        let mut all: Vec<Joints> = k
            .inverse_all(base_T_tcp, near[5])?
            .iter()
            .filter(|s| !reject_singular || s.singularities.is_empty())
            .filter_map(|s| k.joint_limits.wrap_nearest_all(&s.joints, near))
            .collect();
        if all.is_empty() {
            // The kinematics say why: nothing within the limits and the singularity policy.
            return k.inverse_nearest(base_T_tcp, near).map(|s| vec![s.joints]);
        }
        all.sort_by(|a, b| {
            (branch(a) != branch(near))
                .cmp(&(branch(b) != branch(near)))
                .then(joint_distance(a, near).total_cmp(&joint_distance(b, near)))
        });
        Ok(all)
    }

    /// The joints that put the TCP where `current` puts it with the arm highest above the table
    /// (elbow up), nearest `current` among those; `current` itself when it is already that high.
    pub fn safe_home(&self, current: &Joints) -> Joints {
        let tcp = self.kinematics.forward_tcp(current);
        let Ok(all) = self.kinematics.inverse_all(&tcp, current[5]) else {
            return *current;
        };
        let mut options: Vec<(f64, Joints)> = all
            .iter()
            .map(|s| (self.arm_lowest_height(&s.joints), s.joints))
            .collect();
        options.push((self.arm_lowest_height(current), *current));
        let highest = options
            .iter()
            .map(|o| o.0)
            .fold(f64::NEG_INFINITY, f64::max);
        // Within 1 cm of the highest arm, the configuration nearest the current one.
        options
            .iter()
            .filter(|o| o.0 >= highest - 0.01)
            .min_by(|a, b| {
                robots::kinematics::joint_distance(&a.1, current)
                    .total_cmp(&robots::kinematics::joint_distance(&b.1, current))
            })
            .map_or(*current, |o| o.1)
    }

    /// A top-down TCP pose at the grasp height over a part lying at `base_T_part`, with the
    /// closing direction (TCP y) along the grasp's closing axis; of the two equivalent jaw
    /// orientations, the one whose yaw is nearest `reference_yaw` (base frame).
    #[allow(non_snake_case)]
    pub fn grasp_tcp(
        &self,
        base_T_part: &Isometry3<f64>,
        closing_axis: &Vector3<f64>,
        grip_height: f64,
        reference_yaw: f64,
    ) -> Option<Isometry3<f64>> {
        let table_T_part = self.geometry.base_T_table.inverse() * base_T_part;
        let closing = table_T_part.rotation * closing_axis;
        let y = Vector3::new(closing.x, closing.y, 0.0).try_normalize(1e-9)?;
        let mut yaw = y.y.atan2(y.x);
        // The jaws are symmetric: y and −y give the same grasp.
        let wrap = |a: f64| {
            (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
        };
        if wrap(yaw + std::f64::consts::PI - reference_yaw).abs() < wrap(yaw - reference_yaw).abs()
        {
            yaw = wrap(yaw + std::f64::consts::PI);
        }
        let t = table_T_part.translation.vector;
        let table_T_tcp =
            Isometry3::from_parts(Translation3::new(t.x, t.y, grip_height), top_down(yaw));
        Some(self.geometry.base_T_table * table_T_tcp)
    }

    /// Yaw (about table z) of a top-down TCP's closing axis (TCP y).
    #[allow(non_snake_case)]
    pub fn tcp_yaw(&self, base_T_tcp: &Isometry3<f64>) -> f64 {
        let y = (self.geometry.base_T_table.inverse() * base_T_tcp).rotation * Vector3::y();
        y.y.atan2(y.x)
    }
}

/// A top-down TCP rotation (z down) whose closing axis (y) points at `yaw` in the table plane.
pub fn top_down(yaw: f64) -> UnitQuaternion<f64> {
    let y = Vector3::new(yaw.cos(), yaw.sin(), 0.0);
    let z = -Vector3::z();
    let x = y.cross(&z);
    UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_basis_unchecked(&[x, y, z]))
}
