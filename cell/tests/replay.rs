//! `cell replay`: one stored episode re-runs from its seed to the same record, prints its
//! timeline and draws its pictures.

mod support;

use support::{cell, text};

#[test]
fn a_failed_episode_replays_to_its_record_with_a_timeline_and_pictures() {
    let tmp = tempfile::tempdir().unwrap();
    let scenario = support::NoisyScenario::new("replay");
    let out = tmp.path().display().to_string();
    let o = cell(&[
        "run",
        &scenario.path().display().to_string(),
        "--episodes",
        "10",
        "--pictures",
        "0",
        "--out",
        &out,
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let dir = tmp.path().join("usbc-nominal/all");
    let records = std::fs::read_to_string(dir.join("episodes.jsonl")).unwrap();
    let failed = records
        .lines()
        .skip(1)
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .find(|r| {
            r["success"] == false
                && r["steps"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .any(|s| s.get("pose_error").is_some() && s["outcome"] != "seated")
        })
        .expect("a failed insertion in 10 episodes at 3 px");
    let e = failed["episode"].as_u64().unwrap();
    let o = cell(&[
        "replay",
        &dir.display().to_string(),
        "--episode",
        &e.to_string(),
    ]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(t.contains("the replay matches the stored record"), "{t}");
    assert!(
        t.contains("Capture → Perceive") && t.contains("Insert → Verify"),
        "{t}"
    );
    let pictures: Vec<String> = std::fs::read_dir(dir.join("pictures"))
        .unwrap()
        .map(|f| f.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    let stem = format!("episode-{e:06}-");
    assert!(
        pictures
            .iter()
            .any(|p| p.starts_with(&stem) && p.ends_with("-top.png")),
        "{pictures:?}"
    );
    assert!(
        pictures
            .iter()
            .any(|p| p.starts_with(&stem) && p.ends_with("-side.png")),
        "{pictures:?}"
    );
    assert!(
        pictures.contains(&format!("{stem}feeder.png")),
        "{pictures:?}"
    );
    // An episode that is not stored is named.
    let o = cell(&["replay", &dir.display().to_string(), "--episode", "99"]);
    assert!(!o.status.success());
    assert!(
        text(&o).contains("episode 99 is not stored"),
        "{}",
        text(&o)
    );
}
