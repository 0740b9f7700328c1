//! MuJoCo (3.17.0, through the `mujoco-rs` bindings) as a second contact engine beside rapier:
//! models are generated as MJCF from the same convex pieces, masses and friction rapier uses
//! ([`mjcf`]), never kept by hand.
//!
//! The native library is provisioned by the `mujoco-provision` crate (the PyPI wheel of
//! mujoco 3.17.0, sha256-pinned and cached; `MUJOCO_DYNAMIC_LINK_DIR` overrides it). The
//! engine is behind sim's `mujoco` feature (on by default); without it [`ensure_available`]
//! says how to turn it on.

mod available;
mod error;
pub mod mjcf;
#[cfg(feature = "mujoco")]
mod model;

pub use available::{VERSION, ensure_available};
pub use error::MujocoError;
#[cfg(feature = "mujoco")]
pub use model::{Compiled, compile};
