//! Detection and posing by the stable pose a part truly rests in: which ways up the learned
//! pipeline finds, poses and names right, and what it takes the others for. A pooled stable-pose
//! rate hides a way up that is never posed at all (its parts fail the reprojection gate and drop
//! out of every refined figure); this table shows it.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::FrameRecord;

/// One part resting in one stable pose, over all frames.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct StablePoseRow {
    /// Part name.
    pub part: String,
    /// The stable pose the parts truly rest in.
    pub stable_pose: String,
    /// Counted ground-truth instances resting in it.
    pub resting: usize,
    /// Those matched by a detection.
    pub found: usize,
    /// Those matched by a detection with a pose.
    pub posed: usize,
    /// Those posed in this stable pose.
    pub right: usize,
    /// The stable poses the others were posed in, with counts, most first.
    pub taken_for: Vec<(String, usize)>,
}

#[derive(Default)]
struct Tally {
    resting: usize,
    found: usize,
    posed: usize,
    right: usize,
    taken_for: BTreeMap<String, usize>,
}

/// The rows of every part and stable pose seen resting, parts by name and each part's stable
/// poses by how many parts rest in them (most first, then by name).
pub fn stable_pose_rows(frames: &[FrameRecord]) -> Vec<StablePoseRow> {
    let mut tallies: BTreeMap<(String, String), Tally> = BTreeMap::new();
    for f in frames {
        for t in f.truths.iter().filter(|t| !t.ignored && t.resting) {
            let Some(pose) = &t.stable_pose else { continue };
            let tally = tallies.entry((t.part.clone(), pose.clone())).or_default();
            tally.resting += 1;
            let Some(d) = t.detection.and_then(|d| f.detections.get(d)) else {
                continue;
            };
            tally.found += 1;
            if d.refined.is_none() {
                continue;
            }
            tally.posed += 1;
            match &d.stable_pose {
                Some(p) if p == pose => tally.right += 1,
                Some(p) => *tally.taken_for.entry(p.clone()).or_default() += 1,
                None => {}
            }
        }
    }
    let mut rows: Vec<StablePoseRow> = tallies
        .into_iter()
        .map(|((part, stable_pose), t)| {
            let mut taken_for: Vec<(String, usize)> = t.taken_for.into_iter().collect();
            taken_for.sort_by(|a, b| b.1.cmp(&a.1).then_with(|| a.0.cmp(&b.0)));
            StablePoseRow {
                part,
                stable_pose,
                resting: t.resting,
                found: t.found,
                posed: t.posed,
                right: t.right,
                taken_for,
            }
        })
        .collect();
    rows.sort_by(|a, b| {
        a.part
            .cmp(&b.part)
            .then_with(|| b.resting.cmp(&a.resting))
            .then_with(|| a.stable_pose.cmp(&b.stable_pose))
    });
    rows
}

/// The rows as text, one line per part and stable pose.
pub fn text(rows: &[StablePoseRow]) -> String {
    let mut s =
        String::from("by the stable pose parts rest in (resting / found / posed / posed in it):\n");
    for r in rows {
        let wrong: Vec<String> = r
            .taken_for
            .iter()
            .map(|(p, n)| format!("{n} × {p}"))
            .collect();
        s.push_str(&format!(
            "  {:<12} {:<12} {:>5} {:>5} {:>5} {:>5}{}\n",
            r.part,
            r.stable_pose,
            r.resting,
            r.found,
            r.posed,
            r.right,
            if wrong.is_empty() {
                String::new()
            } else {
                format!("  taken for {}", wrong.join(", "))
            }
        ));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::{DetectionRecord, TruthRecord};

    fn truth(pose: Option<&str>, detection: Option<usize>, ignored: bool) -> TruthRecord {
        TruthRecord {
            part: "mold".into(),
            visib_fract: 1.0,
            visible_px: 900,
            touching: false,
            ignored,
            resting: pose.is_some(),
            stable_pose: pose.map(Into::into),
            detection,
            closest: None,
        }
    }

    fn det(truth: usize, posed_as: Option<&str>) -> DetectionRecord {
        let errors = perception::metrics::PoseErrors {
            x_mm: 0.01,
            y_mm: 0.01,
            z_mm: 0.01,
            angle_deg: 0.1,
            sym_angle_deg: 0.1,
            add_mm: 0.01,
            adds_mm: 0.01,
            mssd_mm: 0.01,
            mspd_px: 0.1,
        };
        DetectionRecord {
            part: "mold".into(),
            score: 0.9,
            crop_origin: [0, 0],
            keypoints_px: Vec::new(),
            keypoint_covariances_px: Vec::new(),
            truth: Some(truth),
            iou: Some(0.9),
            pose_failure: posed_as.is_none().then(|| "reprojection RMS 30 px".into()),
            raw: Some(errors),
            refined: posed_as.map(|_| errors),
            stable_pose: posed_as.map(Into::into),
            true_stable_pose: None,
            raw_flip_deg: None,
            refined_flip_deg: None,
            contour_support: None,
            keypoint_refined: None,
            confidence: posed_as.map(|_| 0.9),
            pose: None,
            obj_id: None,
            closest_truth: None,
            graspable: false,
            finger_clearance_mm: None,
        }
    }

    #[test]
    fn each_way_up_counts_its_parts_found_posed_and_right() {
        let frame = FrameRecord {
            scene: 0,
            image: 0,
            failure: None,
            times: None,
            truths: vec![
                truth(Some("+z"), Some(0), false),
                truth(Some("+z"), Some(1), false),
                truth(Some("-z"), Some(2), false),
                truth(Some("-z"), Some(3), false),
                truth(Some("-z"), None, false),
                truth(Some("-z"), Some(4), true),
                truth(None, Some(5), false),
            ],
            detections: vec![
                det(0, Some("+z")),
                det(1, Some("-z")),
                det(2, None),
                det(3, Some("+z")),
                det(5, Some("+z")),
                det(6, Some("+z")),
            ],
        };
        let rows = stable_pose_rows(&[frame]);
        let row = |p: &str| rows.iter().find(|r| r.stable_pose == p).unwrap();
        // Ignored and off-the-table instances count nowhere; -z rests under the most parts.
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[0].stable_pose, "-z");
        let minus = row("-z");
        assert_eq!(
            (minus.resting, minus.found, minus.posed, minus.right),
            (3, 2, 1, 0)
        );
        assert_eq!(minus.taken_for, vec![("+z".to_string(), 1)]);
        let plus = row("+z");
        assert_eq!(
            (plus.resting, plus.found, plus.posed, plus.right),
            (2, 2, 2, 1)
        );
        assert!(text(&rows).contains("taken for 1 × -z"));
    }
}
