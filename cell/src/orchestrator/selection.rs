//! Instance selection: which detected part to pick for a step.
//!
//! An instance qualifies when its stable pose has a catalog grasp, that grasp leads to the
//! step's insertion orientation (a part lying the wrong way up is never picked), the approach,
//! grasp and insertion poses are reachable by IK, and the open fingers clear every other
//! detection by a margin (parry distance against their convex hulls at the estimated poses) and
//! every part perception found but could not pose ([`UnposedObstacle`]: the space its mask
//! outlines on the table, up to the part's largest extent).
//! Qualified instances are ranked by perception confidence in bands of
//! [`SelectionConfig::confidence_band`] (confidences within a band are equally trustworthy);
//! ties are broken by the motion the pick and insertion need (the largest joint travel from the
//! arm's joints at selection to the grasp plus from the grasp to the insertion, a proxy for their
//! time), then by the estimated position (table x, then y), so the choice is deterministic.

use nalgebra::{Isometry3, Vector3};
use parry3d_f64::shape::SharedShape;
use perception::UnposedPart;
use perception::part::Catalog;
use robots::kinematics::Joints;
use sim::convert::vec_from_point;

use super::geometry::CellKnowledge;
use crate::scenario::DEFAULT_MIN_PICK_CONFIDENCE;
use perception::DetectedPart;

/// Selection tuning.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SelectionConfig {
    /// Smallest distance between an open finger and a neighbouring part, metres.
    pub finger_margin: f64,
    /// Largest angle between the part's resting up direction and the direction it must face
    /// at its target, radians.
    pub max_orientation_error: f64,
    /// Smallest confidence a detection needs to be considered.
    pub min_confidence: f64,
    /// Height of the approach pose above the grasp, metres.
    pub approach_height: f64,
    /// Width of the confidence bands instances are ranked in.
    pub confidence_band: f64,
}

impl Default for SelectionConfig {
    fn default() -> Self {
        Self {
            finger_margin: 0.0005,
            max_orientation_error: 10f64.to_radians(),
            min_confidence: DEFAULT_MIN_PICK_CONFIDENCE,
            approach_height: 0.015,
            confidence_band: 0.05,
        }
    }
}

/// Why a detection was not chosen.
#[derive(Debug, Clone, PartialEq)]
pub enum Rejection {
    /// Another part than the step needs.
    OtherPart,
    /// Confidence below the threshold.
    LowConfidence(f64),
    /// Its stable pose has no grasp (e.g. upside down).
    NoGraspForPose(String),
    /// The grasp would not present the part the way the target needs.
    WrongOrientation(String),
    /// A pose of the pick or the insertion has no IK solution.
    Unreachable(String),
    /// An open finger would come closer than the margin to a neighbour.
    NeighbourTooClose {
        /// The neighbour's detection index.
        neighbour: usize,
        /// The distance, metres.
        distance: f64,
    },
    /// An open finger would come closer than the margin to a part perception found but could
    /// not pose.
    UnposedTooClose {
        /// The unposed part's catalog name.
        part: String,
        /// The distance, metres.
        distance: f64,
    },
}

/// A part perception found but could not pose, as the fingers must avoid it: the convex hull,
/// in the robot base frame, of what its mask outlines between the table and the part's largest
/// extent above it.
#[derive(Debug, Clone)]
pub struct UnposedObstacle {
    /// Catalog name.
    pub part: String,
    /// The hull, in the base frame.
    pub hull: SharedShape,
}

impl UnposedObstacle {
    /// The obstacle of `unposed`, its points in the frame of the table at `base_T_table`;
    /// `None` when they span no volume (a mask whose rays all missed the table).
    #[allow(non_snake_case)]
    pub fn new(unposed: &UnposedPart, base_T_table: &Isometry3<f64>) -> Option<Self> {
        let points: Vec<_> = unposed
            .table_points
            .iter()
            .map(|p| vec_from_point(&(base_T_table * p)))
            .collect();
        Some(Self {
            part: unposed.part.clone(),
            hull: perception::part::convex_hull_shape(&points)?,
        })
    }

    /// The obstacles of a frame's `unposed` parts on the table at `base_T_table`, leaving out
    /// those that span no volume.
    #[allow(non_snake_case)]
    pub fn all(unposed: &[UnposedPart], base_T_table: &Isometry3<f64>) -> Vec<Self> {
        (unposed.iter())
            .filter_map(|u| Self::new(u, base_T_table))
            .collect()
    }
}

/// A chosen instance with its grasp.
#[derive(Debug, Clone, PartialEq)]
#[allow(non_snake_case)]
pub struct Selection {
    /// The detection.
    pub detection: DetectedPart,
    /// TCP pose that grasps it.
    pub base_T_grasp: Isometry3<f64>,
    /// The part in the TCP frame as estimated at the grasp.
    pub tcp_T_part: Isometry3<f64>,
    /// How far apart the fingers open for it, metres ([`CellKnowledge::grasp_opening`]).
    pub opening: f64,
    /// Largest joint travel from the arm's joints → grasp plus grasp → insertion, radians (the
    /// tie-breaker).
    pub travel: f64,
}

/// The outcome of a selection: the chosen instance, and why each other one was not.
#[derive(Debug, Clone, PartialEq)]
pub struct SelectionResult {
    /// The best qualified instance.
    pub chosen: Option<Selection>,
    /// (detection index, reason) of each rejected detection of the step's part.
    pub rejected: Vec<(usize, Rejection)>,
}

impl SelectionResult {
    /// A short summary of the rejections (for causes and logs).
    pub fn summary(&self) -> String {
        let mut counts: std::collections::BTreeMap<&str, usize> = Default::default();
        for (_, r) in &self.rejected {
            let k = match r {
                Rejection::OtherPart => continue,
                Rejection::LowConfidence(_) => "low confidence",
                Rejection::NoGraspForPose(_) => "no grasp for its stable pose (wrong way up)",
                Rejection::WrongOrientation(_) => "wrong orientation for the target",
                Rejection::Unreachable(_) => "unreachable",
                Rejection::NeighbourTooClose { .. } => "neighbour too close for the fingers",
                Rejection::UnposedTooClose { .. } => {
                    "a part found but not posed too close for the fingers"
                }
            };
            *counts.entry(k).or_default() += 1;
        }
        if counts.is_empty() {
            return "no instance detected".into();
        }
        counts
            .iter()
            .map(|(k, n)| format!("{n} {k}"))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// What the open fingers come nearest to.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Neighbour {
    /// The posed detection with this index.
    Posed(usize),
    /// A part found but not posed, by catalog name.
    Unposed(String),
}

/// How near the fingers of a TCP at `base_T_grasp`, open `opening` metres apart, come to
/// anything else on the table, and to what: every detection but the one with index `own` (its
/// convex hull at its pose), and every part found but not posed; `None` when there is nothing
/// else.
#[allow(non_snake_case)]
pub fn nearest_to_fingers(
    knowledge: &CellKnowledge,
    (base_T_grasp, opening): (&Isometry3<f64>, f64),
    own: usize,
    detections: &[DetectedPart],
    unposed: &[UnposedObstacle],
) -> Option<(f64, Neighbour)> {
    let posed = detections
        .iter()
        .filter(|n| n.index != own)
        .filter_map(|n| {
            let hull = knowledge.part(&n.part)?.hull.as_ref();
            let distance = knowledge.finger_distance(base_T_grasp, opening, hull, &n.base_T_part);
            Some((distance, Neighbour::Posed(n.index)))
        });
    let base = Isometry3::identity();
    let found = unposed.iter().map(|u| {
        let distance = knowledge.finger_distance(base_T_grasp, opening, u.hull.as_ref(), &base);
        (distance, Neighbour::Unposed(u.part.clone()))
    });
    posed.chain(found).min_by(|a, b| a.0.total_cmp(&b.0))
}

/// Chooses the instance of step `step`'s part to pick among `detections`, whose fingers clear
/// `unposed` too, for an arm at joints `home` (the grasp's jaw orientation, of the two the
/// parallel jaws allow, is the one nearest the arm's current wrist yaw).
#[allow(non_snake_case)]
pub fn select(
    knowledge: &CellKnowledge,
    catalog: &Catalog,
    step: usize,
    detections: &[DetectedPart],
    unposed: &[UnposedObstacle],
    home: &Joints,
    config: &SelectionConfig,
) -> SelectionResult {
    let mut rejected = Vec::new();
    let mut qualified: Vec<Selection> = Vec::new();
    let Some(s) = knowledge.steps.get(step) else {
        return SelectionResult {
            chosen: None,
            rejected,
        };
    };
    let part = catalog.part(&s.part);
    let base_T_target = knowledge.base_T_targets[step];
    let base_T_ins = knowledge.base_T_insertions[step];
    let home_tcp = knowledge.kinematics.forward_tcp(home);
    let home_yaw = knowledge.tcp_yaw(&home_tcp);
    // The direction, in the part frame, that must point up (out of the hole) at the target.
    let up_at_target = base_T_target.rotation.inverse() * (base_T_ins.rotation * Vector3::z());
    for d in detections {
        if d.part != s.part {
            rejected.push((d.index, Rejection::OtherPart));
            continue;
        }
        if d.confidence < config.min_confidence {
            rejected.push((d.index, Rejection::LowConfidence(d.confidence)));
            continue;
        }
        let (Some(part), Some(pose)) = (part, part.and_then(|p| p.stable_pose(&d.stable_pose)))
        else {
            rejected.push((d.index, Rejection::NoGraspForPose(d.stable_pose.clone())));
            continue;
        };
        let Some(grasp) = part.grasp_for(&d.stable_pose) else {
            rejected.push((d.index, Rejection::NoGraspForPose(d.stable_pose.clone())));
            continue;
        };
        let up = Vector3::from(pose.up_in_part);
        let angle = up.normalize().dot(&up_at_target).clamp(-1.0, 1.0).acos();
        if angle > config.max_orientation_error {
            rejected.push((
                d.index,
                Rejection::WrongOrientation(format!(
                    "lies on \"{}\", {:.0}° from the target's up",
                    d.stable_pose,
                    angle.to_degrees()
                )),
            ));
            continue;
        }
        let Some(base_T_grasp) = knowledge.grasp_tcp(
            &d.base_T_part,
            &Vector3::from(grasp.closing_axis),
            grasp.grip_height,
            home_yaw,
        ) else {
            rejected.push((d.index, Rejection::NoGraspForPose(d.stable_pose.clone())));
            continue;
        };
        let tcp_T_part = base_T_grasp.inverse() * d.base_T_part;
        let approach = nalgebra::Translation3::new(0.0, 0.0, config.approach_height) * base_T_grasp;
        let insert = base_T_target * tcp_T_part.inverse();
        let mut q = *home;
        let mut unreachable = None;
        let mut travel = 0.0;
        for (what, pose) in [
            ("approach", approach),
            ("grasp", base_T_grasp),
            ("insert", insert),
        ] {
            match knowledge.kinematics.inverse_nearest(&pose, &q) {
                Ok(sol) => {
                    if what != "grasp" {
                        travel += sol
                            .joints
                            .iter()
                            .zip(&q)
                            .map(|(a, b)| (a - b).abs())
                            .fold(0.0, f64::max);
                    }
                    q = sol.joints;
                }
                Err(e) => {
                    unreachable = Some(format!("{what}: {e}"));
                    break;
                }
            }
        }
        if let Some(why) = unreachable {
            rejected.push((d.index, Rejection::Unreachable(why)));
            continue;
        }
        let opening = knowledge.grasp_opening(&d.part, &Vector3::from(grasp.closing_axis));
        let near = nearest_to_fingers(
            knowledge,
            (&base_T_grasp, opening),
            d.index,
            detections,
            unposed,
        );
        if let Some((distance, neighbour)) = near
            && distance < config.finger_margin
        {
            let why = match neighbour {
                Neighbour::Posed(neighbour) => Rejection::NeighbourTooClose {
                    neighbour,
                    distance,
                },
                Neighbour::Unposed(part) => Rejection::UnposedTooClose { part, distance },
            };
            rejected.push((d.index, why));
            continue;
        }
        qualified.push(Selection {
            detection: d.clone(),
            base_T_grasp,
            tcp_T_part,
            opening,
            travel,
        });
    }
    let band = |c: f64| (c / config.confidence_band.max(1e-9)).floor();
    qualified.sort_by(|a, b| {
        let (ca, cb) = (band(a.detection.confidence), band(b.detection.confidence));
        if ca != cb {
            return cb.total_cmp(&ca);
        }
        if (a.travel - b.travel).abs() > 1e-9 {
            return a.travel.total_cmp(&b.travel);
        }
        let (ta, tb) = (
            a.detection.table_T_part.translation,
            b.detection.table_T_part.translation,
        );
        ta.x.total_cmp(&tb.x).then(ta.y.total_cmp(&tb.y))
    });
    SelectionResult {
        chosen: qualified.into_iter().next(),
        rejected,
    }
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use nalgebra::{Matrix6, Point3, Translation3, UnitQuaternion};

    use super::*;
    use crate::harness::SimSetup;
    use crate::scenario::Scenario;

    /// A face-up main shell at the nominal cell's feeder centre, posed, and the cell's home.
    #[allow(non_snake_case)]
    fn shell_at_the_feeder() -> (SimSetup, DetectedPart) {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/usbc_nominal.toml");
        let setup = SimSetup::new(Scenario::load(&path).unwrap()).unwrap();
        let k = &setup.engine.knowledge;
        let [x, y] = k.spec.feeder.center;
        let spec = setup.engine.scenario.catalog.part("main_shell").unwrap();
        let table_T_part = spec.stable_pose("+z").unwrap().table_T_part(x, y, 0.3);
        let shell = DetectedPart {
            part: "main_shell".into(),
            index: 0,
            truth_instance: None,
            base_T_part: k.geometry.base_T_table * table_T_part,
            table_T_part,
            stable_pose: "+z".into(),
            confidence: 0.9,
            rms_px: 1.0,
            covariance: Matrix6::identity() * 1e-10,
        };
        (setup, shell)
    }

    /// An unposed top shell's space: a box `size` wide and 9 mm tall centred at table (x, y).
    fn unposed_box(x: f64, y: f64, size: f64) -> UnposedPart {
        let h = size / 2.0;
        let table_points = [(-h, -h), (h, -h), (-h, h), (h, h)]
            .iter()
            .flat_map(|(dx, dy)| [0.0, 0.009].map(|z| Point3::new(x + dx, y + dy, z)))
            .collect();
        UnposedPart {
            part: "top_shell".into(),
            table_points,
        }
    }

    #[test]
    fn the_nearest_thing_to_the_open_fingers_is_measured_from_their_faces() {
        let (setup, shell) = shell_at_the_feeder();
        let k = &setup.engine.knowledge;
        let spec = setup.engine.scenario.catalog.part("main_shell").unwrap();
        let grasp = spec.grasp_for("+z").unwrap();
        let base_T_grasp = k
            .grasp_tcp(
                &shell.base_T_part,
                &Vector3::from(grasp.closing_axis),
                grasp.grip_height,
                0.0,
            )
            .unwrap();
        let alone = nearest_to_fingers(
            k,
            (&base_T_grasp, k.gripper().stroke),
            0,
            std::slice::from_ref(&shell),
            &[],
        );
        assert_eq!(alone, None, "the grasped part itself is not a neighbour");
        // 2 cm boxes, 9 mm tall (beside the fingers, which reach down to the grip height),
        // 5 cm out along the closing axis and 3 cm out across it.
        let g = k.gripper();
        let yaw = k.tcp_yaw(&base_T_grasp);
        let centre = Translation3::from(shell.table_T_part.translation.vector.xy().push(0.0));
        let base_T_table = &k.geometry.base_T_table;
        // Box faces square to the closing axis.
        let box_at = |along: f64, across: f64| {
            let turn = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw);
            let mut turned = unposed_box(0.0, 0.0, 0.02);
            for p in &mut turned.table_points {
                *p = centre * (turn * Point3::new(p.x + along, p.y + across, p.z));
            }
            UnposedObstacle::new(&turned, base_T_table).unwrap()
        };
        let along = nearest_to_fingers(
            k,
            (&base_T_grasp, k.gripper().stroke),
            0,
            &[],
            &[box_at(0.05, 0.0)],
        )
        .unwrap();
        let outer_face = g.stroke / 2.0 + g.finger_thickness;
        assert!((along.0 - (0.04 - outer_face)).abs() < 1e-9, "{along:?}");
        let both = [box_at(0.05, 0.0), box_at(0.0, 0.03)];
        let (distance, what) =
            nearest_to_fingers(k, (&base_T_grasp, k.gripper().stroke), 0, &[], &both).unwrap();
        assert!(
            (distance - (0.02 - g.finger_width / 2.0)).abs() < 1e-9,
            "{distance}"
        );
        assert_eq!(what, Neighbour::Unposed("top_shell".into()));
        // A posed neighbour nearer than both is the one reported.
        let mut near = shell.clone();
        near.index = 1;
        let offset = Vector3::new(-0.012 * yaw.sin(), 0.012 * yaw.cos(), 0.0);
        near.table_T_part.translation.vector += offset;
        near.base_T_part = base_T_table * near.table_T_part;
        let (d, what) = nearest_to_fingers(
            k,
            (&base_T_grasp, k.gripper().stroke),
            0,
            &[shell.clone(), near],
            &both,
        )
        .unwrap();
        assert_eq!(what, Neighbour::Posed(1));
        assert!(d < 0.02 - g.finger_width / 2.0, "{d}");
    }

    #[test]
    fn the_fingers_keep_clear_of_a_part_found_but_not_posed() {
        let (setup, shell) = shell_at_the_feeder();
        let (k, catalog) = (&setup.engine.knowledge, &setup.engine.scenario.catalog);
        let home = setup.model.home;
        let config = SelectionConfig::default();
        let select_with = |unposed: &[UnposedObstacle]| {
            select(
                k,
                catalog,
                0,
                std::slice::from_ref(&shell),
                unposed,
                &home,
                &config,
            )
        };
        let alone = select_with(&[]);
        assert!(alone.chosen.is_some(), "{:?}", alone.rejected);
        // Something found but not posed where the fingers go down: the shell is not picked.
        let [x, y] = k.spec.feeder.center;
        let base_T_table = &k.geometry.base_T_table;
        let over = UnposedObstacle::new(&unposed_box(x, y, 0.02), base_T_table).unwrap();
        let blocked = select_with(&[over]);
        assert!(blocked.chosen.is_none());
        assert!(
            matches!(
                &blocked.rejected[..],
                [(0, Rejection::UnposedTooClose { part, distance })]
                    if part == "top_shell" && *distance < config.finger_margin
            ),
            "{:?}",
            blocked.rejected
        );
        assert!(blocked.summary().contains("found but not posed"));
        // The same 5 cm away leaves the fingers room.
        let away = UnposedObstacle::new(&unposed_box(x + 0.05, y, 0.02), base_T_table).unwrap();
        assert!(select_with(&[away]).chosen.is_some());
        // A mask whose rays all missed the table spans nothing.
        let flat = UnposedPart {
            part: "top_shell".into(),
            table_points: vec![Point3::new(x, y, 0.0); 4],
        };
        assert!(UnposedObstacle::new(&flat, base_T_table).is_none());
    }

    /// With `cell.gripper.opening_margin` the fingers open to the part plus the margins, and
    /// the room is checked there: a neighbour 1 mm beyond a finger opened to the part leaves
    /// room, and the same neighbour is in the way of fingers opened the full stroke.
    #[test]
    #[allow(non_snake_case)]
    fn the_room_for_the_fingers_is_checked_at_the_opening_they_open_to() {
        let (setup, shell) = shell_at_the_feeder();
        let (k, catalog) = (&setup.engine.knowledge, &setup.engine.scenario.catalog);
        let g = k.gripper();
        let margin = g
            .opening_margin
            .expect("the nominal scenario sets a margin");
        let home = setup.model.home;
        let config = SelectionConfig::default();
        let alone = select(
            k,
            catalog,
            0,
            std::slice::from_ref(&shell),
            &[],
            &home,
            &config,
        );
        let chosen = alone.chosen.expect("the shell alone is picked");
        let spec = catalog.part("main_shell").unwrap();
        let axis = Vector3::from(spec.grasp_for("+z").unwrap().closing_axis);
        let mesh = catalog.load_mesh(spec).unwrap();
        let width = sim::cell::gripper::width_across(&mesh.vertices, &axis.normalize());
        assert!((chosen.opening - (width + 2.0 * margin)).abs() < 1e-12);
        assert!(chosen.opening < g.stroke);
        // A 2 cm box, square to the closing axis, its near face 1 mm beyond the outer face of
        // a finger opened to the part.
        let base_T_table = &k.geometry.base_T_table;
        let [left, right] = k.finger_poses(&chosen.base_T_grasp, chosen.opening);
        let along = (base_T_table
            .inverse_transform_vector(&(right.translation.vector - left.translation.vector)))
        .xy()
        .normalize();
        let across = Vector3::new(-along.y, along.x, 0.0).xy();
        let centre = shell.table_T_part.translation.vector.xy();
        let face = chosen.opening / 2.0 + g.finger_thickness + 0.001;
        let table_points = [(0.0, -0.01), (0.0, 0.01), (0.02, -0.01), (0.02, 0.01)]
            .iter()
            .flat_map(|&(a, c)| {
                let p = centre + along * (face + a) + across * c;
                [0.0, 0.009].map(|z| Point3::new(p.x, p.y, z))
            })
            .collect();
        let beside = UnposedPart {
            part: "top_shell".into(),
            table_points,
        };
        let obstacle = UnposedObstacle::new(&beside, base_T_table).unwrap();
        let near = select(
            k,
            catalog,
            0,
            std::slice::from_ref(&shell),
            std::slice::from_ref(&obstacle),
            &home,
            &config,
        );
        assert!(near.chosen.is_some(), "{:?}", near.rejected);
        // The full stroke puts the finger into the box.
        assert!(
            k.finger_distance(
                &chosen.base_T_grasp,
                g.stroke,
                obstacle.hull.as_ref(),
                &Isometry3::identity()
            ) < config.finger_margin
        );
    }
}
