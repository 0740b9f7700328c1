//! Why a ground-truth instance was missed and why a detection matched nothing, from what
//! overlaps each most: one classification for the summary's counts and the gallery's captions.

use serde::{Deserialize, Serialize};

use super::{DetectionRecord, TruthRecord};

/// Missed instances by the detection that overlaps each one most
/// ([`super::TruthRecord::closest`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct MissCauses {
    /// Another part's detection covers it at the IoU threshold or above: found, wrong part.
    pub wrong_part: usize,
    /// A detection of its own part covers it, below the threshold: a split or merged mask.
    pub partial: usize,
    /// Only another part's detection touches it, below the threshold: swallowed by a
    /// neighbour's instance or hidden under it.
    pub covered: usize,
    /// No detection overlaps it.
    pub nothing: usize,
}

/// False positives by the ground-truth instance that overlaps each one most
/// ([`super::DetectionRecord::closest_truth`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct FalsePositiveCauses {
    /// It covers another part's instance at the IoU threshold or above: found, wrong part.
    pub wrong_part: usize,
    /// It overlaps an instance of its own part that another detection matched: a split or a
    /// doubled instance.
    pub duplicate: usize,
    /// It overlaps an unmatched instance of its own part, below the threshold: a poor mask.
    pub partial: usize,
    /// It overlaps other parts' instances only, below the threshold: a mask over several
    /// parts, or a part seen where a neighbour lies.
    pub straddling: usize,
    /// It overlaps no instance: a part seen on the empty table.
    pub nothing: usize,
}

/// Why a ground-truth instance was missed ([`MissCauses`] counts them).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MissCause {
    /// Another part's detection covers it at the IoU threshold or above.
    WrongPart,
    /// A detection of its own part covers it, below the threshold.
    Partial,
    /// Only another part's detection touches it, below the threshold.
    Covered,
    /// No detection overlaps it.
    Nothing,
}

impl MissCause {
    /// What it means, for captions.
    pub fn describe(self) -> &'static str {
        match self {
            Self::WrongPart => "found as another part",
            Self::Partial => "a split or merged mask of its own part",
            Self::Covered => "swallowed by a neighbour's instance or hidden under it",
            Self::Nothing => "no detection overlaps it",
        }
    }
}

/// The parts missed instances were found as (`found_as`, counts by part), most first:
/// "square_16 × 91, round_8 × 2" (empty for none).
pub fn found_as_text(found_as: &std::collections::BTreeMap<String, usize>) -> String {
    let mut by_count: Vec<(&String, &usize)> = found_as.iter().collect();
    by_count.sort_by(|a, b| b.1.cmp(a.1).then(a.0.cmp(b.0)));
    let items: Vec<String> = (by_count.iter())
        .map(|(part, n)| format!("{part} × {n}"))
        .collect();
    items.join(", ")
}

/// Why a missed instance of `part` was missed, from the detection overlapping it most
/// (its part and IoU), at match threshold `min_iou`.
pub fn miss_cause(part: &str, closest: Option<(&String, f64)>, min_iou: f64) -> MissCause {
    match closest {
        None => MissCause::Nothing,
        Some((p, _)) if p == part => MissCause::Partial,
        Some((_, iou)) if iou >= min_iou => MissCause::WrongPart,
        Some(_) => MissCause::Covered,
    }
}

impl MissCauses {
    /// The counter of `cause`.
    pub(super) fn slot(&mut self, cause: MissCause) -> &mut usize {
        match cause {
            MissCause::WrongPart => &mut self.wrong_part,
            MissCause::Partial => &mut self.partial,
            MissCause::Covered => &mut self.covered,
            MissCause::Nothing => &mut self.nothing,
        }
    }
}

/// Why a detection matched no instance ([`FalsePositiveCauses`] counts them).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FalsePositiveCause {
    /// It covers another part's instance at the IoU threshold or above.
    WrongPart,
    /// It overlaps an instance of its own part that another detection matched.
    Duplicate,
    /// It overlaps an unmatched instance of its own part, below the threshold.
    Partial,
    /// It overlaps other parts' instances only, below the threshold.
    Straddling,
    /// It overlaps no instance.
    Nothing,
}

impl FalsePositiveCause {
    /// What it means, for captions.
    pub fn describe(self) -> &'static str {
        match self {
            Self::WrongPart => "another part, taken for this one",
            Self::Duplicate => "a second instance of a part found already",
            Self::Partial => "a poor mask of a missed part of its own kind",
            Self::Straddling => "a mask over other parts",
            Self::Nothing => "a part seen on the empty table",
        }
    }
}

/// Why detection `d`, matched to no instance of its frame's `truths`, is a false positive, at
/// match threshold `min_iou`.
pub fn false_positive_cause(
    d: &DetectionRecord,
    truths: &[TruthRecord],
    min_iou: f64,
) -> FalsePositiveCause {
    match d
        .closest_truth
        .and_then(|c| Some((truths.get(c.truth)?, c.iou)))
    {
        None => FalsePositiveCause::Nothing,
        Some((t, _)) if t.part == d.part && t.detection.is_some() => FalsePositiveCause::Duplicate,
        Some((t, _)) if t.part == d.part => FalsePositiveCause::Partial,
        Some((_, iou)) if iou >= min_iou => FalsePositiveCause::WrongPart,
        Some(_) => FalsePositiveCause::Straddling,
    }
}

impl FalsePositiveCauses {
    /// The counter of `cause`.
    pub(super) fn slot(&mut self, cause: FalsePositiveCause) -> &mut usize {
        match cause {
            FalsePositiveCause::WrongPart => &mut self.wrong_part,
            FalsePositiveCause::Duplicate => &mut self.duplicate,
            FalsePositiveCause::Partial => &mut self.partial,
            FalsePositiveCause::Straddling => &mut self.straddling,
            FalsePositiveCause::Nothing => &mut self.nothing,
        }
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::*;

    #[test]
    fn the_parts_found_instead_are_listed_most_first() {
        let found = BTreeMap::from([
            ("round_8".to_string(), 2),
            ("square_16".to_string(), 91),
            ("round_12".to_string(), 2),
        ]);
        assert_eq!(
            found_as_text(&found),
            "square_16 × 91, round_12 × 2, round_8 × 2"
        );
        assert_eq!(found_as_text(&BTreeMap::new()), "");
    }
}
