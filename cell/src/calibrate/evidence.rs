//! What a finished calibration holds: the two poses a scenario needs, their covariances, and the
//! evidence behind them from either method (touch points or hand-eye).

#![allow(non_snake_case)]

use nalgebra::{Isometry3, Matrix6};
use perception::calibration::board_pose::BoardPose;
use perception::calibration::detect::BoardSighting;
use perception::calibration::hand_eye::HandEyeSolution;
use perception::calibration::rigid_fit::{RigidFit, TouchPoint};

/// A finished calibration: the two poses the scenario needs, with their covariances and the
/// evidence behind them.
#[derive(Debug, Clone)]
pub struct Calibration {
    /// The camera in the robot base.
    pub base_T_camera: Isometry3<f64>,
    /// The table (the board's top face) in the robot base.
    pub base_T_table: Isometry3<f64>,
    /// Covariance of `base_T_camera`, `[δt (m); δω (rad)]` with the true pose
    /// `(exp(δω)·R̂, t̂ + δt)`, as perception's PnP states its covariances.
    pub camera_covariance: Matrix6<f64>,
    /// Covariance of `base_T_table`, in the same convention.
    pub table_covariance: Matrix6<f64>,
    /// The board as the camera saw it.
    pub sighting: BoardSighting,
    /// The board's pose in the camera.
    pub board_pose: BoardPose,
    /// How the board was found in the robot base.
    pub base: BaseEvidence,
}

/// How a calibration found the table board in the robot base, with its evidence.
#[derive(Debug, Clone)]
pub enum BaseEvidence {
    /// Pointer touches at the board's marks and their rigid fit.
    Touch {
        /// The touches.
        touches: Vec<TouchPoint>,
        /// The rigid fit of the touches.
        fit: Box<RigidFit>,
    },
    /// A flange board carried through planned poses (AX = XB).
    HandEye(Box<HandEyeEvidence>),
}

/// What a hand-eye run saw: the solution and the poses it had to leave out.
#[derive(Debug, Clone)]
pub struct HandEyeEvidence {
    /// The AX = XB solution (camera in the base, board on the TCP).
    pub solution: HandEyeSolution,
    /// Poses planned.
    pub planned: usize,
    /// The planned poses left out, and why.
    pub left_out: LeftOut,
    /// Per view used: the planned pose's number (from 1) and the board's reprojection RMS, px.
    pub views: Vec<(usize, f64)>,
}

/// The planned poses a hand-eye run left out (numbered from 1), and why.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LeftOut {
    /// Left out before moving: the board would not be in the camera's view.
    pub out_of_view: Vec<usize>,
    /// Refused by the robot (limits, no joint solution), with the reason.
    pub refused: Vec<(usize, String)>,
    /// Reached, but the board could not be posed (tags missed, too oblique, clipped).
    pub unseen: Vec<(usize, String)>,
}
