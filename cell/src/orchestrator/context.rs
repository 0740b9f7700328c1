//! What an episode runs under: the policies ([`EpisodeSettings`]), what stays the same across a
//! scenario's episodes ([`Setup`]) and one episode's read-only view of it ([`EpisodeContext`]),
//! passed to the engine as one value.

use std::sync::Arc;

use perception::part::Catalog;
use robots::kinematics::Joints;

use super::geometry::{CellKnowledge, KnowledgeError};
use super::insertion::RimCache;
use super::planning::PlanningConfig;
use super::selection::SelectionConfig;
use super::state::Timeouts;
use crate::scenario::Scenario;

/// Policies and tuning of an episode.
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeSettings {
    /// Bounds of every state.
    pub timeouts: Timeouts,
    /// Instance selection.
    pub selection: SelectionConfig,
    /// Motion planning.
    pub planning: PlanningConfig,
    /// Pick attempts per step (a failed grasp re-perceives and retries).
    pub max_grasp_attempts: u32,
    /// Home joints; the robot's joints at the start when `None`.
    pub home: Option<Joints>,
    /// Capture and perceive the feeder for the next step while the arm inserts
    /// (`[motion] overlap`).
    pub overlap: bool,
    /// Seconds a capture and its perception take on the cell's clock
    /// (`[motion] perception_time`).
    pub perception_time: f64,
}

impl Default for EpisodeSettings {
    fn default() -> Self {
        Self {
            timeouts: Timeouts::default(),
            selection: SelectionConfig::default(),
            planning: PlanningConfig::default(),
            max_grasp_attempts: 3,
            home: None,
            overlap: false,
            perception_time: 0.0,
        }
    }
}

/// What stays the same across a scenario's episodes on any cell: the scenario, the planner's
/// model of the cell and the policies. Building it touches no robot and no simulator.
#[derive(Clone)]
pub struct Setup {
    /// The scenario.
    pub scenario: Scenario,
    /// The planner's model of the cell.
    pub knowledge: Arc<CellKnowledge>,
    /// Policies.
    pub settings: EpisodeSettings,
    /// Force-guided insertion's rim landings, swept once per step and receiver state for all
    /// the episodes (clones of the set-up share them).
    pub rims: Arc<RimCache>,
}

impl Setup {
    /// Builds the planning model of `scenario`, with the default policies and the scenario's
    /// pick bar (`[policy] min_pick_confidence`).
    pub fn new(scenario: Scenario) -> Result<Self, KnowledgeError> {
        let knowledge = CellKnowledge::new(&scenario)?;
        let mut settings = EpisodeSettings::default();
        settings.selection.min_confidence = scenario.spec.policy.min_pick_confidence;
        settings.planning.blend_radius = scenario.spec.motion.blend_radius;
        settings.overlap = scenario.spec.motion.overlap;
        settings.perception_time = scenario.spec.motion.perception_time;
        Ok(Self {
            scenario,
            knowledge,
            settings,
            rims: Arc::default(),
        })
    }

    /// The context of `episode`.
    pub fn context(&self, episode: u32) -> EpisodeContext<'_> {
        let spec = &self.scenario.spec;
        EpisodeContext {
            scenario: &spec.name,
            seed: spec.seed,
            episode,
            catalog: &self.scenario.catalog,
            knowledge: &self.knowledge,
            settings: &self.settings,
            max_shakes: spec.cell.feeder.max_shakes,
            max_insertion_attempts: spec.policy.max_insertion_attempts.max(1),
            force: spec.force_insertion.as_ref(),
            seat_check: spec.seat_check.as_ref(),
            rims: &self.rims,
        }
    }
}

/// One episode's read-only context: which episode, and everything the engine plans with.
#[derive(Clone, Copy)]
pub struct EpisodeContext<'a> {
    /// Scenario name (for the record).
    pub scenario: &'a str,
    /// Scenario seed (for the record).
    pub seed: u64,
    /// Episode index.
    pub episode: u32,
    /// The part catalog.
    pub catalog: &'a Catalog,
    /// The planner's model of the cell.
    pub knowledge: &'a CellKnowledge,
    /// Policies.
    pub settings: &'a EpisodeSettings,
    /// Feeder shakes allowed per step (`cell.feeder.max_shakes`).
    pub max_shakes: u32,
    /// Insertions allowed per step, at least 1 (`policy.max_insertion_attempts`).
    pub max_insertion_attempts: u32,
    /// Force-guided insertion, when the scenario enables it (`[force_insertion]`).
    pub force: Option<&'a crate::scenario::ForceInsertionSpec>,
    /// Seat verification by camera, when the scenario enables it (`[seat_check]`).
    pub seat_check: Option<&'a crate::scenario::SeatCheckSpec>,
    /// Force-guided insertion's rim landings, shared by the scenario's episodes.
    pub rims: &'a RimCache,
}
