//! Universal Robots Real-Time Data Exchange (RTDE): codec, async client and server.
//!
//! Protocol versions 1 and 2, every package and data type, the canonical variable → type table.

pub mod client;
pub mod frame_io;
pub mod package;
pub mod recipe;
pub mod server;
pub mod state;
pub mod types;
pub mod variables;

pub use package::{ControllerVersion, Protocol, Reply, Request, TextMessage};
pub use recipe::Recipe;
pub use types::{DataType, Slot, Value};

/// Default RTDE port of a UR controller.
pub const RTDE_PORT: u16 = 30004;
