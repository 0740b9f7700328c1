//! `cell run SCENARIO`: run a scenario's episodes in simulation, resumably, and report.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use cell::episode::EpisodeRecord;
use cell::orchestrator::{OrchestratorError, SimSetup, run_sim_episode_blocking};
use cell::report::{ReportFiles, write_report};
use cell::run::{
    LoadedScenario, ResultsStore, RunOptions, RunOutcome, Shard, Summary, results_dir, run_episodes,
};

/// Arguments of `cell run`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scenario file (validated first: an invalid scenario never starts a run).
    pub scenario: PathBuf,
    /// Episodes to run (default: the scenario's `episodes`); a larger number extends an
    /// earlier run.
    #[arg(long)]
    pub episodes: Option<u32>,
    /// Run only shard I of N (episodes i with i % N == I), for an external scheduler; combine
    /// the shards with `cell merge`.
    #[arg(long, default_value = "0/1")]
    pub shard: Shard,
    /// Results root: episodes go to OUT/<scenario>/<shard>/episodes.jsonl, and a rerun
    /// continues with the episodes not yet there.
    #[arg(long, default_value = "runs")]
    pub out: PathBuf,
    /// Worker threads (0: one per core).
    #[arg(long, default_value_t = 0)]
    pub jobs: usize,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// What can stop one simulated episode from producing a record.
#[derive(Debug, thiserror::Error)]
pub enum EpisodeError {
    /// The simulated cell or perception could not be set up.
    #[error(transparent)]
    Setup(#[from] OrchestratorError),
    /// The episode's event log could not be written.
    #[error("writing {}: {source}", path.display())]
    Events {
        /// The event file.
        path: PathBuf,
        /// The failure.
        source: std::io::Error,
    },
}

/// A finished (or resumed-to-completion) run of one shard.
pub struct Executed {
    /// The shard's results folder.
    pub dir: PathBuf,
    /// What this invocation ran.
    pub outcome: RunOutcome,
    /// Their summary.
    pub summary: Summary,
    /// The report written.
    pub report: ReportFiles,
}

/// Runs `episodes` of a loaded scenario's `shard` in simulation under `root`, resuming what is
/// there, then writes the summary and report beside the results.
pub fn execute(
    loaded: &LoadedScenario,
    root: &Path,
    shard: Shard,
    episodes: u32,
    jobs: usize,
    progress: bool,
) -> anyhow::Result<Executed> {
    let name = &loaded.scenario.spec.name;
    let dir = results_dir(root, name, shard);
    let (mut store, opened) = ResultsStore::open(&dir, loaded.header(shard))?;
    if opened.truncated_bytes > 0 {
        eprintln!(
            "{}: cut off a torn last line ({} bytes) from an interrupted run",
            store.path().display(),
            opened.truncated_bytes
        );
    }
    if !opened.created {
        eprintln!(
            "{}: resuming, {} episodes already stored",
            store.path().display(),
            opened.present
        );
    }
    let setup = SimSetup::new(loaded.scenario.clone())?;
    let events = dir.join("events");
    std::fs::create_dir_all(&events)?;
    let options = RunOptions {
        episodes,
        jobs,
        progress,
    };
    let outcome = run_episodes(&setup.scenario, &mut store, &options, |_, e| {
        let out = run_sim_episode_blocking(&setup, e)?;
        let path = events.join(format!("episode-{e:06}.jsonl"));
        let mut bytes = Vec::new();
        out.events
            .write_jsonl(&mut bytes)
            .and_then(|()| sim::fsutil::write_atomic(&path, &bytes))
            .map_err(|source| EpisodeError::Events { path, source })?;
        Ok::<_, EpisodeError>(out.record)
    })?;
    let records: BTreeMap<u32, EpisodeRecord> = store
        .records()
        .range(..episodes)
        .map(|(k, v)| (*k, v.clone()))
        .collect();
    let summary = Summary::new(store.header(), records.values());
    let report = write_report(&dir, &summary, &records)?;
    Ok(Executed {
        dir,
        outcome,
        summary,
        report,
    })
}

/// The headline of a summary, one line.
pub fn headline(s: &Summary) -> String {
    format!(
        "{}: {} of {} episodes assembled, {:.1} % (95 % Wilson {:.1}–{:.1} %)",
        s.scenario,
        s.successes,
        s.episodes,
        100.0 * s.success_rate,
        100.0 * s.success_ci95.lo,
        100.0 * s.success_ci95.hi
    )
}

/// Validates the scenario, runs (or resumes) it, prints the headline and where the report is.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let loaded = LoadedScenario::load(&args.scenario)?;
    let episodes = args.episodes.unwrap_or(loaded.scenario.spec.episodes);
    let done = execute(
        &loaded,
        &args.out,
        args.shard,
        episodes,
        args.jobs,
        !args.quiet,
    )?;
    println!("{}", headline(&done.summary));
    for t in &done.summary.steps {
        println!(
            "  step {} {:<12} seated {}/{} ({:.1} %)",
            t.index,
            t.part,
            t.seated,
            t.reached,
            100.0 * t.rate
        );
    }
    for e in done.summary.error_budget.iter().take(5) {
        println!(
            "  failures blamed on {:<26} {:>4} ({:.0} %)",
            e.source,
            e.failures,
            100.0 * e.share
        );
    }
    println!(
        "ran {} episodes in {:.1} s ({} resumed); results {}, report {}",
        done.outcome.ran,
        done.outcome.wall_s,
        done.outcome.resumed,
        done.dir.join(cell::run::RESULTS_FILE).display(),
        done.report.html.display()
    );
    Ok(ExitCode::SUCCESS)
}
