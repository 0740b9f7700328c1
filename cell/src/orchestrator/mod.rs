//! The orchestrator engine: a tokio state machine that assembles a scenario's parts on any
//! [`Workcell`] (a `robots::Robot` and the cell's [`CellIo`]) with any [`perception::PartPerception`]. It
//! knows only these seams; the simulated cell, keypoint-noise perception and the episode over
//! loopback RTDE are the simulation harness's (`crate::harness`), which a production run never
//! builds.
//!
//! # States
//! Home → Capture → Perceive → Select → PlanPick → Pick → VerifyGrasp → PlanInsert → Insert →
//! Verify → (next step: Capture) or Done, each bounded by a wall-clock timeout ([`Timeouts`]).
//! Recovery, every path bounded: nothing pickable → Shake → Capture, at most
//! `cell.feeder.max_shakes` times, then the step aborts with the cause; a failed grasp → Retract
//! → Capture (re-perceive), at most [`EpisodeSettings::max_grasp_attempts`] picks; an insertion
//! found jammed or missed before the fingers open (`CellIo::seating_check`) → lift clear, correct
//! (the measured slip, a search offset) and insert again, at most `policy.max_insertion_attempts`
//! insertions, then release with the cause (with `[force_insertion]`, the cell's own judgment
//! from force and depth decides instead, after a spiral search on a miss or jam, and a part not
//! confirmed seated is never released: it is lifted clear and the step fails); a robot error (protective stop, e-stop, lost
//! connection, timeout) → stop the arm → SafeStop, and the record says why. A failed step ends
//! the episode (later steps build on it). Every transition is an [`Event`] (JSON line) with
//! simulated and wall time.
//!
//! # API
//! - [`Setup::new`] once per scenario (the planner's [`CellKnowledge`] and the policies); its
//!   [`Setup::context`] is one episode's [`EpisodeContext`].
//! - [`run_episode`] drives one episode on a [`Workcell`]: the simulated cell itself, or a
//!   [`SplitCell`] of `robots::ur_robot::UrRobot` (a real controller, or `cell virtual-ur`) and
//!   the cell's side channels.
//! - Production: [`preflight`] refuses to start without the explicit opt-in, valid limits, a
//!   camera source that opens (`crate::camera`) and an image-reading perception mode; then
//!   [`ProductionCellIo`] with `UrRobot` and the learned perception go through [`run_episode`].
//!
//! # Files
//! `engine` (the state machine, one method per state), `step` (per-step state), `context`
//! (setup, policies, the episode's context), `state` (states and their bounds), `activity`
//! (what the time is spent on, finer than states), `events`,
//! `cell_io` (the cell seams), `perception` (the perception seam), `selection`, `planning`,
//! `geometry` (the planner's model of the cell), `insertion` (force-guided insertion, the same
//! in simulation and production), `view` (whether the arm hides the feeder from the camera),
//! `production` (pre-flight, production side channels).

#![allow(non_snake_case)]

mod activity;
mod blended;
mod cell_io;
mod context;
mod engine;
mod events;
mod geometry;
pub mod insertion;
mod planning;
mod production;
pub mod seat_check;
mod selection;
mod state;
mod step;
pub mod view;

pub use activity::Activity;
pub use cell_io::{CellIo, CellIoError, InsertionCheck, PerceptionAudit, SplitCell, Workcell};
pub use context::{EpisodeContext, EpisodeSettings, Setup};
pub use engine::{FEEDER_EXHAUSTED, FEEDER_SHAKE_BOUND};
pub use events::{Event, EventLog, ShakeStart, WrenchSample, WrenchTrace};
pub use geometry::{CellKnowledge, KnowledgeError, top_down};
pub use planning::{
    MAX_RAISE, Motion, Plan, PlanError, Planner, PlanningConfig, RAISE_STEP, Raised, SearchConfig,
    Speeds, grasped_offset,
};
pub use production::{
    ProductionCellIo, ProductionError, ProductionOptions, force_sensor_preflight, open_camera,
    preflight,
};
pub use selection::{
    Neighbour, Rejection, Selection, SelectionConfig, SelectionResult, UnposedObstacle,
    nearest_to_fingers, select,
};
pub use state::{State, Timeouts};

use crate::episode::EpisodeRecord;

/// One episode's output: the record and its events.
#[derive(Debug, Clone)]
pub struct EpisodeOutput {
    /// The record a run stores.
    pub record: EpisodeRecord,
    /// Every state transition.
    pub events: EventLog,
}

/// Runs one episode in context `ctx` on `cell` with `perception`. Never fails: every problem
/// ends up in the record (aborted step, `abort`).
pub async fn run_episode(
    ctx: EpisodeContext<'_>,
    cell: &mut dyn Workcell,
    perception: &mut dyn perception::PartPerception,
) -> EpisodeOutput {
    let (record, events) = engine::Engine::new(ctx, cell, perception).run().await;
    EpisodeOutput { record, events }
}
