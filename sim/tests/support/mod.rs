//! The repository's nominal scenario (the parts of it the simulator reads) and its prepared part
//! catalog, shared by the sim tests and benches.

#![allow(dead_code)]

pub mod script;

use std::path::{Path, PathBuf};

use perception::part::Catalog;
use robots::ur_arm::UrArm;
use sim::config::{AssemblyStep, CellSpec, NoiseSpec};
use sim::scene::PartModel;

/// The simulator's share of a scenario file.
#[derive(Clone, serde::Deserialize)]
pub struct Nominal {
    /// The cell.
    pub cell: CellSpec,
    /// The assembly steps.
    pub assembly: Vec<AssemblyStep>,
    /// The error sources.
    pub noise: NoiseSpec,
}

/// The repository's `scenarios/` folder.
pub fn scenarios() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios")
}

/// `scenarios/usbc_nominal.toml`.
pub fn scenario() -> Nominal {
    let text = std::fs::read_to_string(scenarios().join("usbc_nominal.toml")).unwrap();
    toml::from_str(&text).unwrap()
}

/// The arm the nominal scenario's `cell.robot` describes.
pub fn arm() -> UrArm {
    UrArm::from_file(scenarios().join(scenario().cell.robot)).unwrap()
}

/// `scenarios/parts/usbc.toml` (committed prepared: keypoints and stable poses).
pub fn catalog() -> Catalog {
    Catalog::load(&scenarios().join("parts/usbc.toml")).unwrap()
}

/// The three USB-C parts of the catalog, ready for scenes and renders.
pub fn usbc_models() -> Vec<PartModel> {
    let names: Vec<String> = ["main_shell", "insert_mold", "top_shell"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    PartModel::from_catalog(&catalog(), &names).unwrap()
}
