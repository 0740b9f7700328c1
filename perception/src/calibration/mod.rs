//! Commissioning a cell: the printed tag board and its families.

pub mod board;
mod error;
pub mod family;

pub use board::{Board, BoardSpec, BoardTag, RemovedBlock};
pub use error::BoardError;
pub use family::{FAMILIES, TagFamily};
