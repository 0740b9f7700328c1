//! `cell dataset`: synthetic images and labels in the BOP format, plus the keypoint crop set.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Context;
use perception::part::{Catalog, PartRole};
use sim::dataset::{DatasetConfig, generate, write_preview};
use sim::scene::{PartModel, Randomisation};

/// Arguments of `cell dataset`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Output folder (created; re-running continues an interrupted run).
    #[arg(long)]
    pub out: PathBuf,
    /// Part catalog.
    #[arg(long, default_value = "scenarios/parts/usbc.toml")]
    pub catalog: PathBuf,
    /// Master seed: the same seed gives a bit-identical dataset.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Parts to render (default: every part that is not a fixture).
    #[arg(long, value_delimiter = ',')]
    pub parts: Vec<String>,
    /// Keypoint training crops per part (128 × 128, full resolution). The defaults make a small
    /// set in about a minute; the full training set (about an hour) is `--train-crops 20000
    /// --test-crops 2000 --train-overviews 2000 --test-overviews 200`.
    #[arg(long, default_value_t = 200)]
    pub train_crops: usize,
    /// Keypoint test crops per part (full set: 2000).
    #[arg(long, default_value_t = 20)]
    pub test_crops: usize,
    /// Share of the crop drops (0–1) whose target is held lying in one of its stable poses,
    /// drawn uniformly, while the other parts fall around it, instead of falling from a random
    /// orientation (default 0: every pose as often as the drops leave parts in it). 0.3 gives
    /// each of a part's poses several per cent of its crops, the rare ones included (the top
    /// shell's −y: 0.6 % of its drops).
    #[arg(long, default_value_t = 0.0)]
    pub posed_crops: f64,
    /// Overview images with all parts (BOP train_pbr), for segmentation training (full set:
    /// 2000).
    #[arg(long, default_value_t = 20)]
    pub train_overviews: usize,
    /// Overview images for testing (BOP test; full set: 200).
    #[arg(long, default_value_t = 5)]
    pub test_overviews: usize,
    /// Feeder frames for segmentation training (BOP train_feeder): 3–4 parts of each kind
    /// dropped so several touch, at full camera resolution, through a window covering them.
    #[arg(long, default_value_t = 0)]
    pub train_feeder: usize,
    /// Feeder frames for testing (BOP test_feeder, what `cell eval` reads).
    #[arg(long, default_value_t = 0)]
    pub test_feeder: usize,
    /// Camera height above the table for the test feeder frames, metres (default: randomised
    /// 1.4–1.9 m like the training frames), e.g. 1.4 or 1.8 to evaluate at those distances.
    #[arg(long)]
    pub camera_distance: Option<f64>,
    /// Half-size of the square each feeder frame's parts are dropped into, metres (default
    /// 0.015: a heap, where a third of the parts lean on or lie on another). 0.035 spreads a
    /// dozen over about the area of the learned scenario's 80 × 60 mm feeder, as the cell sees
    /// them after a shake: most apart, some touching, a few on another.
    #[arg(long)]
    pub feeder_drop_half: Option<f64>,
    /// Fewest copies of each part per overview scene.
    #[arg(long, default_value_t = 1)]
    pub min_per_class: usize,
    /// Most copies of each part per overview scene.
    #[arg(long, default_value_t = 3)]
    pub max_per_class: usize,
    /// Colour samples per pixel along each axis (anti-aliasing).
    #[arg(long, default_value_t = 2)]
    pub supersampling: u32,
    /// Downscaling of overview images relative to the full camera.
    #[arg(long, default_value_t = 0.4)]
    pub overview_scale: f64,
    /// Domain-randomisation ranges (TOML; every key optional, defaults documented in
    /// `sim::scene::Randomisation`), e.g. `exposure = { lo = 0.9, hi = 1.1 }`.
    #[arg(long)]
    pub randomisation: Option<PathBuf>,
    /// Opt-in look: `room` for the built-in one, or a TOML file (every key optional; see
    /// `docs/reference/cycles.md`): a procedural room around the cell (walls, ceiling light
    /// panels, the camera's mount) that metals reflect, rectangular area lights, and a backlit
    /// feeder plate, drawn per image. Without it images are as before, byte for byte.
    #[arg(long)]
    pub environment: Option<PathBuf>,
    /// Randomisation families that widen the ranges (opt-in, each on its own random stream):
    /// a comma-separated list of `lights`, `plating`, `plastic`, `textures`, `distractors`,
    /// `sensor` (or `all`, and `all,-NAME` for an ablation), or a TOML file of their switches
    /// and ranges (see `docs/reference/cycles.md`). Without it images are as before, byte for
    /// byte.
    #[arg(long)]
    pub families: Option<String>,
    /// Also write a contact sheet (PNG) of the first training crops of each part and two
    /// randomised feeder captures, to judge the randomisation at a glance.
    #[arg(long)]
    pub preview: Option<PathBuf>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// Reads and checks a randomisation file: syntax errors carry line and column, bad ranges their
/// key.
fn load_randomisation(path: &std::path::Path) -> anyhow::Result<Randomisation> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let rand: Randomisation = toml::from_str(&text)
        .map_err(|e| anyhow::anyhow!("{}: {}", path.display(), e.to_string().trim_end()))?;
    rand.validate()
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    Ok(rand)
}

/// Loads the parts and writes the dataset.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let catalog = Catalog::load(&args.catalog)?;
    let names: Vec<String> = if args.parts.is_empty() {
        catalog
            .parts
            .iter()
            .filter(|p| p.role != PartRole::Fixture)
            .map(|p| p.name.clone())
            .collect()
    } else {
        for name in &args.parts {
            if catalog.part(name).is_none() {
                anyhow::bail!("{}: no part named {name:?}", args.catalog.display());
            }
        }
        args.parts.clone()
    };
    let models = PartModel::from_catalog(&catalog, &names)?;
    let mut cfg = DatasetConfig::new(args.out.clone(), args.seed);
    cfg.crops_train = args.train_crops;
    cfg.crops_test = args.test_crops;
    cfg.posed_crop_share = args.posed_crops;
    cfg.overviews_train = args.train_overviews;
    cfg.overviews_test = args.test_overviews;
    cfg.parts_per_class = (args.min_per_class, args.max_per_class);
    cfg.feeder_train = args.train_feeder;
    cfg.feeder_test = args.test_feeder;
    cfg.feeder_camera_distance = args.camera_distance;
    if let Some(half) = args.feeder_drop_half {
        cfg.feeder_drop_half = half;
    }
    cfg.render.supersampling = args.supersampling;
    cfg.overview_scale = args.overview_scale;
    cfg.progress = !args.quiet;
    if let Some(path) = &args.randomisation {
        cfg.randomisation = load_randomisation(path)?;
    }
    if let Some(arg) = &args.families {
        let path = std::path::Path::new(arg);
        cfg.families = if path.is_file() {
            cell::scenario::load_families(path)?
        } else {
            sim::dataset::Families::from_list(arg).map_err(|e| {
                anyhow::anyhow!("--families {arg}: neither a file nor a list of families: {e}")
            })?
        };
    }
    if let Some(path) = &args.environment {
        cfg.look = Some(cell::scenario::load_look(path)?);
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(args.threads.unwrap_or(0))
        .build()
        .context("starting worker threads")?;
    let start = Instant::now();
    let summary = pool.install(|| generate(&cfg, &models))?;
    let elapsed = start.elapsed().as_secs_f64();
    if let Some(path) = &args.preview {
        let rows = cfg.crops_train.min(6);
        pool.install(|| write_preview(&cfg, &models, rows, path))?;
        println!("{}: contact sheet", path.display());
    }
    println!(
        "{}: {} overview images, {} feeder frames and {} crop drops rendered, {} items already \
         complete, {:.1} s",
        args.out.display(),
        summary.overviews_rendered,
        summary.feeders_rendered,
        summary.crop_groups_rendered,
        summary.skipped,
        elapsed
    );
    if args.train_crops == 200 && args.train_overviews == 20 {
        println!(
            "this is the small default set; the full training set: --train-crops 20000 \
             --test-crops 2000 --train-overviews 2000 --test-overviews 200 (about an hour)"
        );
    }
    Ok(ExitCode::SUCCESS)
}
