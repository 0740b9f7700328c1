//! Physics, stable poses, part CAD authoring, rendering, datasets and the simulated cell.

pub mod cad;
pub mod cell;
pub mod config;
pub mod convert;
pub mod dataset;
pub mod fsutil;
pub mod mujoco;
pub mod render;
pub mod scene;
pub mod seed;
pub mod stable_poses;
