//! Why a simulated episode could not be set up: the harness's error, in its own file so the
//! perception set-up it wraps can return it without depending on the harness's entry points.

use crate::orchestrator::KnowledgeError;
use crate::scenario::PerceptionMode;
use perception::PerceptionError;

/// Why a simulated episode could not be set up (nothing ran).
#[derive(Debug, thiserror::Error)]
pub enum HarnessError {
    /// The simulated cell could not be built.
    #[error("simulated cell: {0}")]
    Cell(#[from] sim::cell::CellError),
    /// The planning model could not be built.
    #[error(transparent)]
    Knowledge(#[from] KnowledgeError),
    /// Perception could not be set up.
    #[error(transparent)]
    Perception(#[from] PerceptionError),
    /// Keypoint-noise perception was asked for a scenario in another perception mode.
    #[error("keypoint-noise perception asked for, but the scenario's mode is {0:?}")]
    ModeUnavailable(PerceptionMode),
    /// No tokio runtime could be built.
    #[error("tokio runtime: {0}")]
    Runtime(String),
    /// The cell's limits are unusable, so its robot cannot be driven.
    #[error(transparent)]
    Limits(#[from] robots::limits::InvalidLimits),
}
