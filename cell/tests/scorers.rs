//! `cell scorers`: the analytic and contact scorers compared on the nominal scenario's parts
//! loaded from the catalog, through the real binary.

use std::path::Path;
use std::process::Command;

fn cell() -> Command {
    Command::new(env!("CARGO_BIN_EXE_cell"))
}

fn nominal() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/usbc_nominal.toml")
}

#[test]
fn compares_every_step_and_writes_the_disagreements() {
    let out = std::env::temp_dir().join(format!("cell_scorers_{}.json", std::process::id()));
    let run = cell()
        .arg("scorers")
        .arg(nominal())
        .args(["--samples", "60", "--min-agreement", "0.8", "--out"])
        .arg(&out)
        .output()
        .unwrap();
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
        let seated = s["contact_seated"].as_u64().unwrap();
        assert!(seated > 0 && seated < 20, "{s}");
    }
}

#[test]
fn a_minimum_above_the_measured_agreement_fails_and_bad_arguments_are_refused() {
    let run = cell()
        .arg("scorers")
        .arg(nominal())
        .args(["--samples", "30", "--min-agreement", "1.5"])
        .output()
        .unwrap();
    assert!(!run.status.success());
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(
        stderr.contains("--min-agreement must be a fraction"),
        "{stderr}"
    );

    let run = cell()
        .arg("scorers")
        .arg("no/such/scenario.toml")
        .output()
        .unwrap();
    assert!(!run.status.success());
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(stderr.contains("no/such/scenario.toml"), "{stderr}");
}
