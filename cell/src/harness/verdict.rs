//! The simulated cell's verdicts in the engine's terms: step outcomes, cause texts, and the
//! scenario parameter names of the error sources a failure is blamed on.

use sim::cell::ReleaseReport;
use sim::cell::insertion::{InsertionCause, Verdict};
use sim::cell::noise::{ErrorBudget, ErrorSource};

use crate::episode::{PoseError, StepOutcome};
use crate::orchestrator::InsertionCheck;

/// Yaw at insertion beyond which a jam is a half-turn from perception, radians (90°).
const HALF_TURN_SUSPECT: f64 = std::f64::consts::FRAC_PI_2;

/// The scenario parameter name of a simulated error source.
pub fn source_name(s: ErrorSource) -> &'static str {
    match s {
        ErrorSource::RobotRepeatability => "robot_repeatability",
        ErrorSource::CameraCalibration => "calibration_translation",
        ErrorSource::GraspResidual => "grasp_offset",
        ErrorSource::PerceptionAndPlanning => "perception",
    }
}

fn cause_text(c: &InsertionCause) -> Option<String> {
    Some(match c {
        InsertionCause::None => return None,
        InsertionCause::LateralBeyondCapture { offset, capture } => format!(
            "lateral offset {:.3} mm beyond the {:.3} mm capture band",
            offset * 1e3,
            capture * 1e3
        ),
        InsertionCause::TiltBeyondJam { tilt, jam_angle } => format!(
            "tilt {:.2}° beyond the {:.2}° jam angle",
            tilt.to_degrees(),
            jam_angle.to_degrees()
        ),
        InsertionCause::YawBeyondClearance { yaw, limit } => format!(
            "yaw {:.2}° beyond the {:.2}° the clearance allows",
            yaw.to_degrees(),
            limit.to_degrees()
        ),
        InsertionCause::StoppedShort { height } => {
            format!("stopped {:.3} mm short of seated", height * 1e3)
        }
        InsertionCause::OutOfTolerance { lateral, tilt } => format!(
            "fully down but out of tolerance: {:.3} mm lateral, {:.2}° tilt",
            lateral * 1e3,
            tilt.to_degrees()
        ),
        InsertionCause::ReleasedAwayFromTarget => "released away from the target".into(),
    })
}

/// Share of a lateral error along which a source must lie to be blamed for it.
const BLAME_SHARE: f64 = 0.2;

/// The error sources a lateral error is blamed on: each with at least a fifth of it along the
/// error, the largest share first.
pub fn blamed(budget: &ErrorBudget) -> Vec<String> {
    let mut shares = budget.shares.clone();
    shares.sort_by(|a, b| b.1.total_cmp(&a.1));
    shares
        .iter()
        .filter(|(_, s)| *s >= BLAME_SHARE)
        .map(|(s, _)| source_name(*s).to_string())
        .collect()
}

/// What a release (or held-insertion) report of the simulated cell says, in the engine's terms.
pub fn check_of(r: &ReleaseReport) -> InsertionCheck {
    let outcome = match r.verdict {
        Verdict::Seated => StepOutcome::Seated,
        Verdict::Jammed => StepOutcome::Jammed,
        Verdict::Missed => StepOutcome::Missed,
    };
    let mut sources = Vec::new();
    if let InsertionCause::YawBeyondClearance { yaw, .. } = r.cause
        && yaw.abs() > HALF_TURN_SUSPECT
    {
        // The lateral budget cannot speak for a part turned half a revolution: no calibration,
        // robot or grasp error turns a part that far (the jaws square it modulo a half-turn),
        // only a pose estimate that took a near-symmetric part the wrong way round.
        sources.push(source_name(ErrorSource::PerceptionAndPlanning).to_string());
    } else if outcome != StepOutcome::Seated
        && let Some(b) = &r.budget
    {
        sources = blamed(b);
    }
    let pose_error = r.insertion.as_ref().map(|i| PoseError {
        dx_mm: i.start.lateral.x * 1e3,
        dy_mm: i.start.lateral.y * 1e3,
        depth_mm: i.end.height * 1e3,
        tilt_deg: i.start.tilt.to_degrees(),
        yaw_deg: i.start.yaw.to_degrees(),
    });
    InsertionCheck {
        outcome,
        cause: cause_text(&r.cause),
        sources,
        pose_error,
        stop_height: r.insertion.as_ref().map(|i| i.end.height),
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector2;
    use sim::cell::noise::ErrorBudget;

    use super::*;

    fn jam(yaw: f64) -> ReleaseReport {
        ReleaseReport {
            step: Some(2),
            instance: 9,
            part: "top_shell".into(),
            insertion: None,
            verdict: Verdict::Jammed,
            cause: InsertionCause::YawBeyondClearance { yaw, limit: 0.0066 },
            budget: Some(ErrorBudget::new(
                vec![(ErrorSource::GraspResidual, Vector2::new(3e-5, 0.0))],
                Vector2::new(4e-5, 0.0),
            )),
        }
    }

    #[test]
    fn a_half_turn_jam_is_blamed_on_perception_a_small_yaw_on_the_lateral_budget() {
        assert_eq!(check_of(&jam(3.13)).sources, ["perception"]);
        assert_eq!(check_of(&jam(-3.12)).sources, ["perception"]);
        assert_eq!(check_of(&jam(0.01)).sources, ["grasp_offset", "perception"]);
    }
}
