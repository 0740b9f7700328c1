//! `cell run SCENARIO [--robot ROBOT]`: run a scenario's episodes, resumably, and report. The
//! robot is the in-process simulated cell (`sim`, default), the simulated cell behind a virtual
//! UR controller driven over loopback RTDE (`virtual-ur`), or a real controller
//! (`ur://HOST[:PORT]`, after the production pre-flight).

use std::path::PathBuf;
use std::process::ExitCode;

use cell::camera::CameraSpec;
use cell::run::{Driver, LoadedScenario, RobotTarget, Shard, Summary, execute_on, production};

/// Arguments of `cell run`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scenario file (validated first: an invalid scenario never starts a run).
    pub scenario: PathBuf,
    /// Episodes to run (default: the scenario's `episodes`); a larger number extends an
    /// earlier run.
    #[arg(long)]
    pub episodes: Option<u32>,
    /// Run only shard I of N, counting from 1 (episodes e with e % N == I − 1), for an
    /// external scheduler: SLURM `--shard $SLURM_ARRAY_TASK_ID/N` with `--array=1-N`; a
    /// Kubernetes indexed job (0-based) `--shard $((JOB_COMPLETION_INDEX + 1))/N`. Combine the
    /// shards with `cell merge`.
    #[arg(long, default_value = "1/1")]
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
    /// The robot: `sim` (the in-process simulated cell), `virtual-ur` (the simulated cell behind
    /// a virtual UR controller on 127.0.0.1, driven by the production RTDE client; episodes run
    /// one after another in real time) or `ur://HOST[:PORT]` (a real controller, RTDE port 30004
    /// by default; needs --allow-motion and --camera, and an image-reading perception mode).
    #[arg(long, default_value = "sim")]
    pub robot: RobotTarget,
    /// Production opt-in: allow a real arm to move (only with --robot ur://HOST).
    #[arg(long)]
    pub allow_motion: bool,
    /// Production camera source (only with --robot ur://HOST), one new full-sensor PNG or TIFF
    /// image per capture: `folder:/path` (or a plain folder) waits for a new, fully written
    /// image that a grab tool writes there; `cmd:'grab --out {path}'` runs the command per
    /// capture and reads the image it writes to {path}; `files:/path` (or a plain image file)
    /// replays recorded images in name order; `aravis:[DEVICE]` grabs from a GenICam camera
    /// (builds with `--features aravis`).
    #[arg(long, value_name = "SPEC")]
    pub camera: Option<CameraSpec>,
    /// How long one capture may wait for its image (e.g. `5s`, `800ms`); a capture that gets
    /// no new image in time aborts the step before any motion.
    #[arg(long, default_value = "5s", value_name = "DURATION", value_parser = parse_timeout)]
    pub capture_timeout: std::time::Duration,
    /// Failed episodes to draw pictures of (the failing insertion from two views with its
    /// capture band, and the feeder), linked from the report; 0 for none. Unless 0, the report
    /// also opens with the first episode's first capture and what perception found in it.
    #[arg(long, default_value_t = 20)]
    pub pictures: usize,
}

/// A positive duration such as `5s` or `800ms`.
pub fn parse_timeout(s: &str) -> Result<std::time::Duration, String> {
    let d = humantime::parse_duration(s).map_err(|e| format!("{s:?}: {e}"))?;
    if d.is_zero() {
        return Err(format!("{s:?}: the capture timeout must be positive"));
    }
    Ok(d)
}

/// Draws the report's opening picture (the first episode's first capture with its detections)
/// and the pictures of the first `limit` failed episodes of a simulated run into
/// `dir/pictures`, and rewrites the report so it shows them; returns how many failed episodes.
fn draw_pictures(
    loaded: &LoadedScenario,
    dir: &std::path::Path,
    episodes: u32,
    limit: usize,
) -> anyhow::Result<usize> {
    use cell::report::pictures::failure_pictures;
    let results = cell::run::read_results(&dir.join(cell::run::RESULTS_FILE))?;
    let records: std::collections::BTreeMap<u32, cell::episode::EpisodeRecord> = results
        .records
        .range(..episodes)
        .map(|(k, v)| (*k, v.clone()))
        .collect();
    let failed: Vec<&cell::episode::EpisodeRecord> = records
        .values()
        .filter(|r| !r.success)
        .take(limit)
        .collect();
    let Some(&first) = records.keys().next() else {
        return Ok(0);
    };
    let setup = cell::harness::SimSetup::new(loaded.scenario.clone())?;
    let pictures = dir.join(cell::report::PICTURES_DIR);
    cell::report::capture_picture::first_capture_picture(&setup, first, &pictures)?;
    for r in &failed {
        let feeder = setup
            .cell(r.episode)?
            .lock()
            .map(|c| c.feeder_parts().to_vec())
            .unwrap_or_default();
        failure_pictures(&loaded.scenario, r, Some(&feeder), &pictures)?;
        if setup.perception.needs_pixels() {
            cell::report::capture_picture::capture_picture(&setup, r, &pictures)?;
        }
    }
    let summary = Summary::new(&results.header, records.values());
    cell::report::write_report(dir, &summary, &records)?;
    Ok(failed.len())
}

/// `n` and a noun, singular for one: "1 episode", "3 episodes".
pub fn count(n: usize, noun: &str) -> String {
    if n == 1 {
        format!("1 {noun}")
    } else {
        format!("{n} {noun}s")
    }
}

/// The headline of a summary, one line.
pub fn headline(s: &Summary) -> String {
    format!(
        "{}: {} of {} assembled, {:.1} % (95 % Wilson {:.1}–{:.1} %)",
        s.scenario,
        s.successes,
        count(s.episodes as usize, "episode"),
        100.0 * s.success_rate,
        100.0 * s.success_ci95.lo,
        100.0 * s.success_ci95.hi
    )
}

/// Validates the scenario, runs (or resumes) it, prints the headline and where the report is.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let loaded = LoadedScenario::load(&args.scenario)?;
    let episodes = args.episodes.unwrap_or(loaded.scenario.spec.episodes);
    let driver = match &args.robot {
        RobotTarget::Ur { .. } => production(
            &loaded.scenario,
            &args.robot,
            args.allow_motion,
            args.camera.as_ref(),
            args.capture_timeout,
        )?,
        other => {
            anyhow::ensure!(
                !args.allow_motion && args.camera.is_none(),
                "--allow-motion and --camera are for a real controller (--robot ur://HOST), \
                 not --robot {other}"
            );
            match other {
                RobotTarget::VirtualUr => Driver::VirtualUr,
                _ => Driver::Sim,
            }
        }
    };
    let done = execute_on(
        &loaded,
        &args.out,
        args.shard,
        episodes,
        args.jobs,
        !args.quiet,
        &driver,
    )?;
    let drawn = if args.pictures > 0 && matches!(args.robot, RobotTarget::Sim) {
        draw_pictures(&loaded, &done.dir, episodes, args.pictures)?
    } else {
        0
    };
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
    if let Some(line) = cell::run::phases::breakdown_line(&done.summary.cycle_phases) {
        println!("  {line}");
    }
    if let Some(line) = cell::run::phases::activity_line(&done.summary.cycle_activities) {
        println!("  {line}");
    }
    let o = &done.outcome;
    println!(
        "ran {} in {:.1} s{} ({} resumed); results {}, report {}",
        count(o.ran, "episode"),
        o.wall_s,
        match o.ran {
            0 => String::new(),
            n => format!(", {:.3} s per episode", o.wall_s / n as f64),
        },
        o.resumed,
        done.dir.join(cell::run::RESULTS_FILE).display(),
        done.report.html.display()
    );
    if drawn > 0 {
        println!(
            "pictures of {} in {}",
            count(drawn, "failed episode"),
            done.dir.join(cell::report::PICTURES_DIR).display()
        );
    }
    if o.beyond > 0 {
        eprintln!(
            "note: {} holds {} more from an earlier, longer run; summary.json and report.html \
             cover episodes 0..{episodes} only (run with --episodes {} to include them)",
            done.dir.display(),
            count(o.beyond, "episode"),
            episodes as usize + o.beyond
        );
    }
    Ok(ExitCode::SUCCESS)
}
