//! `cell regress SCENARIO... --baseline DIR`: run each scenario and gate on its success rate
//! against the committed baseline (one-sided Fisher exact test, Holm-corrected across the
//! episode rate and the step rates; see `cell::regress::stats` for why).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, bail};
use cell::regress::{Baseline, compare};
use cell::run::{LoadedScenario, Shard};

use super::run::headline;
use cell::run::execute;

/// Arguments of `cell regress`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scenario files (all are validated before any runs).
    #[arg(required = true)]
    pub scenarios: Vec<PathBuf>,
    /// Folder of baselines, `<scenario name>.json` each (scenarios/baselines in the repo).
    #[arg(long)]
    pub baseline: PathBuf,
    /// Significance level of a drop.
    #[arg(long, default_value_t = 0.01)]
    pub alpha: f64,
    /// Episodes per scenario (default: the scenario's `episodes`).
    #[arg(long)]
    pub episodes: Option<u32>,
    /// Rewrite each baseline from this run instead of gating.
    #[arg(long)]
    pub update: bool,
    /// Results root (resumed like `cell run --out`); default: a fresh folder under the
    /// system's temporary folder, so stale results never stand in for the code under test.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Worker threads (0: one per core).
    #[arg(long, default_value_t = 0)]
    pub jobs: usize,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// The commit being measured (`-dirty` with uncommitted changes to tracked files), if git can
/// tell.
fn current_commit() -> Option<String> {
    let git = |args: &[&str]| {
        std::process::Command::new("git")
            .args(args)
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
    };
    let head = git(&["rev-parse", "HEAD"])?;
    let dirty =
        git(&["status", "--porcelain", "--untracked-files=no"]).is_some_and(|s| !s.is_empty());
    Some(if dirty { format!("{head}-dirty") } else { head })
}

/// Runs every scenario, prints a verdict table each, fails on any significant drop.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    if !(args.alpha > 0.0 && args.alpha < 1.0) {
        bail!("--alpha must be in (0, 1), got {}", args.alpha);
    }
    let loaded = args
        .scenarios
        .iter()
        .map(|p| LoadedScenario::load(p))
        .collect::<Result<Vec<_>, _>>()?;
    let mut baselines = Vec::new();
    for l in &loaded {
        let path = Baseline::path(&args.baseline, &l.scenario.spec.name);
        let baseline = if args.update {
            None
        } else {
            Some(Baseline::load(&path)?)
        };
        baselines.push((path, baseline));
    }
    let root = match &args.out {
        Some(o) => o.clone(),
        None => {
            let nanos = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_nanos());
            std::env::temp_dir().join(format!("cell-regress-{}-{nanos}", std::process::id()))
        }
    };
    let mut regressed = false;
    for (l, (path, baseline)) in loaded.iter().zip(baselines) {
        let episodes = args.episodes.unwrap_or(l.scenario.spec.episodes);
        let done = execute(l, &root, Shard::ALL, episodes, args.jobs, !args.quiet)
            .with_context(|| format!("running {}", l.scenario.path.display()))?;
        println!("{}", headline(&done.summary));
        println!("  results and report: {}", done.dir.display());
        match baseline {
            Some(b) => {
                let verdict = compare(&b, &done.summary, args.alpha);
                print!("{}", verdict.table());
                regressed |= verdict.regressed();
            }
            None => {
                let date = humantime::format_rfc3339_seconds(std::time::SystemTime::now());
                let b = Baseline::from_summary(&done.summary, current_commit(), date.to_string());
                b.save(&path)?;
                println!("  baseline updated: {}", path.display());
            }
        }
    }
    Ok(if regressed {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    })
}
