//! Statistics for success rates: Wilson score intervals, the one-sided Fisher exact test for a
//! drop, and Holm's step-down correction for testing several rates at once.
//!
//! Why Fisher's exact test: assembly success rates sit close to 100 % and runs are a few dozen
//! to a few hundred episodes, exactly where the normal approximation behind a two-proportion z
//! test (even with a continuity correction) misstates tail probabilities. Fisher's test
//! conditions on the table's margins and sums hypergeometric probabilities exactly, so its
//! false-alarm rate never exceeds alpha at any sample size; the price is some conservatism,
//! which for a CI gate is the right side to err on. One-sided, because the gate only fails on
//! a drop; an improvement is reported but never fails it.

use serde::{Deserialize, Serialize};
use statrs::distribution::{ContinuousCDF, Normal};
use statrs::stats_tests::{Alternative, fishers_exact};

/// Successes out of trials.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Counts {
    /// Successes.
    pub successes: u32,
    /// Trials.
    pub trials: u32,
}

impl Counts {
    /// `successes` of `trials`.
    pub fn new(successes: u32, trials: u32) -> Self {
        Self { successes, trials }
    }

    /// The observed rate (0 when there were no trials).
    pub fn rate(&self) -> f64 {
        if self.trials == 0 {
            0.0
        } else {
            f64::from(self.successes) / f64::from(self.trials)
        }
    }
}

/// A closed interval of rates.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Interval {
    /// Lower bound.
    pub lo: f64,
    /// Upper bound.
    pub hi: f64,
}

/// The Wilson score interval for a binomial rate at `confidence` (e.g. 0.95); `[0, 1]` without
/// trials. Unlike the Wald interval it stays inside [0, 1] and keeps its coverage near 0 and 1.
pub fn wilson(c: Counts, confidence: f64) -> Interval {
    if c.trials == 0 {
        return Interval { lo: 0.0, hi: 1.0 };
    }
    let z = Normal::standard().inverse_cdf(1.0 - (1.0 - confidence) / 2.0);
    let n = f64::from(c.trials);
    let p = c.rate();
    let z2n = z * z / n;
    let centre = (p + z2n / 2.0) / (1.0 + z2n);
    let half = z / (1.0 + z2n) * (p * (1.0 - p) / n + z2n / (4.0 * n)).sqrt();
    Interval {
        lo: (centre - half).max(0.0),
        hi: (centre + half).min(1.0),
    }
}

/// p-value of the one-sided Fisher exact test of "the current rate is lower than the
/// baseline's" (null: equal rates), from the 2×2 table current/baseline × success/failure.
pub fn drop_p_value(baseline: Counts, current: Counts) -> f64 {
    let table = [
        u64::from(current.successes),
        u64::from(current.trials.saturating_sub(current.successes)),
        u64::from(baseline.successes),
        u64::from(baseline.trials.saturating_sub(baseline.successes)),
    ];
    // The table's margins always describe a valid hypergeometric distribution; an error would
    // be a bug in statrs, and "no evidence of a drop" is then the only safe answer.
    fishers_exact(&table, Alternative::Less).unwrap_or(1.0)
}

/// Holm's step-down adjusted p-values: rejecting where the adjusted value is below alpha keeps
/// the chance of any false alarm among all the tests at most alpha.
pub fn holm(p: &[f64]) -> Vec<f64> {
    let m = p.len();
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by(|a, b| p[*a].total_cmp(&p[*b]));
    let mut adjusted = vec![0.0; m];
    let mut running: f64 = 0.0;
    for (rank, &i) in order.iter().enumerate() {
        running = running.max(((m - rank) as f64 * p[i]).min(1.0));
        adjusted[i] = running;
    }
    adjusted
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    #[test]
    fn wilson_matches_newcombe_1998() {
        // Newcombe, Statistics in Medicine 17 (1998), Table I, method 3 (score, no correction).
        for (k, n, lo, hi) in [
            (81, 263, 0.2553, 0.3662),
            (15, 148, 0.0624, 0.1605),
            (0, 20, 0.0, 0.1611),
            (1, 29, 0.0061, 0.1718),
        ] {
            let i = wilson(Counts::new(k, n), 0.95);
            assert!(
                close(i.lo, lo, 6e-5) && close(i.hi, hi, 6e-5),
                "{k}/{n}: {i:?}"
            );
        }
        assert_eq!(
            wilson(Counts::new(0, 0), 0.95),
            Interval { lo: 0.0, hi: 1.0 }
        );
        let all = wilson(Counts::new(20, 20), 0.95);
        assert_eq!(all.hi, 1.0);
        assert!(close(all.lo, 1.0 - 0.1611, 6e-5));
    }

    #[test]
    fn fisher_one_sided_matches_the_hypergeometric_tail() {
        // Baseline 10/10, current 5/10: P(X <= 5), X ~ Hypergeometric(20 total, 15 successes,
        // 10 drawn) = C(15,5)·C(5,5)/C(20,10) = 3003/184756.
        let p = drop_p_value(Counts::new(10, 10), Counts::new(5, 10));
        assert!(close(p, 3003.0 / 184_756.0, 1e-12), "{p}");
        // An improvement is no evidence of a drop; equal counts give p = 1.
        assert!(drop_p_value(Counts::new(5, 10), Counts::new(10, 10)) > 0.99);
        // Equal rates: the observed table is the mode, so p = P(X <= 7) for X ~ Hyp(20, 14, 10).
        let equal = drop_p_value(Counts::new(7, 10), Counts::new(7, 10));
        assert!(close(equal, 0.685_758_513_931_888_6, 1e-9), "{equal}");
        assert_eq!(drop_p_value(Counts::new(10, 10), Counts::new(10, 10)), 1.0);
    }

    #[test]
    fn holm_adjusts_step_down() {
        let a = holm(&[0.01, 0.04, 0.03, 0.5]);
        // Sorted 0.01, 0.03, 0.04, 0.5 times 4, 3, 2, 1, made monotone.
        let expect = [0.04, 0.09, 0.09, 0.5];
        for (x, y) in a.iter().zip(expect) {
            assert!(close(*x, y, 1e-12), "{a:?}");
        }
    }
}
