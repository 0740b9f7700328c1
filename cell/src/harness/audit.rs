//! The perception audit of the error budget: each detection the engine picks is checked against
//! the simulated world (is a part there, of that kind, in that stable pose, and how far off), and
//! a step that finds nothing counts the parts perception missed. Simulation only.

use nalgebra::{Isometry3, Vector3};
use perception::DetectedPart;
use sim::cell::SimCell;
use sim::cell::feeder::FeederPart;

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
    let up = table_T_part.rotation.inverse() * Vector3::z();
    cell.model()
        .geometry
        .parts
        .get(part)?
        .stable_poses
        .iter()
        .max_by(|a, b| {
            let dot = |s: &[f64; 3]| Vector3::from(*s).dot(&up);
            dot(&a.up_in_part).total_cmp(&dot(&b.up_in_part))
        })
        .map(|s| s.name.clone())
}

/// Checks one detection against the world.
pub fn audit(cell: &SimCell, d: &DetectedPart) -> PerceptionAudit {
    let Some(truth) = matched(cell, d) else {
        return PerceptionAudit {
            verdict: PerceptionVerdict::Phantom,
            table_error: None,
        };
    };
    let verdict = if truth.part != d.part {
        PerceptionVerdict::WrongPart
    } else if stable_pose_of(cell, &truth.part, &truth.table_T_part).as_deref()
        != Some(d.stable_pose.as_str())
    {
        PerceptionVerdict::WrongStablePose
    } else {
        PerceptionVerdict::Right
    };
    PerceptionAudit {
        verdict,
        table_error: (verdict != PerceptionVerdict::WrongPart)
            .then(|| table_error(&truth.table_T_part, &d.table_T_part)),
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

    use nalgebra::{Matrix6, Translation3, UnitQuaternion};

    use super::*;
    use crate::harness::SimSetup;
    use crate::run::LoadedScenario;

    fn cell() -> SimCell {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/usbc_nominal.toml");
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
