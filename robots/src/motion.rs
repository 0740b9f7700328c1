//! How fast a commanded move may go: the motion parameters every [`crate::robot::Robot`] move
//! takes and [`crate::limits::Limits`] checks (their own module, so that `robot` and `limits` do
//! not import each other).

use serde::{Deserialize, Serialize};

/// Speed and acceleration of a joint-space move (the leading joint's, like URScript `movej`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct JointMotion {
    /// Joint speed (rad/s).
    pub speed: f64,
    /// Joint acceleration (rad/s²).
    pub acceleration: f64,
}

/// Speed and acceleration of a straight-line TCP move (like URScript `movel`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LinearMotion {
    /// TCP speed (m/s).
    pub speed: f64,
    /// TCP acceleration (m/s²).
    pub acceleration: f64,
}
