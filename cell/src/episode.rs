//! What one episode produced: the record a run appends (one JSON line per episode) and that
//! reports, merges and the regression gate read. This is the contract between the orchestrator
//! (which fills it) and the run harness (which stores and summarises it).

use serde::{Deserialize, Serialize};

use crate::orchestrator::{Activity, State};

/// Format version of episode records; a results file with another version is refused.
pub const RECORD_VERSION: u32 = 1;

/// The outcome of one assembly step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StepOutcome {
    /// Fully inserted within the step's tolerances.
    Seated,
    /// Stuck part-way (wedged on a chamfer, tilted, over-constrained).
    Jammed,
    /// Landed beside the mating feature.
    Missed,
    /// The step never reached insertion (nothing pickable, grasp failures, planning, safety).
    Aborted,
}

/// What the simulator knows of the detection a step picked (simulation only): the perception
/// failure classes of the error budget.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PerceptionVerdict {
    /// The right part in the right stable pose (its pose error is in `perception_error`).
    Right,
    /// Another kind of part lies there.
    WrongPart,
    /// The right part, lying in another stable pose than perceived.
    WrongStablePose,
    /// No part lies there.
    Phantom,
}

impl PerceptionVerdict {
    /// The error-budget source a failure after this verdict is blamed on (`None` when right).
    pub fn source(self) -> Option<&'static str> {
        match self {
            PerceptionVerdict::Right => None,
            PerceptionVerdict::WrongPart => Some("perception.wrong_part"),
            PerceptionVerdict::WrongStablePose => Some("perception.wrong_stable_pose"),
            PerceptionVerdict::Phantom => Some("perception.phantom"),
        }
    }
}

/// Error-budget source of a step that found nothing to pick while the camera saw parts of its
/// kind that perception missed.
pub const PERCEPTION_MISSED: &str = "perception.missed";

/// Error-budget source of a step given up because the fingers closed on nothing every time,
/// after perception named the right part in the right stable pose (its pose error, in the
/// record, says how far off the pick was).
pub const GRASP_MISSED: &str = "grasp.missed";

/// True error of the held part relative to its target when insertion started.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseError {
    /// Offset along the target frame's x, millimetres.
    pub dx_mm: f64,
    /// Offset along the target frame's y, millimetres.
    pub dy_mm: f64,
    /// Height above fully seated at the end, millimetres.
    pub depth_mm: f64,
    /// Tilt from the target orientation, degrees.
    pub tilt_deg: f64,
    /// Rotation about the insertion axis, degrees.
    pub yaw_deg: f64,
}

/// What a force-guided insertion (`[force_insertion]`) decided before the fingers opened, from
/// the wrist's force and the arm's depth alone: recorded alike in simulation and production (a
/// production cell has nothing else to judge a seat by).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ForceRecord {
    /// Seated (and confirmed), jammed or missed.
    pub verdict: StepOutcome,
    /// First contact above seated of the reading that decided, millimetres (a seat: the
    /// confirming reading; otherwise the planned descent's, or where nothing was met, how far
    /// the descent went, below seated).
    pub contact_mm: f64,
    /// Force out of the hole in that reading, newtons.
    pub force_n: f64,
    /// Guarded descents of the step's last insertion (the planned one and spiral probes).
    pub probes: u32,
}

/// What a seat check by camera (`[seat_check]`) found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SeatCheckVerdict {
    /// The placed part's outline was found within the tolerances.
    Passed,
    /// Found, but farther from its target than the tolerances allow.
    Failed,
    /// Too few of the part's own edges found: absent, hidden, or far off.
    NotVisible,
    /// No capture was used: the arm or a held part stood in the camera's view of the fixture,
    /// or the camera failed.
    Refused,
}

/// A seat check by camera on a step's placed part (`[seat_check]`), in simulation and
/// production alike.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SeatCheckRecord {
    /// Passed, failed, not visible or refused.
    pub verdict: SeatCheckVerdict,
    /// Measured offset from the target across the insertion axis (insertion frame x, y),
    /// millimetres.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub offset_mm: Option<[f64; 2]>,
    /// Measured turn about the insertion axis, milliradians.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub yaw_mrad: Option<f64>,
    /// Share of the part's own outline samples that found an edge.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub support: Option<f64>,
    /// How many outline samples were the part's own (not on an edge of what was there before).
    #[serde(default)]
    pub samples: u32,
    /// The lateral and yaw tolerances applied, millimetres and milliradians.
    pub tolerance: [f64; 2],
    /// The true lateral offset of the placed part across the insertion axis (simulation only),
    /// millimetres.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub true_offset_mm: Option<[f64; 2]>,
}

/// One assembly step of an episode.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StepRecord {
    /// Catalog part placed by the step.
    pub part: String,
    /// How it ended.
    pub outcome: StepOutcome,
    /// Pick-and-insert attempts used (1 when the first attempt worked).
    pub attempts: u32,
    /// Insertions tried (1 when the first one seated; retries after a jam or miss add one each).
    #[serde(default)]
    pub insertion_attempts: u32,
    /// Feeder shakes used.
    pub shakes: u32,
    /// Why it failed, in words, when it did.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cause: Option<String>,
    /// Error sources blamed for a failure, by their scenario parameter names
    /// (`perception`, `calibration_translation`, `robot_repeatability`, `grasp_offset`, ...).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sources: Vec<String>,
    /// True pose error at insertion, when an insertion happened.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pose_error: Option<PoseError>,
    /// Perception error of the picked instance in the table plane (x, y in mm; yaw in degrees);
    /// written as `perception_error_xy_mm_yaw_deg` (records from before read their
    /// `perception_error`).
    #[serde(
        default,
        rename = "perception_error_xy_mm_yaw_deg",
        alias = "perception_error",
        skip_serializing_if = "Option::is_none"
    )]
    pub perception_error: Option<[f64; 3]>,
    /// What the picked detection really was (simulation only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub perception_verdict: Option<PerceptionVerdict>,
    /// Perception's confidence in the picked instance, in (0, 1].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub confidence: Option<f64>,
    /// Simulated seconds the step took.
    pub sim_time_s: f64,
    /// The force-guided insertion's own verdict, on a step that inserted by feel.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub force: Option<ForceRecord>,
    /// The seat check by camera, on a step that seated with `[seat_check]` on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seat_check: Option<SeatCheckRecord>,
}

/// One episode: the full assembly attempt from a fresh feeder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpisodeRecord {
    /// Record format version ([`RECORD_VERSION`]).
    pub version: u32,
    /// Scenario name.
    pub scenario: String,
    /// Scenario seed.
    pub seed: u64,
    /// Episode index; with the seed it replays the episode alone.
    pub episode: u32,
    /// Every step seated.
    pub success: bool,
    /// The steps attempted, in order.
    pub steps: Vec<StepRecord>,
    /// Simulated cycle time of the whole assembly, seconds.
    pub cycle_time_s: f64,
    /// Wall-clock seconds the episode took to compute.
    pub wall_time_s: f64,
    /// Why the episode stopped early, if it did (safety stop, lost connection, ...).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub abort: Option<String>,
    /// Where the cycle's simulated time went, state by state in order; the spans add up to
    /// `cycle_time_s` (empty in records from before they were kept).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub phases: Vec<PhaseSpan>,
}

/// Simulated time spent in one state of the orchestrator, on the critical path of the cycle, on
/// one activity (a state's time is split at the end of each of its motions).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PhaseSpan {
    /// The state.
    pub state: State,
    /// What the time went on (absent in records from before activities were kept).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub activity: Option<Activity>,
    /// The assembly step it served, when inside one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub step: Option<usize>,
    /// Simulated seconds spent in it.
    #[serde(rename = "s")]
    pub duration_s: f64,
}

impl EpisodeRecord {
    /// Simulated seconds spent in each state over the whole cycle.
    pub fn time_by_state(&self) -> std::collections::BTreeMap<State, f64> {
        let mut out = std::collections::BTreeMap::new();
        for p in &self.phases {
            *out.entry(p.state).or_insert(0.0) += p.duration_s;
        }
        out
    }

    /// Simulated seconds spent on each activity over the whole cycle (empty for records from
    /// before activities were kept).
    pub fn time_by_activity(&self) -> std::collections::BTreeMap<Activity, f64> {
        let mut out = std::collections::BTreeMap::new();
        for p in &self.phases {
            if let Some(a) = p.activity {
                *out.entry(a).or_insert(0.0) += p.duration_s;
            }
        }
        out
    }
}
