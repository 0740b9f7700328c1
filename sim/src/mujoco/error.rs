//! Why MuJoCo could not be used: the error every MuJoCo model, compile and simulation returns.

use thiserror::Error;

/// Why MuJoCo could not be used.
#[derive(Debug, Error)]
pub enum MujocoError {
    /// Not in this build, or the library loaded is not MuJoCo 3.17.0.
    #[error("{0}")]
    Unavailable(String),
    /// A convex piece MuJoCo cannot turn into a collision mesh.
    #[error("part {part:?}, convex piece {piece}: {reason}")]
    Piece {
        /// The part.
        part: String,
        /// Index of the piece in the part's convex pieces.
        piece: usize,
        /// Why.
        reason: String,
    },
    /// MuJoCo refused the generated model.
    #[error("MuJoCo refused the generated model: {0}")]
    Compile(String),
    /// The simulation of an accepted model failed.
    #[error("MuJoCo simulation failed: {0}")]
    Simulation(String),
}
