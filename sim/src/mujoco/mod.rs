//! MuJoCo (3.17.0, through the `mujoco-rs` bindings) as a second contact engine beside rapier:
//! models are generated as MJCF from the same convex pieces, masses and friction rapier uses
//! ([`mjcf`]), never kept by hand.
//!
//! The native library is provisioned by the `mujoco-provision` crate (the PyPI wheel of
//! mujoco 3.17.0, sha256-pinned and cached; `MUJOCO_DYNAMIC_LINK_DIR` overrides it). The
//! engine is behind sim's `mujoco` feature (on by default); without it [`ensure_available`]
//! says how to turn it on.

pub mod mjcf;
#[cfg(feature = "mujoco")]
mod model;

#[cfg(feature = "mujoco")]
pub use model::{Compiled, compile};

use thiserror::Error;

/// The MuJoCo version the bindings are generated for and the provisioning pins.
pub const VERSION: &str = "3.17.0";

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

/// Checks that MuJoCo can be used: this build has the `mujoco` feature and the library the
/// loader found is MuJoCo 3.17.0.
pub fn ensure_available() -> Result<(), MujocoError> {
    #[cfg(feature = "mujoco")]
    {
        model::check_version()
    }
    #[cfg(not(feature = "mujoco"))]
    {
        Err(MujocoError::Unavailable(format!(
            "this build of sim has no MuJoCo: its `mujoco` feature (on by default) was turned \
             off; rebuild without --no-default-features, or with --features sim/mujoco (MuJoCo \
             {VERSION} is then provisioned automatically)"
        )))
    }
}
