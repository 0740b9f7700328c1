//! The run loop: the episodes of a shard that are not stored yet, in parallel over cores (each
//! episode builds its own world from (seed, episode), so the order they finish in does not
//! matter), each appended to the results file the moment it finishes.

use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;

use super::Shard;
use super::header::ResultsHeader;
use super::store::{ResultsStore, StoreError};
use crate::episode::EpisodeRecord;
use crate::scenario::{Scenario, ScenarioError};

/// Why a run could not start or stopped.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The scenario failed validation: nothing was run or written.
    #[error("the scenario is invalid; nothing was run:\n{0}")]
    Scenario(#[from] ScenarioError),
    /// The results file refused the run or an append failed.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// The episode could not be set up (the simulated cell or perception failed to build).
    #[error("episode {episode}: {source}")]
    Episode {
        /// The episode.
        episode: u32,
        /// What failed.
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// The episode function returned a record for another episode.
    #[error("asked for episode {asked}, the episode function returned episode {got}")]
    WrongEpisode {
        /// The episode asked for.
        asked: u32,
        /// The episode in the returned record.
        got: u32,
    },
    /// The worker threads could not be started.
    #[error("cannot start {jobs} worker threads: {reason}")]
    Threads {
        /// Threads asked for.
        jobs: usize,
        /// The failure.
        reason: String,
    },
}

/// A scenario file, validated, with the bytes its results header hashes.
#[derive(Debug, Clone)]
pub struct LoadedScenario {
    /// The validated scenario.
    pub scenario: Scenario,
    /// The file's bytes, as read once for both validation and hashing.
    pub bytes: Vec<u8>,
}

impl LoadedScenario {
    /// Reads and validates a scenario file; a file that fails `cell check` is an error here, so
    /// it can never start a run.
    pub fn load(path: &Path) -> Result<Self, RunError> {
        let bytes = crate::scenario::read_scenario(path)?;
        let scenario = Scenario::from_bytes(&bytes, path)?;
        Ok(Self { scenario, bytes })
    }

    /// The results header of this scenario for `shard`.
    pub fn header(&self, shard: Shard) -> ResultsHeader {
        let spec = &self.scenario.spec;
        ResultsHeader {
            capture_mm: spec
                .assembly
                .iter()
                .map(|s| (s.clearance / 2.0 + s.lead_in) * 1e3)
                .collect(),
            scenario_file: std::path::absolute(&self.scenario.path).ok(),
            ..ResultsHeader::new(&spec.name, spec.seed, &self.bytes, shard)
        }
    }
}

/// `root/<scenario name>/<shard>`: where a shard's results live (the name is made safe for a
/// folder name).
pub fn results_dir(root: &Path, scenario: &str, shard: Shard) -> PathBuf {
    root.join(safe_name(scenario)).join(shard.dir_name())
}

/// `name` with every character other than ASCII letters, digits, `-`, `_` and `.` replaced by
/// `_` (and never `.` or `..` alone).
pub fn safe_name(name: &str) -> String {
    let s: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "-_.".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect();
    if s.is_empty() || s.chars().all(|c| c == '.') {
        format!("_{s}")
    } else {
        s
    }
}

/// How to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RunOptions {
    /// Episodes of the whole run (`0..episodes`, of which the shard takes its part).
    pub episodes: u32,
    /// Worker threads (0: one per core; 1 for a single real robot).
    pub jobs: usize,
    /// Show a progress bar on stderr.
    pub progress: bool,
}

/// What a run did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunOutcome {
    /// Episodes of this shard in `0..episodes`.
    pub planned: usize,
    /// Episodes already stored before this run, skipped.
    pub resumed: usize,
    /// Episodes run now.
    pub ran: usize,
    /// Wall-clock seconds spent.
    pub wall_s: f64,
    /// Episodes stored from an earlier, longer run at or beyond `episodes`: kept in the file,
    /// but outside this run's summary and report.
    pub beyond: usize,
}

/// Runs the shard's episodes of `0..options.episodes` that `store` lacks, with `episode`
/// producing each record, appending each as it finishes. Stops at the first episode that
/// cannot be set up or the first failed append; everything stored so far stays (resumable).
pub fn run_episodes<F, E>(
    scenario: &Scenario,
    store: &mut ResultsStore,
    options: &RunOptions,
    episode: F,
) -> Result<RunOutcome, RunError>
where
    F: Fn(&Scenario, u32) -> Result<EpisodeRecord, E> + Sync,
    E: std::error::Error + Send + Sync + 'static,
{
    let start = Instant::now();
    let shard = store.header().shard;
    let planned: Vec<u32> = shard.episodes(options.episodes).collect();
    let pending: Vec<u32> = planned
        .iter()
        .copied()
        .filter(|e| !store.contains(*e))
        .collect();
    let resumed = planned.len() - pending.len();
    let beyond = store.records().range(options.episodes..).count();
    let progress = if options.progress {
        let pb = ProgressBar::new(planned.len() as u64);
        pb.set_style(
            ProgressStyle::with_template(
                "{prefix} [{elapsed_precise}] {wide_bar} {pos}/{len} episodes, eta {eta} {msg}",
            )
            .expect("a valid progress template"),
        );
        pb.set_prefix(format!("{} {}", scenario.spec.name, shard));
        pb.set_position(resumed as u64);
        pb
    } else {
        ProgressBar::hidden()
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(options.jobs)
        .build()
        .map_err(|e| RunError::Threads {
            jobs: options.jobs,
            reason: e.to_string(),
        })?;
    let store = Mutex::new(store);
    let failures = std::sync::atomic::AtomicUsize::new(0);
    pool.install(|| {
        pending
            .par_iter()
            .with_max_len(1)
            .try_for_each(|&e| -> Result<(), RunError> {
                let record = episode(scenario, e).map_err(|err| RunError::Episode {
                    episode: e,
                    source: Box::new(err),
                })?;
                if record.episode != e {
                    return Err(RunError::WrongEpisode {
                        asked: e,
                        got: record.episode,
                    });
                }
                let failed = !record.success;
                store
                    .lock()
                    .unwrap_or_else(|p| p.into_inner())
                    .append(record)?;
                if failed {
                    let n = failures.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                    progress.set_message(format!("({n} failed)"));
                }
                progress.inc(1);
                Ok(())
            })
    })?;
    progress.finish();
    Ok(RunOutcome {
        planned: planned.len(),
        resumed,
        ran: pending.len(),
        wall_s: start.elapsed().as_secs_f64(),
        beyond,
    })
}
