//! The orchestrator's explicit states and the time each may take.

use std::time::Duration;

use serde::{Deserialize, Serialize};

/// A state of the episode state machine (ordered as one step passes through them).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum State {
    /// Open the gripper and move to the home joints.
    Home,
    /// Take a camera frame.
    Capture,
    /// Estimate part poses in the frame.
    Perceive,
    /// Choose an instance to pick.
    Select,
    /// Plan and check the pick motion.
    PlanPick,
    /// Approach, grasp, lift.
    Pick,
    /// Check that a part is in the fingers.
    VerifyGrasp,
    /// Plan and check the insertion motion.
    PlanInsert,
    /// Transfer, pre-insert, insert (slow); the fingers stay closed until Verify.
    Insert,
    /// Judge the insertion with the part still held when the cell can: lift clear and retry a
    /// jam or miss (bounded), or release, retreat and record the result.
    Verify,
    /// Shake the feeder because nothing is pickable.
    Shake,
    /// Open the gripper and back away after a failed grasp or a jam.
    Retract,
    /// Every step done (seated or given up).
    Done,
    /// Stopped safely after a safety event or a lost connection.
    SafeStop,
}

impl State {
    /// The state's name as records and reports write it (`plan_pick`).
    pub fn name(self) -> &'static str {
        match self {
            State::Home => "home",
            State::Capture => "capture",
            State::Perceive => "perceive",
            State::Select => "select",
            State::PlanPick => "plan_pick",
            State::Pick => "pick",
            State::VerifyGrasp => "verify_grasp",
            State::PlanInsert => "plan_insert",
            State::Insert => "insert",
            State::Verify => "verify",
            State::Shake => "shake",
            State::Retract => "retract",
            State::Done => "done",
            State::SafeStop => "safe_stop",
        }
    }

    /// Whether the episode ends in this state.
    pub fn is_terminal(self) -> bool {
        matches!(self, State::Done | State::SafeStop)
    }
}

/// Wall-clock bound of every state; a state that overruns it stops the episode safely.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Timeouts {
    /// Bound of states that only compute (capture, perceive, select, plan, verify).
    pub compute: Duration,
    /// Bound of states that move the arm (home, pick, insert, retract, shake).
    pub motion: Duration,
}

impl Default for Timeouts {
    /// 10 s to compute, 60 s to move (a real UR at cell speeds needs a few seconds per move).
    fn default() -> Self {
        Self {
            compute: Duration::from_secs(10),
            motion: Duration::from_secs(60),
        }
    }
}

impl Timeouts {
    /// The bound of `state`.
    pub fn of(&self, state: State) -> Duration {
        match state {
            State::Home | State::Pick | State::Insert | State::Retract | State::Shake => {
                self.motion
            }
            State::Capture
            | State::Perceive
            | State::Select
            | State::PlanPick
            | State::VerifyGrasp
            | State::PlanInsert
            | State::Verify
            | State::Done
            | State::SafeStop => self.compute,
        }
    }
}
