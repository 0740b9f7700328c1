//! Aggregation of the per-frame records into the numbers `cell eval` reports: per part and
//! pooled, detection precision / recall (also for touching instances) with the causes of each
//! miss and false positive, pose errors raw and refined, BOP MSSD / MSPD recall, stable-pose rate,
//! the picks the cell would make, and time per stage.

use std::collections::BTreeMap;

use perception::metrics::{ErrorSummary, PoseErrors, Summary, SummaryOptions};
use serde::{Deserialize, Serialize};

use super::causes::{FalsePositiveCauses, MissCause, MissCauses, false_positive_cause, miss_cause};
use super::picks::{Pickable, Picks, is_assembly_grade};
use super::table1::{Table1Entry, Table1Row};
use super::{DetectionRecord, EvalOptions, FrameRecord, StageMs};

/// BOP MSSD thresholds, fractions of the object diameter.
pub const MSSD_FRACTIONS: [f64; 10] = [0.05, 0.10, 0.15, 0.20, 0.25, 0.30, 0.35, 0.40, 0.45, 0.50];
/// MSPD thresholds, pixels of the evaluated images (BOP uses 5r … 50r with r = width / 640 for
/// its 640-pixel-wide images; ours are full-resolution crops, so r = 1).
pub const MSPD_PX: [f64; 10] = [5.0, 10.0, 15.0, 20.0, 25.0, 30.0, 35.0, 40.0, 45.0, 50.0];

/// Pose errors of one method (raw or refined) over a set of estimates.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PoseStats {
    /// Every metric over all estimates (outliers kept).
    pub all: ErrorSummary,
    /// Every metric without the outliers, as the seed reports.
    pub seed_style: ErrorSummary,
    /// Outliers that lie within the outlier angle of a near-symmetric equivalent of the truth
    /// (180° flips of the nearly symmetric parts).
    pub symmetry_flips: usize,
    /// Fraction of the counted ground-truth instances recalled with MSSD below each of
    /// [`MSSD_FRACTIONS`] × diameter.
    pub mssd_recall: Vec<f64>,
    /// The same for MSPD below each of [`MSPD_PX`].
    pub mspd_recall: Vec<f64>,
    /// BOP average recall AR_MSSD (mean of `mssd_recall`).
    pub ar_mssd: f64,
    /// BOP average recall AR_MSPD.
    pub ar_mspd: f64,
}

/// Everything reported for one part (or all parts pooled).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PartSummary {
    /// Part name, or "all".
    pub part: String,
    /// Ground-truth instances counted (not ignored).
    pub truths: usize,
    /// Ground-truth instances ignored for low visibility.
    pub ignored: usize,
    /// Counted instances whose mask touches another.
    pub touching: usize,
    /// Detections of this part.
    pub detections: usize,
    /// Detections matched to a counted instance.
    pub true_positives: usize,
    /// Detections matched to nothing.
    pub false_positives: usize,
    /// true positives / (true positives + false positives).
    pub precision: f64,
    /// true positives / counted instances.
    pub recall: f64,
    /// Recall over the touching instances only.
    pub recall_touching: f64,
    /// Recall over the instances that touch nothing.
    pub recall_isolated: f64,
    /// Why the counted instances that were missed were missed.
    #[serde(default)]
    pub misses: MissCauses,
    /// The missed instances found as another part ([`MissCauses::wrong_part`]), by that part:
    /// which parts the detector confuses.
    #[serde(default)]
    pub found_as: BTreeMap<String, usize>,
    /// Why the detections matched to nothing are false positives.
    #[serde(default)]
    pub false_positive_causes: FalsePositiveCauses,
    /// Matched detections without a pose (PnP, refinement or the reprojection gate failed).
    pub pose_failures: usize,
    /// The pose failures by kind (the reason with its numbers replaced by `#`), most first.
    pub pose_failure_kinds: Vec<(String, usize)>,
    /// Counted instances not resting on the table (leaning on or lying on another part).
    #[serde(default)]
    pub not_resting: usize,
    /// Matched detections of those that still got a pose (left out of `refined`).
    #[serde(default)]
    pub not_resting_posed: usize,
    /// Matched detections of resting instances with a pose (what `refined` covers).
    pub poses: usize,
    /// Those poses within [`super::picks::ASSEMBLY_GRADE_MM`] and
    /// [`super::picks::ASSEMBLY_GRADE_DEG`] of the truth.
    #[serde(default)]
    pub assembly_grade: usize,
    /// Those poses confident enough for the cell to pick ([`EvalOptions::pick_confidence`]).
    #[serde(default)]
    pub pickable: usize,
    /// The pickable poses that are assembly-grade.
    #[serde(default)]
    pub pickable_assembly_grade: usize,
    /// The poses the cell would pick, by what they turned out to be.
    #[serde(default)]
    pub picks: Picks,
    /// Per frame and part, the most confident of those picks (the one the cell takes first),
    /// by what it turned out to be (`crowded` stays 0: a crowded pose is not a pick).
    #[serde(default)]
    pub first_picks: Picks,
    /// Raw PnP errors.
    pub raw: PoseStats,
    /// Errors after planar refinement, over the resting instances.
    pub refined: PoseStats,
    /// Matched poses of resting instances whose stable pose is the one the refiner gives the
    /// true pose.
    pub stable_pose_right: usize,
    /// `stable_pose_right / poses`.
    pub stable_pose_rate: f64,
}

/// Mean, median and p95 of one stage, ms.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StageSummary {
    /// Stage name.
    pub stage: String,
    /// Mean, ms.
    pub mean_ms: f64,
    /// Median, ms.
    pub median_ms: f64,
    /// 95th percentile, ms.
    pub p95_ms: f64,
}

/// The whole evaluation in numbers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EvalSummary {
    /// Images evaluated.
    pub frames: usize,
    /// Images on which the detector failed outright.
    pub frame_failures: usize,
    /// The first few of those failures.
    pub failure_examples: Vec<String>,
    /// Per part, in object-id order.
    pub parts: Vec<PartSummary>,
    /// All parts pooled.
    pub pooled: PartSummary,
    /// Table 1 rows per part: raw seed-style, raw all, refined seed-style, refined all.
    pub table1: Vec<Table1Entry>,
    /// Detection and posing by the stable pose the parts rest in.
    #[serde(default)]
    pub stable_poses: Vec<super::stable_poses::StablePoseRow>,
    /// Time per stage.
    pub stages: Vec<StageSummary>,
    /// Frames per second of the pipeline (1 / mean total time).
    pub frames_per_s: f64,
}

/// A failure reason with its numbers replaced by `#`, so that reasons of one kind count together.
pub fn failure_kind(reason: &str) -> String {
    let mut out = String::with_capacity(reason.len());
    let mut in_number = false;
    for c in reason.chars() {
        if c.is_ascii_digit() || (in_number && c == '.') {
            if !in_number {
                out.push('#');
                in_number = true;
            }
        } else {
            in_number = false;
            out.push(c);
        }
    }
    out
}

fn ratio(a: usize, b: usize) -> f64 {
    if b == 0 {
        f64::NAN
    } else {
        a as f64 / b as f64
    }
}

/// One estimate's errors against the truth (raw PnP, or refined) and its error up to the
/// part's near-symmetry.
struct Estimate<'a> {
    det: &'a DetectionRecord,
    errors: PoseErrors,
    flip: Option<f64>,
}

fn pose_stats(
    estimates: &[Estimate<'_>],
    counted_truths: usize,
    diameter_mm: &dyn Fn(&str) -> f64,
    options: &EvalOptions,
) -> PoseStats {
    let errors: Vec<PoseErrors> = estimates.iter().map(|e| e.errors).collect();
    let opts = |drop_outliers| SummaryOptions {
        drop_outliers,
        outlier_deg: options.outlier_deg,
    };
    let symmetry_flips = estimates
        .iter()
        .map(|e| (e.errors, e.flip))
        .filter(|(e, flip)| {
            e.sym_angle_deg > options.outlier_deg && flip.is_some_and(|f| f <= options.outlier_deg)
        })
        .count();
    let mssd_recall: Vec<f64> = MSSD_FRACTIONS
        .iter()
        .map(|f| {
            let hits = estimates
                .iter()
                .filter(|e| e.errors.mssd_mm < f * diameter_mm(&e.det.part))
                .count();
            ratio(hits, counted_truths)
        })
        .collect();
    let mspd_recall: Vec<f64> = MSPD_PX
        .iter()
        .map(|t| {
            let hits = estimates.iter().filter(|e| e.errors.mspd_px < *t).count();
            ratio(hits, counted_truths)
        })
        .collect();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    PoseStats {
        all: ErrorSummary::of(&errors, opts(false)),
        seed_style: ErrorSummary::of(&errors, opts(true)),
        symmetry_flips,
        ar_mssd: mean(&mssd_recall),
        ar_mspd: mean(&mspd_recall),
        mssd_recall,
        mspd_recall,
    }
}

/// Summarises one part (`Some(name)`) or all parts pooled (`None`).
fn part_summary(
    frames: &[FrameRecord],
    part: Option<&str>,
    diameter_mm: &dyn Fn(&str) -> f64,
    options: &EvalOptions,
) -> PartSummary {
    let mine = |p: &str| part.is_none_or(|n| n == p);
    let (mut truths, mut ignored, mut touching, mut recalled, mut recalled_touching) =
        (0, 0, 0, 0, 0);
    let (mut detections, mut tp, mut fp, mut pose_failures, mut stable_right) = (0, 0, 0, 0, 0);
    let (mut raw_estimates, mut refined_estimates) = (Vec::new(), Vec::new());
    let (mut not_resting, mut not_resting_posed) = (0, 0);
    let mut misses = MissCauses::default();
    let mut found_as: BTreeMap<String, usize> = BTreeMap::new();
    let mut fp_causes = FalsePositiveCauses::default();
    let (mut assembly_grade, mut pickable, mut pickable_assembly_grade) = (0, 0, 0);
    let pick_at = options.pick_confidence;
    let mut kinds: BTreeMap<String, usize> = Default::default();
    let (mut picks, mut first_picks) = (Picks::default(), Picks::default());
    for f in frames {
        // The cell takes the most confident pick of the part it needs.
        let mut first: BTreeMap<&str, &DetectionRecord> = BTreeMap::new();
        for t in f.truths.iter().filter(|t| mine(&t.part)) {
            if t.ignored {
                ignored += 1;
                continue;
            }
            truths += 1;
            touching += usize::from(t.touching);
            not_resting += usize::from(!t.resting);
            if t.detection.is_some() {
                recalled += 1;
                recalled_touching += usize::from(t.touching);
                continue;
            }
            let closest = t
                .closest
                .and_then(|c| f.detections.get(c.detection).map(|d| (&d.part, c.iou)));
            let cause = miss_cause(&t.part, closest, options.min_iou);
            *misses.slot(cause) += 1;
            if let (MissCause::WrongPart, Some((other, _))) = (cause, closest) {
                *found_as.entry(other.clone()).or_default() += 1;
            }
        }
        for d in f.detections.iter().filter(|d| mine(&d.part)) {
            detections += 1;
            match Picks::judge(d, &f.truths, pick_at, options.finger_margin) {
                Pickable::No => {}
                Pickable::Crowded => picks.crowded += 1,
                Pickable::Yes => {
                    picks.add(d, &f.truths);
                    let best = first.entry(&d.part).or_insert(d);
                    if d.confidence > best.confidence {
                        *best = d;
                    }
                }
            }
            let Some(t) = d.truth else {
                fp += 1;
                *fp_causes.slot(false_positive_cause(d, &f.truths, options.min_iou)) += 1;
                continue;
            };
            if f.truths[t].ignored {
                continue;
            }
            tp += 1;
            // Raw PnP counts for every estimate, also one the reprojection gate refused (the
            // paper's Table 1 is ungated); refined only for accepted poses.
            if let Some(raw) = d.raw {
                raw_estimates.push(Estimate {
                    det: d,
                    errors: raw,
                    flip: d.raw_flip_deg,
                });
            }
            match d.refined {
                // No planar estimate of a part off the table can be right: counted apart.
                Some(_) if !f.truths[t].resting => not_resting_posed += 1,
                Some(refined) => {
                    if d.stable_pose.is_some() && d.stable_pose == d.true_stable_pose {
                        stable_right += 1;
                    }
                    let good = is_assembly_grade(&refined, d.refined_flip_deg);
                    let picked = d.confidence.is_some_and(|c| c >= pick_at);
                    assembly_grade += usize::from(good);
                    pickable += usize::from(picked);
                    pickable_assembly_grade += usize::from(good && picked);
                    refined_estimates.push(Estimate {
                        det: d,
                        errors: refined,
                        flip: d.refined_flip_deg,
                    });
                }
                None => {
                    pose_failures += 1;
                    let reason = d.pose_failure.as_deref().unwrap_or("no pose given");
                    *kinds.entry(failure_kind(reason)).or_default() += 1;
                }
            }
        }
        for d in first.into_values() {
            first_picks.add(d, &f.truths);
        }
    }
    let raw = pose_stats(&raw_estimates, truths, diameter_mm, options);
    let refined = pose_stats(&refined_estimates, truths, diameter_mm, options);
    PartSummary {
        part: part.unwrap_or("all").into(),
        truths,
        ignored,
        touching,
        detections,
        true_positives: tp,
        false_positives: fp,
        precision: ratio(tp, tp + fp),
        recall: ratio(recalled, truths),
        recall_touching: ratio(recalled_touching, touching),
        recall_isolated: ratio(recalled - recalled_touching, truths - touching),
        misses,
        found_as,
        false_positive_causes: fp_causes,
        pose_failures,
        pose_failure_kinds: {
            let mut v: Vec<(String, usize)> = kinds.into_iter().collect();
            v.sort_by(|a, b| b.1.cmp(&a.1).then_with(|| a.0.cmp(&b.0)));
            v
        },
        not_resting,
        not_resting_posed,
        poses: refined_estimates.len(),
        assembly_grade,
        pickable,
        pickable_assembly_grade,
        picks,
        first_picks,
        raw,
        refined,
        stable_pose_right: stable_right,
        stable_pose_rate: ratio(stable_right, refined_estimates.len()),
    }
}

/// Summarises the frames for the parts `parts` (name, diameter in mm), in that order.
pub fn summarise(
    frames: &[FrameRecord],
    parts: &[(String, f64)],
    options: &EvalOptions,
) -> EvalSummary {
    let diameter = |name: &str| {
        parts
            .iter()
            .find(|(n, _)| n == name)
            .map_or(f64::NAN, |(_, d)| *d)
    };
    let per_part: Vec<PartSummary> = parts
        .iter()
        .map(|(n, _)| part_summary(frames, Some(n), &diameter, options))
        .collect();
    let pooled = part_summary(frames, None, &diameter, options);
    let mut table1 = Vec::new();
    for method in ["pnp", "refined"] {
        for dropped in [true, false] {
            let rows: Vec<Table1Row> = per_part
                .iter()
                .map(|p| {
                    let s = if method == "pnp" { &p.raw } else { &p.refined };
                    Table1Row::of(if dropped { &s.seed_style } else { &s.all })
                })
                .collect();
            for (p, row) in per_part.iter().zip(&rows) {
                table1.push(Table1Entry {
                    part: p.part.clone(),
                    method: method.into(),
                    outliers_dropped: dropped,
                    row: *row,
                });
            }
            table1.push(Table1Entry {
                part: "average".into(),
                method: method.into(),
                outliers_dropped: dropped,
                row: Table1Row::average(&rows),
            });
        }
    }
    let times: Vec<StageMs> = frames.iter().filter_map(|f| f.times).collect();
    let stages = StageMs::STAGES
        .iter()
        .map(|(name, get)| {
            let s = Summary::of(times.iter().map(get));
            StageSummary {
                stage: (*name).into(),
                mean_ms: s.mean,
                median_ms: s.p50,
                p95_ms: s.p95,
            }
        })
        .collect::<Vec<_>>();
    let mean_total = stages.last().map_or(f64::NAN, |s| s.mean_ms);
    let failures: Vec<&FrameRecord> = frames.iter().filter(|f| f.failure.is_some()).collect();
    EvalSummary {
        frames: frames.len(),
        frame_failures: failures.len(),
        failure_examples: failures
            .iter()
            .take(5)
            .map(|f| {
                format!(
                    "scene {} image {}: {}",
                    f.scene,
                    f.image,
                    f.failure.as_deref().unwrap_or_default()
                )
            })
            .collect(),
        parts: per_part,
        pooled,
        table1,
        stable_poses: super::stable_poses::stable_pose_rows(frames),
        stages,
        frames_per_s: 1e3 / mean_total,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::table1_text::text_table;
    use crate::eval::{DetectionOverlap, TruthOverlap, TruthRecord};

    fn errors(x: f64, angle: f64) -> PoseErrors {
        PoseErrors {
            x_mm: x,
            y_mm: x,
            z_mm: 10.0 * x,
            angle_deg: angle,
            sym_angle_deg: angle,
            add_mm: x,
            adds_mm: x,
            mssd_mm: x,
            mspd_px: 4.0 * x,
        }
    }

    fn truth(part: &str, detection: Option<usize>, touching: bool, ignored: bool) -> TruthRecord {
        TruthRecord {
            part: part.into(),
            visib_fract: if ignored { 0.05 } else { 0.9 },
            visible_px: 100,
            touching,
            ignored,
            resting: true,
            stable_pose: Some("+z".into()),
            detection,
            closest: None,
        }
    }

    fn det(part: &str, truth: Option<usize>, pose: Option<(f64, f64)>) -> DetectionRecord {
        DetectionRecord {
            part: part.into(),
            score: 0.9,
            crop_origin: [0, 0],
            keypoints_px: Vec::new(),
            keypoint_covariances_px: Vec::new(),
            truth,
            iou: truth.map(|_| 0.8),
            pose_failure: if pose.is_none() && truth.is_some() {
                Some("PnP failed".into())
            } else {
                None
            },
            raw: pose.map(|(x, a)| errors(x, a)),
            refined: pose.map(|(x, a)| errors(x / 2.0, a / 2.0)),
            stable_pose: pose.map(|_| "+z".into()),
            true_stable_pose: pose.map(|(_, a)| if a < 15.0 { "+z" } else { "-z" }.into()),
            raw_flip_deg: pose.map(|(_, a)| if a > 100.0 { 180.0 - a } else { a }),
            refined_flip_deg: pose.map(|(_, a)| a / 2.0),
            contour_support: None,
            confidence: None,
            keypoint_refined: None,
            pose: None,
            obj_id: None,
            closest_truth: None,
            graspable: false,
            finger_clearance_mm: None,
        }
    }

    /// Two frames: part "a" with 5 counted instances (2 touching), 1 ignored; part "b" with 1.
    fn frames() -> Vec<FrameRecord> {
        vec![
            FrameRecord {
                scene: 0,
                image: 0,
                failure: None,
                times: Some(StageMs {
                    preprocess: 1.0,
                    segment: 2.0,
                    instances: 1.0,
                    crops: 1.0,
                    keypoint_net: 3.0,
                    voting: 1.0,
                    pose: 1.0,
                    total: 10.0,
                }),
                truths: vec![
                    truth("a", Some(0), true, false),
                    truth("a", Some(1), true, false),
                    truth("a", Some(2), false, false),
                    truth("a", Some(4), false, true),
                    truth("b", None, false, false),
                ],
                detections: vec![
                    det("a", Some(0), Some((1.0, 2.0))),
                    det("a", Some(1), Some((3.0, 170.0))),
                    det("a", Some(2), None),
                    det("b", None, None),
                    det("a", Some(3), Some((9.0, 9.0))),
                ],
            },
            FrameRecord {
                scene: 0,
                image: 1,
                failure: Some("bad frame".into()),
                times: None,
                truths: vec![
                    truth("a", None, false, false),
                    truth("a", None, false, false),
                ],
                detections: vec![],
            },
        ]
    }

    /// The summary of one frame with these truths and detections, parts "a" and "b".
    fn one_frame(truths: Vec<TruthRecord>, detections: Vec<DetectionRecord>) -> EvalSummary {
        let frame = FrameRecord {
            scene: 0,
            image: 0,
            failure: None,
            times: None,
            truths,
            detections,
        };
        let parts = [("a".into(), 10.0), ("b".into(), 10.0)];
        summarise(&[frame], &parts, &EvalOptions::default())
    }

    #[test]
    fn misses_are_told_apart_by_the_detection_that_overlaps_them_most() {
        let missed = |closest: Option<(usize, f64)>| TruthRecord {
            closest: closest.map(|(detection, iou)| DetectionOverlap { detection, iou }),
            ..truth("a", None, true, false)
        };
        let s = one_frame(
            vec![
                truth("a", Some(0), true, false),
                missed(Some((1, 0.7))),
                missed(Some((1, 0.2))),
                missed(Some((0, 0.3))),
                missed(Some((2, 0.3))),
                missed(None),
            ],
            vec![
                det("a", Some(0), None),
                det("b", None, None),
                det("a", None, None),
            ],
        );
        let m = s.parts[0].misses;
        assert_eq!(
            (m.wrong_part, m.partial, m.covered, m.nothing),
            (1, 2, 1, 1),
            "{m:?}"
        );
        // The one found as the wrong part was found as "b"; the covered one is not counted.
        assert_eq!(s.parts[0].found_as, BTreeMap::from([("b".to_string(), 1)]));
        assert_eq!(s.pooled.found_as, s.parts[0].found_as);
        assert_eq!(s.parts[1].misses, MissCauses::default());
        assert!(s.parts[1].found_as.is_empty());
    }

    #[test]
    fn false_positives_are_told_apart_by_the_truth_that_overlaps_them_most() {
        let unmatched = |part: &str, closest: Option<(usize, f64)>| DetectionRecord {
            closest_truth: closest.map(|(truth, iou)| TruthOverlap { truth, iou }),
            ..det(part, None, None)
        };
        let s = one_frame(
            vec![
                truth("a", Some(0), true, false),
                truth("a", None, true, false),
                truth("b", None, true, false),
            ],
            vec![
                det("a", Some(0), None),
                unmatched("a", Some((0, 0.3))),
                unmatched("a", Some((1, 0.4))),
                unmatched("a", Some((2, 0.6))),
                unmatched("a", Some((2, 0.2))),
                unmatched("a", None),
                unmatched("b", Some((0, 0.2))),
            ],
        );
        let f = s.parts[0].false_positive_causes;
        assert_eq!(s.parts[0].false_positives, 5);
        assert_eq!(
            (
                f.wrong_part,
                f.duplicate,
                f.partial,
                f.straddling,
                f.nothing
            ),
            (1, 1, 1, 1, 1),
            "{f:?}"
        );
        let b = s.parts[1].false_positive_causes;
        assert_eq!((b.straddling, s.parts[1].false_positives), (1, 1));
        assert_eq!(s.pooled.false_positive_causes.straddling, 2);
    }

    #[test]
    fn detection_counts_precision_and_recall() {
        let s = summarise(
            &frames(),
            &[("a".into(), 10.0), ("b".into(), 10.0)],
            &EvalOptions::default(),
        );
        let a = &s.parts[0];
        assert_eq!((a.truths, a.ignored, a.touching), (5, 1, 2));
        // The detection on the ignored instance counts neither way.
        assert_eq!(
            (a.detections, a.true_positives, a.false_positives),
            (4, 3, 0)
        );
        assert!((a.precision - 1.0).abs() < 1e-12);
        assert!((a.recall - 3.0 / 5.0).abs() < 1e-12);
        assert!((a.recall_touching - 1.0).abs() < 1e-12);
        assert!((a.recall_isolated - 1.0 / 3.0).abs() < 1e-12);
        assert_eq!((a.poses, a.pose_failures), (2, 1));
        assert_eq!(a.pose_failure_kinds, vec![("PnP failed".to_string(), 1)]);
        assert_eq!(
            failure_kind("reprojection RMS 35.36 px exceeds the gate of 4.00 px."),
            "reprojection RMS # px exceeds the gate of # px."
        );
        let b = &s.parts[1];
        assert_eq!((b.truths, b.false_positives, b.recall), (1, 1, 0.0));
        assert_eq!(b.precision, 0.0);
        assert_eq!(s.pooled.truths, 6);
        assert_eq!(s.pooled.false_positives, 1);
        assert_eq!((s.frames, s.frame_failures), (2, 1));
        assert!(s.failure_examples[0].contains("image 1: bad frame"));
    }

    #[test]
    fn table1_counts_outliers_and_drops_them_only_seed_style() {
        let s = summarise(&frames(), &[("a".into(), 10.0)], &EvalOptions::default());
        let a = &s.parts[0];
        // Raw: angles 2° and 170° → one outlier, a symmetry flip (10° from the flipped truth).
        assert_eq!((a.raw.all.samples, a.raw.all.outliers), (2, 1));
        assert_eq!(a.raw.symmetry_flips, 1);
        assert!((a.raw.all.x_mm.mean - 2.0).abs() < 1e-12);
        assert!((a.raw.seed_style.x_mm.mean - 1.0).abs() < 1e-12);
        assert_eq!(a.raw.seed_style.x_mm.count, 1);
        // Refined halves everything: 1° and 85° → still one outlier, not a flip (85° away).
        assert_eq!((a.refined.all.outliers, a.refined.symmetry_flips), (1, 0));
        let row = |method: &str, dropped: bool| {
            s.table1
                .iter()
                .find(|e| e.part == "a" && e.method == method && e.outliers_dropped == dropped)
                .unwrap()
                .row
        };
        let r = row("pnp", false);
        assert_eq!((r.n, r.outliers), (2, 1));
        assert!((r.x_mm[0] - 2.0).abs() < 1e-12 && (r.x_mm[1] - 1.0).abs() < 1e-12);
        assert!((r.z_mm[0] - 20.0).abs() < 1e-12);
        assert!((r.angle_deg[0] - 86.0).abs() < 1e-12);
        let r = row("pnp", true);
        assert_eq!((r.n, r.outliers), (1, 1));
        assert!((r.angle_deg[0] - 2.0).abs() < 1e-12 && r.angle_deg[1] == 0.0);
        // Stable pose: the 2° estimate agrees ("+z"), the 170° one does not ("-z").
        assert_eq!(a.stable_pose_right, 1);
        assert!((a.stable_pose_rate - 0.5).abs() < 1e-12);
        // MSSD: raw 1 mm and 3 mm against a 10 mm diameter, over 5 counted instances.
        assert_eq!(a.raw.mssd_recall[0], 0.0, "0.5 mm threshold");
        assert_eq!(a.raw.mssd_recall[1], 0.0, "1.0 mm is not < 1.0 mm");
        assert!(
            (a.raw.mssd_recall[3] - 0.2).abs() < 1e-12,
            "2 mm: only the 1 mm one"
        );
        assert!((a.raw.mssd_recall[6] - 0.4).abs() < 1e-12, "3.5 mm: both");
        // MSPD: 4 px and 12 px.
        assert!((a.raw.mspd_recall[0] - 0.2).abs() < 1e-12);
        assert!((a.raw.mspd_recall[2] - 0.4).abs() < 1e-12);
        assert!((a.raw.ar_mspd - (0.2 + 0.2 + 8.0 * 0.4) / 10.0).abs() < 1e-12);
    }

    #[test]
    fn parts_off_the_table_keep_their_raw_pnp_but_leave_the_refined_rows() {
        let mut frames = frames();
        // The 170° estimate's truth leans on a neighbour.
        frames[0].truths[1].resting = false;
        let s = summarise(&frames, &[("a".into(), 10.0)], &EvalOptions::default());
        let a = &s.parts[0];
        assert_eq!((a.not_resting, a.not_resting_posed), (1, 1));
        assert_eq!(a.raw.all.samples, 2);
        assert_eq!((a.refined.all.samples, a.refined.all.outliers), (1, 0));
        assert_eq!((a.poses, a.stable_pose_right), (1, 1));
        assert!((a.stable_pose_rate - 1.0).abs() < 1e-12);
        // Detection counts do not change.
        assert_eq!((a.truths, a.true_positives, a.pose_failures), (5, 3, 1));
    }

    #[test]
    fn assembly_grade_poses_are_counted_with_and_without_the_pick_confidence() {
        let mut frames = frames();
        // Refined errors are half the given ones: 0.06 mm (0.085 mm laterally) at 0.4°, a
        // confident pose; 0.1 mm (0.14 mm laterally) at 0.4°, confident; 0.02 mm at 0.4°,
        // too unsure to pick.
        frames[0].detections = vec![
            det("a", Some(0), Some((0.12, 0.8))),
            det("a", Some(1), Some((0.2, 0.8))),
            det("a", Some(2), Some((0.04, 0.8))),
        ];
        for (d, c) in frames[0].detections.iter_mut().zip([0.9, 0.5, 0.1]) {
            d.confidence = Some(c);
        }
        let s = summarise(&frames, &[("a".into(), 10.0)], &EvalOptions::default());
        let a = &s.parts[0];
        assert_eq!(a.poses, 3);
        assert_eq!(a.assembly_grade, 2, "the 0.14 mm pose is not");
        assert_eq!((a.pickable, a.pickable_assembly_grade), (2, 1));
    }

    #[test]
    fn picks_are_told_apart_by_what_the_picked_part_turned_out_to_be() {
        let mut frame = frames().swap_remove(0);
        frame.truths = (0..5).map(|k| truth("a", Some(k), false, k == 4)).collect();
        frame.truths[3].resting = false;
        frame.detections = vec![
            // 0.085 mm laterally at 0.4°: assembly-grade.
            det("a", Some(0), Some((0.12, 0.8))),
            // 0.28 mm laterally: further off.
            det("a", Some(1), Some((0.4, 0.8))),
            // Taken for +z, truly −z.
            det("a", Some(2), Some((0.12, 20.0))),
            det("a", Some(3), Some((0.12, 0.8))),
            det("a", None, Some((0.12, 0.8))),
            // Not counted: an ignored instance, too unsure to pick, no grasp for its pose.
            det("a", Some(4), Some((0.12, 0.8))),
            det("a", Some(0), Some((0.12, 0.8))),
            det("a", Some(0), Some((0.12, 0.8))),
            // Assembly-grade, with 0.3 mm and 0.7 mm of room for the open fingers.
            det("a", Some(0), Some((0.12, 0.8))),
            det("a", Some(0), Some((0.12, 0.8))),
            // Another part, matched to nothing.
            det("b", None, Some((0.12, 0.8))),
        ];
        for (k, d) in frame.detections.iter_mut().enumerate() {
            // The first pick is the most confident: the ignored and the ungraspable ones are
            // no picks, so the 0.3 mm one, or without room for it the further-off one.
            d.confidence = Some(match k {
                5 | 7 => 0.999,
                8 => 0.99,
                1 => 0.95,
                6 => 0.1,
                _ => 0.9,
            });
            d.graspable = k != 7;
            d.finger_clearance_mm = [(8, 0.3), (9, 0.7)]
                .iter()
                .find_map(|&(i, c)| (i == k).then_some(c));
        }
        let parts = [("a".into(), 10.0)];
        let s = summarise(
            std::slice::from_ref(&frame),
            &parts,
            &EvalOptions::default(),
        );
        let picks = Picks {
            picks: 7,
            assembly_grade: 3,
            off: 1,
            wrong_stable_pose: 1,
            not_resting: 1,
            unmatched: 1,
            crowded: 0,
        };
        assert_eq!(s.parts[0].picks, picks, "room for the fingers not checked");
        let one = |slot: fn(&mut Picks) -> &mut usize| {
            let mut p = Picks {
                picks: 1,
                ..Picks::default()
            };
            *slot(&mut p) += 1;
            p
        };
        assert_eq!(s.parts[0].first_picks, one(|p| &mut p.assembly_grade));
        // Pooled, each part's first pick counts: part b's is matched to nothing.
        let pooled = &s.pooled.first_picks;
        assert_eq!(
            (pooled.picks, pooled.assembly_grade, pooled.unmatched),
            (2, 1, 1)
        );
        let options = EvalOptions {
            finger_margin: Some(0.0005),
            ..EvalOptions::default()
        };
        let s = summarise(&[frame], &parts, &options);
        let crowded = Picks {
            picks: 6,
            assembly_grade: 2,
            crowded: 1,
            ..picks
        };
        assert_eq!(s.parts[0].picks, crowded, "the 0.3 mm one has no room");
        assert_eq!(s.parts[0].first_picks, one(|p| &mut p.off));
    }

    #[test]
    fn averages_follow_the_seed_and_timing_is_summarised() {
        let rows = [
            Table1Row {
                n: 2,
                outliers: 1,
                x_mm: [1.0, 0.5],
                y_mm: [1.0, 0.5],
                z_mm: [10.0, 2.0],
                angle_deg: [2.0, 1.0],
            },
            Table1Row {
                n: 4,
                outliers: 0,
                x_mm: [3.0, 1.5],
                y_mm: [1.0, 0.5],
                z_mm: [30.0, 4.0],
                angle_deg: [4.0, 3.0],
            },
            Table1Row {
                n: 0,
                outliers: 2,
                x_mm: [f64::NAN; 2],
                y_mm: [f64::NAN; 2],
                z_mm: [f64::NAN; 2],
                angle_deg: [f64::NAN; 2],
            },
        ];
        let a = Table1Row::average(&rows);
        assert_eq!((a.n, a.outliers), (6, 3));
        assert_eq!(a.x_mm, [2.0, 1.0]);
        assert_eq!(a.z_mm, [20.0, 3.0]);
        let s = summarise(&frames(), &[("a".into(), 10.0)], &EvalOptions::default());
        let total = s.stages.iter().find(|t| t.stage == "total").unwrap();
        assert_eq!((total.mean_ms, total.median_ms), (10.0, 10.0));
        assert!((s.frames_per_s - 100.0).abs() < 1e-9);
        let text = text_table(&s);
        assert!(text.contains("ours PnP, all"));
        assert!(text.contains("2.00 ± 1.00"), "{text}");
    }
}
