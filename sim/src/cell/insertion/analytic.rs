//! The analytic capture model: clearance, lead-in chamfer, yaw fit and the two-point tilt jam of
//! a rigidly held part, decided in microseconds.
//!
//! - Missed: the leading face lands outside the chamfer (lateral offset on an axis, plus the
//!   corner swing of the yaw, beyond clearance/2 + lead-in); the part rests on the rim.
//! - Otherwise the chamfer guides it laterally into the clearance, and:
//!   - jammed when the tilt exceeds the angle at which the tilted part's cross-section over the
//!     engagement depth D no longer fits (`w cos θ + D tan θ > w + c`): it stops where the two
//!     corners wedge, at depth `(c + w (1 − cos θ)) / tan θ` into the fit;
//!   - jammed when the yaw exceeds what the clearance admits (stuck at the bottom of the chamfer);
//!   - seated otherwise: pressed flat on its seat, its leading face within clearance/2 laterally.
//!
//! Errors are measured on the held part's twin nearest seated ([`Mating::twins`]): a part with
//! exact symmetries about the insertion axis is judged by its smallest equivalent yaw.

use nalgebra::{Isometry3, Vector2};

use super::{InsertionResult, Mating, classify};

/// Scores an insertion that starts with the held part at `ins_T_part` (insertion frame).
#[allow(non_snake_case)]
pub fn score(mating: &Mating, ins_T_part: &Isometry3<f64>) -> InsertionResult {
    let start = mating.pose_error(ins_T_part);
    // The errors are the nearest twin's, and so is the pose built from them; the part ends in
    // its own frame.
    let twin = mating.twin(&ins_T_part.rotation);
    let (c, d) = (mating.clearance, mating.engagement);
    let end_pose = if mating.capture_reach(&start) > mating.capture() {
        mating.pose_with_error(
            start.lateral,
            d,
            start.yaw,
            start.tilt,
            start.tilt_direction,
        )
    } else {
        let h = c / 2.0;
        let centred = Vector2::new(start.lateral.x.clamp(-h, h), start.lateral.y.clamp(-h, h));
        let jam = mating.jam_angle(&start.tilt_direction);
        if start.tilt > jam {
            let w = mating.width_along(&start.tilt_direction);
            let entered = (c + w * (1.0 - start.tilt.cos())) / start.tilt.tan();
            let height = (d - entered).max(0.0);
            mating.pose_with_error(centred, height, start.yaw, start.tilt, start.tilt_direction)
        } else if start.yaw.abs() > mating.yaw_limit() {
            let height = (d - mating.lead_in).max(0.0);
            mating.pose_with_error(centred, height, start.yaw, start.tilt, start.tilt_direction)
        } else {
            mating.pose_with_error(centred, 0.0, start.yaw, 0.0, Vector2::zeros())
        }
    };
    let end_pose = if mating.twins.len() < 2 {
        end_pose
    } else {
        end_pose * twin.inverse()
    };
    let end = mating.pose_error(&end_pose);
    let (verdict, cause) = classify(mating, &start, &end);
    InsertionResult {
        verdict,
        cause,
        start,
        end,
        ins_T_part: end_pose,
    }
}

/// The analytic model as an [`InsertionScorer`](super::InsertionScorer).
#[derive(Debug, Clone, Copy, Default)]
pub struct Analytic;

impl super::InsertionScorer for Analytic {
    fn name(&self) -> &'static str {
        "analytic"
    }

    fn score(&self, case: &super::InsertionCase<'_>) -> Result<super::Scored, super::ScorerError> {
        Ok(super::Scored {
            result: score(case.mating, &case.ins_T_part),
            simulated_time: 0.0,
            steps: 0,
        })
    }
}
