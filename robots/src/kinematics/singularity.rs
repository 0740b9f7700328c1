//! Singular configurations of a UR arm and how close counts as singular.

use serde::{Deserialize, Serialize};
use std::fmt;

/// Which singularities a joint configuration is at (or within the thresholds of).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Singularities {
    /// Wrist singularity: sin q5 ≈ 0, joints 4 and 6 are aligned and q6 is not determined.
    pub wrist: bool,
    /// Elbow singularity: sin q3 ≈ 0, the arm is stretched (q3 = 0) or folded (q3 = π).
    pub elbow: bool,
    /// Shoulder singularity: the wrist centre lies on the joint 1 axis as seen in the arm's plane
    /// (its horizontal distance from the base z axis equals the shoulder offset d4), so q1 is
    /// ill-conditioned and the two shoulder branches meet.
    pub shoulder: bool,
}

impl Singularities {
    /// True when the configuration is at no singularity.
    pub fn is_empty(&self) -> bool {
        !(self.wrist || self.elbow || self.shoulder)
    }
}

impl fmt::Display for Singularities {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let names: Vec<&str> = [
            (self.wrist, "wrist"),
            (self.elbow, "elbow"),
            (self.shoulder, "shoulder"),
        ]
        .iter()
        .filter(|(on, _)| *on)
        .map(|(_, name)| *name)
        .collect();
        if names.is_empty() {
            f.write_str("none")
        } else {
            f.write_str(&names.join(" + "))
        }
    }
}

/// How close to a singularity a configuration must be to be flagged.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SingularityThresholds {
    /// Flag the wrist singularity when |sin q5| is below this.
    pub wrist_sin_q5: f64,
    /// Flag the elbow singularity when |sin q3| is below this.
    pub elbow_sin_q3: f64,
    /// Flag the shoulder singularity when the wrist centre is closer than this (m) to the
    /// joint 1 axis, measured in the arm's plane.
    pub shoulder_distance: f64,
}

impl Default for SingularityThresholds {
    /// |sin q| < 0.01 (about 0.6°) for the wrist and the elbow, 1 cm for the shoulder: inside
    /// these, a Cartesian motion needs joint speeds about 100× those of a well-conditioned pose.
    fn default() -> Self {
        Self {
            wrist_sin_q5: 0.01,
            elbow_sin_q3: 0.01,
            shoulder_distance: 0.01,
        }
    }
}

/// What inverse kinematics does with solutions flagged singular when picking one.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SingularityPolicy {
    /// Return them like any other solution, flagged.
    #[default]
    Report,
    /// Never pick them; fail with `IkError::Singular` when only singular solutions exist.
    Reject,
}
