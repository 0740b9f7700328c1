//! Training smoke test: `cell dataset` writes a tiny crop + feeder set, training/smoke.py trains
//! both networks for two steps on it and exports them; the manifests must load as
//! `perception::onnx::manifest::ModelManifest` and match their ONNX files' checksums.
//! Runs only where torch is importable (training/.venv, else python3); otherwise it prints
//! "skipped: torch not present" (CI never installs torch).

use std::path::{Path, PathBuf};
use std::process::Command;

use perception::onnx::manifest::ModelManifest;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// A Python that can import torch, onnx and PIL, if there is one.
fn python_with_torch() -> Option<PathBuf> {
    let candidates = [
        repo().join("training/.venv/bin/python"),
        PathBuf::from("python3"),
    ];
    candidates.into_iter().find(|py| {
        Command::new(py)
            .args(["-c", "import torch, onnx, PIL, numpy"])
            .output()
            .map(|o| o.status.success())
            .unwrap_or(false)
    })
}

#[test]
fn smoke_trains_and_exports_both_networks() {
    let Some(py) = python_with_torch() else {
        println!("skipped: torch not present");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    let status = Command::new(env!("CARGO_BIN_EXE_cell"))
        .current_dir(repo())
        .args(["dataset", "--out"])
        .arg(&data)
        .args([
            "--seed",
            "5",
            "--train-crops",
            "2",
            "--test-crops",
            "1",
            "--train-overviews",
            "0",
            "--test-overviews",
            "0",
            "--train-feeder",
            "1",
            "--test-feeder",
            "1",
            "--quiet",
        ])
        .status()
        .unwrap();
    assert!(status.success(), "cell dataset failed");
    let out = dir.path().join("models");
    let run = Command::new(&py)
        .current_dir(repo().join("training"))
        .arg("smoke.py")
        .arg(&data)
        .arg(&out)
        .output()
        .unwrap();
    let log = format!(
        "{}\n{}",
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(run.status.success(), "smoke.py failed:\n{log}");
    assert!(log.contains("smoke: ok"), "{log}");
    for (name, input, outputs) in [
        ("keypoints", "crop", ["mask", "vectors"]),
        ("segmenter", "image", ["logits", "offsets"]),
    ] {
        let m = ModelManifest::load(&out.join(format!("{name}.toml"))).unwrap();
        assert_eq!(m.parts, ["main_shell", "insert_mold", "top_shell"]);
        assert_eq!(m.opset, 17);
        assert_eq!(m.inputs[0].name, input);
        let names: Vec<&str> = m.outputs.iter().map(|o| o.name.as_str()).collect();
        assert_eq!(names, outputs);
        let bytes = std::fs::read(m.model_path()).unwrap();
        use sha2::Digest;
        let sha: String = sha2::Sha256::digest(&bytes)
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect();
        assert_eq!(sha, m.sha256, "{name}: manifest checksum");
        let training = m.training.expect("trained models carry provenance");
        assert!(out.join(&training.curve).is_file());
        assert!(training.test_metrics.contains_key(if name == "keypoints" {
            "mask_iou"
        } else {
            "instance_recall"
        }));
    }
}
