//! `cell eval` end to end with the committed models: a tiny full-resolution feeder split is
//! rendered at test time with `cell dataset`, evaluated, and the printed table and written files
//! are checked against accuracy bounds.

use std::path::{Path, PathBuf};
use std::process::Command;

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

fn cell(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_cell"))
        .current_dir(workspace())
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn cell_eval_on_a_rendered_feeder_split() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = tmp.path().join("ds");
    let out = tmp.path().join("eval");
    let ds_s = ds.to_str().unwrap();
    let made = cell(&[
        "dataset",
        "--out",
        ds_s,
        "--seed",
        "5",
        "--train-crops",
        "0",
        "--test-crops",
        "0",
        "--train-overviews",
        "0",
        "--test-overviews",
        "0",
        "--test-feeder",
        "2",
        "--camera-distance",
        "1.5",
        "--supersampling",
        "1",
        "--quiet",
    ]);
    assert!(
        made.status.success(),
        "cell dataset: {}",
        String::from_utf8_lossy(&made.stderr)
    );
    let run = cell(&[
        "eval",
        ds_s,
        "--out",
        out.to_str().unwrap(),
        "--gallery",
        "4",
        "--quiet",
    ]);
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "cell eval: {}\n{stdout}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(
        stdout.contains("seed paper, PnP") && stdout.contains("frames/s"),
        "{stdout}"
    );

    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("eval.json")).unwrap()).unwrap();
    assert_eq!(json["meta"]["split"], "test_feeder");
    // Picks are counted at the cell's default bar unless `--pick-confidence` says otherwise.
    assert_eq!(json["meta"]["options"]["pick_confidence"], 0.2);
    let s = &json["summary"];
    assert_eq!(s["frames"], 2);
    assert_eq!(s["frame_failures"], 0);
    let p = &s["pooled"];
    let f = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
    // Feeder frames hold 3–4 copies of each of the three parts.
    assert!(p["truths"].as_u64().unwrap() >= 12, "{p}");
    // Measured with the committed models on these two frames (seed 5): recall 95.2 % (20 of 21),
    // precision 100 % (the CPU-trained pair before them: 90.5 % each, 19 of 21).
    assert!(f(&p["recall"]) >= 0.9, "recall {}", p["recall"]);
    assert!(f(&p["precision"]) >= 0.9, "precision {}", p["precision"]);
    // Raw PnP is reported for every matched detection, also those whose pose the reprojection
    // gate refused (at the default 4 px gate most are, with their reason).
    let tp = p["true_positives"].as_u64().unwrap();
    assert_eq!(p["raw"]["all"]["samples"].as_u64(), Some(tp), "{p}");
    // Every miss and every false positive has exactly one cause.
    let causes = |v: &serde_json::Value| -> u64 {
        let counts = v.as_object().unwrap_or_else(|| panic!("{v}"));
        counts.values().map(|n| n.as_u64().unwrap()).sum()
    };
    assert_eq!(
        causes(&p["misses"]),
        p["truths"].as_u64().unwrap() - tp,
        "{p}"
    );
    let fp = p["false_positives"].as_u64().unwrap();
    assert_eq!(causes(&p["false_positive_causes"]), fp, "{p}");
    // Each match either has a pose (of a resting part, or of one leaning on another, counted
    // apart) or a failure.
    assert_eq!(
        p["poses"].as_u64().unwrap()
            + p["not_resting_posed"].as_u64().unwrap()
            + p["pose_failures"].as_u64().unwrap(),
        tp,
        "{p}"
    );
    // The rows by stable pose split exactly the resting instances, the poses and the right ones.
    let rows = s["stable_poses"].as_array().unwrap();
    let sum = |key: &str| -> u64 { rows.iter().map(|r| r[key].as_u64().unwrap()).sum() };
    let resting = p["truths"].as_u64().unwrap() - p["not_resting"].as_u64().unwrap();
    assert_eq!(sum("resting"), resting, "{rows:?}");
    assert_eq!(sum("posed"), p["poses"].as_u64().unwrap(), "{rows:?}");
    assert_eq!(
        sum("right"),
        p["stable_pose_right"].as_u64().unwrap(),
        "{rows:?}"
    );
    // Every pick is one of its kinds, and the assembly-grade ones are among the pickable
    // assembly-grade poses.
    let picks = &p["picks"];
    let n = picks["picks"].as_u64().unwrap();
    let crowded = picks["crowded"].as_u64().unwrap();
    assert_eq!(causes(picks) - n - crowded, n, "{picks}");
    assert!(
        picks["assembly_grade"].as_u64().unwrap() <= p["pickable_assembly_grade"].as_u64().unwrap(),
        "{p}"
    );
    let html = std::fs::read_to_string(out.join("eval.html")).unwrap();
    assert!(html.contains("Table 1") && html.contains("By stable pose") && html.contains("Picks"));
    // The gallery holds the 4 worst posed crops by MSSD (resting or not) and the ⌈4 / 3⌉ = 2
    // resting parts in the right stable pose worst placed in the plane (one picture for a
    // detection in both), the 2 worst detections without a pose and the ⌈4 / 2⌉ = 2 most
    // visible misses and highest-scoring false positives, as far as there are such (no
    // instance of these frames is ignored).
    assert_eq!(p["ignored"].as_u64(), Some(0), "{p}");
    let count = |key: &str| p[key].as_u64().unwrap() as usize;
    let posed = count("poses") + count("not_resting_posed");
    let unposed = count("pose_failures");
    let (missed, false_positives) = (count("truths") - count("true_positives"), fp as usize);
    let outlier_deg = json["meta"]["options"]["outlier_deg"].as_f64().unwrap();
    let (mut by_mssd, mut in_plane) = (Vec::new(), Vec::new());
    for (i, frame) in json["frames"].as_array().unwrap().iter().enumerate() {
        for (k, d) in frame["detections"].as_array().unwrap().iter().enumerate() {
            let (Some(e), Some(t)) = (
                d.get("refined").filter(|e| !e.is_null()),
                d["truth"].as_u64(),
            ) else {
                continue;
            };
            let f = |key: &str| e[key].as_f64().unwrap();
            by_mssd.push((f("mssd_mm"), (i, k)));
            if frame["truths"][t as usize]["resting"] == true
                && d["stable_pose"] == d["true_stable_pose"]
                && f("angle_deg") <= outlier_deg
            {
                in_plane.push((f("x_mm").hypot(f("y_mm")), (i, k)));
            }
        }
    }
    let worst = |mut v: Vec<(f64, (usize, usize))>, n: usize| {
        v.sort_by(|a, b| b.0.total_cmp(&a.0));
        v.into_iter().take(n).map(|(_, at)| at).collect::<Vec<_>>()
    };
    let mut pictured = worst(by_mssd, 4);
    pictured.extend(worst(in_plane, 2));
    pictured.sort();
    pictured.dedup();
    assert!(pictured.len() >= posed.min(4), "{p}");
    let gallery: Vec<_> = std::fs::read_dir(out.join("gallery")).unwrap().collect();
    assert_eq!(
        gallery.len(),
        pictured.len() + unposed.min(2) + missed.min(2) + false_positives.min(2),
        "{p}"
    );
    assert!(posed >= 1, "no pose passes the gate: {p}");
}

#[test]
fn a_missing_dataset_is_a_clear_error() {
    let tmp = tempfile::tempdir().unwrap();
    let missing = tmp.path().join("nothing");
    let run = cell(&["eval", missing.to_str().unwrap(), "--quiet"]);
    assert!(!run.status.success());
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(err.contains("nothing") && err.contains("split"), "{err}");
}

#[test]
fn a_pick_confidence_outside_0_to_1_is_refused() {
    let run = cell(&["eval", "ds", "--pick-confidence", "1.5", "--quiet"]);
    assert!(!run.status.success());
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(
        err.contains("--pick-confidence") && err.contains("between 0 and 1"),
        "{err}"
    );
}
