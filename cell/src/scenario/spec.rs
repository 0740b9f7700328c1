//! The scenario file schema: every table and key a scenario may hold. Unknown keys are errors.
//! The cell's physical description comes from `sim::config`, shared with the simulator.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};
use sim::cell::insertion::Scorer;
use sim::config::{AssemblyStep, CellSpec, NoiseSpec};

/// A whole scenario: the cell, the parts, perception, the assembly sequence and the noise models.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScenarioSpec {
    /// Short name used in reports.
    pub name: String,
    /// One line for people.
    #[serde(default)]
    pub description: String,
    /// Root seed; episode i draws from (seed, i), so any episode replays alone.
    pub seed: u64,
    /// Episodes a run performs by default.
    pub episodes: u32,
    /// The physical cell.
    pub cell: CellSpec,
    /// The part catalog.
    pub parts: PartsSpec,
    /// How parts are perceived.
    pub perception: PerceptionSpec,
    /// Assembly steps, in order.
    pub assembly: Vec<AssemblyStep>,
    /// Error sources; each is a named parameter so failures can be attributed.
    #[serde(default)]
    pub noise: NoiseSpec,
    /// Recovery bounds of the orchestrator.
    #[serde(default)]
    pub policy: PolicySpec,
    /// How the simulated cell decides outcomes.
    #[serde(default)]
    pub simulation: SimulationSpec,
}

/// Simulation settings (`[simulation]`); a real controller ignores them.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimulationSpec {
    /// Which scorer decides insertions: `analytic` (capture model, microseconds; the default),
    /// `contact` (rapier contact simulation of the real meshes, the reference; ~15 ms per
    /// insertion) or `mujoco` (the same in MuJoCo). `cell scorers` measures how often they agree.
    #[serde(default)]
    pub insertion_scorer: Scorer,
}

/// The orchestrator's default insertion attempts per step (first try plus retries).
pub const DEFAULT_INSERTION_ATTEMPTS: u32 = 3;
/// The most insertion attempts per step a scenario may ask for.
pub const MAX_INSERTION_ATTEMPTS: u32 = 10;

/// The least perception confidence the cell picks a part at, unless `[policy]` says otherwise.
pub const DEFAULT_MIN_PICK_CONFIDENCE: f64 = 0.2;

/// Recovery bounds and the pick bar (`[policy]`): every recovery path of an episode is bounded.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PolicySpec {
    /// Insertion attempts per step: a jammed or missed insertion, found before the fingers
    /// open, is lifted clear, corrected and retried until this many attempts were made, then
    /// released with its cause (1 = no retry).
    #[serde(default = "default_insertion_attempts")]
    pub max_insertion_attempts: u32,
    /// The least perception confidence a detected part needs to be picked, in [0, 1]: below it
    /// the part is left where it lies (and, with no other candidate, the feeder shakes). Feeders
    /// where parts pile up gain from a higher bar, sparse ones lose cycle time to it.
    #[serde(default = "default_min_pick_confidence")]
    pub min_pick_confidence: f64,
}

impl Default for PolicySpec {
    fn default() -> Self {
        Self {
            max_insertion_attempts: DEFAULT_INSERTION_ATTEMPTS,
            min_pick_confidence: DEFAULT_MIN_PICK_CONFIDENCE,
        }
    }
}

fn default_min_pick_confidence() -> f64 {
    DEFAULT_MIN_PICK_CONFIDENCE
}

fn default_insertion_attempts() -> u32 {
    DEFAULT_INSERTION_ATTEMPTS
}

/// Where the catalog lives.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PartsSpec {
    /// Catalog file, relative to the scenario file.
    pub catalog: PathBuf,
}

/// Perception modes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PerceptionMode {
    /// True keypoints with pixel noise through the real PnP and refinement (the paper's ablation).
    KeypointNoise,
    /// Learned segmentation and keypoint networks.
    Learned,
}

/// Perception settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PerceptionSpec {
    /// Which pipeline runs.
    pub mode: PerceptionMode,
    /// Standard deviation of keypoint noise per axis, pixels (keypoint-noise mode).
    #[serde(default = "half")]
    pub keypoint_noise_px: f64,
    /// Fraction of keypoints replaced by gross outliers (keypoint-noise mode).
    #[serde(default)]
    pub outlier_fraction: f64,
    /// Folder with ONNX models (learned mode), relative to the scenario file.
    #[serde(default)]
    pub models: Option<PathBuf>,
    /// Reprojection gate of the learned pipeline, pixels: poses whose keypoints reproject
    /// further (RMS) are not reported. It trades missed parts against wrong poses, so it should
    /// follow the keypoint net's measured accuracy.
    #[serde(default = "learned_gate")]
    pub max_rms_px: f64,
}

/// The learned pipeline's own default gate.
fn learned_gate() -> f64 {
    perception::learned::PipelineConfig::default()
        .estimator
        .max_rms_px
}

fn half() -> f64 {
    0.5
}
