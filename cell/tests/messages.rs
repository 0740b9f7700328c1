//! Messages a new user meets: each error names the file, the place and the fix, `check` refuses
//! what `run` would, and both say the same thing about the same file.

mod support;

use std::path::{Path, PathBuf};

use cell::scenario::Scenario;
use support::{cell, text};

fn scenarios() -> PathBuf {
    support::root().join("scenarios")
}

fn nominal_text() -> String {
    std::fs::read_to_string(scenarios().join("usbc_nominal.toml")).unwrap()
}

/// A file beside the nominal scenario (so relative paths resolve), removed when dropped.
struct Temp(PathBuf);

impl Temp {
    fn new(dir: &Path, name: &str, bytes: &[u8]) -> Self {
        let path = dir.join(format!(".msg_{}_{name}", std::process::id()));
        std::fs::write(&path, bytes).unwrap();
        Self(path)
    }
}

impl Drop for Temp {
    fn drop(&mut self) {
        std::fs::remove_file(&self.0).ok();
    }
}

fn line_of(text: &str, needle: &str) -> usize {
    text.lines()
        .position(|l| l.contains(needle))
        .expect("needle")
        + 1
}

/// `cell check` and `cell run` on the same file: both fail, and run's error holds check's text.
fn check_and_run(path: &Path) -> (String, String) {
    let p = path.display().to_string();
    let out = tempfile::tempdir().unwrap();
    let o = out.path().display().to_string();
    let check = cell(&["check", &p]);
    let run = cell(&["run", &p, "--out", &o, "--quiet"]);
    assert!(!check.status.success() && !run.status.success());
    // Nothing was written for a refused scenario.
    assert_eq!(std::fs::read_dir(out.path()).unwrap().count(), 0);
    (text(&check), text(&run))
}

#[test]
fn an_invalid_scenario_prints_each_error_once_and_the_same_from_check_and_run() {
    let t = nominal_text().replace("name = \"usbc-nominal\"", "name = \"usbc-nominal\" = 3");
    let f = Temp::new(&scenarios(), "eq.toml", t.as_bytes());
    let (check, run) = check_and_run(&f.0);
    let message = check.trim();
    assert!(
        message.contains(&format!("{}:4:", f.0.display())),
        "{check}"
    );
    assert!(run.contains(message), "{run}");
    assert_eq!(run.matches(message).count(), 1, "printed twice: {run}");

    // Binary garbage: one located error, the same from both.
    let garbage: Vec<u8> = (0..4000u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8 | 0x80)
        .collect();
    let f = Temp::new(&scenarios(), "bin.toml", &garbage);
    let (check, run) = check_and_run(&f.0);
    assert!(check.contains("not UTF-8 text"), "{check}");
    assert!(run.contains(check.trim()), "check: {check}\nrun: {run}");
}

#[test]
fn learned_perception_without_usable_models_is_refused_by_check_at_its_line() {
    // No models named: refused at the mode.
    let t = nominal_text().replace("mode = \"keypoint-noise\"", "mode = \"learned\"");
    let f = Temp::new(&scenarios(), "learned.toml", t.as_bytes());
    let err = Scenario::load(&f.0).unwrap_err();
    let p = &err.0[0];
    assert_eq!(p.key.as_deref(), Some("perception.mode"), "{err}");
    assert_eq!(p.line, line_of(&t, "mode = \"learned\""), "{err}");
    assert!(p.message.contains("models"), "{err}");
    assert!(!p.message.contains("Learned"), "{err}");
    let (_, run) = check_and_run(&f.0);
    assert!(run.contains("perception.mode"), "{run}");
    // A models folder that does not exist: refused at `models`, naming the folder.
    let t = nominal_text().replace(
        "mode = \"keypoint-noise\"",
        "mode = \"learned\"\nmodels = \"models/nowhere\"",
    );
    let f = Temp::new(&scenarios(), "learned_nowhere.toml", t.as_bytes());
    let err = Scenario::load(&f.0).unwrap_err();
    let p = &err.0[0];
    assert_eq!(p.key.as_deref(), Some("perception.models"), "{err}");
    assert_eq!(p.line, line_of(&t, "models = \"models/nowhere\""), "{err}");
    assert!(p.message.contains("nowhere"), "{err}");
}

#[test]
fn a_reprojection_gate_that_is_not_positive_is_refused_at_its_line() {
    for bad in ["0.0", "-3.0", "nan"] {
        let t = nominal_text().replace(
            "mode = \"keypoint-noise\"",
            &format!("mode = \"keypoint-noise\"\nmax_rms_px = {bad}"),
        );
        let f = Temp::new(&scenarios(), "gate.toml", t.as_bytes());
        let err = Scenario::load(&f.0).unwrap_err();
        let p = err
            .0
            .iter()
            .find(|p| p.key.as_deref() == Some("perception.max_rms_px"))
            .unwrap_or_else(|| panic!("{bad}: {err}"));
        assert_eq!(p.line, line_of(&t, "max_rms_px"), "{err}");
        assert!(p.message.contains("must be positive"), "{err}");
    }
}

#[test]
fn an_input_scale_that_is_no_scale_is_refused_at_its_line() {
    for bad in ["-1.5", "\"scaled\""] {
        let t = nominal_text().replace(
            "mode = \"keypoint-noise\"",
            &format!("mode = \"keypoint-noise\"\ninput_scale = {bad}"),
        );
        let f = Temp::new(&scenarios(), "scale.toml", t.as_bytes());
        let err = Scenario::load(&f.0).unwrap_err();
        let p = &err.0[0];
        assert_eq!(p.line, line_of(&t, "input_scale"), "{bad}: {err}");
        assert!(
            p.message.contains("positive number of pixels per mm"),
            "{bad}: {err}"
        );
    }
}

#[test]
fn a_camera_that_cannot_see_the_feeder_or_resolve_the_parts_is_refused() {
    let pose = "base_T_camera = { translation = [0.0, -0.45, 1.51], rotation = [3.141592653589793, 0.0, 0.0] }";
    assert!(nominal_text().contains(pose));
    let cases = [
        // Looking at the ceiling.
        (
            "base_T_camera = { translation = [0.0, -0.45, 1.51], rotation = [0.0, 0.0, 0.0] }",
            "behind the camera",
        ),
        // Looking down, but 0.5 m to the side: the feeder is outside the image.
        (
            "base_T_camera = { translation = [0.5, -0.45, 1.51], rotation = [3.141592653589793, 0.0, 0.0] }",
            "outside the 5472 × 3648 image",
        ),
        // Straight down from 5 m: all in view, but the 25 mm lens sees the ~9 mm parts over
        // fewer than 24 pixels.
        (
            "base_T_camera = { translation = [0.0, -0.45, 5.0], rotation = [3.141592653589793, 0.0, 0.0] }",
            "pixels",
        ),
    ];
    for (replacement, expected) in cases {
        let t = nominal_text().replace(pose, replacement);
        let f = Temp::new(&scenarios(), "camera.toml", t.as_bytes());
        let err = Scenario::load(&f.0).unwrap_err();
        let p = err
            .0
            .iter()
            .find(|p| p.key.as_deref() == Some("cell.camera.base_T_camera"))
            .unwrap_or_else(|| panic!("{err}"));
        assert!(p.message.contains(expected), "{err}");
        assert_eq!(p.line, line_of(&t, "base_T_camera ="), "{err}");
    }
}

#[test]
fn type_errors_and_duplicate_keys_name_what_was_expected() {
    let t = nominal_text().replace("episodes = 200", "episodes = \"many\"");
    let f = Temp::new(&scenarios(), "type.toml", t.as_bytes());
    let err = Scenario::load(&f.0).unwrap_err().to_string();
    assert!(err.contains("expected a whole number"), "{err}");
    assert!(!err.contains("u32"), "{err}");

    let t = nominal_text().replace("seed = 7", "seed = 7\nseed = 8");
    let f = Temp::new(&scenarios(), "dup.toml", t.as_bytes());
    let err = Scenario::load(&f.0).unwrap_err();
    assert!(err.0[0].message.contains("duplicate key `seed`"), "{err}");
    assert_eq!(err.0[0].line, line_of(&t, "seed = 8"), "{err}");
}

#[test]
fn a_mesh_that_cannot_be_loaded_names_the_catalog_line_the_file_and_why() {
    let parts = scenarios().join("parts");
    let catalog = std::fs::read_to_string(parts.join("usbc.toml")).unwrap();
    let binary: Vec<u8> = (0..3000u32).map(|i| (i * 7 + 200) as u8).collect();
    let cases: [(&str, &[u8], &str); 4] = [
        ("missing.obj", b"", "cannot read"),
        ("binary.obj", &binary, "byte 0 is not text"),
        (
            "text.obj",
            b"v 0 0 0\nhello world\n",
            "line 2: \"hello\" is not an OBJ statement",
        ),
        ("binary.stl", &binary, "bytes 80..84 say"),
    ];
    for (name, bytes, why) in cases {
        let mesh = Temp::new(&parts, name, bytes);
        if bytes.is_empty() {
            std::fs::remove_file(&mesh.0).unwrap();
        }
        let mesh_name = mesh.0.file_name().unwrap().to_str().unwrap().to_string();
        let cat = catalog.replacen(
            "mesh = \"main_shell.obj\"",
            &format!("mesh = \"{mesh_name}\""),
            1,
        );
        let cat_file = Temp::new(&parts, "catalog.toml", cat.as_bytes());
        let cat_name = cat_file.0.file_name().unwrap().to_str().unwrap();
        let t = nominal_text().replace(
            "catalog = \"parts/usbc.toml\"",
            &format!("catalog = \"parts/{cat_name}\""),
        );
        let f = Temp::new(&scenarios(), "mesh.toml", t.as_bytes());
        let err = Scenario::load(&f.0).unwrap_err().to_string();
        let at = format!(
            "{}:{}:8: part \"main_shell\"",
            cat_file.0.display(),
            line_of(&cat, &mesh_name)
        );
        assert!(err.contains(&at), "{err}\nwanted {at}");
        assert!(err.contains(&mesh.0.display().to_string()), "{err}");
        assert!(err.contains(why), "{err}");
    }
}

#[test]
fn shards_count_from_one_and_merge_refuses_a_missing_shard_unless_allowed() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().display().to_string();
    let nominal = support::nominal();
    let run = |shard: &str| {
        let o = cell(&[
            "run",
            &nominal,
            "--episodes",
            "4",
            "--shard",
            shard,
            "--out",
            &root,
            "--quiet",
        ]);
        assert!(o.status.success(), "{}", text(&o));
    };
    run("2/2");
    assert!(
        tmp.path()
            .join("usbc-nominal/shard-2-of-2/episodes.jsonl")
            .is_file()
    );
    let zero = cell(&["run", &nominal, "--shard", "0/2", "--out", &root]);
    assert!(!zero.status.success());
    assert!(text(&zero).contains("count from 1"), "{}", text(&zero));

    let scenario_dir = tmp.path().join("usbc-nominal").display().to_string();
    let merged = tmp.path().join("merged").display().to_string();
    let o = cell(&["merge", &scenario_dir, "--out", &merged]);
    assert!(!o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains("1 of 2 shards missing: 1/2 (folder shard-1-of-2)")
            && text(&o).contains("--allow-partial"),
        "{}",
        text(&o)
    );
    let o = cell(&["merge", &scenario_dir, "--out", &merged, "--allow-partial"]);
    assert!(o.status.success(), "{}", text(&o));
    run("1/2");
    let o = cell(&["merge", &scenario_dir, "--out", &merged]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("of 4 episodes succeeded"), "{}", text(&o));
}

#[test]
fn a_shorter_rerun_says_what_its_report_covers_and_one_episode_is_singular() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().display().to_string();
    let nominal = support::nominal();
    let run = |n: &str| cell(&["run", &nominal, "--episodes", n, "--out", &root, "--quiet"]);
    let o = run("1");
    assert!(text(&o).contains("ran 1 episode in"), "{}", text(&o));
    assert!(text(&o).contains("of 1 episode assembled"), "{}", text(&o));
    assert!(run("3").status.success());
    let o = run("2");
    assert!(o.status.success());
    assert!(
        text(&o).contains("1 episode more from an earlier, longer run")
            && text(&o).contains("cover episodes 0..2 only")
            && text(&o).contains("--episodes 3"),
        "{}",
        text(&o)
    );
}

#[test]
fn results_of_another_robot_are_refused() {
    use cell::run::{LoadedScenario, ResultsStore, Shard, StoreError};
    let l = LoadedScenario::load(&scenarios().join("usbc_nominal.toml")).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    ResultsStore::open(tmp.path(), l.header(Shard::ALL)).unwrap();
    let err =
        ResultsStore::open(tmp.path(), l.header(Shard::ALL).with_robot("virtual-ur")).unwrap_err();
    assert!(
        matches!(err, StoreError::Foreign { field: "robot", .. }),
        "{err}"
    );
    assert!(
        err.to_string()
            .contains("robot is sim, this run has virtual-ur"),
        "{err}"
    );
}

#[test]
fn help_shows_the_typical_flow_one_command_a_line() {
    let o = cell(&["--help"]);
    let t = text(&o);
    for command in ["cell check ", "cell run ", "cell replay ", "cell regress "] {
        assert!(
            t.lines().any(|l| l.trim_start().starts_with(command)),
            "{command} not on a line of its own:\n{t}"
        );
    }
}

#[test]
fn learned_models_for_other_parts_are_refused_by_check_at_their_line() {
    let models = tempfile::tempdir().unwrap();
    let from = scenarios().join("models/usbc");
    for name in ["segmenter", "keypoints"] {
        std::fs::copy(
            from.join(format!("{name}.onnx")),
            models.path().join(format!("{name}.onnx")),
        )
        .unwrap();
        let manifest = std::fs::read_to_string(from.join(format!("{name}.toml"))).unwrap();
        let other = manifest.replace(
            "parts = [\"main_shell\", \"insert_mold\", \"top_shell\"]",
            "parts = [\"lid\", \"gasket\", \"base\"]",
        );
        assert_ne!(other, manifest, "{name}.toml names the catalog's parts");
        std::fs::write(models.path().join(format!("{name}.toml")), other).unwrap();
    }
    let line = format!("models = {:?}", models.path().display().to_string());
    let t = nominal_text().replace(
        "mode = \"keypoint-noise\"",
        &format!("mode = \"learned\"\n{line}"),
    );
    let f = Temp::new(&scenarios(), "learned_other.toml", t.as_bytes());
    let err = Scenario::load(&f.0).unwrap_err();
    let p = &err.0[0];
    assert_eq!(p.key.as_deref(), Some("perception.models"), "{err}");
    assert_eq!(p.line, line_of(&t, &line), "{err}");
    assert!(p.message.contains("lid"), "{err}");
}
