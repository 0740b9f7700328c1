//! The cell orchestrator library: scenario files, part preparation, runs, reports and the
//! regression gate. The `cell` binary is a thin command-line layer over it.

pub mod episode;
pub mod orchestrator;
pub mod prepare;
pub mod regress;
pub mod report;
pub mod run;
pub mod scenario;
