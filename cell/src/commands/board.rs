//! `cell board BOARD.toml --out board.svg`: the board as a vector file to print at exact scale.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use cell::calibrate::svg::{board_svg, page_size};
use perception::calibration::Board;

/// Arguments of `cell board`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The board file (see docs/reference/board.md), e.g. scenarios/boards/seed.toml.
    pub board: PathBuf,
    /// Where to write the SVG.
    #[arg(long, value_name = "FILE.svg")]
    pub out: PathBuf,
}

/// Reads the board (errors name file:line:column), writes its print atomically and says how to
/// print it.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let board = Board::load(&args.board)?;
    let name = args.board.file_name().map_or_else(
        || args.board.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    );
    let svg = board_svg(&board, &name);
    sim::fsutil::write_atomic(&args.out, svg.as_bytes())
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    let [w, h] = page_size(&board);
    let [pw, ph] = board.spec().plate.map(|v| v * 1e3);
    let tags = board.tags();
    println!(
        "{}: {} tags of {} (ids {}–{}) on a {pw} × {ph} mm plate; page {w} × {h} mm. Print at \
         100 % (actual size) and check the 100 mm scale bar with a ruler.",
        args.out.display(),
        tags.len(),
        board.family().name,
        tags.first().map_or(0, |t| t.id),
        tags.last().map_or(0, |t| t.id),
    );
    Ok(ExitCode::SUCCESS)
}
