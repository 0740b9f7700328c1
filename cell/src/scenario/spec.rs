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
    /// Force-guided insertion (`[force_insertion]`): present, every insertion descends under a
    /// force limit, is judged from force and depth before the fingers open and searches after a
    /// miss; absent, insertions are position-controlled as before.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub force_insertion: Option<ForceInsertionSpec>,
    /// Seat verification by camera (`[seat_check]`): present, every seat is checked after the
    /// release and retreat on a capture of the fixture (the placed part's outline aligned
    /// from its target pose); absent (the default), no capture is taken and nothing changes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seat_check: Option<SeatCheckSpec>,
    /// How the orchestrator moves the arm between stops (`[motion]`); absent, every move stops
    /// at its target as before.
    #[serde(default, skip_serializing_if = "MotionSpec::is_default")]
    pub motion: MotionSpec,
}

/// How far (m) the planner's lifts and approaches rise above what they clear (the planner's
/// default, kept here so that `cell check` bounds the blend radius without the planner).
pub const PLANNER_CLEARANCE_HEIGHT: f64 = 0.010;

/// Length (m) of the planner's slow final segments into a grasp or an insertion (as
/// [`PLANNER_CLEARANCE_HEIGHT`]).
pub const PLANNER_SLOW_DISTANCE: f64 = 0.001;

/// `[motion]`: blended transits and overlapped work.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotionSpec {
    /// Blend radius (m) of the lift → transit → approach chains: above 0 the orchestrator runs
    /// them as one blended path ([`robots::robot::Robot::move_path`]), its corners raised by
    /// the radius so the rounded corner keeps the planner's clearance; 0 (the default) stops at
    /// every via-point. At most the planner's clearance height less its slow distance (half of
    /// the shortest segment it blends).
    #[serde(default)]
    pub blend_radius: f64,
    /// Work overlapped (simulated cell only; a production run ignores it with a warning):
    /// while the arm inserts a part, the camera captures the feeder and perception runs for
    /// the next step, so that step starts with its detections ready. A capture with the arm
    /// or the held part between the camera and the feeder is refused and taken again later.
    #[serde(default)]
    pub overlap: bool,
    /// Seconds a capture and its perception take on the cell's clock (0, the default: free,
    /// as before). Without `overlap` every step waits for them; with it, the insertion's
    /// motion runs meanwhile and the next step waits only for what remains.
    #[serde(default)]
    pub perception_time: f64,
}

impl MotionSpec {
    /// True for the default (no blending), which is not written out.
    pub fn is_default(&self) -> bool {
        *self == MotionSpec::default()
    }
}

/// Force-guided insertion settings (`[force_insertion]`), the same in simulation and production.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ForceInsertionSpec {
    /// Force against the descent at which the guarded move stops, N: above the wrist sensor's
    /// precision (±4 N on a UR5e) and below the force that makes a held part slip in the fingers.
    #[serde(default = "default_contact_force")]
    pub contact_force: f64,
    /// Speed of the guarded descent, m/s (the planner's slow insertion speed; the contact
    /// engines' wrist descends at 25 mm/s).
    #[serde(default = "default_contact_speed")]
    pub contact_speed: f64,
    /// Axial stiffness of the held part pressed onto what stops it, N/m: the stop is this much
    /// past first contact per newton, and the depth of first contact is read back with it.
    #[serde(default = "default_contact_stiffness")]
    pub contact_stiffness: f64,
    /// How far below seated the guarded descent goes before it concludes that nothing is under
    /// the tool, metres.
    #[serde(default = "default_overtravel")]
    pub overtravel: f64,
    /// Largest height above seated at which first contact still counts as seated, metres.
    #[serde(default = "default_seat_band")]
    pub seat_band: f64,
    /// Probes of the spiral search after a miss on the receiver's rim or a jam, per insertion
    /// attempt (0 = no search): lift clear, step sideways within the capture band, descend.
    #[serde(default = "default_search_points")]
    pub search_points: u32,
}

/// Seat verification by camera (`[seat_check]`), the same in simulation and production: after a
/// seated verdict, the release and the retreat, the camera captures the fixture (with the arm
/// out of its view) and the placed part's outline is aligned from its target pose; the seat
/// passes when the measured offset is within the tolerances with enough of the part's own
/// edges found.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SeatCheckSpec {
    /// Largest measured lateral offset (across the insertion axis) of a passing seat, metres;
    /// absent: each step's `tolerances.lateral` plus the measurement's allowance
    /// ([`SEAT_CHECK_ALLOWANCE`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lateral: Option<f64>,
    /// Largest measured turn about the insertion axis of a passing seat, radians.
    #[serde(default = "default_seat_yaw")]
    pub yaw: f64,
    /// Least share (0–1) of the part's own outline samples (those not on an edge of what was
    /// there before it: the nest's pocket, the receiving part) that must find an image edge
    /// within a pixel; below it the part is "not visible" and the check does not pass.
    #[serde(default = "default_seat_min_support")]
    pub min_support: f64,
}

fn default_seat_min_support() -> f64 {
    0.6
}

fn default_seat_yaw() -> f64 {
    0.035
}

/// What a seat check's lateral tolerance adds to a step's `tolerances.lateral` when
/// `[seat_check] lateral` is absent, metres: the check's own error (on 50 seated parts of the
/// nominal USB-C cell, measured against the true offset: 63.9 µm mean, 122.9 µm largest, a
/// camera pixel being 141 µm at the fixture).
pub const SEAT_CHECK_ALLOWANCE: f64 = 0.00006;

impl Default for SeatCheckSpec {
    fn default() -> Self {
        Self {
            lateral: None,
            yaw: default_seat_yaw(),
            min_support: default_seat_min_support(),
        }
    }
}

/// The most spiral probes an insertion attempt may make.
pub const MAX_SEARCH_POINTS: u32 = 32;

fn default_contact_force() -> f64 {
    10.0
}

fn default_contact_speed() -> f64 {
    0.02
}

fn default_contact_stiffness() -> f64 {
    sim::cell::wrench::HELD_CONTACT_STIFFNESS
}

fn default_overtravel() -> f64 {
    0.001
}

fn default_seat_band() -> f64 {
    0.0002
}

fn default_search_points() -> u32 {
    8
}

impl Default for ForceInsertionSpec {
    fn default() -> Self {
        Self {
            contact_force: default_contact_force(),
            contact_speed: default_contact_speed(),
            contact_stiffness: default_contact_stiffness(),
            overtravel: default_overtravel(),
            seat_band: default_seat_band(),
            search_points: default_search_points(),
        }
    }
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
    /// The table scale the learned pipeline's networks see each frame at: `"trained"` (the
    /// middle of the segmenter's training range), `"sensor"` (as captured) or pixels per mm.
    #[serde(default = "trained_scale")]
    pub input_scale: perception::learned::InputScale,
}

/// The learned pipeline's own default gate.
fn learned_gate() -> f64 {
    perception::learned::PipelineConfig::default()
        .estimator
        .max_rms_px
}

/// The learned pipeline's own default input scale.
fn trained_scale() -> perception::learned::InputScale {
    perception::learned::PipelineConfig::default().input_scale
}

fn half() -> f64 {
    0.5
}
