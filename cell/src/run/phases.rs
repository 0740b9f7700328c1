//! Where the cycle time goes: the mean simulated time each orchestrator state takes per
//! assembly, over a run's successful episodes, and the episodes that show it best (a typical one
//! and the slowest).

use serde::{Deserialize, Serialize};

use crate::episode::EpisodeRecord;
use crate::orchestrator::{Activity, State};

/// Mean simulated seconds one state takes per successful assembly.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PhaseMean {
    /// The state.
    pub state: State,
    /// Mean seconds per successful episode (0 for an episode that never entered it).
    pub mean_s: f64,
    /// Share of the mean cycle time.
    pub share: f64,
}

/// The mean time of each state over the successful episodes that kept their phases, states in
/// order; empty when there are none.
pub fn phase_means<'a>(records: impl IntoIterator<Item = &'a EpisodeRecord>) -> Vec<PhaseMean> {
    mean_shares(records, EpisodeRecord::time_by_state)
        .into_iter()
        .map(|(state, mean_s, share)| PhaseMean {
            state,
            mean_s,
            share,
        })
        .collect()
}

/// Per key (a state or an activity), the mean seconds per successful episode whose `times` are
/// not empty, and that mean's share of their mean cycle time; keys in order.
fn mean_shares<'a, K: Ord>(
    records: impl IntoIterator<Item = &'a EpisodeRecord>,
    times: impl Fn(&EpisodeRecord) -> std::collections::BTreeMap<K, f64>,
) -> Vec<(K, f64, f64)> {
    let mut sums = std::collections::BTreeMap::<K, f64>::new();
    let mut n = 0usize;
    let mut cycle = 0.0;
    for r in records.into_iter().filter(|r| r.success) {
        let by = times(r);
        if by.is_empty() {
            continue;
        }
        n += 1;
        cycle += r.cycle_time_s;
        for (k, s) in by {
            *sums.entry(k).or_insert(0.0) += s;
        }
    }
    if n == 0 {
        return Vec::new();
    }
    let mean_cycle = cycle / n as f64;
    sums.into_iter()
        .map(|(k, s)| {
            let mean = s / n as f64;
            let share = if mean_cycle > 0.0 {
                mean / mean_cycle
            } else {
                0.0
            };
            (k, mean, share)
        })
        .collect()
}

/// Mean simulated seconds one activity takes per successful assembly.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ActivityMean {
    /// The activity.
    pub activity: Activity,
    /// Mean seconds per successful episode.
    pub mean_s: f64,
    /// Share of the mean cycle time.
    pub share: f64,
}

/// The mean time of each activity over the successful episodes that kept their activities,
/// in [`Activity`]'s order; empty when there are none.
pub fn activity_means<'a>(
    records: impl IntoIterator<Item = &'a EpisodeRecord>,
) -> Vec<ActivityMean> {
    mean_shares(records, EpisodeRecord::time_by_activity)
        .into_iter()
        .map(|(activity, mean_s, share)| ActivityMean {
            activity,
            mean_s,
            share,
        })
        .collect()
}

/// One line for people on activities: `by activity: transit 3.10 s (34 %), …`.
pub fn activity_line(means: &[ActivityMean]) -> Option<String> {
    let rows = means.iter().map(|m| (m.activity.name(), m.mean_s, m.share));
    Some(format!("by activity: {}", largest_first(rows)?))
}

/// `name mean s (share %)` of each row with time, largest first, joined; `None` without rows.
fn largest_first<'a>(rows: impl Iterator<Item = (&'a str, f64, f64)>) -> Option<String> {
    let mut rows: Vec<(&str, f64, f64)> = rows.collect();
    if rows.is_empty() {
        return None;
    }
    rows.retain(|r| r.1 > 0.0);
    rows.sort_by(|a, b| b.1.total_cmp(&a.1));
    let parts: Vec<String> = rows
        .iter()
        .map(|(name, mean, share)| format!("{name} {mean:.2} s ({:.0} %)", 100.0 * share))
        .collect();
    Some(parts.join(", "))
}

/// A typical successful episode (the one whose cycle time is the median's) and the slowest, each
/// with its phases; `None` when no successful episode kept them. The two may be the same.
pub fn typical_and_slowest<'a>(
    records: impl IntoIterator<Item = &'a EpisodeRecord>,
) -> Option<(&'a EpisodeRecord, &'a EpisodeRecord)> {
    let mut ok: Vec<&EpisodeRecord> = records
        .into_iter()
        .filter(|r| r.success && !r.phases.is_empty())
        .collect();
    ok.sort_by(|a, b| {
        a.cycle_time_s
            .total_cmp(&b.cycle_time_s)
            .then(a.episode.cmp(&b.episode))
    });
    let slowest = *ok.last()?;
    Some((ok[(ok.len() - 1) / 2], slowest))
}

/// One line for people: the mean cycle and its largest parts, e.g.
/// `mean cycle 9.19 s: insert 3.10 s (34 %), pick 2.50 s (27 %), …`.
pub fn breakdown_line(means: &[PhaseMean]) -> Option<String> {
    let total: f64 = means.iter().map(|m| m.mean_s).sum();
    let rows = means.iter().map(|m| (m.state.name(), m.mean_s, m.share));
    Some(format!("mean cycle {total:.2} s: {}", largest_first(rows)?))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::episode::{PhaseSpan, RECORD_VERSION};

    fn record(episode: u32, success: bool, spans: &[(State, f64)]) -> EpisodeRecord {
        EpisodeRecord {
            version: RECORD_VERSION,
            scenario: "s".into(),
            seed: 1,
            episode,
            success,
            steps: vec![],
            cycle_time_s: spans.iter().map(|s| s.1).sum(),
            wall_time_s: 0.0,
            abort: None,
            phases: spans
                .iter()
                .map(|&(state, duration_s)| PhaseSpan {
                    state,
                    activity: None,
                    step: Some(0),
                    duration_s,
                })
                .collect(),
        }
    }

    #[test]
    fn means_cover_successful_episodes_and_add_up_to_the_mean_cycle() {
        let records = [
            record(
                0,
                true,
                &[(State::Pick, 2.0), (State::Insert, 3.0), (State::Pick, 1.0)],
            ),
            record(
                1,
                true,
                &[
                    (State::Pick, 1.0),
                    (State::Shake, 1.5),
                    (State::Insert, 2.5),
                ],
            ),
            record(2, false, &[(State::Pick, 100.0)]),
        ];
        let means = phase_means(&records);
        let get = |s: State| means.iter().find(|m| m.state == s).map(|m| m.mean_s);
        assert_eq!(get(State::Pick), Some(2.0));
        assert_eq!(get(State::Insert), Some(2.75));
        assert_eq!(get(State::Shake), Some(0.75));
        let total: f64 = means.iter().map(|m| m.mean_s).sum();
        assert!((total - 5.5).abs() < 1e-12);
        let shares: f64 = means.iter().map(|m| m.share).sum();
        assert!((shares - 1.0).abs() < 1e-12);
        // states come in the order a step passes through them
        assert!(means.windows(2).all(|w| w[0].state < w[1].state));
        let line = breakdown_line(&means).unwrap();
        assert!(
            line.starts_with("mean cycle 5.50 s: insert 2.75 s (50 %), pick 2.00 s (36 %)"),
            "{line}"
        );
    }

    #[test]
    fn typical_is_the_median_and_slowest_the_longest_success() {
        let records = [
            record(0, true, &[(State::Pick, 3.0)]),
            record(1, true, &[(State::Pick, 1.0)]),
            record(2, true, &[(State::Pick, 2.0)]),
            record(3, false, &[(State::Pick, 9.0)]),
        ];
        let (typical, slowest) = typical_and_slowest(&records).unwrap();
        assert_eq!((typical.episode, slowest.episode), (2, 0));
        assert!(typical_and_slowest(&records[3..]).is_none());
        assert!(phase_means(&records[3..]).is_empty());
    }
}
