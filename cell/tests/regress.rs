//! The regression gate and runs through the real `cell` binary and the real simulated cell:
//! passes against the committed baseline, flags a real drop (a noisier camera), refuses invalid
//! scenarios before running, and sharded/resumed runs equal an uninterrupted one.

use std::path::Path;

mod support;

use support::{cell, nominal, root, text};

/// The nominal scenario copied to `dir` with absolute data paths and `edit` applied.
fn variant(dir: &Path, edit: (&str, &str)) -> String {
    let r = root();
    let src = std::fs::read_to_string(r.join("scenarios/usbc_nominal.toml")).unwrap();
    let out = src
        .replace(
            "\"parts/usbc.toml\"",
            &format!("{:?}", r.join("scenarios/parts/usbc.toml")),
        )
        .replace(
            "\"robots/ur5e.urdf\"",
            &format!("{:?}", r.join("scenarios/robots/ur5e.urdf")),
        )
        .replacen(edit.0, edit.1, 1);
    assert!(out.contains(edit.1));
    let path = dir.join("variant.toml");
    std::fs::write(&path, out).unwrap();
    path.display().to_string()
}

#[test]
fn regress_passes_on_the_nominal_cell_and_flags_a_noisier_camera() {
    let tmp = tempfile::tempdir().unwrap();
    let baselines = root().join("scenarios/baselines").display().to_string();
    let out = tmp.path().join("a").display().to_string();
    let o = cell(&[
        "regress",
        &nominal(),
        "--baseline",
        &baselines,
        "--episodes",
        "100",
        "--out",
        &out,
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("usbc-nominal: ok"), "{}", text(&o));

    // Keypoint noise 0.5 px → 3 px: a real drop through perception, PnP and insertion.
    let noisy = variant(
        tmp.path(),
        ("keypoint_noise_px = 0.5", "keypoint_noise_px = 3.0"),
    );
    let out = tmp.path().join("b").display().to_string();
    let o = cell(&[
        "regress",
        &noisy,
        "--baseline",
        &baselines,
        "--episodes",
        "100",
        "--out",
        &out,
        "--quiet",
    ]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let t = text(&o);
    assert!(t.contains("REGRESSED") && t.contains("DROP"), "{t}");
    assert!(t.contains("scenario file changed"), "{t}");
}

#[test]
fn an_invalid_scenario_never_starts_a_run() {
    let tmp = tempfile::tempdir().unwrap();
    let bad = variant(tmp.path(), ("episodes = 200", "episodes = \"many\""));
    let out = tmp.path().join("runs");
    let o = cell(&["run", &bad, "--out", &out.display().to_string(), "--quiet"]);
    assert!(!o.status.success());
    assert!(text(&o).contains("variant.toml:"), "{}", text(&o));
    assert!(!out.exists(), "an invalid scenario created results");
    let o = cell(&[
        "regress",
        &bad,
        "--baseline",
        &tmp.path().display().to_string(),
        "--quiet",
    ]);
    assert!(!o.status.success());
}

/// Records of a results file with the (non-deterministic) wall time removed.
fn records(file: &Path) -> Vec<serde_json::Value> {
    let text = std::fs::read_to_string(file).unwrap();
    let mut v: Vec<serde_json::Value> = text
        .lines()
        .skip(1)
        .map(|l| {
            let mut r: serde_json::Value = serde_json::from_str(l).unwrap();
            r.as_object_mut().unwrap().remove("wall_time_s");
            r
        })
        .collect();
    v.sort_by_key(|r| r["episode"].as_u64());
    v
}

#[test]
fn shards_and_resumes_equal_an_uninterrupted_run() {
    let tmp = tempfile::tempdir().unwrap();
    let s = nominal();
    let run = |out: &str, extra: &[&str]| {
        let mut args = vec![
            "run",
            s.as_str(),
            "--out",
            out,
            "--episodes",
            "30",
            "--quiet",
        ];
        args.extend_from_slice(extra);
        let o = cell(&args);
        assert!(o.status.success(), "{}", text(&o));
    };
    let whole = tmp.path().join("whole").display().to_string();
    run(&whole, &[]);
    let whole = records(&tmp.path().join("whole/usbc-nominal/all/episodes.jsonl"));
    assert_eq!(whole.len(), 30);

    let sharded = tmp.path().join("sharded").display().to_string();
    for shard in ["1/3", "2/3", "3/3"] {
        run(&sharded, &["--shard", shard]);
    }
    let merged = tmp.path().join("merged");
    let o = cell(&[
        "merge",
        &format!("{sharded}/usbc-nominal"),
        "--out",
        &merged.display().to_string(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(records(&merged.join("episodes.jsonl")), whole);
    assert!(merged.join("report.html").exists() && merged.join("summary.json").exists());

    // Resumed: 10 episodes, then the same run asked for 30.
    let resumed = tmp.path().join("resumed").display().to_string();
    let o = cell(&["run", &s, "--out", &resumed, "--episodes", "10", "--quiet"]);
    assert!(o.status.success(), "{}", text(&o));
    let o = cell(&["run", &s, "--out", &resumed, "--episodes", "30", "--quiet"]);
    assert!(
        text(&o).contains("ran 20 episodes") && text(&o).contains("(10 resumed)"),
        "{}",
        text(&o)
    );
    assert_eq!(
        records(&tmp.path().join("resumed/usbc-nominal/all/episodes.jsonl")),
        whole
    );
    let a = std::fs::read(tmp.path().join("resumed/usbc-nominal/all/summary.json")).unwrap();
    let b = std::fs::read(merged.join("summary.json")).unwrap();
    assert_eq!(a, b, "summaries of a resumed and a merged run differ");
}
