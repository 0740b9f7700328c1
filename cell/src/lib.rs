//! The cell orchestrator library: scenario files, part preparation, the orchestrator engine
//! (`orchestrator`), the simulation harness that puts it in front of the simulated cell
//! (`harness`), runs, reports and the regression gate. The `cell` binary is a thin
//! command-line layer over it.

pub mod calibrate;
pub mod camera;
pub mod episode;
pub mod eval;
pub mod harness;
pub mod learned;
pub mod orchestrator;
pub mod prepare;
pub mod regress;
pub mod report;
pub mod run;
pub mod scenario;
