//! How an insertion ended: the verdict, its cause, and [`classify`], which every scorer shares to
//! decide them from the pose errors at the start and end.

use nalgebra::Isometry3;
use serde::{Deserialize, Serialize};

use super::mating::Mating;
use super::pose_error::PoseError;

/// How an insertion ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// Fully inserted within the step's tolerances.
    Seated,
    /// Entered the lead-in but stuck (or ended out of tolerance).
    Jammed,
    /// Never entered the lead-in: resting on the rim or beside the target.
    Missed,
}

/// Why an insertion was not seated (or `None` when it was).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum InsertionCause {
    /// Seated: nothing went wrong.
    None,
    /// The leading face was laterally beyond clearance/2 + lead-in on one axis (metres).
    LateralBeyondCapture {
        /// Offset on the worst axis, including the reach of the yaw error, metres.
        offset: f64,
        /// Capture half-width: clearance/2 + lead-in, metres.
        capture: f64,
    },
    /// The part was tilted beyond the angle at which it wedges in the clearance (radians).
    TiltBeyondJam {
        /// Tilt at the start.
        tilt: f64,
        /// Jam angle in the tilt's direction.
        jam_angle: f64,
    },
    /// The part was turned about the insertion axis more than the clearance allows (radians).
    YawBeyondClearance {
        /// Yaw at the start.
        yaw: f64,
        /// Largest yaw that fits.
        limit: f64,
    },
    /// The contact simulation stopped the part short of seated for no single start cause.
    StoppedShort {
        /// Height above seated where it stopped, metres.
        height: f64,
    },
    /// Fully down but outside a tolerance.
    OutOfTolerance {
        /// Final lateral error, metres.
        lateral: f64,
        /// Final tilt, radians.
        tilt: f64,
    },
    /// The gripper opened with the part away from any target.
    ReleasedAwayFromTarget,
}

/// The result of one insertion.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[allow(non_snake_case)]
pub struct InsertionResult {
    /// Seated, jammed or missed.
    pub verdict: Verdict,
    /// Why.
    pub cause: InsertionCause,
    /// True pose error when the insertion started.
    pub start: PoseError,
    /// True pose error where the part ended.
    pub end: PoseError,
    /// Where the part ended, in the insertion frame.
    pub ins_T_part: Isometry3<f64>,
}

impl InsertionResult {
    /// The result of an insertion that started at `start` and left the part at `ins_T_part`
    /// (insertion frame), classified by [`classify`].
    #[allow(non_snake_case)]
    pub fn ended_at(mating: &Mating, start: PoseError, ins_T_part: Isometry3<f64>) -> Self {
        let end = mating.pose_error(&ins_T_part);
        let (verdict, cause) = classify(mating, &start, &end);
        Self {
            verdict,
            cause,
            start,
            end,
            ins_T_part,
        }
    }
}

/// Decides the verdict from where the part ended, and when it is not seated, the cause from the
/// start error: seated within the tolerances; missed when the leading face ended outside the
/// capture band (on the rim or beside the target); jammed otherwise.
pub fn classify(mating: &Mating, start: &PoseError, end: &PoseError) -> (Verdict, InsertionCause) {
    let tol = &mating.tolerances;
    let seated =
        end.height <= tol.depth && end.lateral.norm() <= tol.lateral && end.tilt <= tol.tilt;
    if seated {
        return (Verdict::Seated, InsertionCause::None);
    }
    let capture = mating.capture();
    let reach = mating.capture_reach(end);
    if reach > capture {
        return (
            Verdict::Missed,
            InsertionCause::LateralBeyondCapture {
                offset: reach,
                capture,
            },
        );
    }
    let jam_angle = mating.jam_angle(&start.tilt_direction);
    if start.tilt > jam_angle {
        return (
            Verdict::Jammed,
            InsertionCause::TiltBeyondJam {
                tilt: start.tilt,
                jam_angle,
            },
        );
    }
    let limit = mating.yaw_limit();
    if start.yaw.abs() > limit {
        return (
            Verdict::Jammed,
            InsertionCause::YawBeyondClearance {
                yaw: start.yaw,
                limit,
            },
        );
    }
    if end.height > tol.depth {
        return (
            Verdict::Jammed,
            InsertionCause::StoppedShort { height: end.height },
        );
    }
    (
        Verdict::Jammed,
        InsertionCause::OutOfTolerance {
            lateral: end.lateral.norm(),
            tilt: end.tilt,
        },
    )
}
