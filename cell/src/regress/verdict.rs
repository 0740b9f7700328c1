//! The verdict: the overall success rate and each step's seated rate against the baseline, each
//! by the one-sided Fisher exact test, with Holm's correction across the informative rows of a
//! scenario so that testing the steps too does not raise the false-alarm rate above alpha.

use std::fmt::Write as _;

use super::baseline::Baseline;
use super::stats::{Counts, drop_p_value, holm};
use crate::run::Summary;

/// One tested rate.
#[derive(Debug, Clone, PartialEq)]
pub struct Comparison {
    /// What is compared: `episode success` or `step I (part) seated`.
    pub what: String,
    /// Baseline counts.
    pub baseline: Counts,
    /// Current counts.
    pub current: Counts,
    /// One-sided Fisher exact p-value of a drop.
    pub p_value: f64,
    /// Holm-adjusted p-value across the scenario's rows.
    pub p_holm: f64,
    /// A significant drop: `p_holm < alpha`.
    pub drop: bool,
}

/// The gate's verdict on one scenario.
#[derive(Debug, Clone, PartialEq)]
pub struct Verdict {
    /// Scenario name.
    pub scenario: String,
    /// Significance level.
    pub alpha: f64,
    /// Overall first, then the steps.
    pub rows: Vec<Comparison>,
    /// Caveats (changed scenario file, steps that do not match the baseline, ...).
    pub notes: Vec<String>,
}

impl Verdict {
    /// Whether any row dropped significantly.
    pub fn regressed(&self) -> bool {
        self.rows.iter().any(|r| r.drop)
    }

    /// A plain-text table of the rows and notes.
    pub fn table(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "{}: {} (alpha {}, one-sided Fisher exact, Holm across rows)",
            self.scenario,
            if self.regressed() { "REGRESSED" } else { "ok" },
            self.alpha
        );
        let _ = writeln!(
            s,
            "  {:<34} {:>17} {:>17} {:>8} {:>10} {:>10}  verdict",
            "rate", "baseline", "current", "Δ pp", "p", "p (Holm)"
        );
        let frac = |c: Counts| format!("{}/{} {:5.1}%", c.successes, c.trials, 100.0 * c.rate());
        for r in &self.rows {
            let delta = 100.0 * (r.current.rate() - r.baseline.rate());
            let _ = writeln!(
                s,
                "  {:<34} {:>17} {:>17} {:>+8.1} {:>10.3e} {:>10.3e}  {}",
                r.what,
                frac(r.baseline),
                frac(r.current),
                delta,
                r.p_value,
                r.p_holm,
                if r.drop { "DROP" } else { "ok" }
            );
        }
        for n in &self.notes {
            let _ = writeln!(s, "  note: {n}");
        }
        s
    }
}

/// Compares a run's summary with its baseline at significance `alpha`.
pub fn compare(baseline: &Baseline, current: &Summary, alpha: f64) -> Verdict {
    let mut notes = Vec::new();
    if baseline.scenario_sha256 != current.scenario_sha256 {
        notes.push(format!(
            "the scenario file changed since the baseline ({} at {}); the comparison mixes a \
             scenario change with code changes",
            baseline.commit.as_deref().unwrap_or("unknown commit"),
            baseline.date
        ));
    }
    if baseline.seed != current.seed {
        notes.push(format!(
            "seed {} differs from the baseline's {}",
            current.seed, baseline.seed
        ));
    }
    if baseline.record_version != current.record_version {
        notes.push(format!(
            "record version {} differs from the baseline's {}",
            current.record_version, baseline.record_version
        ));
    }
    let mut tested: Vec<(String, Counts, Counts)> = vec![(
        "episode success".into(),
        baseline.counts(),
        current.counts(),
    )];
    for b in &baseline.steps {
        match current
            .steps
            .iter()
            .find(|c| c.index == b.index && c.part == b.part)
        {
            Some(c) => tested.push((
                format!("step {} ({}) seated", b.index, b.part),
                Counts::new(b.seated, b.reached),
                c.counts(),
            )),
            None => notes.push(format!(
                "step {} ({}) of the baseline was never reached in this run",
                b.index, b.part
            )),
        }
    }
    for c in &current.steps {
        if !baseline
            .steps
            .iter()
            .any(|b| b.index == c.index && b.part == c.part)
        {
            notes.push(format!(
                "step {} ({}) is not in the baseline",
                c.index, c.part
            ));
        }
    }
    let p: Vec<f64> = tested
        .iter()
        .map(|(_, b, c)| drop_p_value(*b, *c))
        .collect();
    // A table without a failure (or without a success) on either side, or with an empty side,
    // has a degenerate conditional distribution: its p-value is 1 whatever happens, so it can
    // never alarm and does not count towards the correction (Tarone's argument for discrete
    // tests). The rest are Holm-corrected together.
    let informative: Vec<usize> = (0..tested.len())
        .filter(|&i| {
            let (_, b, c) = &tested[i];
            let successes = b.successes + c.successes;
            let trials = b.trials + c.trials;
            b.trials > 0 && c.trials > 0 && successes > 0 && successes < trials
        })
        .collect();
    let mut adjusted = vec![1.0; p.len()];
    let held: Vec<f64> = informative.iter().map(|&i| p[i]).collect();
    for (&i, a) in informative.iter().zip(holm(&held)) {
        adjusted[i] = a;
    }
    let rows = tested
        .into_iter()
        .zip(p.iter().zip(adjusted))
        .map(|((what, b, c), (&p_value, p_holm))| Comparison {
            what,
            baseline: b,
            current: c,
            p_value,
            p_holm,
            drop: p_holm < alpha,
        })
        .collect();
    Verdict {
        scenario: current.scenario.clone(),
        alpha,
        rows,
        notes,
    }
}
