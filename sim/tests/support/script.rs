//! A scripted pick-and-insert episode with perception excluded, for the sim crate's own tests
//! and benches (which cannot use the orchestrator in the `cell` crate above them): part poses
//! come from what the camera sees mapped through the calibrated (nominal) camera pose, so
//! calibration error, robot repeatability and grasp residuals act, but no pose estimator does.
//! It is test support, not library code: the orchestrator engine is the only driver the crates
//! ship.

use nalgebra::{Isometry3, Translation3};
use robots::robot::{LinearMotion, RobotError};
use serde::{Deserialize, Serialize};

use sim::cell::SimCell;
use sim::cell::error::CellError;
use sim::cell::insertion::{InsertionCause, Verdict};

/// Clearance above a part or target for approach moves, metres.
const APPROACH: f64 = 0.02;
/// Candidate parts tried before shaking the feeder.
const TRIES_PER_SHAKE: usize = 3;

/// Fast transfer moves.
const TRANSFER: LinearMotion = LinearMotion {
    speed: 0.25,
    acceleration: 1.2,
};
/// Slow final approach and insertion.
const INSERT: LinearMotion = LinearMotion {
    speed: 0.02,
    acceleration: 0.5,
};

/// What happened to one assembly step.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StepOutcome {
    /// Step index.
    pub step: usize,
    /// Grasps attempted.
    pub grasp_attempts: usize,
    /// Verdict of the insertion (`None`: no part could be picked).
    pub verdict: Option<Verdict>,
    /// Cause of the verdict.
    pub cause: Option<InsertionCause>,
}

/// An episode's outcome.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpisodeSummary {
    /// Per step, in order, up to the first failure.
    pub steps: Vec<StepOutcome>,
    /// Simulated cycle time, seconds.
    pub cycle_time: f64,
    /// Every step seated.
    pub success: bool,
}

/// Why the scripted episode stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum ScriptError {
    /// The cell refused a motion.
    #[error("robot: {0}")]
    Robot(#[from] RobotError),
    /// The feeder could not be shaken or refilled.
    #[error("cell: {0}")]
    Cell(#[from] CellError),
}

fn above(pose: &Isometry3<f64>, h: f64) -> Isometry3<f64> {
    Translation3::new(0.0, 0.0, h) * pose
}

/// Runs every assembly step: pick a visible part with a grasp, insert it at the step's target
/// (nominal grasp assumed in the hand), release, report.
pub fn run_episode(cell: &mut SimCell) -> Result<EpisodeSummary, ScriptError> {
    let model = cell.model().clone();
    let mut outcomes = Vec::new();
    let mut success = true;
    for (i, step) in model.steps.iter().enumerate() {
        let mut attempts = 0;
        let mut nominal_tcp_T_part = None;
        'pick: for _ in 0..=model.spec.feeder.max_shakes {
            let nominal_camera = cell.base_T_camera_nominal();
            let mut seen: Vec<(Isometry3<f64>, Isometry3<f64>)> = cell
                .camera_view()
                .into_iter()
                .filter(|c| c.part == step.part)
                .filter_map(|c| {
                    let base_T_part = nominal_camera * c.camera_T_part;
                    Some((model.grasp_tcp(&c.part, &base_T_part)?, base_T_part))
                })
                .collect();
            seen.truncate(TRIES_PER_SHAKE);
            for (grasp, base_T_part) in seen {
                attempts += 1;
                cell.move_l_sync(above(&grasp, APPROACH), TRANSFER)?;
                cell.move_l_sync(grasp, INSERT)?;
                cell.close_gripper_sync();
                let held = cell.held().is_some();
                if !held {
                    cell.open_gripper_sync();
                }
                cell.move_l_sync(above(&grasp, APPROACH), TRANSFER)?;
                if held {
                    nominal_tcp_T_part = Some(grasp.inverse() * base_T_part);
                    break 'pick;
                }
            }
            cell.shake()?;
        }
        let Some(tcp_T_part) = nominal_tcp_T_part else {
            outcomes.push(StepOutcome {
                step: i,
                grasp_attempts: attempts,
                verdict: None,
                cause: None,
            });
            success = false;
            break;
        };
        let Some(target) = cell.target(i) else {
            success = false;
            break;
        };
        let insert_tcp = target * tcp_T_part.inverse();
        cell.move_l_sync(above(&insert_tcp, APPROACH), TRANSFER)?;
        cell.move_l_sync(insert_tcp, INSERT)?;
        cell.open_gripper_sync();
        cell.move_l_sync(above(&insert_tcp, APPROACH), TRANSFER)?;
        let report = cell.last_release().cloned();
        let verdict = report.as_ref().map(|r| r.verdict);
        outcomes.push(StepOutcome {
            step: i,
            grasp_attempts: attempts,
            verdict,
            cause: report.map(|r| r.cause),
        });
        if verdict != Some(Verdict::Seated) {
            success = false;
            break;
        }
    }
    Ok(EpisodeSummary {
        steps: outcomes,
        cycle_time: cell.clock(),
        success,
    })
}
