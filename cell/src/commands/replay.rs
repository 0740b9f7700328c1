//! `cell replay RESULTS --episode N`: re-run one stored episode of a simulated run from its seed,
//! print its event timeline, check it against the stored record, and write its pictures.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use cell::episode::EpisodeRecord;
use cell::harness::{SimSetup, run_sim_episode_blocking};
use cell::report::pictures::failure_pictures;
use cell::report::{PICTURES_DIR, html::seconds_text};
use cell::run::{LoadedScenario, RESULTS_FILE, read_results};

/// Arguments of `cell replay`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A results folder (holding episodes.jsonl) or results file of `cell run`.
    pub results: PathBuf,
    /// The episode to replay.
    #[arg(long)]
    pub episode: u32,
    /// The scenario file (default: the one the results header names).
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Folder for the pictures (default: `pictures` beside the results).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// The deterministic part of a record (everything but wall-clock time).
fn same_outcome(a: &EpisodeRecord, b: &EpisodeRecord) -> bool {
    // Records from before phases were kept have none: compare the rest.
    let keep_phases = !a.phases.is_empty() && !b.phases.is_empty();
    let strip = |r: &EpisodeRecord| EpisodeRecord {
        wall_time_s: 0.0,
        phases: if keep_phases {
            r.phases.clone()
        } else {
            vec![]
        },
        ..r.clone()
    };
    strip(a) == strip(b)
}

/// Replays the episode; fails when it cannot, or when the replay differs from the record.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let file = if args.results.is_dir() {
        args.results.join(RESULTS_FILE)
    } else {
        args.results.clone()
    };
    let results = read_results(&file)?;
    let header = &results.header;
    let stored = results.records.get(&args.episode).with_context(|| {
        format!(
            "{}: episode {} is not stored (the file holds {} episodes of shard {})",
            file.display(),
            args.episode,
            results.records.len(),
            header.shard
        )
    })?;
    let scenario_path = match (&args.scenario, &header.scenario_file) {
        (Some(p), _) => p.clone(),
        (None, Some(p)) => p.clone(),
        (None, None) => anyhow::bail!(
            "{}: the results header does not name its scenario file (written before replay \
             existed); pass --scenario FILE",
            file.display()
        ),
    };
    let loaded = LoadedScenario::load(&scenario_path)?;
    let sha = cell::run::sha256_hex(&loaded.bytes);
    if sha != header.scenario_sha256 {
        eprintln!(
            "warning: {} changed since the run (SHA-256 {} then, {} now); the replay uses it as \
             it is now",
            scenario_path.display(),
            &header.scenario_sha256[..12],
            &sha[..12]
        );
    }
    if header.robot != cell::run::header::SIM_ROBOT {
        eprintln!(
            "note: the episode ran on {}; the replay runs it in the in-process simulation",
            header.robot
        );
    }
    let setup = SimSetup::new(loaded.scenario.clone())?;
    let feeder = setup
        .cell(args.episode)?
        .lock()
        .map(|c| c.feeder_parts().to_vec())
        .unwrap_or_default();
    let out = run_sim_episode_blocking(&setup, args.episode)?;
    println!(
        "episode {} of {} (seed {}):",
        args.episode, header.scenario, header.seed
    );
    for e in out.events.events() {
        let step = e.step.map_or("      ".to_string(), |s| format!("step {s}"));
        println!(
            "  {:>8.3} s  {step}  {:?} → {:?}{}",
            e.sim_time_s,
            e.from,
            e.to,
            if e.detail.is_empty() {
                String::new()
            } else {
                format!("  {}", e.detail)
            }
        );
    }
    // Compare what a reader of the results file gets (a JSON round trip), as the store does.
    let r: &EpisodeRecord = &serde_json::from_slice(&serde_json::to_vec(&out.record)?)?;
    println!(
        "{} in {:.2} s simulated ({} of compute){}",
        if r.success { "assembled" } else { "failed" },
        r.cycle_time_s,
        seconds_text(r.wall_time_s),
        r.steps
            .iter()
            .find_map(|s| s.cause.as_ref().map(|c| format!(": {} {c}", s.part)))
            .unwrap_or_default()
    );
    let dir = match args.out {
        Some(d) => d,
        None => file
            .parent()
            .map_or_else(|| PathBuf::from(PICTURES_DIR), |p| p.join(PICTURES_DIR)),
    };
    let by_state = r.time_by_state();
    if !by_state.is_empty() {
        let parts: Vec<String> = by_state
            .iter()
            .filter(|(_, s)| **s > 0.0)
            .map(|(state, s)| format!("{} {s:.2} s", state.name()))
            .collect();
        println!("where the time went: {}", parts.join(", "));
    }
    let mut pictures = failure_pictures(&loaded.scenario, r, Some(&feeder), &dir)?;
    if !r.phases.is_empty() {
        let path = dir.join(format!("episode-{:06}-timeline.svg", r.episode));
        let svg = cell::report::timeline::cycle_timeline(&[(
            format!("episode {} ({:.1} s)", r.episode, r.cycle_time_s),
            r,
        )])?;
        std::fs::create_dir_all(&dir)?;
        sim::fsutil::write_atomic(&path, svg.as_bytes())?;
        pictures.push(path);
    }
    // Each force-guided insertion's wrench trace, numbered by step and attempt.
    let mut attempts = std::collections::BTreeMap::<Option<usize>, u32>::new();
    for e in out.events.events() {
        let Some(trace) = &e.wrench_trace else {
            continue;
        };
        let n = attempts.entry(e.step).or_default();
        *n += 1;
        let step = e.step.map_or_else(|| "x".to_string(), |s| s.to_string());
        let path = dir.join(format!(
            "episode-{:06}-step-{step}-insertion-{n}-wrench.svg",
            r.episode
        ));
        let svg = cell::report::wrench::wrench_trace_plot(
            &format!(
                "episode {}, step {step}, insertion {n}: the wrist during the guarded descents",
                r.episode
            ),
            trace,
        )?;
        std::fs::create_dir_all(&dir)?;
        sim::fsutil::write_atomic(&path, svg.as_bytes())?;
        pictures.push(path);
    }
    if !r.success && setup.perception.needs_pixels() {
        pictures.extend(cell::report::capture_picture::capture_picture(
            &setup, r, &dir,
        )?);
    }
    for p in &pictures {
        println!("wrote {}", p.display());
    }
    if same_outcome(r, stored) {
        println!("the replay matches the stored record");
        Ok(ExitCode::SUCCESS)
    } else {
        eprintln!(
            "the replay DIFFERS from the stored record:\n  stored:   {}\n  replayed: {}",
            serde_json::to_string(stored)?,
            serde_json::to_string(r)?
        );
        Ok(ExitCode::FAILURE)
    }
}
