//! Insertion scoring: from the true pose of the held part relative to its target when the
//! insertion starts to seated, jammed or missed, with the cause.
//!
//! Every scorer implements [`InsertionScorer`] and shares [`Mating`] (the step's geometry) and
//! [`classify`]: [`analytic`] (capture by clearance and lead-in, two-point tilt jam;
//! microseconds), [`contact`] (rapier at millimetre scale with a compliant [`Wrist`] pushing the
//! real convex pieces together; the reference where they disagree) and [`mujoco`] (the same
//! wrist and pieces in MuJoCo, a second independent contact engine). [`agreement`] measures how
//! often they agree near the capture boundary. Adding a scorer is one file implementing
//! [`InsertionScorer`] plus its variant in [`Scorer`] and its line in [`Scorer::build`].
//!
//! Poses are expressed in the step's insertion frame: origin at the seated part origin, z pointing
//! out of the hole (against the insertion axis).

pub mod agreement;
pub mod analytic;
pub mod contact;
mod mating;
pub mod mujoco;
mod scorer;
mod wrist;

pub use mating::{Mating, ReceiverPart};
pub use scorer::{InsertionCase, InsertionScorer, Scored, ScorerError};
pub use wrist::Wrist;

use std::sync::Arc;

use nalgebra::{Isometry3, Vector2, Vector3};
use serde::{Deserialize, Serialize};

/// Which scorer decides insertions (the scenario key `[simulation] insertion_scorer`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Scorer {
    /// Capture model from clearance, lead-in and tilt (fast).
    #[default]
    Analytic,
    /// Rapier contact simulation of the real meshes with a compliant wrist.
    Contact,
    /// MuJoCo contact simulation of the same pieces and wrist (needs the `mujoco` feature).
    Mujoco,
}

impl Scorer {
    /// Every scorer, in the order reports list them.
    pub const ALL: [Scorer; 3] = [Scorer::Analytic, Scorer::Contact, Scorer::Mujoco];

    /// The name the scenario key and `cell scorers --engines` use.
    pub fn name(self) -> &'static str {
        match self {
            Scorer::Analytic => "analytic",
            Scorer::Contact => "contact",
            Scorer::Mujoco => "mujoco",
        }
    }

    /// The scorer called `name` (`rapier` is accepted for `contact`).
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "rapier" => Some(Scorer::Contact),
            _ => Self::ALL.into_iter().find(|s| s.name() == name),
        }
    }

    /// Builds the scorer with its default settings; fails when it is not part of this build.
    pub fn build(self) -> Result<Arc<dyn InsertionScorer>, ScorerError> {
        Ok(match self {
            Scorer::Analytic => Arc::new(analytic::Analytic),
            Scorer::Contact => Arc::new(contact::Rapier::default()),
            Scorer::Mujoco => mujoco::build()?,
        })
    }
}

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

/// The pose of a part relative to its seated target, in the insertion frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseError {
    /// Lateral offset of the part's leading point (x, y), metres.
    pub lateral: Vector2<f64>,
    /// Height of the part origin above seated along the insertion frame's z, metres.
    pub height: f64,
    /// Angle between the part's axis and the insertion axis, radians.
    pub tilt: f64,
    /// Horizontal direction the part's axis leans toward (unit, or zero without tilt).
    pub tilt_direction: Vector2<f64>,
    /// Rotation about the insertion axis, radians in (−π, π].
    pub yaw: f64,
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

/// Swing-twist: the twist angle of `r` about `z`.
pub(crate) fn twist_about_z(r: &nalgebra::UnitQuaternion<f64>) -> f64 {
    let q = r.quaternion();
    let yaw = 2.0 * q.k.atan2(q.w);
    nalgebra::RealField::atan2(yaw.sin(), yaw.cos())
}

/// The z axis of a rotation's frame.
pub(crate) fn tilt_of(r: &nalgebra::UnitQuaternion<f64>) -> (f64, Vector2<f64>) {
    let z = r * Vector3::z();
    let tilt = z.z.clamp(-1.0, 1.0).acos();
    let h = Vector2::new(z.x, z.y);
    let dir = if h.norm() > 1e-15 {
        h.normalize()
    } else {
        Vector2::zeros()
    };
    (tilt, dir)
}
