//! Why a simulated cell could not be built or could not act.

use perception::part::PartError;
use thiserror::Error;

/// Why building or driving the simulated cell failed.
#[derive(Debug, Error)]
pub enum CellError {
    /// The scenario asks for something impossible; each entry is (key path, reason).
    #[error("infeasible scenario: {}", format_problems(.0))]
    Infeasible(Vec<(String, String)>),
    /// A part named by the scenario is missing from the catalog.
    #[error("part {0:?} is not in the catalog")]
    UnknownPart(String),
    /// A part's mesh could not be loaded.
    #[error("part {part:?}: {source}")]
    Mesh {
        /// The part.
        part: String,
        /// Why.
        source: PartError,
    },
    /// A part's mesh spans no volume (no convex hull).
    #[error("part {0:?}: the mesh spans no volume (no convex hull)")]
    DegenerateMesh(String),
    /// A feeder part has no stable-pose table (run `cell parts prepare`).
    #[error("part {0:?} has no stable poses: run `cell parts prepare` on the catalog")]
    NoStablePoses(String),
    /// Feeder parts could not be placed without overlap.
    #[error("could not place {placed} of {wanted} parts without overlap in the feeder")]
    FeederFull {
        /// Parts placed.
        placed: usize,
        /// Parts wanted.
        wanted: usize,
    },
    /// The simulated camera could not deliver an image.
    #[error("camera: {0}")]
    Camera(String),
    /// The physics drop failed.
    #[error("feeder drop: {0}")]
    Drop(String),
    /// The scenario's insertion scorer cannot be built or refuses a part.
    #[error("{0}")]
    Scorer(#[from] super::insertion::ScorerError),
    /// The robot's home pose has no joint solution.
    #[error("home pose unreachable: {0}")]
    Home(String),
}

fn format_problems(problems: &[(String, String)]) -> String {
    problems
        .iter()
        .map(|(k, m)| format!("{k}: {m}"))
        .collect::<Vec<_>>()
        .join("; ")
}
