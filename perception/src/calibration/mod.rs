//! Commissioning a cell: the printed tag board and its families, finding the board in an image,
//! the camera's pose from it, and the board's pose in the robot base from touch points or from
//! hand-eye motions.

pub mod board;
pub mod board_pose;
pub mod covariance;
pub mod detect;
pub mod edges;
mod error;
pub mod family;
pub mod hand_eye;
pub mod rigid_fit;
pub mod touch_marks;

pub use board::{Board, BoardSpec, BoardTag, RemovedBlock};
pub use detect::{BoardSighting, DetectorSettings, TagSighting, detect_board};
pub use error::{BoardError, CalibrationError};
pub use family::{FAMILIES, TagFamily};
