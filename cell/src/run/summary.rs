//! The summary of a results set: success rate with its Wilson interval, per-step rates, failure
//! causes, the error budget (which error source each failure is blamed on), cycle times and
//! pose errors. A pure function of the stored records' deterministic fields (never wall time),
//! so a resumed or merged run summarises exactly like an uninterrupted one.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::distribution::Distribution;
use super::mechanism::MechanismCount;
use super::outcomes::{OUTCOMES, outcome_index, outcome_name};

use super::header::ResultsHeader;
use super::mechanism::Mechanisms;
use crate::episode::{EpisodeRecord, StepOutcome};
use crate::regress::stats::{Counts, Interval, wilson};

/// Confidence of every interval in a summary.
pub const CONFIDENCE: f64 = 0.95;

/// Error-budget entry for failures whose step named no error source.
pub const UNATTRIBUTED: &str = "unattributed";

/// Pose error at insertion of one step, over the episodes that inserted.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseErrorStats {
    /// Lateral offset √(dx² + dy²), millimetres.
    pub lateral_mm: Distribution,
    /// Tilt, degrees.
    pub tilt_deg: Distribution,
    /// |yaw| about the insertion axis, degrees.
    pub yaw_abs_deg: Distribution,
}

/// One assembly step over all episodes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StepSummary {
    /// Position in the assembly sequence (0-based).
    pub index: usize,
    /// Part placed by the step.
    pub part: String,
    /// Episodes in which the step was attempted.
    pub reached: u32,
    /// Episodes in which it seated.
    pub seated: u32,
    /// Episodes in which it jammed.
    pub jammed: u32,
    /// Episodes in which the part missed the mating feature.
    pub missed: u32,
    /// Episodes in which the step never reached insertion.
    pub aborted: u32,
    /// seated / reached.
    pub rate: f64,
    /// Wilson interval of `rate`.
    pub ci95: Interval,
    /// Mean pick-and-insert attempts per reached episode.
    pub mean_attempts: f64,
    /// Feeder shakes over all episodes.
    pub shakes: u32,
    /// Episodes in which the step inserted its part at least once (records written before
    /// `insertion_attempts` was recorded count none).
    #[serde(default)]
    pub inserted: u32,
    /// Mean insertions per episode that inserted (1 when every first insertion was final);
    /// `None` when no episode inserted.
    #[serde(default)]
    pub mean_insertion_attempts: Option<f64>,
    /// Episodes in which the step seated only after a retry (more than one insertion).
    #[serde(default)]
    pub seated_after_retry: u32,
    /// Pose error at insertion, when any insertion happened.
    pub pose_error: Option<PoseErrorStats>,
    /// The step's lateral capture band (clearance / 2 + lead-in), millimetres, when the
    /// results header records it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub capture_mm: Option<f64>,
}

impl StepSummary {
    /// Seated out of reached.
    pub fn counts(&self) -> Counts {
        Counts::new(self.seated, self.reached)
    }
}

/// How often one failure cause ended an episode.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct CauseCount {
    /// The failing step's part (`None`: the episode stopped outside any step).
    pub part: Option<String>,
    /// The failing step's outcome.
    pub outcome: Option<StepOutcome>,
    /// The cause as recorded.
    pub cause: String,
    /// Failed episodes with this cause.
    pub count: u32,
}

/// One error source's share of the failures.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SourceShare {
    /// Scenario parameter name of the source (or [`UNATTRIBUTED`]).
    pub source: String,
    /// Failed episodes that blame it (an episode may blame several sources).
    pub failures: u32,
    /// failures / all failed episodes.
    pub share: f64,
}

/// Everything a report and the regression gate need from a results set.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// Scenario name.
    pub scenario: String,
    /// Scenario seed.
    pub seed: u64,
    /// SHA-256 of the scenario file.
    pub scenario_sha256: String,
    /// Episode record version.
    pub record_version: u32,
    /// Episodes summarised.
    pub episodes: u32,
    /// Episodes with every step seated.
    pub successes: u32,
    /// successes / episodes.
    pub success_rate: f64,
    /// Wilson interval of `success_rate`.
    pub success_ci95: Interval,
    /// Per assembly step, in order.
    pub steps: Vec<StepSummary>,
    /// Failed episodes.
    pub failures: u32,
    /// Causes of failed episodes, most frequent first.
    pub failure_causes: Vec<CauseCount>,
    /// The same failures grouped by mechanism (the cause with its numbers taken out), most
    /// frequent first.
    #[serde(default)]
    pub failure_mechanisms: Vec<MechanismCount>,
    /// Error sources blamed for failures, most blamed first.
    pub error_budget: Vec<SourceShare>,
    /// Simulated cycle time of successful episodes, seconds.
    pub cycle_time_s: Option<Distribution>,
    /// Where that time goes: the mean seconds of each orchestrator state per successful
    /// assembly (empty for records from before phases were kept).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub cycle_phases: Vec<super::phases::PhaseMean>,
    /// The same time by activity (transit, approach, grasp, insertion, retreat, shake,
    /// waiting; empty for records from before activities were kept).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub cycle_activities: Vec<super::phases::ActivityMean>,
}

impl Summary {
    /// Successes out of episodes.
    pub fn counts(&self) -> Counts {
        Counts::new(self.successes, self.episodes)
    }

    /// Summarises `records` stored under `header`.
    pub fn new<'a>(
        header: &ResultsHeader,
        records: impl IntoIterator<Item = &'a EpisodeRecord>,
    ) -> Self {
        let mut records: Vec<&EpisodeRecord> = records.into_iter().collect();
        records.sort_by_key(|r| r.episode);
        let episodes = records.len() as u32;
        let successes = records.iter().filter(|r| r.success).count() as u32;

        let mut steps: Vec<StepAcc> = Vec::new();
        let mut causes: BTreeMap<(Option<String>, Option<usize>, String), u32> = BTreeMap::new();
        let mut mechanisms = Mechanisms::default();
        let mut sources: BTreeMap<String, u32> = BTreeMap::new();
        let mut cycle = Vec::new();
        for r in &records {
            for (i, s) in r.steps.iter().enumerate() {
                let acc = match steps.iter_mut().find(|a| a.index == i && a.part == s.part) {
                    Some(a) => a,
                    None => {
                        steps.push(StepAcc::new(i, &s.part));
                        steps.last_mut().expect("just pushed")
                    }
                };
                acc.add(s);
            }
            if r.success {
                cycle.push(r.cycle_time_s);
                continue;
            }
            let failed = r.steps.iter().find(|s| s.outcome != StepOutcome::Seated);
            let key = match failed {
                Some(s) => (
                    Some(s.part.clone()),
                    Some(outcome_index(s.outcome)),
                    s.cause
                        .clone()
                        .unwrap_or_else(|| outcome_name(s.outcome).into()),
                ),
                None => (
                    None,
                    None,
                    r.abort
                        .clone()
                        .unwrap_or_else(|| "no cause recorded".into()),
                ),
            };
            mechanisms.add(key.0.clone(), key.1.map(|k| OUTCOMES[k]), &key.2, r.episode);
            *causes.entry(key).or_default() += 1;
            let blamed: Vec<String> = match failed {
                Some(s) if !s.sources.is_empty() => {
                    let mut v = s.sources.clone();
                    v.sort();
                    v.dedup();
                    v
                }
                _ => vec![UNATTRIBUTED.into()],
            };
            for b in blamed {
                *sources.entry(b).or_default() += 1;
            }
        }
        steps.sort_by(|a, b| a.index.cmp(&b.index).then(a.part.cmp(&b.part)));
        let failures = episodes - successes;
        let mut failure_causes: Vec<CauseCount> = causes
            .into_iter()
            .map(|((part, outcome, cause), count)| CauseCount {
                part,
                outcome: outcome.map(|k| OUTCOMES[k]),
                cause,
                count,
            })
            .collect();
        failure_causes.sort_by_key(|c| std::cmp::Reverse(c.count));
        let mut error_budget: Vec<SourceShare> = sources
            .into_iter()
            .map(|(source, n)| SourceShare {
                source,
                failures: n,
                share: f64::from(n) / f64::from(failures.max(1)),
            })
            .collect();
        error_budget.sort_by_key(|e| std::cmp::Reverse(e.failures));
        let counts = Counts::new(successes, episodes);
        Self {
            scenario: header.scenario.clone(),
            seed: header.seed,
            scenario_sha256: header.scenario_sha256.clone(),
            record_version: header.record_version,
            episodes,
            successes,
            success_rate: counts.rate(),
            success_ci95: wilson(counts, CONFIDENCE),
            steps: steps
                .into_iter()
                .map(|a| {
                    let capture = header.capture_mm.get(a.index).copied();
                    a.finish(capture)
                })
                .collect(),
            failures,
            failure_causes,
            failure_mechanisms: mechanisms.finish(),
            error_budget,
            cycle_time_s: Distribution::of(&cycle),
            cycle_phases: super::phases::phase_means(records.iter().copied()),
            cycle_activities: super::phases::activity_means(records.iter().copied()),
        }
    }
}

struct StepAcc {
    index: usize,
    part: String,
    outcomes: [u32; 4],
    attempts: u64,
    shakes: u32,
    inserted: u32,
    insertions: u64,
    seated_after_retry: u32,
    lateral: Vec<f64>,
    tilt: Vec<f64>,
    yaw: Vec<f64>,
}

impl StepAcc {
    fn new(index: usize, part: &str) -> Self {
        Self {
            index,
            part: part.into(),
            outcomes: [0; 4],
            attempts: 0,
            shakes: 0,
            inserted: 0,
            insertions: 0,
            seated_after_retry: 0,
            lateral: Vec::new(),
            tilt: Vec::new(),
            yaw: Vec::new(),
        }
    }

    fn add(&mut self, s: &crate::episode::StepRecord) {
        self.outcomes[outcome_index(s.outcome)] += 1;
        self.attempts += u64::from(s.attempts);
        self.shakes += s.shakes;
        if s.insertion_attempts > 0 {
            self.inserted += 1;
            self.insertions += u64::from(s.insertion_attempts);
        }
        if s.outcome == StepOutcome::Seated && s.insertion_attempts > 1 {
            self.seated_after_retry += 1;
        }
        if let Some(e) = &s.pose_error {
            self.lateral.push(e.dx_mm.hypot(e.dy_mm));
            self.tilt.push(e.tilt_deg);
            self.yaw.push(e.yaw_deg.abs());
        }
    }

    fn finish(self, capture_mm: Option<f64>) -> StepSummary {
        let reached: u32 = self.outcomes.iter().sum();
        let c = Counts::new(self.outcomes[0], reached);
        let pose_error = match (
            Distribution::of(&self.lateral),
            Distribution::of(&self.tilt),
            Distribution::of(&self.yaw),
        ) {
            (Some(lateral_mm), Some(tilt_deg), Some(yaw_abs_deg)) => Some(PoseErrorStats {
                lateral_mm,
                tilt_deg,
                yaw_abs_deg,
            }),
            _ => None,
        };
        StepSummary {
            index: self.index,
            part: self.part,
            reached,
            seated: self.outcomes[0],
            jammed: self.outcomes[1],
            missed: self.outcomes[2],
            aborted: self.outcomes[3],
            rate: c.rate(),
            ci95: wilson(c, CONFIDENCE),
            mean_attempts: if reached == 0 {
                0.0
            } else {
                self.attempts as f64 / f64::from(reached)
            },
            shakes: self.shakes,
            inserted: self.inserted,
            mean_insertion_attempts: (self.inserted > 0)
                .then(|| self.insertions as f64 / f64::from(self.inserted)),
            seated_after_retry: self.seated_after_retry,
            pose_error,
            capture_mm,
        }
    }
}
