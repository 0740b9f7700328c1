//! The interface every insertion scorer implements, so the simulated cell, `cell scorers` and
//! the agreement check drive any engine the same way: adding a scorer is one new file plus its
//! line in [`Scorer::build`](super::Scorer::build).

use nalgebra::Isometry3;

use super::error::ScorerError;
use super::mating::{Mating, ReceiverPart};
use super::outcome::InsertionResult;
use super::wrist::WristWrench;
use crate::cell::geometry::PartGeometry;

/// One insertion to score: the step's geometry and where the held part starts.
#[derive(Debug, Clone, Copy)]
#[allow(non_snake_case)]
pub struct InsertionCase<'a> {
    /// The step's mating geometry.
    pub mating: &'a Mating,
    /// The held part's shapes.
    pub held: &'a PartGeometry,
    /// What it goes into (first) and everything already in place around it.
    pub receivers: &'a [ReceiverPart<'a>],
    /// The held part's true pose in the insertion frame when the insertion starts.
    pub ins_T_part: Isometry3<f64>,
}

/// A scored insertion with the time it took on the cell's clock.
#[derive(Debug, Clone, PartialEq)]
pub struct Scored {
    /// The verdict, cause and poses.
    pub result: InsertionResult,
    /// Simulated seconds of pushing (zero for a scorer that does not simulate time).
    pub simulated_time: f64,
    /// Physics steps taken (zero for an analytic scorer).
    pub steps: usize,
}

/// Decides how an insertion ends, from the step's geometry and the start pose.
pub trait InsertionScorer: Send + Sync + std::fmt::Debug {
    /// The scorer's name, as the scenario key and `cell scorers --engines` spell it.
    fn name(&self) -> &'static str;

    /// Checks that the engine accepts `part`'s shapes (a scorer without a model of its own
    /// accepts everything), so a bad part is refused before a run starts.
    fn check_part(&self, part: &PartGeometry) -> Result<(), ScorerError> {
        let _ = part;
        Ok(())
    }

    /// Scores one insertion.
    fn score(&self, case: &InsertionCase<'_>) -> Result<Scored, ScorerError>;

    /// Scores one insertion as [`Self::score`] does (the same result) and records the wrist's
    /// load through it ([`super::Wrist::spring_wrench`], every
    /// [`super::contact::WRENCH_SAMPLE_PERIOD`] and at the end); a scorer that simulates no
    /// wrist records nothing.
    fn score_with_wrench(
        &self,
        case: &InsertionCase<'_>,
    ) -> Result<(Scored, Vec<WristWrench>), ScorerError> {
        Ok((self.score(case)?, Vec::new()))
    }
}
