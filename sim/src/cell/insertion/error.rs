//! Why an insertion scorer could not be built or could not score: its own file, so the cell's
//! error type can carry it without depending on the scorers.

use thiserror::Error;

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
