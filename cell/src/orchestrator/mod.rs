//! The cell orchestrator: a tokio state machine that assembles a scenario's parts with any
//! `robots::Robot`.
//!
//! # States
//! Home → Capture → Perceive → Select → PlanPick → Pick → VerifyGrasp → PlanInsert → Insert →
//! Verify → (next step: Capture) or Done, each bounded by a wall-clock timeout ([`Timeouts`]).
//! Recovery, every path bounded: nothing pickable → Shake → Capture, at most
//! `cell.feeder.max_shakes` times, then the step aborts with the cause; a failed grasp → Retract
//! → Capture (re-perceive), at most [`EpisodeSettings::max_grasp_attempts`] picks; an insertion
//! found jammed or missed before the fingers open (`CellIo::seating_check`) → lift clear, correct
//! (the measured slip, a search offset) and insert again, at most `policy.max_insertion_attempts`
//! insertions, then release with the cause; a robot error
//! (protective stop, e-stop, lost connection, timeout) → stop the arm → SafeStop, and the record
//! says why. A failed step ends the episode (later steps build on it). Every transition is an
//! [`Event`] (JSON line) with simulated and wall time.
//!
//! # API
//! - [`SimSetup::new`] once per scenario (cell model for the simulator, the planner's
//!   [`CellKnowledge`]); then [`run_sim_episode`] (async) or [`run_sim_episode_blocking`] (builds
//!   a current-thread tokio runtime: use it from rayon workers) per episode. Same
//!   (scenario, episode) → same record.
//! - [`run_episode`] drives any robot and cell: `&mut dyn Robot` (the shared simulated cell
//!   [`SharedSimRobot`], or `robots::ur_robot::UrRobot` over RTDE to a real controller or to
//!   `cell virtual-ur`), a [`CellIo`] (camera, feeder, sensors; [`SimCellIo`] for the simulated
//!   cell) and a [`PartPerception`] ([`KeypointNoise`] until learned models exist).
//! - Production: [`preflight`] refuses to start without the explicit opt-in, valid limits, a
//!   camera source with images ([`ImageSource`]) and an image-reading perception mode; then
//!   [`ProductionCellIo`] with `UrRobot` and the learned perception go through [`run_episode`].
//! - [`keypoint_noise_for`] builds the scenario's keypoint-noise perception for an episode from
//!   its own seeded stream.
//!
//! All randomness is seeded from (scenario seed, episode): any episode replays alone.

#![allow(non_snake_case)]

mod cell_io;
mod driver;
mod events;
mod geometry;
mod over_rtde;
mod perception;
mod planning;
mod production;
mod selection;
mod state;

pub use cell_io::{CellIo, CellIoError, InsertionCheck, SharedSimRobot, SimCellIo, source_name};
pub use driver::EpisodeSettings;
pub use events::{Event, EventLog};
pub use geometry::{CellKnowledge, KnowledgeError, top_down};
pub use over_rtde::{OverRtdeError, SimOverRtde, connect_sim_over_rtde, sim_episode_over_rtde};
pub use perception::{
    DetectedPart, Frame, FrameContent, KeypointNoise, KeypointNoiseConfig, PartPerception,
    PerceptionError, TruePart,
};
pub use planning::{
    Motion, Plan, PlanError, Planner, PlanningConfig, SearchConfig, Speeds, grasped_offset,
};
pub use production::{
    ImageSource, ProductionCellIo, ProductionError, ProductionOptions, preflight,
};
pub use selection::{Rejection, Selection, SelectionConfig, SelectionResult, select};
pub use state::{State, Timeouts};

use std::sync::{Arc, Mutex};

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use robots::robot::Robot;
use sim::cell::{CellModel, SimCell};

use crate::episode::EpisodeRecord;
use crate::scenario::{PerceptionMode, Scenario};

/// Why an episode could not be set up (nothing ran).
#[derive(Debug, thiserror::Error)]
pub enum OrchestratorError {
    /// The simulated cell could not be built.
    #[error("simulated cell: {0}")]
    Cell(#[from] sim::cell::CellError),
    /// The planning model could not be built.
    #[error(transparent)]
    Knowledge(#[from] KnowledgeError),
    /// Perception could not be set up.
    #[error(transparent)]
    Perception(#[from] PerceptionError),
    /// The scenario asks for a perception mode that is not available.
    #[error("perception mode {0:?} is not available yet (no trained models)")]
    ModeUnavailable(PerceptionMode),
    /// No tokio runtime could be built.
    #[error("tokio runtime: {0}")]
    Runtime(String),
    /// The cell's limits are unusable, so its robot cannot be driven.
    #[error(transparent)]
    Limits(#[from] robots::limits::InvalidLimits),
}

/// One episode's output: the record and its events.
#[derive(Debug, Clone)]
pub struct EpisodeOutput {
    /// The record a run stores.
    pub record: EpisodeRecord,
    /// Every state transition.
    pub events: EventLog,
}

/// Runs one episode of `scenario` on `robot` and `io` with `perception`, planning with
/// `knowledge`. Never fails: every problem ends up in the record (aborted step, `abort`).
pub async fn run_episode(
    scenario: &Scenario,
    knowledge: &CellKnowledge,
    episode: u32,
    robot: &mut dyn Robot,
    io: &mut dyn CellIo,
    perception: &mut dyn PartPerception,
    settings: &EpisodeSettings,
) -> EpisodeOutput {
    let d = driver::Driver::new(
        scenario.spec.name.clone(),
        scenario.spec.seed,
        episode,
        &scenario.catalog,
        knowledge,
        robot,
        io,
        perception,
        settings,
        scenario.spec.cell.feeder.max_shakes,
        scenario.spec.policy.max_insertion_attempts,
    );
    let (record, events) = d.run().await;
    EpisodeOutput { record, events }
}

/// The seed of one of an episode's random streams (SplitMix64 of seed, episode and stream).
pub fn stream_seed(seed: u64, episode: u32, stream: u64) -> u64 {
    let mut z = seed
        ^ (u64::from(episode)).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ stream.wrapping_mul(0xD1B5_4A32_D192_ED03);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Stream id of the perception noise.
const PERCEPTION_STREAM: u64 = 0x5045_5243;

/// The scenario's keypoint-noise perception for `episode`, with its own seeded stream.
pub fn keypoint_noise_for(
    scenario: &Scenario,
    episode: u32,
) -> Result<KeypointNoise<ChaCha8Rng>, OrchestratorError> {
    let p = &scenario.spec.perception;
    if p.mode != PerceptionMode::KeypointNoise {
        return Err(OrchestratorError::ModeUnavailable(p.mode));
    }
    let rng =
        ChaCha8Rng::seed_from_u64(stream_seed(scenario.spec.seed, episode, PERCEPTION_STREAM));
    Ok(KeypointNoise::new(
        &scenario.catalog,
        scenario.spec.cell.base_T_table.isometry(),
        scenario.spec.cell.camera.base_T_camera.isometry(),
        KeypointNoiseConfig::new(p.keypoint_noise_px, p.outlier_fraction),
        rng,
    )?)
}

/// What stays the same across a scenario's simulated episodes.
pub struct SimSetup {
    /// The scenario.
    pub scenario: Scenario,
    /// The simulator's cell model.
    pub model: Arc<CellModel>,
    /// The planner's model of the cell.
    pub knowledge: Arc<CellKnowledge>,
    /// Policies.
    pub settings: EpisodeSettings,
}

impl SimSetup {
    /// Builds the simulated cell model (with the scenario's insertion scorer) and the planning
    /// model.
    pub fn new(scenario: Scenario) -> Result<Self, OrchestratorError> {
        let s = &scenario.spec;
        let scorer = s.simulation.insertion_scorer;
        let model = CellModel::new(
            &s.cell,
            &scenario.robot,
            &s.assembly,
            &s.noise,
            &scenario.catalog,
            scorer,
        )?;
        let knowledge = CellKnowledge::new(&scenario)?;
        Ok(Self {
            scenario,
            model,
            knowledge,
            settings: EpisodeSettings::default(),
        })
    }

    /// A fresh simulated cell for `episode`, shared so robot and side channels see one world.
    pub fn cell(&self, episode: u32) -> Result<Arc<Mutex<SimCell>>, OrchestratorError> {
        let cell = SimCell::new(
            self.model.clone(),
            self.scenario.spec.seed,
            u64::from(episode),
        )?;
        Ok(Arc::new(Mutex::new(cell)))
    }
}

/// Runs `episode` in the in-process simulated cell.
pub async fn run_sim_episode(
    setup: &SimSetup,
    episode: u32,
) -> Result<EpisodeOutput, OrchestratorError> {
    let cell = setup.cell(episode)?;
    let mut robot = setup.model.limited(SharedSimRobot::new(cell.clone()))?;
    let mut io = SimCellIo::new(cell);
    let mut perception = keypoint_noise_for(&setup.scenario, episode)?;
    Ok(run_episode(
        &setup.scenario,
        &setup.knowledge,
        episode,
        &mut robot,
        &mut io,
        &mut perception,
        &setup.settings,
    )
    .await)
}

/// [`run_sim_episode`] on a current-thread tokio runtime built for the call (for rayon workers).
pub fn run_sim_episode_blocking(
    setup: &SimSetup,
    episode: u32,
) -> Result<EpisodeOutput, OrchestratorError> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_time()
        .build()
        .map_err(|e| OrchestratorError::Runtime(e.to_string()))?;
    rt.block_on(run_sim_episode(setup, episode))
}
