//! The perception audit of the error budget: each detection the engine picks is checked against
//! the simulated world (is a part there, of that kind, in that stable pose, and how far off), and
//! a step that finds nothing counts the parts perception missed. Simulation only.
//!
//! A part with exact symmetries is judged against the twin of its true pose nearest the
//! estimate: a square peg seen a quarter turn off is right with no yaw error, a peg standing on
//! its top end is right when perceived standing on its bottom end (the symmetry maps one stable
//! pose onto the other), and a round peg (a 48-gon: `perception::part::round_axes`) turned about
//! its axis has no yaw error.

use nalgebra::{Isometry3, Unit, UnitQuaternion, Vector3};
use perception::DetectedPart;
use perception::part::StablePose;
use perception::symmetry::{nearest_twin_round, stable_pose_twins, symmetry_group};
use sim::cell::SimCell;
use sim::cell::feeder::FeederPart;
use sim::cell::geometry::PartGeometry;

use crate::episode::PerceptionVerdict;
use crate::orchestrator::PerceptionAudit;

/// A detection whose table position lies within this of a part's origin is that part, metres
/// (the parts are about 9 mm across; neighbours' origins lie farther apart).
pub const MATCH_RADIUS: f64 = 0.004;

/// The feeder part a detection refers to: the simulator's instance when perception knows it,
/// otherwise the part nearest to the estimate within [`MATCH_RADIUS`].
fn matched<'a>(cell: &'a SimCell, d: &DetectedPart) -> Option<&'a FeederPart> {
    let parts = cell.feeder_parts();
    if let Some(i) = d.truth_instance {
        return parts.iter().find(|p| p.instance == i);
    }
    let at = d.table_T_part.translation.vector.xy();
    parts
        .iter()
        .map(|p| ((p.table_T_part.translation.vector.xy() - at).norm(), p))
        .filter(|(dist, _)| *dist <= MATCH_RADIUS)
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, p)| p)
}

/// The name of the stable pose a part at `table_T_part` lies in: the class whose up direction
/// (in the part frame) is nearest to the table normal seen from the part.
#[allow(non_snake_case)]
fn stable_pose_of(cell: &SimCell, part: &str, table_T_part: &Isometry3<f64>) -> Option<String> {
    let part = cell.model().geometry.parts.get(part)?;
    let group = symmetry_group(&part.symmetries);
    StablePose::nearest_up_to(&part.stable_poses, &table_T_part.rotation, &group)
        .map(|(s, _)| s.name.clone())
}

/// Whether the stable pose named `seen` is the one named `truth`, or its twin under the part's
/// exact symmetries (the same resting state: a peg on either end).
fn same_resting_state(part: Option<&PartGeometry>, truth: &str, seen: &str) -> bool {
    if truth == seen {
        return true;
    }
    let Some(part) = part else {
        return false;
    };
    let group = symmetry_group(&part.symmetries);
    if group.len() < 2 {
        return false;
    }
    let named = |name: &str| part.stable_poses.iter().find(|s| s.name == name);
    match (named(truth), named(seen)) {
        (Some(a), Some(b)) => stable_pose_twins(a, b, &group),
        _ => false,
    }
}

/// Checks one detection against the world.
pub fn audit(cell: &SimCell, d: &DetectedPart) -> PerceptionAudit {
    let Some(truth) = matched(cell, d) else {
        return PerceptionAudit {
            verdict: PerceptionVerdict::Phantom,
            table_error: None,
        };
    };
    let geometry = cell.model().geometry.parts.get(&truth.part);
    let verdict = if truth.part != d.part {
        PerceptionVerdict::WrongPart
    } else if !stable_pose_of(cell, &truth.part, &truth.table_T_part)
        .is_some_and(|t| same_resting_state(geometry, &t, &d.stable_pose))
    {
        PerceptionVerdict::WrongStablePose
    } else {
        PerceptionVerdict::Right
    };
    let table_error = (verdict != PerceptionVerdict::WrongPart).then(|| {
        let group = geometry.map_or_else(Vec::new, |g| symmetry_group(&g.symmetries));
        let round = geometry.map_or(&[][..], |g| &g.round_axes);
        twin_table_error(&truth.table_T_part, &d.table_T_part, &group, round)
    });
    PerceptionAudit {
        verdict,
        table_error,
    }
}

/// Parts named `part` in the camera's view that no detection of that part matches.
pub fn missed(cell: &SimCell, part: &str, detections: &[DetectedPart]) -> usize {
    let seen: Vec<u32> = detections
        .iter()
        .filter(|d| d.part == part)
        .filter_map(|d| matched(cell, d).map(|p| p.instance))
        .collect();
    cell.camera_view()
        .iter()
        .filter(|p| p.part == part && !seen.contains(&p.instance))
        .count()
}

/// [`table_error`] against the twin of the truth nearest the estimate (`truth · g · r` for the
/// symmetry `g` of `group` and the turn `r` about an axis of `round` that bring it closest): with
/// the identity alone, [`table_error`]. A round peg's turn about its axis is no yaw error.
#[allow(non_snake_case)]
pub fn twin_table_error(
    truth: &Isometry3<f64>,
    estimate: &Isometry3<f64>,
    group: &[UnitQuaternion<f64>],
    round: &[Unit<Vector3<f64>>],
) -> [f64; 3] {
    if group.len() < 2 && round.is_empty() {
        return table_error(truth, estimate);
    }
    let g = nearest_twin_round(&estimate.rotation, &truth.rotation, group, round);
    table_error(&(truth * g), estimate)
}

/// Error of an estimate in the table plane: x, y in mm and yaw in degrees.
#[allow(non_snake_case)]
pub fn table_error(truth: &Isometry3<f64>, estimate: &Isometry3<f64>) -> [f64; 3] {
    let d = estimate.translation.vector - truth.translation.vector;
    let r = estimate.rotation * truth.rotation.inverse();
    let yaw = r.scaled_axis().z;
    [d.x * 1e3, d.y * 1e3, yaw.to_degrees()]
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use nalgebra::{Matrix6, Translation3, UnitQuaternion, Vector3};

    use super::*;
    use crate::harness::SimSetup;
    use crate::run::LoadedScenario;

    fn cell() -> SimCell {
        cell_of("usbc_nominal.toml")
    }

    fn cell_of(scenario: &str) -> SimCell {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../scenarios")
            .join(scenario);
        let loaded = LoadedScenario::load(&path).unwrap();
        SimSetup::new(loaded.scenario).unwrap().sim_cell(3).unwrap()
    }

    #[allow(non_snake_case)]
    fn detection(part: &str, table_T_part: Isometry3<f64>, stable_pose: &str) -> DetectedPart {
        DetectedPart {
            part: part.into(),
            index: 0,
            truth_instance: None,
            base_T_part: table_T_part,
            table_T_part,
            stable_pose: stable_pose.into(),
            confidence: 1.0,
            rms_px: 0.1,
            covariance: Matrix6::identity(),
        }
    }

    #[test]
    fn detections_are_judged_against_the_world() {
        let cell = cell();
        let truth = cell.feeder_parts()[0].clone();
        let pose = stable_pose_of(&cell, &truth.part, &truth.table_T_part).unwrap();
        // 1 mm and 2° off, same part and stable pose: right, with that error.
        let t = truth.table_T_part;
        let near = Isometry3::from_parts(
            Translation3::from(t.translation.vector + Vector3::new(0.001, 0.0, 0.0)),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 2f64.to_radians()) * t.rotation,
        );
        let a = audit(&cell, &detection(&truth.part, near, &pose));
        assert_eq!(a.verdict, PerceptionVerdict::Right);
        let [dx, dy, yaw] = a.table_error.unwrap();
        assert!(
            (dx - 1.0).abs() < 0.2 && dy.abs() < 0.2 && (yaw - 2.0).abs() < 1e-6,
            "{dx} {dy} {yaw}"
        );
        // Another stable pose's name for the same part.
        let other_pose = cell.model().geometry.parts[&truth.part]
            .stable_poses
            .iter()
            .find(|s| s.name != pose)
            .unwrap()
            .name
            .clone();
        let wrong_pose = audit(&cell, &detection(&truth.part, near, &other_pose));
        assert_eq!(wrong_pose.verdict, PerceptionVerdict::WrongStablePose);
        // Another kind of part there.
        let other_part = cell
            .feeder_parts()
            .iter()
            .find(|p| p.part != truth.part)
            .unwrap()
            .part
            .clone();
        let wrong_part = audit(&cell, &detection(&other_part, near, &pose));
        assert_eq!(wrong_part.verdict, PerceptionVerdict::WrongPart);
        // Nothing within reach of a point far off the feeder.
        let far = Isometry3::translation(1.0, 1.0, 0.0);
        assert_eq!(
            audit(&cell, &detection(&truth.part, far, &pose)).verdict,
            PerceptionVerdict::Phantom
        );
    }

    #[test]
    fn a_round_peg_standing_has_no_yaw_error_whatever_its_turn_and_a_square_one_has() {
        let pegs = cell_of("nist_pegs_nominal.toml");
        let (mut round, mut square) = (0, 0);
        for truth in pegs.feeder_parts() {
            let up = truth.table_T_part.rotation.inverse() * Vector3::z();
            if up.z.abs() < 0.99 {
                continue;
            }
            let pose = stable_pose_of(&pegs, &truth.part, &truth.table_T_part).unwrap();
            // 3°: under half a square's quarter turn, over half a 48-gon's 7.5° facet.
            let mut d = detection(&truth.part, turned(&truth.table_T_part, 0.05236), &pose);
            d.truth_instance = Some(truth.instance);
            let a = audit(&pegs, &d);
            assert_eq!(a.verdict, PerceptionVerdict::Right, "{}", truth.part);
            let [dx, dy, yaw] = a.table_error.unwrap();
            assert!(
                dx.abs() < 1e-9 && dy.abs() < 1e-9,
                "{}: {dx} {dy}",
                truth.part
            );
            let is_round = truth.part.starts_with("round_");
            (round, square) = if is_round {
                (round + 1, square)
            } else {
                (round, square + 1)
            };
            let expected = if is_round { 0.0 } else { 3.0 };
            assert!((yaw - expected).abs() < 1e-3, "{}: {yaw}", truth.part);
        }
        assert!(
            round >= 1 && square >= 1,
            "{round} round, {square} square pegs standing"
        );
    }

    /// `table_T_part` turned by `angle` about the table's vertical through the part's origin.
    #[allow(non_snake_case)]
    fn turned(table_T_part: &Isometry3<f64>, angle: f64) -> Isometry3<f64> {
        Isometry3::from_parts(
            table_T_part.translation,
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), angle) * table_T_part.rotation,
        )
    }

    #[test]
    fn a_symmetric_twin_of_the_truth_is_right_and_a_turn_of_an_asymmetric_part_is_not() {
        use std::f64::consts::{FRAC_PI_2, PI};

        let pegs = cell_of("nist_pegs_nominal.toml");
        let squares: Vec<FeederPart> = (pegs.feeder_parts().iter())
            .filter(|p| p.part.starts_with("square_"))
            .cloned()
            .collect();
        assert!(squares.len() >= 3);
        for truth in &squares {
            let geometry = &pegs.model().geometry.parts[&truth.part];
            assert!(!geometry.symmetries.is_empty(), "{}", truth.part);
            let pose = stable_pose_of(&pegs, &truth.part, &truth.table_T_part).unwrap();
            // Standing on an end, a quarter turn about the vertical is a symmetry; lying on a
            // side, only a half turn is (the peg is longer than wide).
            let up = truth.table_T_part.rotation.inverse() * Vector3::z();
            let turn = if up.z.abs() > 0.99 { FRAC_PI_2 } else { PI };
            let mut d = detection(&truth.part, turned(&truth.table_T_part, turn), &pose);
            d.truth_instance = Some(truth.instance);
            let a = audit(&pegs, &d);
            assert_eq!(a.verdict, PerceptionVerdict::Right, "{} {pose}", truth.part);
            let [dx, dy, yaw] = a.table_error.unwrap();
            assert!(
                dx.abs() < 1e-9 && dy.abs() < 1e-9 && yaw.abs() < 1e-6,
                "{} {pose}: {dx} {dy} {yaw}",
                truth.part
            );
            // The twin resting state (the other end, the opposite side) is merged into the one
            // class the catalog names: the truth turned end over end (a symmetry of the peg)
            // lies in it too, and is seen right; a side for an end, or an end for a side, is not.
            let poses = &geometry.stable_poses;
            let own = poses.iter().find(|s| s.name == pose).unwrap();
            let group = symmetry_group(&geometry.symmetries);
            let end_over_end = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), PI);
            let flipped = Isometry3::from_parts(
                truth.table_T_part.translation,
                truth.table_T_part.rotation * end_over_end,
            );
            assert_eq!(
                stable_pose_of(&pegs, &truth.part, &flipped).as_deref(),
                Some(pose.as_str()),
                "{} on its other end",
                truth.part
            );
            let mut f = detection(&truth.part, flipped, &pose);
            f.truth_instance = Some(truth.instance);
            assert_eq!(
                audit(&pegs, &f).verdict,
                PerceptionVerdict::Right,
                "{} {pose} on its other end",
                truth.part
            );
            let other = (poses.iter())
                .find(|s| !stable_pose_twins(own, s, &group))
                .unwrap();
            d.stable_pose = other.name.clone();
            assert_eq!(
                audit(&pegs, &d).verdict,
                PerceptionVerdict::WrongStablePose,
                "{} {pose} seen as {}",
                truth.part,
                other.name
            );
        }
        // A USB-C part declares no exact symmetry (near ones only): a quarter turn off is 90° of
        // yaw error, and its other stable poses stay wrong.
        let usbc = cell();
        let truth = usbc.feeder_parts()[0].clone();
        let symmetries = &usbc.model().geometry.parts[&truth.part].symmetries;
        assert_eq!(symmetry_group(symmetries).len(), 1);
        let pose = stable_pose_of(&usbc, &truth.part, &truth.table_T_part).unwrap();
        let mut d = detection(&truth.part, turned(&truth.table_T_part, FRAC_PI_2), &pose);
        d.truth_instance = Some(truth.instance);
        let a = audit(&usbc, &d);
        assert_eq!(a.verdict, PerceptionVerdict::Right);
        let yaw = a.table_error.unwrap()[2];
        assert!((yaw - 90.0).abs() < 1e-6, "{yaw}");
        for other in &usbc.model().geometry.parts[&truth.part].stable_poses {
            if other.name != pose {
                d.stable_pose = other.name.clone();
                assert_eq!(audit(&usbc, &d).verdict, PerceptionVerdict::WrongStablePose);
            }
        }
    }

    #[test]
    fn missed_counts_the_visible_parts_no_detection_matches() {
        let cell = cell();
        let part = cell.feeder_parts()[0].part.clone();
        let visible = cell.camera_view().iter().filter(|p| p.part == part).count();
        assert!(visible >= 2);
        assert_eq!(missed(&cell, &part, &[]), visible);
        let all: Vec<DetectedPart> = cell
            .feeder_parts()
            .iter()
            .filter(|p| p.part == part)
            .map(|p| detection(&part, p.table_T_part, "+z"))
            .collect();
        assert_eq!(missed(&cell, &part, &all), 0);
        assert_eq!(missed(&cell, &part, &all[1..]), 1);
    }
}
