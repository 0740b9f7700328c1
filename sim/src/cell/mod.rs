//! The simulated cell: it decides whether an assembly succeeded from the true state of the world,
//! through geometry and physics, never from a configured rate.
//!
//! # World
//! The table (tag board plane, z up), a flexible-feeder rectangle where parts lie in stable poses
//! ([`feeder`]: sampled from the catalog's stable-pose table without overlap, or dropped with
//! rapier), the fixture nest, a UR5e ([`robots::kinematics::UrKinematics`], TCP at the
//! fingertip centre `tcp_offset` below the flange) moving along commanded trajectories timed by
//! trapezoidal profiles under the cell's limits ([`motion`]), and a parallel gripper
//! ([`gripper`]). Error sources ([`noise`]): robot repeatability (the true TCP is off the
//! commanded one after every motion; encoders do not see it), camera extrinsic calibration (the
//! true camera differs from the calibrated one), grasp residuals. Camera noise belongs to the
//! perception stage (the scenario's `[perception]`), which works from what the camera sees.
//!
//! # Driving it
//! Build a [`CellModel`] once per scenario ([`CellModel::new`]: checks feasibility, loads the
//! shapes) and a [`SimCell`] per episode ([`SimCell::new`]`(model, seed, episode)`: same triple,
//! same world and outcomes). Drive the arm through [`robots::robot::Robot`]
//! (`move_j`, `move_l`, `open_gripper`, `close_gripper`; every target is checked against the
//! cell's limits; a path that puts the fingertips or the held part into the table protective-
//! stops) — or the same operations synchronously (`move_j_sync` …) — and read back:
//! - [`SimCell::camera_view`]: every feeder part the camera sees, with its true `camera_T_part`
//!   from the TRUE camera pose (the orchestrator only knows [`SimCell::base_T_camera_nominal`],
//!   so calibration error is real);
//! - [`SimCell::held`]: the part in the gripper and its true `tcp_T_part`;
//!   [`SimCell::last_grasp`]: the grasp or its failure cause;
//! - [`SimCell::last_release`]: seated / jammed / missed, the cause, the true pose errors at the
//!   start and end of the insertion, and the start error split by error source;
//! - [`SimCell::target`]: where a step's part goes in the base frame as the world evolves (the
//!   main shell's true seated pose defines where the next parts go);
//!   [`CellModel::nominal_target`] and [`CellModel::grasp_tcp`] for planning;
//! - [`SimCell::shake`], [`SimCell::refill`], [`SimCell::clock`] (simulated seconds).
//!
//! An insertion happens when a motion ends with the held part below its receiver's top within
//! reach of its target; the scorer ([`insertion::Scorer`]) decides it from the part's true pose
//! in the insertion frame, and opening the gripper releases the part there and reports it.
//! [`arm::SimArm`] plugs the cell into the virtual UR controller as its arm model.

#![allow(non_snake_case)]

pub mod arm;
mod capture;
pub mod error;
pub mod feasible;
pub mod feeder;
mod feeder_window;
pub mod fixture_view;
pub mod geometry;
pub mod gripper;
pub mod insertion;
pub mod model;
pub mod motion;
pub mod noise;
mod sim_cell;
pub mod wrench;

pub use capture::FeederImage;
pub use error::CellError;
pub use feasible::check_feasible;
pub use feeder_window::{calibrated_feeder_window, feeder_window};
pub use fixture_view::FixtureImage;
pub use model::CellModel;
pub use sim_cell::{CameraPart, HeldPart, PlacedPart, ReleaseReport, SimCell};
