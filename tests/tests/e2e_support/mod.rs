//! Shared set-up of the end-to-end tests: the nominal scenario, optionally edited, in a scratch
//! copy of `scenarios/` (so edits never touch the repository's files).

#![allow(dead_code)]

use std::ops::{Deref, DerefMut};
use std::path::{Path, PathBuf};

use cell::harness::SimSetup;
use cell::scenario::Scenario;
use tempfile::TempDir;

/// A simulated set-up whose scenario files live in a scratch folder.
pub struct Setup {
    inner: SimSetup,
    _dir: TempDir,
}

impl Deref for Setup {
    type Target = SimSetup;
    fn deref(&self) -> &SimSetup {
        &self.inner
    }
}

impl DerefMut for Setup {
    fn deref_mut(&mut self) -> &mut SimSetup {
        &mut self.inner
    }
}

/// Copies the folder `from` into `to`, recursively.
pub fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).unwrap();
        }
    }
}

/// The repository's `scenarios/` folder when its catalog is prepared; otherwise a copy with the
/// catalog prepared by `cell::prepare` (physics drops, about a minute), cached in the test
/// target folder per catalog text so the test binaries prepare it once.
pub fn prepared_scenarios() -> PathBuf {
    let root = cell_tests::repo_root().join("scenarios");
    let catalog_path = root.join("parts/usbc.toml");
    let text = std::fs::read_to_string(&catalog_path).unwrap();
    let catalog = perception::part::Catalog::parse(&text, &catalog_path).unwrap();
    let needs = catalog
        .parts
        .iter()
        .any(|p| p.role != perception::part::PartRole::Fixture && !p.is_prepared());
    if !needs {
        return root;
    }
    // FNV-1a of the catalog text names the cache.
    let hash = text.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    });
    let cache = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("scenarios-{hash:016x}"));
    if cache.join("parts/usbc.toml").exists() {
        return cache;
    }
    let scratch = cache.with_extension(format!("tmp{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&scratch);
    copy_dir(&root, &scratch);
    cell::prepare::prepare_catalog(
        &scratch.join("parts/usbc.toml"),
        &sim::stable_poses::DropSettings::default(),
        None,
    )
    .unwrap();
    // Another test binary may have finished first: either copy is the same.
    if std::fs::rename(&scratch, &cache).is_err() {
        let _ = std::fs::remove_dir_all(&scratch);
    }
    cache
}

/// The nominal scenario with `edit` applied to the scenario file and `edit_catalog` to the
/// part catalog.
pub fn scenario_with(
    edit: impl FnOnce(&mut toml_edit::DocumentMut),
    edit_catalog: impl FnOnce(&mut toml_edit::DocumentMut),
) -> Setup {
    let (dir, scenario) = load_with(edit, edit_catalog);
    let scenario = scenario.unwrap_or_else(|e| panic!("{e}"));
    let inner = SimSetup::new(scenario).unwrap_or_else(|e| panic!("{e}"));
    Setup { inner, _dir: dir }
}

/// The nominal scenario with `edit` applied to the scenario file and `edit_catalog` to the part
/// catalog, as `Scenario::load` reads it (its refusals included), and the scratch folder that
/// holds it.
pub fn load_with(
    edit: impl FnOnce(&mut toml_edit::DocumentMut),
    edit_catalog: impl FnOnce(&mut toml_edit::DocumentMut),
) -> (TempDir, Result<Scenario, cell::scenario::ScenarioError>) {
    let dir = tempfile::tempdir().unwrap();
    copy_dir(&prepared_scenarios(), dir.path());
    let path = dir.path().join("usbc_nominal.toml");
    let mut doc: toml_edit::DocumentMut = std::fs::read_to_string(&path).unwrap().parse().unwrap();
    edit(&mut doc);
    std::fs::write(&path, doc.to_string()).unwrap();
    let catalog = dir.path().join("parts/usbc.toml");
    let mut cat: toml_edit::DocumentMut =
        std::fs::read_to_string(&catalog).unwrap().parse().unwrap();
    edit_catalog(&mut cat);
    std::fs::write(&catalog, cat.to_string()).unwrap();
    let scenario = Scenario::load(&path);
    (dir, scenario)
}

/// The nominal scenario with `edit` applied.
pub fn setup(edit: impl FnOnce(&mut toml_edit::DocumentMut)) -> Setup {
    scenario_with(edit, |_| {})
}

/// Makes every instance of `part` come to rest in stable pose `pose`: that class gets
/// probability 1, every other 0.
pub fn all_in_pose(catalog: &mut toml_edit::DocumentMut, part: &str, pose: &str) {
    let parts = catalog["part"].as_array_of_tables_mut().unwrap();
    let p = parts
        .iter_mut()
        .find(|t| t["name"].as_str() == Some(part))
        .unwrap();
    let poses = p["stable_pose"].as_array_of_tables_mut().unwrap();
    assert!(
        poses.iter().any(|s| s["name"].as_str() == Some(pose)),
        "no stable pose {pose}"
    );
    for s in poses.iter_mut() {
        let v = if s["name"].as_str() == Some(pose) {
            1.0
        } else {
            0.0
        };
        s["probability"] = toml_edit::value(v);
    }
}
