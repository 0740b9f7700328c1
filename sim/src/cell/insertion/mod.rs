//! Insertion scoring: from the true pose of the held part relative to its target when the
//! insertion starts to seated, jammed or missed, with the cause.
//!
//! Every scorer implements [`InsertionScorer`] and shares [`Mating`] (the step's geometry) and
//! [`classify`]: [`analytic`] (capture by clearance and lead-in, two-point tilt jam;
//! microseconds), [`contact`] (rapier at millimetre scale with a compliant [`Wrist`] pushing the
//! real convex pieces together; the reference where they disagree) and [`mujoco`] (the same
//! wrist and pieces in MuJoCo, a second independent contact engine). [`agreement`] measures how
//! often they agree near the capture boundary. Adding a scorer is one file implementing
//! [`InsertionScorer`] plus its variant in [`Scorer`] and its line in [`Scorer::build`].
//!
//! Poses are expressed in the step's insertion frame: origin at the seated part origin, z pointing
//! out of the hole (against the insertion axis).

pub mod agreement;
pub mod analytic;
pub mod contact;
mod error;
pub mod felt;
pub mod landing;
mod mating;
pub mod mujoco;
mod outcome;
mod pieces_check;
mod pose_error;
mod scorer;
mod wrist;

pub use error::ScorerError;
pub use mating::{Mating, ReceiverPart};
pub use outcome::{InsertionCause, InsertionResult, Verdict, classify};
pub use pieces_check::check_pieces;
pub use pose_error::PoseError;
pub use scorer::{InsertionCase, InsertionScorer, Scored};
pub use wrist::Wrist;

use std::sync::Arc;

use serde::{Deserialize, Serialize};

/// Which scorer decides insertions (the scenario key `[simulation] insertion_scorer`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Scorer {
    /// Capture model from clearance, lead-in and tilt (fast).
    #[default]
    Analytic,
    /// Rapier contact simulation of the real meshes with a compliant wrist.
    Contact,
    /// MuJoCo contact simulation of the same pieces and wrist (needs the `mujoco` feature).
    Mujoco,
}

impl Scorer {
    /// Every scorer, in the order reports list them.
    pub const ALL: [Scorer; 3] = [Scorer::Analytic, Scorer::Contact, Scorer::Mujoco];

    /// The name the scenario key and `cell scorers --engines` use.
    pub fn name(self) -> &'static str {
        match self {
            Scorer::Analytic => "analytic",
            Scorer::Contact => "contact",
            Scorer::Mujoco => "mujoco",
        }
    }

    /// The scorer called `name` (`rapier` is accepted for `contact`).
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "rapier" => Some(Scorer::Contact),
            _ => Self::ALL.into_iter().find(|s| s.name() == name),
        }
    }

    /// Builds the scorer with its default settings; fails when it is not part of this build.
    pub fn build(self) -> Result<Arc<dyn InsertionScorer>, ScorerError> {
        Ok(match self {
            Scorer::Analytic => Arc::new(analytic::Analytic),
            Scorer::Contact => Arc::new(contact::Rapier::default()),
            Scorer::Mujoco => mujoco::build()?,
        })
    }
}
