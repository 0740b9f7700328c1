//! Training smoke test: `cell dataset` writes a tiny crop + feeder set, training/smoke.py trains
//! both networks for two steps on it and exports them; the manifests must load as
//! `perception::onnx::manifest::ModelManifest`, match their ONNX files' checksums, list the
//! catalog's parts, and pass the cell's own checks of a model folder against its catalog. Run for
//! the USB-C catalog and for a two-part catalog, since the trainers take their parts from the
//! catalog. Runs only where torch is importable (training/.venv, else python3); otherwise it
//! prints "skipped: torch not present" (CI never installs torch).

use std::path::{Path, PathBuf};
use std::process::Command;

use perception::learned::LearnedModels;
use perception::onnx::manifest::ModelManifest;
use perception::part::{Catalog, PartRole};

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

/// Makes a tiny dataset of `catalog`, trains both nets on it for two steps into `out`, and checks
/// what they wrote against the catalog.
fn smoke(py: &Path, catalog: &Path, dir: &Path) {
    let data = dir.join("data");
    let status = Command::new(env!("CARGO_BIN_EXE_cell"))
        .current_dir(repo())
        .args(["dataset", "--out"])
        .arg(&data)
        .arg("--catalog")
        .arg(catalog)
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
            // Two frames, from two camera heights: `--fixed-scale` must make their range one scale.
            "--train-feeder",
            "2",
            "--test-feeder",
            "1",
            "--quiet",
        ])
        .status()
        .unwrap();
    assert!(status.success(), "cell dataset failed");
    let out = dir.join("models");
    let run = Command::new(py)
        .current_dir(repo().join("training"))
        .arg("smoke.py")
        .arg(&data)
        .arg(&out)
        .arg(catalog)
        .output()
        .unwrap();
    let log = format!(
        "{}\n{}",
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(run.status.success(), "smoke.py failed:\n{log}");
    assert!(log.contains("smoke: ok"), "{log}");
    let catalog = Catalog::load(catalog).unwrap();
    let parts: Vec<String> = catalog
        .parts
        .iter()
        .filter(|p| p.role != PartRole::Fixture)
        .map(|p| p.name.clone())
        .collect();
    for (name, input, outputs) in [
        ("keypoints", "crop", ["mask", "vectors"]),
        ("segmenter", "image", ["logits", "offsets"]),
    ] {
        let m = ModelManifest::load(&out.join(format!("{name}.toml"))).unwrap();
        assert_eq!(m.parts, parts);
        assert_eq!(m.name, format!("{}-{name}", catalog.name));
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
    let models = LearnedModels::in_dir(&out).expect("the folder passes the model contract");
    models
        .check_catalog(&catalog)
        .expect("the models handle the catalog's parts");
}

#[test]
fn smoke_trains_and_exports_both_networks() {
    let Some(py) = python_with_torch() else {
        println!("skipped: torch not present");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    smoke(&py, &repo().join("scenarios/parts/usbc.toml"), dir.path());
}

/// Parts with exact symmetries (the NIST pegs) are labelled by their twins: the keypoint net trains
/// against the nearer of two and reports its error to the nearest twin.
#[test]
fn smoke_trains_a_symmetric_catalog() {
    let Some(py) = python_with_torch() else {
        println!("skipped: torch not present");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    smoke(
        &py,
        &repo().join("scenarios/parts/nist_pegs.toml"),
        dir.path(),
    );
    let m = ModelManifest::load(&dir.path().join("models/keypoints.toml")).unwrap();
    let metrics = m
        .training
        .expect("trained models carry provenance")
        .test_metrics;
    assert!(
        metrics.contains_key("keypoint_px_median_nearest_twin"),
        "{metrics:?}"
    );
}

/// The trainers take the parts from the catalog: a product of two parts gets nets with two
/// one-hot planes and three segmenter classes, which the cell accepts for that catalog.
#[test]
fn smoke_trains_a_two_part_catalog() {
    let Some(py) = python_with_torch() else {
        println!("skipped: torch not present");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let parts_dir = repo().join("scenarios/parts").canonicalize().unwrap();
    let text = std::fs::read_to_string(parts_dir.join("usbc.toml")).unwrap();
    let mut doc: toml::Table = toml::from_str(&text).unwrap();
    doc.insert("name".into(), "pair".into());
    let toml::Value::Array(parts) = doc.remove("part").unwrap() else {
        panic!("usbc.toml has [[part]]");
    };
    let kept: Vec<toml::Value> = parts
        .into_iter()
        .filter(|p| p["name"].as_str() != Some("insert_mold"))
        .map(|mut p| {
            let mesh = parts_dir.join(p["mesh"].as_str().unwrap());
            p.as_table_mut()
                .unwrap()
                .insert("mesh".into(), mesh.to_string_lossy().into_owned().into());
            p
        })
        .collect();
    doc.insert("part".into(), toml::Value::Array(kept));
    let catalog = dir.path().join("pair.toml");
    std::fs::write(&catalog, toml::to_string(&doc).unwrap()).unwrap();
    smoke(&py, &catalog, dir.path());
    let m = ModelManifest::load(&dir.path().join("models/segmenter.toml")).unwrap();
    assert_eq!(m.parts, ["main_shell", "top_shell"]);
    assert_eq!(m.outputs[0].shape[1], 3, "background and two parts");
}
