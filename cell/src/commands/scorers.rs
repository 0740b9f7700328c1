//! `cell scorers SCENARIO`: how often the analytic insertion scorer agrees with the contact
//! simulation near the capture boundary of each assembly step.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Context;
use cell::scenario::Scenario;
use sim::cell::geometry::CellGeometry;
use sim::cell::insertion::agreement::{StepGeometry, compare_scorers};
use sim::cell::insertion::contact::ContactSettings;

/// Arguments of `cell scorers`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scenario whose assembly steps to check.
    pub scenario: PathBuf,
    /// Misalignments to score with both scorers (a third per step for three steps).
    #[arg(long, default_value_t = 1000)]
    pub samples: usize,
    /// Seed of the misalignment draws.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Exit non-zero when fewer than this fraction of samples agree.
    #[arg(long, default_value_t = 0.95)]
    pub min_agreement: f64,
    /// Also write the counts and every disagreement as JSON (atomically).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Scores boundary misalignments with both scorers, prints a table per step and the overall
/// agreement, and fails when it is below `--min-agreement`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    anyhow::ensure!(args.samples > 0, "--samples must be at least 1");
    anyhow::ensure!(
        (0.0..=1.0).contains(&args.min_agreement),
        "--min-agreement must be a fraction between 0 and 1, got {}",
        args.min_agreement
    );
    let scenario = Scenario::load(&args.scenario).map_err(|e| anyhow::anyhow!("{e}"))?;
    let spec = &scenario.spec;
    let geometry = CellGeometry::new(&spec.cell, &spec.assembly, &scenario.catalog)
        .context("loading the part shapes")?;
    let steps = (0..spec.assembly.len())
        .map(|i| {
            StepGeometry::nominal(&geometry, &spec.assembly, i).with_context(|| {
                format!(
                    "assembly step {} ({}): its part or destination has no shape",
                    i + 1,
                    spec.assembly[i].part
                )
            })
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let started = Instant::now();
    let agreement = compare_scorers(&steps, args.samples, args.seed, &ContactSettings::default());
    let elapsed = started.elapsed().as_secs_f64();

    println!(
        "{:<14} {:>7} {:>10} {:>9} {:>16} {:>15}",
        "step", "samples", "disagree", "agree %", "analytic seated", "contact seated"
    );
    for st in &agreement.steps {
        let agree = 100.0 * (1.0 - st.disagreements as f64 / st.samples.max(1) as f64);
        println!(
            "{:<14} {:>7} {:>10} {:>9.1} {:>16} {:>15}",
            st.part, st.samples, st.disagreements, agree, st.analytic_seated, st.contact_seated
        );
    }
    let rate = agreement.rate();
    println!(
        "{} samples in {elapsed:.1} s: the scorers agree on {:.1} % (contact simulation is the \
         reference; goal ≥ {:.1} %)",
        agreement.samples(),
        100.0 * rate,
        100.0 * args.min_agreement
    );
    if let Some(out) = &args.out {
        let json = serde_json::to_vec_pretty(&agreement)?;
        sim::fsutil::write_atomic(out, &json)
            .with_context(|| format!("writing {}", out.display()))?;
        println!("wrote {}", out.display());
    }
    Ok(if rate >= args.min_agreement {
        ExitCode::SUCCESS
    } else {
        eprintln!(
            "error: the analytic scorer agrees with the contact simulation on {:.1} % of samples, \
             below --min-agreement {:.1} %",
            100.0 * rate,
            100.0 * args.min_agreement
        );
        ExitCode::FAILURE
    })
}
