//! `cell run --robot` through the real binary: the simulated cell behind the virtual UR
//! controller over loopback RTDE gives the in-process run's outcomes and writes the same
//! results and report; a real controller without the opt-in is refused before anything
//! connects; malformed robot values are refused with what was expected. Loopback only.

use std::net::TcpListener;
use std::path::Path;

mod support;

use support::{cell, nominal, text};

/// The episode records of a results file (the header line skipped).
fn records(dir: &Path) -> Vec<serde_json::Value> {
    let text = std::fs::read_to_string(dir.join("usbc-nominal/all/episodes.jsonl")).unwrap();
    let mut lines = text.lines();
    let header: serde_json::Value = serde_json::from_str(lines.next().unwrap()).unwrap();
    assert_eq!(header["format"], "cell-episodes");
    let mut out: Vec<serde_json::Value> = lines.map(|l| serde_json::from_str(l).unwrap()).collect();
    out.sort_by_key(|r| r["episode"].as_u64());
    out
}

/// What must agree between robots: success and each step's part, outcome, picks and shakes.
fn outcomes(r: &serde_json::Value) -> serde_json::Value {
    let steps: Vec<serde_json::Value> = r["steps"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| serde_json::json!([s["part"], s["outcome"], s["attempts"], s["shakes"]]))
        .collect();
    serde_json::json!({"episode": r["episode"], "success": r["success"], "steps": steps})
}

#[test]
fn a_virtual_ur_run_matches_the_sim_run_and_writes_the_same_results() {
    let tmp = tempfile::tempdir().unwrap();
    let scenario = nominal();
    let vur_out = tmp.path().join("vur");
    let sim_out = tmp.path().join("sim");
    let o = cell(&[
        "run",
        &scenario,
        "--robot",
        "virtual-ur",
        "--episodes",
        "2",
        "--out",
        &vur_out.display().to_string(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("of 2 episodes assembled"), "{}", text(&o));
    let o = cell(&[
        "run",
        &scenario,
        "--episodes",
        "2",
        "--out",
        &sim_out.display().to_string(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", text(&o));

    // The same files as a sim run: results, summary, report, one event log per episode.
    let shard = |root: &Path| root.join("usbc-nominal/all");
    for f in [
        "episodes.jsonl",
        "summary.json",
        "report.html",
        "events/episode-000000.jsonl",
        "events/episode-000001.jsonl",
    ] {
        assert!(shard(&vur_out).join(f).is_file(), "{f} missing");
        assert!(
            shard(&sim_out).join(f).is_file(),
            "{f} missing in the sim run"
        );
    }
    let (remote, local) = (records(&vur_out), records(&sim_out));
    assert_eq!(remote.len(), 2);
    for (r, l) in remote.iter().zip(&local) {
        assert_eq!(r["abort"], serde_json::Value::Null, "{r}");
        assert_eq!(outcomes(r), outcomes(l));
    }
    let summary = |root: &Path| -> serde_json::Value {
        let t = std::fs::read_to_string(shard(root).join("summary.json")).unwrap();
        serde_json::from_str(&t).unwrap()
    };
    let (rs, ls) = (summary(&vur_out), summary(&sim_out));
    assert_eq!(rs["episodes"], 2);
    assert_eq!(rs["successes"], ls["successes"]);
    assert_eq!(rs["scenario_sha256"], ls["scenario_sha256"]);
}

#[test]
fn a_real_controller_without_the_opt_in_is_refused_before_connecting() {
    // A listener where the "controller" would be: nothing may connect to it.
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    listener.set_nonblocking(true).unwrap();
    let port = listener.local_addr().unwrap().port();
    let robot = format!("ur://127.0.0.1:{port}");
    let tmp = tempfile::tempdir().unwrap();
    let out_dir = tmp.path().join("runs");
    let (scenario, out) = (nominal(), out_dir.display().to_string());
    // `cell run` on that controller with `extra` options.
    let run_on = |extra: &[&str]| {
        let mut args = vec!["run", &scenario, "--robot", &robot, "--out", &out];
        args.extend_from_slice(extra);
        cell(&args)
    };
    let o = run_on(&["--episodes", "1", "--quiet"]);
    assert!(!o.status.success());
    let t = text(&o);
    assert!(
        t.contains("refusing to run on") && t.contains("--allow-motion"),
        "{t}"
    );

    // With the opt-in and a camera source, the scenario's keypoint-noise perception is
    // refused: it cannot read camera images.
    let camera = tmp.path().join("camera");
    std::fs::create_dir(&camera).unwrap();
    std::fs::write(camera.join("frame-0001.png"), b"not looked at").unwrap();
    let camera = camera.display().to_string();
    let o = run_on(&[
        "--allow-motion",
        "--camera",
        &camera,
        "--episodes",
        "1",
        "--quiet",
    ]);
    assert!(!o.status.success());
    let t = text(&o);
    assert!(
        t.contains("keypoint-noise perception") && t.contains("camera images"),
        "{t}"
    );

    // The opt-in without a camera source is refused too.
    let o = run_on(&["--allow-motion"]);
    assert!(!o.status.success());
    assert!(text(&o).contains("--camera"), "{}", text(&o));

    match listener.accept() {
        Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {}
        Ok((_, peer)) => panic!("{peer} connected to the controller port"),
        Err(e) => panic!("accept: {e}"),
    }
    assert!(!out_dir.exists(), "a refused run wrote results");
}

#[test]
fn malformed_robot_values_are_refused_with_what_was_expected() {
    let scenario = nominal();
    for (bad, why) in [
        ("kuka", "unknown robot"),
        ("ur://", "no host"),
        ("ur://10.0.0.1:0", "port must be"),
        ("ur://10.0.0.1:http", "port must be"),
        ("ur://bad host", "letters, digits"),
        ("ur://[::1", "unclosed '['"),
        ("virtual_ur", "unknown robot"),
    ] {
        let o = cell(&["run", &scenario, "--robot", bad, "--episodes", "1"]);
        assert_eq!(o.status.code(), Some(2), "{bad}: {}", text(&o));
        let t = text(&o);
        assert!(
            t.contains("sim, virtual-ur or ur://HOST[:PORT]") && t.contains(why),
            "{bad}: {t}"
        );
    }
    // --allow-motion means nothing to a simulated robot: refused, not silently ignored.
    let o = cell(&["run", &scenario, "--allow-motion", "--episodes", "1"]);
    assert!(!o.status.success());
    assert!(text(&o).contains("real controller"), "{}", text(&o));
}
