//! The interface every insertion scorer implements, so the simulated cell, `cell scorers` and
//! the agreement check drive any engine the same way: adding a scorer is one new file plus its
//! line in [`Scorer::build`](super::Scorer::build).

use nalgebra::Isometry3;
use thiserror::Error;

use super::{InsertionResult, Mating, ReceiverPart};
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

/// Why a scorer could not be built or could not score.
#[derive(Debug, Error)]
pub enum ScorerError {
    /// The scorer is not part of this build or its native library is missing.
    #[error("insertion scorer {scorer:?} is unavailable: {reason}")]
    Unavailable {
        /// The scorer's name.
        scorer: &'static str,
        /// Why, and how to make it available.
        reason: String,
    },
    /// A part's shape cannot be turned into the engine's model.
    #[error("part {part:?}, convex piece {piece}: {reason}")]
    Geometry {
        /// The part.
        part: String,
        /// Index of the convex piece in the part's pieces.
        piece: usize,
        /// Why the engine rejects it.
        reason: String,
    },
    /// The engine failed on a model it accepted.
    #[error("insertion scorer {scorer:?} failed: {reason}")]
    Engine {
        /// The scorer's name.
        scorer: &'static str,
        /// What the engine said.
        reason: String,
    },
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
}
