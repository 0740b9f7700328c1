//! `cell merge DIR...`: combine shard results into one results set and report.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use cell::report::write_report;
use cell::run::{Summary, merge, write_results};

/// Arguments of `cell merge`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Shard folders (holding episodes.jsonl), results files, or a scenario's results folder
    /// (all its shard-* folders).
    #[arg(required = true)]
    pub inputs: Vec<PathBuf>,
    /// Folder for the merged episodes.jsonl, summary.json and report.html (default: `merged`
    /// beside the first shard folder).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Merges, writes the merged results and report, prints the headline.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let merged = merge(&args.inputs)?;
    let out = match args.out {
        Some(o) => o,
        None => {
            let first = &merged.inputs[0].0;
            let shard_dir = first.parent().context("a results file has a folder")?;
            shard_dir.parent().unwrap_or(shard_dir).join("merged")
        }
    };
    for (path, shard) in &merged.inputs {
        println!("{}: shard {shard}", path.display());
    }
    for path in &merged.torn {
        eprintln!(
            "warning: {}: ignored a torn last line (that episode is absent)",
            path.display()
        );
    }
    let gaps = merged.gaps();
    if !gaps.is_empty() {
        let shown: Vec<String> = gaps.iter().take(20).map(u32::to_string).collect();
        eprintln!(
            "warning: {} episodes below the highest one are missing (a shard not run or not \
             finished?): {}{}",
            gaps.len(),
            shown.join(", "),
            if gaps.len() > 20 { ", ..." } else { "" }
        );
    }
    let file = write_results(&out, &merged.header, &merged.records)?;
    let summary = Summary::new(&merged.header, merged.records.values());
    let report = write_report(&out, &summary, &merged.records)?;
    println!(
        "{}: {} of {} episodes succeeded ({:.1} %, 95 % CI {:.1}–{:.1} %)\nwrote {}, {}, {}",
        summary.scenario,
        summary.successes,
        summary.episodes,
        100.0 * summary.success_rate,
        100.0 * summary.success_ci95.lo,
        100.0 * summary.success_ci95.hi,
        file.display(),
        report.summary.display(),
        report.html.display()
    );
    Ok(ExitCode::SUCCESS)
}
