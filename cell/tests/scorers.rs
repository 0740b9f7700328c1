//! `cell scorers`: the analytic and contact scorers compared on the nominal scenario's parts
//! loaded from the catalog, through the real binary.

mod support;

use support::{cell, nominal};

#[test]
fn compares_every_step_and_writes_the_disagreements() {
    let out = std::env::temp_dir().join(format!("cell_scorers_{}.json", std::process::id()));
    let out_arg = out.display().to_string();
    let scenario = nominal();
    let run = cell(&[
        "scorers",
        &scenario,
        "--samples",
        "60",
        "--min-agreement",
        "0.8",
        "--out",
        &out_arg,
    ]);
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&run.stderr)
    );
    for part in ["main_shell", "insert_mold", "top_shell"] {
        assert!(stdout.contains(part), "{stdout}");
    }
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap();
    std::fs::remove_file(&out).unwrap();
    let steps = json["steps"].as_array().unwrap();
    assert_eq!(steps.len(), 3);
    let samples: u64 = steps.iter().map(|s| s["samples"].as_u64().unwrap()).sum();
    assert_eq!(samples, 60);
    let disagreements: u64 = steps
        .iter()
        .map(|s| s["disagreements"].as_u64().unwrap())
        .sum();
    assert_eq!(
        disagreements as usize,
        json["disagreements"].as_array().unwrap().len()
    );
    // Near the boundary some insertions seat and some do not, for each step.
    for s in steps {
        let seated = s["seated"]["contact"].as_u64().unwrap();
        assert!(seated > 0 && seated < 20, "{s}");
    }
}

#[test]
fn a_minimum_above_the_measured_agreement_fails_and_bad_arguments_are_refused() {
    let scenario = nominal();
    let run = cell(&[
        "scorers",
        &scenario,
        "--samples",
        "30",
        "--min-agreement",
        "1.5",
    ]);
    assert!(!run.status.success());
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(
        stderr.contains("--min-agreement must be a fraction"),
        "{stderr}"
    );

    let run = cell(&["scorers", "no/such/scenario.toml"]);
    assert!(!run.status.success());
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(stderr.contains("no/such/scenario.toml"), "{stderr}");
}
