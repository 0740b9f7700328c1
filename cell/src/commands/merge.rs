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
    /// Merge even when shards or episodes are missing (a partial results set); without it a
    /// missing shard or episode is an error, so a CI job cannot pass on half a run.
    #[arg(long)]
    pub allow_partial: bool,
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
    let missing: Vec<String> = merged
        .missing_shards()
        .iter()
        .map(|m| format!("{m} (folder {})", m.dir_name()))
        .collect();
    let gaps = merged.gaps();
    let mut partial = Vec::new();
    if !missing.is_empty() {
        partial.push(format!(
            "{} of {} shards missing: {}",
            missing.len(),
            merged.inputs[0].1.count,
            missing.join(", ")
        ));
    }
    if !gaps.is_empty() {
        let shown: Vec<String> = gaps.iter().take(20).map(u32::to_string).collect();
        partial.push(format!(
            "{} below the highest one missing (a shard not run or not finished?): {}{}",
            super::run::count(gaps.len(), "episode"),
            shown.join(", "),
            if gaps.len() > 20 { ", ..." } else { "" }
        ));
    }
    if !partial.is_empty() {
        let what = partial.join("; ");
        anyhow::ensure!(
            args.allow_partial,
            "the results are incomplete: {what}; run the missing shards, or pass \
             --allow-partial to merge what is there"
        );
        eprintln!("warning: merging a partial results set (--allow-partial): {what}");
    }
    let file = write_results(&out, &merged.header, &merged.records)?;
    let summary = Summary::new(&merged.header, merged.records.values());
    let report = write_report(&out, &summary, &merged.records)?;
    println!(
        "{}: {} of {} succeeded ({:.1} %, 95 % CI {:.1}–{:.1} %)\nwrote {}, {}, {}",
        summary.scenario,
        summary.successes,
        super::run::count(summary.episodes as usize, "episode"),
        100.0 * summary.success_rate,
        100.0 * summary.success_ci95.lo,
        100.0 * summary.success_ci95.hi,
        file.display(),
        report.summary.display(),
        report.html.display()
    );
    Ok(ExitCode::SUCCESS)
}
