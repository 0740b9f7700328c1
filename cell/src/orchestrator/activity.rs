//! What the cell is doing with its time, finer than the orchestrator's states: a pick is a
//! transit, an approach and a grasp; an insertion a transit, an approach, the insertion and a
//! retreat. Every span of an episode's cycle has one activity, from the motion that ended it or
//! from its state, so a run can say where the time goes in the terms an integrator tunes.

use serde::{Deserialize, Serialize};

use super::state::State;

/// One kind of work on the cycle's critical path (ordered as a step passes through them).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Activity {
    /// Waiting for the feeder's parts to come to rest before a capture (a shake started while
    /// the arm was busy elsewhere, still settling).
    Waiting,
    /// Capturing, perceiving, selecting and planning (no simulated time in the simulated cell).
    Perception,
    /// Fast joint moves between the feeder and the fixture.
    Transit,
    /// Fast and slow straight moves down to a grasp or an insertion.
    Approach,
    /// Opening the fingers to the part and closing them on it.
    Grasp,
    /// The slow insertion and the release.
    Insertion,
    /// Lifting away: after a grasp, a release, a jam or a missed grasp.
    Retreat,
    /// A shake the arm waited for.
    Shake,
}

impl Activity {
    /// The name in records and reports.
    pub fn name(self) -> &'static str {
        match self {
            Activity::Waiting => "waiting",
            Activity::Perception => "perception",
            Activity::Transit => "transit",
            Activity::Approach => "approach",
            Activity::Grasp => "grasp",
            Activity::Insertion => "insertion",
            Activity::Retreat => "retreat",
            Activity::Shake => "shake",
        }
    }

    /// The activity of a motion by its waypoint name (the planner's and the engine's names);
    /// `None` for a name this table does not know.
    pub fn of_motion(waypoint: &str) -> Option<Activity> {
        Some(match waypoint {
            "approach" | "transfer" | "rise" => Activity::Transit,
            "pre-grasp" | "grasp" | "pre-insert" => Activity::Approach,
            "open fingers" | "close" => Activity::Grasp,
            "insert" | "release" => Activity::Insertion,
            "lift" | "retreat" | "lift clear" => Activity::Retreat,
            _ => return None,
        })
    }

    /// The activity of time in `state` that no motion accounts for; `after` is the state
    /// before it (a capture after a shake waits for that shake).
    pub fn of_state(state: State, after: Option<State>) -> Activity {
        match state {
            State::Capture if after == Some(State::Shake) => Activity::Shake,
            State::Capture => Activity::Waiting,
            State::Shake => Activity::Shake,
            State::Pick => Activity::Transit,
            State::Insert | State::Verify => Activity::Insertion,
            State::Retract => Activity::Retreat,
            State::Home
            | State::Perceive
            | State::Select
            | State::PlanPick
            | State::VerifyGrasp
            | State::PlanInsert
            | State::Done
            | State::SafeStop => Activity::Perception,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_planned_waypoint_has_an_activity() {
        for name in [
            "open fingers",
            "approach",
            "pre-grasp",
            "grasp",
            "close",
            "lift",
            "transfer",
            "pre-insert",
            "insert",
            "release",
            "retreat",
            "lift clear",
        ] {
            assert!(Activity::of_motion(name).is_some(), "{name}");
        }
        assert_eq!(Activity::of_motion("dance"), None);
        assert_eq!(
            Activity::of_state(State::Capture, Some(State::Shake)),
            Activity::Shake
        );
        assert_eq!(
            Activity::of_state(State::Capture, Some(State::Verify)),
            Activity::Waiting
        );
    }
}
