//! `cell eval`: the learned perception pipeline against a BOP test split (the paper's Table 1,
//! detection precision / recall, stable-pose rate, MSSD / MSPD, stage times, worst crops). The
//! work lives in `cell::eval`; this file parses arguments, loads the models and prints.

use std::io::Write as _;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Context;
use cell::eval::causes::found_as_text;
use cell::eval::fingers::FingerCheck;
use cell::eval::picks::{ASSEMBLY_GRADE_DEG, ASSEMBLY_GRADE_MM, Picks};
use cell::eval::report_html::{EvalMeta, write_eval_report};
use cell::eval::summary::summarise;
use cell::eval::table1_text::text_table;
use cell::eval::{EvalDataset, EvalOptions, evaluate, resolve_split, stable_poses};
use cell::scenario::{DEFAULT_MIN_PICK_CONFIDENCE, Scenario};
use perception::contour::ContourConfig;
use perception::estimate::EstimatorConfig;
use perception::learned::{
    InputScale, LearnedModels, LearnedPipeline, PipelineConfig, STACKING_TOLERANCE,
};
use perception::part::Catalog;

/// Arguments of `cell eval`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The BOP dataset folder (written by `cell dataset`).
    pub dataset: PathBuf,
    /// Split folder to read (default: test_feeder, or test when the dataset has no
    /// test_feeder).
    #[arg(long)]
    pub split: Option<String>,
    /// Folder of the models (segmenter.toml, keypoints.toml).
    #[arg(long, default_value = "scenarios/models/usbc")]
    pub models: PathBuf,
    /// Part catalog the dataset was made from (object id = catalog index + 1).
    #[arg(long, default_value = "scenarios/parts/usbc.toml")]
    pub catalog: PathBuf,
    /// Output folder for eval.json, the BOP results file, eval.html, plots/ and gallery/.
    #[arg(long, default_value = "target/eval")]
    pub out: PathBuf,
    /// Evaluate at most this many images.
    #[arg(long)]
    pub limit: Option<usize>,
    /// Worst crops shown in the gallery.
    #[arg(long, default_value_t = 24)]
    pub gallery: usize,
    /// Mask IoU a detection needs to match a ground-truth instance.
    #[arg(long, default_value_t = 0.5)]
    pub min_iou: f64,
    /// Ground-truth instances less visible than this fraction are ignored.
    #[arg(long, default_value_t = 0.1)]
    pub min_visib: f64,
    /// Reprojection RMS gate of the pose estimator, pixels: poses above it are refused with
    /// their reason (the learned scenario's `[perception] max_rms_px` is 12).
    #[arg(long, default_value_t = 4.0)]
    pub max_rms_px: f64,
    /// The least confidence of a pose the cell would pick, in [0, 1] (a scenario's
    /// `[policy] min_pick_confidence`, default 0.2): the picks line counts those poses.
    #[arg(long, default_value_t = DEFAULT_MIN_PICK_CONFIDENCE, value_parser = unit_interval)]
    pub pick_confidence: f64,
    /// The scenario whose gripper, grasps and finger margin check that each pick leaves the open
    /// fingers room (reach is not checked: a dataset's parts lie where its drops put them).
    #[arg(long, default_value = "scenarios/usbc_learned.toml")]
    pub scenario: PathBuf,
    /// Count picks without checking room for the fingers (an upper bound on the picks).
    #[arg(long)]
    pub no_finger_check: bool,
    /// Keypoint poses only: skip the contour alignment on the frame's edges (for comparison).
    #[arg(long)]
    pub no_contour: bool,
    /// The table scale the networks see frames at: `trained` (the middle of the segmenter's
    /// training range, from its manifest), `sensor` (as captured), or pixels per mm.
    #[arg(long, default_value = "trained", value_parser = str::parse::<InputScale>)]
    pub input_scale: InputScale,
    /// Keep the poses of parts lying on or under another one (their estimates on the table
    /// overlap), which the pipeline otherwise withdraws (for comparison).
    #[arg(long)]
    pub no_stacking_check: bool,
    /// No progress line.
    #[arg(long)]
    pub quiet: bool,
}

/// A confidence: a number in [0, 1].
fn unit_interval(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if (0.0..=1.0).contains(&v) => Ok(v),
        Ok(v) => Err(format!("a confidence is between 0 and 1, got {v}")),
        Err(e) => Err(format!("not a number: {e}")),
    }
}

/// Runs the evaluation and writes its report.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let fingers = if args.no_finger_check {
        None
    } else {
        let scenario = Scenario::load(&args.scenario)?;
        let check = FingerCheck::new(&scenario)
            .with_context(|| format!("the cell of {}", args.scenario.display()))?;
        Some(check)
    };
    let options = EvalOptions {
        min_iou: args.min_iou,
        min_visib_fract: args.min_visib,
        gallery: args.gallery,
        limit: args.limit,
        pick_confidence: args.pick_confidence,
        finger_margin: fingers.as_ref().map(FingerCheck::margin),
        ..EvalOptions::default()
    };
    let catalog = Catalog::load(&args.catalog)?;
    let split = resolve_split(&args.dataset, args.split.as_deref());
    let dataset = EvalDataset::open(&args.dataset, &split, &catalog, &options)?;
    let models = LearnedModels::in_dir(&args.models)
        .with_context(|| format!("loading the models in {}", args.models.display()))?;
    let runtime = perception::onnx::Runtime::get().context("loading ONNX Runtime")?;
    let config = PipelineConfig {
        estimator: EstimatorConfig::with_gate(args.max_rms_px),
        contour: (!args.no_contour).then(ContourConfig::default),
        stacking_tolerance: (!args.no_stacking_check).then_some(STACKING_TOLERANCE),
        input_scale: args.input_scale,
        ..PipelineConfig::default()
    };
    let pipeline = LearnedPipeline::with_config(&models, &catalog, &runtime, config)
        .with_context(|| format!("loading the models in {}", args.models.display()))?;
    let mut detector = pipeline;
    let started = Instant::now();
    let quiet = args.quiet;
    let run = evaluate(
        &dataset,
        &mut detector,
        &options,
        fingers.as_ref(),
        |done, total| {
            if !quiet {
                eprint!("\r{done}/{total} images");
                let _ = std::io::stderr().flush();
            }
        },
    )?;
    if !quiet {
        eprintln!();
    }
    let elapsed = started.elapsed().as_secs_f64();
    let parts: Vec<(String, f64)> = dataset
        .parts
        .values()
        .map(|p| (p.name.clone(), p.diameter_mm))
        .collect();
    let summary = summarise(&run.frames, &parts, &options);
    let meta = EvalMeta {
        dataset: args.dataset.clone(),
        split: split.clone(),
        catalog: args.catalog.clone(),
        models: args.models.clone(),
        options,
    };
    let files = write_eval_report(&args.out, &meta, &summary, &run)?;
    print!("{}", text_table(&summary));
    let p = &summary.pooled;
    println!(
        "\ndetection (IoU ≥ {}): precision {:.1} %, recall {:.1} % ({} of {} instances; touching \
         {:.1} % of {}), {} false positives",
        options.min_iou,
        100.0 * p.precision,
        100.0 * p.recall,
        p.true_positives,
        p.truths,
        100.0 * p.recall_touching,
        p.touching,
        p.false_positives
    );
    let m = &p.misses;
    println!(
        "missed {}: {} found as the wrong part{}, {} with a split or merged mask (IoU < {}), {} \
         under another part's instance, {} with no detection at all",
        p.truths - p.true_positives,
        m.wrong_part,
        match found_as_text(&p.found_as) {
            t if t.is_empty() => t,
            t => format!(" (as {t})"),
        },
        m.partial,
        options.min_iou,
        m.covered,
        m.nothing
    );
    let f = &p.false_positive_causes;
    println!(
        "false positives {}: {} on another part's instance, {} a second instance of a found \
         part, {} a poor mask of a missed one, {} over other parts below IoU {}, {} on the empty \
         table",
        p.false_positives,
        f.wrong_part,
        f.duplicate,
        f.partial,
        f.straddling,
        options.min_iou,
        f.nothing
    );
    println!(
        "poses: {} matched with a pose (parts resting on the table), {} without; stable pose \
         right {:.1} %; AR_MSSD {:.1} % (PnP {:.1} %), AR_MSPD {:.1} % (PnP {:.1} %)",
        p.poses,
        p.pose_failures,
        100.0 * p.stable_pose_rate,
        100.0 * p.refined.ar_mssd,
        100.0 * p.raw.ar_mssd,
        100.0 * p.refined.ar_mspd,
        100.0 * p.raw.ar_mspd
    );
    println!(
        "assembly-grade poses (within {} mm and {}° of the truth): {} of {} ({:.1} %); of the {} \
         confident enough for the cell to pick (≥ {}): {} ({:.1} %)",
        ASSEMBLY_GRADE_MM,
        ASSEMBLY_GRADE_DEG,
        p.assembly_grade,
        p.poses,
        percent(p.assembly_grade, p.poses),
        p.pickable,
        options.pick_confidence,
        p.pickable_assembly_grade,
        percent(p.pickable_assembly_grade, p.pickable)
    );
    let k = &p.picks;
    let room = options.finger_margin.map_or_else(
        || "room for the fingers not checked".to_string(),
        |m| format!("{:.1} mm of room for the fingers", m * 1e3),
    );
    println!(
        "picks the cell would make (confidence ≥ {}, a stable pose it has a grasp for, {room}): \
         {}; {} more without room for the fingers",
        options.pick_confidence,
        pick_outcomes(k),
        k.crowded
    );
    println!(
        "the cell's first pick, per frame and part the most confident of those: {}",
        pick_outcomes(&p.first_picks)
    );
    println!(
        "parts not resting on the table (leaning on or lying on another part, in no stable pose): \
         {} of {}; {} of them matched with a pose, left out of the refined rows",
        p.not_resting, p.truths, p.not_resting_posed
    );
    print!("{}", stable_poses::text(&summary.stable_poses));
    if !p.pose_failure_kinds.is_empty() {
        let kinds: Vec<String> = p
            .pose_failure_kinds
            .iter()
            .map(|(k, n)| format!("{n} × {k}"))
            .collect();
        println!("without a pose: {}", kinds.join("; "));
    }
    let stages: Vec<String> = summary
        .stages
        .iter()
        .map(|s| format!("{} {:.1}", s.stage, s.mean_ms))
        .collect();
    println!(
        "time per frame, mean ms: {}; {:.1} frames/s",
        stages.join(", "),
        summary.frames_per_s
    );
    if summary.frame_failures > 0 {
        println!(
            "{} of {} frames failed, e.g. {}",
            summary.frame_failures,
            summary.frames,
            summary.failure_examples.join("; ")
        );
    }
    println!(
        "{} images of {}/{} in {:.1} s; wrote {}, {} and {}",
        summary.frames,
        args.dataset.display(),
        split,
        elapsed,
        files.json.display(),
        files.bop_results.display(),
        files.html.display()
    );
    Ok(ExitCode::SUCCESS)
}

/// What the picks `k` turned out to be, for the picks lines.
fn pick_outcomes(k: &Picks) -> String {
    format!(
        "{}; assembly-grade {} ({:.1} %), further off {}, in another stable pose {}, on or under \
         another part {}, on no part {}",
        k.picks,
        k.assembly_grade,
        percent(k.assembly_grade, k.picks),
        k.off,
        k.wrong_stable_pose,
        k.not_resting,
        k.unmatched
    )
}

/// `a` as a percentage of `b` (0 when `b` is 0).
fn percent(a: usize, b: usize) -> f64 {
    100.0 * a as f64 / b.max(1) as f64
}
