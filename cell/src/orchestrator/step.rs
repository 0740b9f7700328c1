//! The state one assembly step carries while the engine works on it, reset as a whole when the
//! next step begins.

use std::collections::BTreeSet;

use nalgebra::{Isometry3, Vector3};

use super::planning::{Motion, Plan};
use super::selection::{Selection, UnposedObstacle};
use crate::episode::{PerceptionVerdict, PoseError, StepOutcome, StepRecord};
use perception::{DetectedPart, Frame};

/// Per-step state of the engine.
pub(super) struct StepState {
    /// Cell clock when the step began, seconds.
    pub start: f64,
    /// Picks started.
    pub attempts: u32,
    /// Feeder shakes counted against this step's bound.
    pub shakes: u32,
    /// Insertion attempts (first try and retries).
    pub insertions: u32,
    /// Search offset of the next insertion in the insertion frame.
    pub correction: Isometry3<f64>,
    /// Measured slip of the held part up the fingers so far, metres.
    pub slip: f64,
    /// Release and retreat of the insertion in progress, run once it is judged.
    pub pending: Vec<(&'static str, Motion)>,
    /// The last camera frame, until perceived.
    pub frame: Option<Frame>,
    /// What the last frame showed.
    pub detections: Vec<DetectedPart>,
    /// The parts the last frame showed that perception could not pose.
    pub unposed: Vec<UnposedObstacle>,
    /// Detections of this frame ruled out (unplannable, or blocked by an excluded neighbour).
    pub excluded: BTreeSet<usize>,
    /// Where (base frame) picks of this step closed on nothing since the feeder last moved:
    /// the same pick there would miss again (an unseen neighbour, a pose the fingers cannot
    /// take), so parts there wait for a shake.
    pub missed_at: Vec<Vector3<f64>>,
    /// The instance chosen to pick.
    pub selection: Option<Selection>,
    /// The plan about to run.
    pub plan: Option<Plan>,
    /// Perception error of the picked instance in the table plane (x, y mm; yaw °).
    pub perception_error: Option<[f64; 3]>,
    /// What the picked detection really was (simulation only).
    pub perception_verdict: Option<PerceptionVerdict>,
    /// Perception's confidence in the picked instance.
    pub confidence: Option<f64>,
    /// What the force-guided insertion in progress found, until judged.
    pub force: Option<super::insertion::ForceVerdict>,
    /// What the last force-guided insertion decided, for the record.
    pub force_record: Option<crate::episode::ForceRecord>,
    /// The seat check by camera of this step's placed part, for the record.
    pub seat_check: Option<crate::episode::SeatCheckRecord>,
    /// What the cell knew of the part after the first force-guided insertion's planned descent,
    /// before any search or retry offset it (simulation only): the error budget of a step given
    /// up after the search.
    pub planned_truth: Option<super::cell_io::InsertionCheck>,
}

/// Detections closer than this (table plane) to a missed pick count as the same part, metres.
const MISSED_RADIUS: f64 = 2e-3;

impl StepState {
    /// Whether `d` stands where a pick of this step missed since the feeder last moved.
    pub fn missed_before(&self, d: &DetectedPart) -> bool {
        let p = d.base_T_part.translation.vector;
        self.missed_at
            .iter()
            .any(|m| (m - p).xy().norm() < MISSED_RADIUS)
    }

    /// A fresh step starting at `start` with `shakes` already counted against it.
    pub fn new(start: f64, shakes: u32) -> Self {
        Self {
            start,
            attempts: 0,
            shakes,
            insertions: 0,
            correction: Isometry3::identity(),
            slip: 0.0,
            pending: Vec::new(),
            frame: None,
            detections: Vec::new(),
            unposed: Vec::new(),
            excluded: BTreeSet::new(),
            missed_at: Vec::new(),
            selection: None,
            plan: None,
            perception_error: None,
            perception_verdict: None,
            confidence: None,
            force: None,
            force_record: None,
            seat_check: None,
            planned_truth: None,
        }
    }

    /// The record of this step ending now (`now` on the cell clock) with `outcome`.
    pub fn record(
        &self,
        part: String,
        outcome: StepOutcome,
        cause: Option<String>,
        sources: Vec<String>,
        pose_error: Option<PoseError>,
        now: f64,
    ) -> StepRecord {
        StepRecord {
            part,
            outcome,
            attempts: self.attempts,
            insertion_attempts: self.insertions,
            shakes: self.shakes,
            cause,
            sources,
            pose_error,
            perception_error: self.perception_error,
            perception_verdict: self.perception_verdict,
            confidence: self.confidence,
            sim_time_s: now - self.start,
            force: self.force_record,
            seat_check: self.seat_check,
        }
    }
}
