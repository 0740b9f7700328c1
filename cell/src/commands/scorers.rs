//! `cell scorers SCENARIO [--engines analytic,rapier,mujoco]`: how often the insertion scorers
//! agree near the capture boundary of each assembly step, with every case where they do not.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Instant;

use anyhow::Context;
use cell::scenario::Scenario;
use sim::cell::geometry::CellGeometry;
use sim::cell::insertion::agreement::{Agreement, Disagreement, StepGeometry, compare_scorers};
use sim::cell::insertion::{InsertionScorer, PoseError, Scorer};

/// Disagreeing cases printed (all of them go to `--out`).
const SHOWN_CASES: usize = 20;

/// Arguments of `cell scorers`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scenario whose assembly steps to check.
    pub scenario: PathBuf,
    /// Misalignments to score with every engine (a third per step for three steps).
    #[arg(long, default_value_t = 1000)]
    pub samples: usize,
    /// Seed of the misalignment draws.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Engines to compare, comma-separated: analytic, rapier (or contact), mujoco.
    #[arg(long, value_delimiter = ',', default_value = "analytic,rapier")]
    pub engines: Vec<String>,
    /// The engine the others are checked against.
    #[arg(long, default_value = "rapier")]
    pub reference: String,
    /// Exit non-zero when, on some step, an engine agrees with the reference on fewer than
    /// this fraction of samples.
    #[arg(long, default_value_t = 0.95)]
    pub min_agreement: f64,
    /// Also write the counts and every disagreement as JSON (atomically).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Instead of comparing engines, read each boundary insertion as force-guided insertion
    /// does (first contact from force and depth, through the wrist sensor's noise, against the
    /// scenario's `[force_insertion]` thresholds, or the defaults) and compare the verdicts with
    /// the `--reference` engine's truth; `--min-agreement` applies to seated-or-not.
    #[arg(long)]
    pub force_verdicts: bool,
}

/// Scores boundary misalignments with every engine, prints a table per step, the cases where
/// an engine disagrees with the reference, and fails when a step's agreement is below
/// `--min-agreement`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    anyhow::ensure!(args.samples > 0, "--samples must be at least 1");
    anyhow::ensure!(
        (0.0..=1.0).contains(&args.min_agreement),
        "--min-agreement must be a fraction between 0 and 1, got {}",
        args.min_agreement
    );
    let engines = build_engines(&args.engines)?;
    let reference = Scorer::from_name(&args.reference)
        .with_context(|| format!("--reference {:?} is not an engine", args.reference))?
        .name();
    anyhow::ensure!(
        engines.iter().any(|e| e.name() == reference),
        "--reference {reference} is not among --engines"
    );
    let scenario = Scenario::load(&args.scenario).map_err(|e| anyhow::anyhow!("{e}"))?;
    let spec = &scenario.spec;
    let geometry = CellGeometry::new(&spec.cell, &spec.assembly, &scenario.catalog)
        .context("loading the part shapes")?;
    for engine in &engines {
        for part in geometry.parts.values() {
            engine.check_part(part)?;
        }
    }
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
    if args.force_verdicts {
        let truth = engines
            .iter()
            .find(|e| e.name() == reference)
            .expect("the reference is among the engines");
        return force_verdicts(&args, &scenario, &steps, truth);
    }
    let started = Instant::now();
    let agreement = compare_scorers(&steps, args.samples, args.seed, &engines)?;
    let elapsed = started.elapsed().as_secs_f64();

    let others: Vec<&str> = agreement
        .engines
        .iter()
        .map(String::as_str)
        .filter(|e| *e != reference)
        .collect();
    print_table(&agreement, reference, &others);
    println!(
        "{} samples in {elapsed:.1} s; agreement with {reference} (the reference; goal ≥ {:.1} % \
         per step): {}",
        agreement.samples(),
        100.0 * args.min_agreement,
        others
            .iter()
            .map(|o| format!("{o} {:.1} %", 100.0 * agreement.pair_rate(o, reference)))
            .collect::<Vec<_>>()
            .join(", ")
    );
    print_cases(&agreement, reference);
    if let Some(out) = &args.out {
        let json = serde_json::to_vec_pretty(&agreement)?;
        sim::fsutil::write_atomic(out, &json)
            .with_context(|| format!("writing {}", out.display()))?;
        println!("wrote {}", out.display());
    }
    let mut below = Vec::new();
    for st in &agreement.steps {
        for o in &others {
            let rate = st.pair_rate(o, reference);
            if rate < args.min_agreement {
                below.push(format!("{} {o} {:.1} %", st.part, 100.0 * rate));
            }
        }
    }
    Ok(if below.is_empty() {
        ExitCode::SUCCESS
    } else {
        eprintln!(
            "error: agreement with {reference} below --min-agreement {:.1} % on: {}",
            100.0 * args.min_agreement,
            below.join("; ")
        );
        ExitCode::FAILURE
    })
}

/// The engines named on the command line, each once.
fn build_engines(names: &[String]) -> anyhow::Result<Vec<Arc<dyn InsertionScorer>>> {
    let mut engines: Vec<Arc<dyn InsertionScorer>> = Vec::new();
    for name in names {
        let scorer = Scorer::from_name(name.trim()).with_context(|| {
            format!("--engines: {name:?} is not an engine (analytic, rapier, mujoco)")
        })?;
        anyhow::ensure!(
            engines.iter().all(|e| e.name() != scorer.name()),
            "--engines names {} twice",
            scorer.name()
        );
        engines.push(scorer.build()?);
    }
    anyhow::ensure!(engines.len() >= 2, "--engines needs at least two engines");
    Ok(engines)
}

fn print_table(agreement: &Agreement, reference: &str, others: &[&str]) {
    let mut header = format!("{:<14} {:>7}", "step", "samples");
    for e in &agreement.engines {
        header += &format!(" {:>16}", format!("{e} seated"));
    }
    for o in others {
        header += &format!(" {:>18}", format!("{o}~{reference} %"));
    }
    header += &format!(" {:>12}", "all agree %");
    println!("{header}");
    for st in &agreement.steps {
        let mut row = format!("{:<14} {:>7}", st.part, st.samples);
        for e in &agreement.engines {
            row += &format!(" {:>16}", st.seated.get(e).copied().unwrap_or(0));
        }
        for o in others {
            row += &format!(" {:>18.1}", 100.0 * st.pair_rate(o, reference));
        }
        let all = 1.0 - st.disagreements as f64 / st.samples.max(1) as f64;
        row += &format!(" {:>12.1}", 100.0 * all);
        println!("{row}");
    }
}

/// Prints the cases where an engine other than the analytic model disagrees with the
/// reference: the start pose, then each engine's verdict and final pose.
fn print_cases(agreement: &Agreement, reference: &str) {
    let cases: Vec<&Disagreement> = agreement
        .disagreements
        .iter()
        .filter(|d| {
            d.outcomes
                .iter()
                .any(|o| o.engine != "analytic" && Some(o.verdict) != d.verdict(reference))
        })
        .collect();
    if cases.is_empty() {
        return;
    }
    println!(
        "\n{} cases where a contact engine disagrees with {reference} (lateral x,y µm; height \
         above seated µm; tilt, yaw mrad){}:",
        cases.len(),
        if cases.len() > SHOWN_CASES {
            format!("; the first {SHOWN_CASES}")
        } else {
            String::new()
        }
    );
    for d in cases.iter().take(SHOWN_CASES) {
        println!(
            "  step {} sample {}: start {}",
            d.step + 1,
            d.sample,
            pose(&d.start)
        );
        for o in &d.outcomes {
            println!(
                "    {:<9} {:<7} end {}",
                o.engine,
                format!("{:?}", o.verdict).to_lowercase(),
                pose(&o.end)
            );
        }
    }
}

fn pose(p: &PoseError) -> String {
    format!(
        "lateral ({:+.1}, {:+.1}) height {:+.1} tilt {:.2} yaw {:+.2}",
        p.lateral.x * 1e6,
        p.lateral.y * 1e6,
        p.height * 1e6,
        p.tilt * 1e3,
        p.yaw * 1e3
    )
}

/// `--force-verdicts`: the force-guided verdicts against the reference engine's truth.
fn force_verdicts(
    args: &Args,
    scenario: &Scenario,
    steps: &[StepGeometry<'_>],
    truth: &Arc<dyn InsertionScorer>,
) -> anyhow::Result<ExitCode> {
    use cell::orchestrator::insertion::agreement::{ForceCounts, force_agreement};
    let spec = scenario.spec.force_insertion.unwrap_or_default();
    let started = Instant::now();
    let cell_scorer = scenario.spec.simulation.insertion_scorer.build()?;
    for part in steps.iter().map(|s| s.held) {
        cell_scorer.check_part(part)?;
    }
    let a = force_agreement(steps, args.samples, args.seed, truth, &cell_scorer, &spec)?;
    let elapsed = started.elapsed().as_secs_f64();
    let t = &a.truth;
    println!(
        "force-guided verdicts against {t} (seat band {:.3} mm, contact {:.1} N at {:.0} N/mm, \
         UR5e sensor noise); \"from {t}'s stop\": first contact where {t} stopped the part; \
         \"from the cell's stop\": where the simulated cell's contact model stops it (the \
         scenario's scorer, {})",
        spec.seat_band * 1e3,
        spec.contact_force,
        spec.contact_stiffness * 1e-3,
        a.cell
    );
    println!(
        "{:<14} {:>7} {:>10} {:>22} {:>22} {:>22} {:>22}",
        "step",
        "samples",
        format!("{t} seated"),
        format!("seated? from {t} %"),
        format!("outcome from {t} %"),
        "seated? from cell %",
        "outcome from cell %"
    );
    let row = |name: &str, c: &ForceCounts| {
        println!(
            "{:<14} {:>7} {:>10} {:>22.1} {:>22.1} {:>22.1} {:>22.1}",
            name,
            c.samples,
            c.truth_seated,
            100.0 * c.rate(c.engine_seating),
            100.0 * c.rate(c.engine_outcome),
            100.0 * c.rate(c.cell_seating),
            100.0 * c.rate(c.cell_outcome)
        );
    };
    for (part, c) in &a.steps {
        row(part, c);
    }
    row("all", &a.all);
    let um = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{:.1}", v * 1e6));
    for (part, c) in a
        .steps
        .iter()
        .map(|(p, c)| (p.as_str(), c))
        .chain([("all", &a.all)])
    {
        println!(
            "{part}: {t} stops seated parts up to {} µm above seated and the rest from {} µm; \
             the seat band is {:.1} µm",
            um(c.seated_stop_max),
            um(c.unseated_stop_min),
            spec.seat_band * 1e6
        );
    }
    let mm = |v: f64| format!("{:.3}", v * 1e3);
    for ((part, c), rims) in a.steps.iter().zip(&a.rims) {
        let bands: Vec<String> = rims
            .bands
            .iter()
            .map(|b| format!("{}–{}", mm(b[0]), mm(b[1])))
            .collect();
        println!(
            "{part}: missed from {} mm above seated (the receiver's top) and where a part beyond \
             the capture band lands: {} mm",
            mm(rims.rim),
            if bands.is_empty() {
                "nowhere".to_string()
            } else {
                bands.join(", ")
            }
        );
        let n = &c.confusion;
        println!(
            "  {t} → read from {t}'s stop: seated {} / {} / {}, jammed {} / {} / {}, missed {} / \
             {} / {} (read seated / jammed / missed)",
            n[0][0], n[0][1], n[0][2], n[1][0], n[1][1], n[1][2], n[2][0], n[2][1], n[2][2]
        );
    }
    println!("{} insertions in {elapsed:.1} s", a.all.samples);
    let word = |o: cell::episode::StepOutcome| format!("{o:?}").to_lowercase();
    // The engine's own signature first (do force and depth tell its outcomes apart?), then
    // what the simulated cell's stop adds (its scorer's disagreement with the engine).
    for (from_engine, title) in [
        (true, format!("read from {t}'s stop")),
        (
            false,
            "read from the cell's stop (where only that differs)".to_string(),
        ),
    ] {
        let cases: Vec<_> = a
            .disagreements
            .iter()
            .filter(|c| {
                if from_engine {
                    c.engine != c.truth
                } else {
                    c.engine == c.truth && c.cell != c.truth
                }
            })
            .collect();
        if cases.is_empty() {
            continue;
        }
        println!(
            "\n{} verdicts {title} differ from {t} (stops µm above seated, noise N along the \
             axis){}:",
            cases.len(),
            if cases.len() > SHOWN_CASES {
                format!("; the first {SHOWN_CASES}")
            } else {
                String::new()
            }
        );
        for c in cases.iter().take(SHOWN_CASES) {
            let (stop, read) = if from_engine {
                (c.truth_stop, c.engine)
            } else {
                (c.cell_stop, c.cell)
            };
            println!(
                "  {} sample {}: {t} {} stopping at {:+.1}, read {} at {:+.1} (noise {:+.2}); \
                 start {}",
                a.steps[c.step].0,
                c.sample,
                word(c.truth),
                c.truth_stop * 1e6,
                word(read),
                stop * 1e6 + c.noise_n / spec.contact_stiffness * 1e6,
                c.noise_n,
                pose(&c.start),
            );
        }
    }
    if let Some(out) = &args.out {
        let json = serde_json::to_vec_pretty(&a)?;
        sim::fsutil::write_atomic(out, &json)
            .with_context(|| format!("writing {}", out.display()))?;
        println!("wrote {}", out.display());
    }
    let rate = a.all.rate(a.all.engine_seating);
    Ok(if rate >= args.min_agreement {
        ExitCode::SUCCESS
    } else {
        eprintln!(
            "error: force-guided seating verdicts agree with {t} on {:.1} %, below \
             --min-agreement {:.1} %",
            100.0 * rate,
            100.0 * args.min_agreement
        );
        ExitCode::FAILURE
    })
}
