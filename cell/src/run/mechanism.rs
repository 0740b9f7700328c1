//! Failure mechanisms: the recorded causes with their numbers taken out, so that 99 causes such
//! as "lateral offset 0.169 mm beyond the 0.135 mm capture band" become one mechanism with the
//! offsets as a distribution.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::distribution::Distribution;
use super::outcomes::{outcome_index, outcome_name};
use crate::episode::StepOutcome;

/// How often one failure mechanism ended an episode, with the numbers its causes carried.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MechanismCount {
    /// The failing step's part (`None`: the episode stopped outside any step).
    pub part: Option<String>,
    /// The failing step's outcome.
    pub outcome: Option<StepOutcome>,
    /// The mechanism in words ("missed: lateral offset beyond the capture band").
    pub mechanism: String,
    /// The causes with every number replaced by its range over these episodes.
    pub detail: String,
    /// Failed episodes with this mechanism.
    pub count: u32,
    /// The first number of each cause (the offset, tilt, ... that failed), when causes have one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub value: Option<Distribution>,
    /// The failed episodes, in order.
    pub episodes: Vec<u32>,
}

/// A cause's text with each number replaced by `#`, and the numbers in order.
pub fn pattern(cause: &str) -> (String, Vec<f64>) {
    // "(after 3 insertion attempts)" says how often it was retried, not how it failed.
    let cause = match cause.find(" (after ") {
        Some(i) if cause.ends_with(" insertion attempts)") => &cause[..i],
        _ => cause,
    };
    let mut out = String::with_capacity(cause.len());
    let mut numbers = Vec::new();
    let chars: Vec<char> = cause.chars().collect();
    let mut i = 0;
    while i < chars.len() {
        let starts_number = chars[i].is_ascii_digit()
            || (chars[i] == '-'
                && chars.get(i + 1).is_some_and(char::is_ascii_digit)
                && (i == 0 || !chars[i - 1].is_alphanumeric()));
        let inside_word = i > 0 && (chars[i - 1].is_alphabetic() || chars[i - 1] == '_');
        if starts_number && !inside_word {
            let start = i;
            i += 1;
            while i < chars.len()
                && (chars[i].is_ascii_digit()
                    || (chars[i] == '.' && chars.get(i + 1).is_some_and(char::is_ascii_digit)))
            {
                i += 1;
            }
            let text: String = chars[start..i].iter().collect();
            if let Ok(v) = text.parse::<f64>() {
                numbers.push(v);
                out.push('#');
                continue;
            }
            out.push_str(&text);
            continue;
        }
        out.push(chars[i]);
        i += 1;
    }
    (out, numbers)
}

/// The mechanism of a cause pattern, in words, for the known causes; the pattern otherwise.
pub fn mechanism_name(pattern: &str, outcome: Option<StepOutcome>) -> String {
    let known: [(&str, &str); 9] = [
        ("lateral offset", "lateral offset beyond the capture band"),
        ("tilt", "tilted beyond the jam angle"),
        ("yaw", "yawed beyond what the clearance allows"),
        ("stopped", "stopped short of seated"),
        (
            "fully down but out of tolerance",
            "fully down, out of tolerance",
        ),
        ("released away", "released away from the target"),
        ("no usable", "no usable part in the feeder"),
        ("grasp failed", "grasp failed"),
        ("insertion plan", "insertion could not be planned"),
    ];
    let what = known
        .iter()
        .find(|(prefix, _)| pattern.starts_with(prefix))
        .map_or(pattern.to_string(), |(_, name)| (*name).to_string());
    match outcome {
        Some(o) => format!("{}: {what}", outcome_name(o)),
        None => format!("stopped: {what}"),
    }
}

/// `pattern` with its `#`s replaced by the range of each number over `rows`.
fn detail(pattern: &str, rows: &[Vec<f64>]) -> String {
    let mut out = String::new();
    let mut k = 0;
    for c in pattern.chars() {
        if c != '#' {
            out.push(c);
            continue;
        }
        let values: Vec<f64> = rows.iter().filter_map(|r| r.get(k).copied()).collect();
        let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let fmt = |v: f64| {
            if v.fract() == 0.0 {
                format!("{v:.0}")
            } else {
                format!("{v:.3}")
            }
        };
        if values.is_empty() {
            out.push('#');
        } else if lo == hi {
            out.push_str(&fmt(lo));
        } else {
            out.push_str(&format!("{}–{}", fmt(lo), fmt(hi)));
        }
        k += 1;
    }
    out
}

type Key = (Option<String>, Option<usize>, String);

/// The failures of one mechanism: outcome, cause patterns seen, each cause's numbers, episodes.
type Group = (Option<StepOutcome>, Vec<String>, Vec<Vec<f64>>, Vec<u32>);

/// Failed episodes grouped by (part, outcome, mechanism).
#[derive(Default)]
pub struct Mechanisms {
    groups: BTreeMap<Key, Group>,
}

impl Mechanisms {
    /// Adds one failed episode.
    pub fn add(
        &mut self,
        part: Option<String>,
        outcome: Option<StepOutcome>,
        cause: &str,
        episode: u32,
    ) {
        let (pat, numbers) = pattern(cause);
        let name = mechanism_name(&pat, outcome);
        let key = (part, outcome.map(outcome_index), name.clone());
        let g = self
            .groups
            .entry(key)
            .or_insert_with(|| (outcome, Vec::new(), Vec::new(), Vec::new()));
        if !g.1.contains(&pat) {
            g.1.push(pat);
        }
        g.2.push(numbers);
        g.3.push(episode);
    }

    /// The groups, most frequent first.
    pub fn finish(self) -> Vec<MechanismCount> {
        let mut out: Vec<MechanismCount> = self
            .groups
            .into_iter()
            .map(
                |((part, _, mechanism), (outcome, patterns, rows, mut episodes))| {
                    episodes.sort_unstable();
                    let first: Vec<f64> = rows.iter().filter_map(|r| r.first().copied()).collect();
                    let detail = if patterns.len() == 1 {
                        detail(&patterns[0], &rows)
                    } else {
                        patterns.join("; ")
                    };
                    MechanismCount {
                        part,
                        outcome,
                        mechanism,
                        detail,
                        count: episodes.len() as u32,
                        value: Distribution::of(&first),
                        episodes,
                    }
                },
            )
            .collect();
        out.sort_by_key(|m| std::cmp::Reverse(m.count));
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_taken_out_and_retries_dropped() {
        let (p, n) = pattern(
            "lateral offset 0.169 mm beyond the 0.135 mm capture band (after 3 insertion attempts)",
        );
        assert_eq!(p, "lateral offset # mm beyond the # mm capture band");
        assert_eq!(n, vec![0.169, 0.135]);
        let (p, n) = pattern("tilt -1.25° beyond the 0.50° jam angle");
        assert_eq!(p, "tilt #° beyond the #° jam angle");
        assert_eq!(n, vec![-1.25, 0.5]);
        // Digits inside names stay.
        assert_eq!(
            pattern("no usable top_shell2 after 8 shakes").0,
            "no usable top_shell2 after # shakes"
        );
    }

    #[test]
    fn ninety_nine_offsets_are_one_mechanism_with_a_distribution() {
        let mut m = Mechanisms::default();
        for e in 0..99u32 {
            let cause = format!(
                "lateral offset {:.3} mm beyond the 0.135 mm capture band",
                0.14 + f64::from(e) * 0.001
            );
            m.add(
                Some("insert_mold".into()),
                Some(StepOutcome::Missed),
                &cause,
                e,
            );
        }
        m.add(
            Some("insert_mold".into()),
            Some(StepOutcome::Jammed),
            "tilt 1.00° beyond the 0.50° jam angle",
            200,
        );
        let out = m.finish();
        assert_eq!(out.len(), 2);
        assert_eq!(out[0].count, 99);
        assert_eq!(
            out[0].mechanism,
            "missed: lateral offset beyond the capture band"
        );
        assert_eq!(
            out[0].detail,
            "lateral offset 0.140–0.238 mm beyond the 0.135 mm capture band"
        );
        let v = out[0].value.expect("offsets");
        assert!((v.p50 - 0.189).abs() < 1e-9 && v.n == 99, "{v:?}");
        assert_eq!(out[1].mechanism, "jammed: tilted beyond the jam angle");
        assert_eq!(out[1].episodes, vec![200]);
    }
}
