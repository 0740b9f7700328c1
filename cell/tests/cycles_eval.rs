//! `cell eval` with the committed models on the committed Blender Cycles sets (issue 45): the
//! first feeder frames of the seed-2 test set rendered again by an independent, physically based
//! renderer (`scripts/cycles_render`), under soft light and under a hard off-axis key light with
//! blur and sensor noise. The sets are read as images: no Blender is needed. The bounds sit a
//! few instances below the figures measured on these exact files (cell/tests/fixtures/cycles/
//! README.md), so a regression of the models or the pipeline on renders that are not our own
//! fails here.

use std::path::{Path, PathBuf};
use std::process::Command;

use sha2::{Digest, Sha256};

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/cycles")
}

/// Runs `cell eval SET --max-rms-px 12` (the learned scenario's gate) and returns eval.json.
fn eval(look: &str) -> serde_json::Value {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("eval");
    let set = fixtures().join(look);
    let run = Command::new(env!("CARGO_BIN_EXE_cell"))
        .current_dir(workspace())
        .args([
            "eval",
            set.to_str().unwrap(),
            "--max-rms-px",
            "12",
            "--out",
            out.to_str().unwrap(),
            "--gallery",
            "0",
            "--quiet",
        ])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "cell eval {look}: {}\n{stdout}",
        String::from_utf8_lossy(&run.stderr)
    );
    serde_json::from_slice(&std::fs::read(out.join("eval.json")).unwrap()).unwrap()
}

/// What a look must reach: the figures measured on the committed set, less a few instances.
struct Bounds {
    frames: u64,
    min_precision: f64,
    min_recall: f64,
    max_wrong_part: u64,
    min_poses: u64,
    min_stable_pose_rate: f64,
    min_assembly_grade: f64,
    max_refined_xy_mm: f64,
}

fn check(look: &str, b: &Bounds) {
    let json = eval(look);
    let s = &json["summary"];
    assert_eq!(s["frames"].as_u64(), Some(b.frames), "{look}");
    assert_eq!(s["frame_failures"].as_u64(), Some(0), "{look}");
    let p = &s["pooled"];
    let f = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
    let u = |v: &serde_json::Value| v.as_u64().unwrap_or(u64::MAX);
    let (precision, recall) = (f(&p["precision"]), f(&p["recall"]));
    assert!(
        precision >= b.min_precision,
        "{look}: precision {precision} < {}",
        b.min_precision
    );
    assert!(
        recall >= b.min_recall,
        "{look}: recall {recall} < {}",
        b.min_recall
    );
    let wrong = u(&p["misses"]["wrong_part"]);
    assert!(
        wrong <= b.max_wrong_part,
        "{look}: {wrong} instances found as the wrong part > {}",
        b.max_wrong_part
    );
    let poses = u(&p["poses"]);
    assert!(
        poses >= b.min_poses && poses != u64::MAX,
        "{look}: {poses} resting parts posed < {}",
        b.min_poses
    );
    let stable = f(&p["stable_pose_rate"]);
    assert!(
        stable >= b.min_stable_pose_rate,
        "{look}: right stable pose {stable} < {}",
        b.min_stable_pose_rate
    );
    let grade = u(&p["assembly_grade"]) as f64 / poses as f64;
    assert!(
        grade >= b.min_assembly_grade,
        "{look}: assembly-grade share {grade} < {}",
        b.min_assembly_grade
    );
    // Refined x / y, outliers (θ > 10°) dropped, as the README's perception table reports them.
    let refined = &p["refined"]["seed_style"];
    for axis in ["x_mm", "y_mm"] {
        let e = f(&refined[axis]["mean"]);
        assert!(
            e <= b.max_refined_xy_mm,
            "{look}: refined |e_{}| {e} mm > {} mm",
            &axis[..1],
            b.max_refined_xy_mm
        );
    }
}

#[test]
fn the_cycles_sets_are_the_committed_renders() {
    // Every file the sets hold is listed with its sha256, and matches it: a set re-rendered
    // with other settings must come with new checksums and new bounds.
    let root = fixtures();
    let sums = std::fs::read_to_string(root.join("SHA256SUMS")).unwrap();
    let mut listed = 0;
    for (i, line) in sums.lines().enumerate() {
        let (hash, path) = line
            .split_once("  ")
            .unwrap_or_else(|| panic!("SHA256SUMS:{}: not `HASH  PATH`", i + 1));
        let bytes = std::fs::read(root.join(path))
            .unwrap_or_else(|e| panic!("SHA256SUMS:{}: {path}: {e}", i + 1));
        let got: String = Sha256::digest(&bytes)
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect();
        assert_eq!(got, hash, "{path}");
        listed += 1;
    }
    for look in ["soft", "hard"] {
        let rgb = root.join(look).join("test_feeder/000000/rgb");
        let n = std::fs::read_dir(&rgb).unwrap().count();
        assert!(n > 0, "{}", rgb.display());
        assert!(
            sums.lines()
                .filter(|l| l.contains(&format!("{look}/test_feeder/000000/rgb/")))
                .count()
                == n,
            "{look}: every rgb image is listed"
        );
        // The renderer's own record: bpy's version and the geometry check it passed.
        let record: serde_json::Value =
            serde_json::from_slice(&std::fs::read(root.join(look).join("cycles.json")).unwrap())
                .unwrap();
        assert_eq!(record["bpy"], "4.5.15");
        assert_eq!(record["look"], look);
        assert!(record["median_iou"].as_f64().unwrap() >= 0.98, "{record}");
    }
    assert!(listed > 0);
}

#[test]
fn cycles_soft_light() {
    // Measured on these 20 frames (212 instances) with the pair of 2026-11-30 (a cycle on the
    // randomisation families): precision 98.5 %, recall 92.5 %, 2 found as the wrong part, 72
    // resting parts posed, 98.6 % in the right stable pose, 81.9 % assembly-grade, refined
    // |e_x| / |e_y| 0.037 / 0.041 mm. The pair before (2026-11-27): 98.0 / 92.5 %, 4 wrong, 70
    // posed, 100 %, 77.1 %, 0.039 / 0.043 mm (95.0 / 90.6 %, 79.2 % when the sets were made).
    check(
        "soft",
        &Bounds {
            frames: 20,
            min_precision: 0.96,
            min_recall: 0.90,
            max_wrong_part: 5,
            min_poses: 66,
            min_stable_pose_rate: 0.96,
            min_assembly_grade: 0.75,
            max_refined_xy_mm: 0.05,
        },
    );
}

#[test]
fn cycles_hard_light_blur_and_noise() {
    // Measured on these 20 frames (212 instances) with the pair of 2026-11-30: precision 71.3 %,
    // recall 75.0 %, 14 found as the wrong part, 54 resting parts posed, 98.1 % in the right
    // stable pose, 18.5 % assembly-grade, refined |e_x| / |e_y| 0.185 / 0.183 mm. The pair
    // before: 55.1 / 66.0 %, 11 wrong, 43 posed, 86.0 %, 11.6 %, 0.271 / 0.283 mm. The key
    // light's long shadows still split and merge masks (20 misses) and hide parts under others'
    // instances (18): the 97 % is far off, and these bounds stop the models falling back.
    check(
        "hard",
        &Bounds {
            frames: 20,
            min_precision: 0.67,
            min_recall: 0.71,
            max_wrong_part: 18,
            min_poses: 47,
            min_stable_pose_rate: 0.94,
            min_assembly_grade: 0.14,
            max_refined_xy_mm: 0.22,
        },
    );
}
