//! `cell board-study`: how well the board is found and its pose measured, on boards rendered
//! under the renderer's randomisation at 1.4–1.9 m, against the simulator's truth: tags decoded,
//! corner error before and after refinement, board pose error against its Cramér–Rao bound, and
//! time per stage on the full 20 MP frame.
//!
//! Rendering runs in parallel first; detection then runs one image at a time with the detector's
//! threads, so its timings are those of a cell.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use cell::calibrate::study::{Report, frame, measure, render, save, summarise, summary_text};
use perception::Camera;
use perception::calibration::detect::BoardDetector;
use perception::calibration::{Board, DetectorSettings};
use rayon::prelude::*;

/// Arguments of `cell board-study`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Boards to render.
    #[arg(long, default_value_t = 100)]
    pub images: usize,
    /// The board file (default: the seed's board).
    #[arg(long)]
    pub board: Option<PathBuf>,
    /// Seed of every random draw.
    #[arg(long, default_value_t = 42)]
    pub seed: u64,
    /// Detect in the window that covers the board instead of the full 20 MP frame.
    #[arg(long)]
    pub window_only: bool,
    /// Quad decimation of the reference detector.
    #[arg(long)]
    pub decimation: Option<f32>,
    /// Threads of the reference detector.
    #[arg(long)]
    pub threads: Option<u8>,
    /// Gaussian blur sigma (pixels) before the reference detector's quad segmentation.
    #[arg(long)]
    pub sigma: Option<f32>,
    /// Report the reference detector's corners, unrefined.
    #[arg(long)]
    pub no_refine: bool,
    /// Save each rendered window (PNG) and its truth (JSON) here, for the comparison scripts.
    #[arg(long)]
    pub save: Option<PathBuf>,
    /// Write the per-image and overall results here (JSON).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Runs the study and prints (and writes) its figures.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    if args.images == 0 {
        anyhow::bail!("--images must be at least 1");
    }
    let board = match &args.board {
        Some(p) => Board::load(p)?,
        None => Board::seed(),
    };
    let camera = Camera::basler_seed();
    let mut settings = DetectorSettings::default();
    if let Some(d) = args.decimation {
        anyhow::ensure!(d >= 1.0 && d.is_finite(), "--decimation must be ≥ 1");
        settings.decimation = d;
    }
    if let Some(t) = args.threads {
        anyhow::ensure!(t >= 1, "--threads must be ≥ 1");
        settings.threads = t;
    }
    if let Some(s) = args.sigma {
        anyhow::ensure!(s >= 0.0 && s.is_finite(), "--sigma must be ≥ 0");
        settings.sigma = s;
    }
    settings.refine_corners = !args.no_refine;

    eprintln!("rendering {} boards …", args.images);
    let renders = (0..args.images)
        .into_par_iter()
        .map(|i| render(&board, &camera, args.seed, i))
        .collect::<anyhow::Result<Vec<_>>>()?;
    if let Some(dir) = &args.save {
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        renders
            .par_iter()
            .enumerate()
            .try_for_each(|(i, r)| save(dir, i, r, &board, &camera))?;
    }

    eprintln!(
        "detecting ({} threads, decimation {}) …",
        settings.threads, settings.decimation
    );
    let mut detector = BoardDetector::new(&board, &settings)?;
    let mut results = Vec::with_capacity(renders.len());
    for (i, r) in renders.iter().enumerate() {
        let frame = frame(r, &camera, !args.window_only);
        results.push(measure(i, r, &frame, &mut detector, &board, &camera));
    }
    let board_name = args
        .board
        .as_ref()
        .map_or_else(|| "seed".to_string(), |p| p.display().to_string());
    let summary = summarise(
        &results,
        &board,
        &camera,
        &settings,
        !args.window_only,
        &board_name,
    );
    print!("{}", summary_text(&summary));
    if let Some(path) = &args.out {
        let json = serde_json::to_vec_pretty(&Report {
            summary: &summary,
            images: &results,
        })?;
        sim::fsutil::write_atomic(path, &json)
            .with_context(|| format!("cannot write {}", path.display()))?;
        println!("wrote {}", path.display());
    }
    Ok(ExitCode::SUCCESS)
}
