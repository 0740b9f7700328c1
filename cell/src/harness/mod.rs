//! The simulation harness: everything that puts the orchestrator engine (`crate::orchestrator`)
//! in front of the simulated cell instead of a real one. A production run builds none of it.
//!
//! - [`SimSetup::new`] once per scenario: the engine's [`Setup`] and the simulator's
//!   [`CellModel`] (with the scenario's insertion scorer).
//! - [`run_sim_episode`] (async) or [`run_sim_episode_blocking`] (a current-thread tokio runtime
//!   built for the call: use it from rayon workers) runs one episode in process: the
//!   [`SimCell`] is the engine's whole [`Workcell`] (`sim_io`), perception is
//!   [`KeypointNoise`] (`keypoint_noise`). Same (scenario, episode) → same record.
//! - [`sim_episode_over_rtde`] runs it through the production client instead: the cell behind
//!   a virtual UR controller on loopback, `UrRobot` over RTDE, [`SimCellIo`] for the side
//!   channels (`over_rtde`).
//! - `verdict`: the simulated cell's insertion reports as the engine's [`InsertionCheck`]s.
//!
//! All randomness is seeded from (scenario seed, episode): any episode replays alone.
//!
//! [`InsertionCheck`]: crate::orchestrator::InsertionCheck
//! [`Workcell`]: crate::orchestrator::Workcell

#![allow(non_snake_case)]

mod audit;
mod error;
mod keypoint_noise;
mod over_rtde;
mod sim_camera;
mod sim_io;
mod sim_perception;
mod verdict;

pub use error::HarnessError;
pub use keypoint_noise::{KeypointNoise, keypoint_noise_for};
pub use over_rtde::{
    OverRtdeError, SimOverRtde, connect_sim_over_rtde, sim_cell_io, sim_episode_over_rtde,
};
pub use sim_camera::SimulatedCamera;
pub use sim_io::SimCellIo;
pub use sim_perception::{EpisodePerception, PipelinePool, SimPerception};
pub use verdict::{check_of, source_name};

use std::sync::{Arc, Mutex};

use sim::cell::{CellModel, SimCell};

use crate::orchestrator::{EpisodeOutput, Setup, run_episode};
use crate::scenario::Scenario;
use perception::PartPerception;

/// What stays the same across a scenario's simulated episodes.
pub struct SimSetup {
    /// What the engine needs: scenario, planning model, policies.
    pub engine: Setup,
    /// The simulator's cell model.
    pub model: Arc<CellModel>,
    /// How episodes perceive (learned pipelines are pooled here).
    pub perception: SimPerception,
}

impl SimSetup {
    /// Builds the simulated cell model (with the scenario's insertion scorer) and the engine's
    /// set-up.
    pub fn new(scenario: Scenario) -> Result<Self, HarnessError> {
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
        Ok(Self {
            perception: SimPerception::new(&scenario)?,
            engine: Setup::new(scenario)?,
            model,
        })
    }

    /// The scenario.
    pub fn scenario(&self) -> &Scenario {
        &self.engine.scenario
    }

    /// A fresh simulated cell for `episode`.
    pub fn sim_cell(&self, episode: u32) -> Result<SimCell, HarnessError> {
        Ok(SimCell::new(
            self.model.clone(),
            self.engine.scenario.spec.seed,
            u64::from(episode),
        )?
        .render_captures(self.perception.needs_pixels()))
    }

    /// A fresh simulated cell for `episode`, shared with a virtual controller that moves it.
    pub fn cell(&self, episode: u32) -> Result<Arc<Mutex<SimCell>>, HarnessError> {
        Ok(Arc::new(Mutex::new(self.sim_cell(episode)?)))
    }
}

/// Runs `episode` in the in-process simulated cell.
pub async fn run_sim_episode(
    setup: &SimSetup,
    episode: u32,
) -> Result<EpisodeOutput, HarnessError> {
    let mut perception = setup.perception.for_episode(setup.scenario(), episode)?;
    run_sim_episode_with(setup, episode, &mut perception).await
}

/// Runs `episode` in the in-process simulated cell with `perception` (e.g. one that records
/// what it saw, to draw a failure).
pub async fn run_sim_episode_with(
    setup: &SimSetup,
    episode: u32,
    perception: &mut dyn PartPerception,
) -> Result<EpisodeOutput, HarnessError> {
    let mut cell = setup.model.limited(setup.sim_cell(episode)?)?;
    Ok(run_episode(setup.engine.context(episode), &mut cell, perception).await)
}

/// [`run_sim_episode`] on a current-thread tokio runtime built for the call (for rayon workers).
pub fn run_sim_episode_blocking(
    setup: &SimSetup,
    episode: u32,
) -> Result<EpisodeOutput, HarnessError> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_time()
        .build()
        .map_err(|e| HarnessError::Runtime(e.to_string()))?;
    rt.block_on(run_sim_episode(setup, episode))
}
