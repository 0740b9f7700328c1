//! `cell parts prepare`: compute each part's keypoints, mass properties and stable poses, and
//! write them back into the catalog file, keeping its comments and hand-written keys.

use std::path::Path;

use indicatif::ProgressBar;
use nalgebra::Point3;
use perception::part::{
    ALIKE_WITHIN_REL, AlikePoses, Catalog, MeshRepairs, PartRole, PartSpec, StablePose, TriMesh,
    alike_stable_poses, farthest_point_sample, sample_surface,
};
use perception::symmetry::symmetry_group;
use sim::stable_poses::{DropEngine, DropSettings, StablePoseReport, stable_poses_with};
use toml_edit::{Array, ArrayOfTables, DocumentMut, Item, Table, value};

/// Surface samples the keypoints are chosen from.
const SURFACE_SAMPLES: usize = 20_000;

/// What preparing one part produced.
#[derive(Debug, Clone)]
pub struct PreparedPart {
    /// Part name.
    pub name: String,
    /// Mass in kg.
    pub mass: f64,
    /// Centre of mass, part frame, metres.
    pub center_of_mass: Point3<f64>,
    /// 8 FPS keypoints then the centre, metres.
    pub keypoints: Vec<Point3<f64>>,
    /// The drop statistics and classes.
    pub report: StablePoseReport,
    /// What loading repaired in the mesh file (warn the user about each).
    pub repairs: MeshRepairs,
    /// Pairs of the report's classes a camera cannot tell apart (warn the user about each).
    pub alike: Vec<AlikePoses>,
}

/// Errors of `prepare`.
#[derive(Debug, thiserror::Error)]
pub enum PrepareError {
    /// The catalog or a mesh could not be loaded.
    #[error(transparent)]
    Part(#[from] perception::part::PartError),
    /// The drop engine failed (MuJoCo missing, or a mesh it rejects).
    #[error(transparent)]
    Engine(#[from] sim::mujoco::MujocoError),
    /// The catalog could not be rewritten.
    #[error("{path}: {message}")]
    Write {
        /// The catalog file.
        path: String,
        /// What went wrong.
        message: String,
    },
}

/// The 9 keypoints of a mesh: 8 farthest-point samples of its surface, seeded from the
/// bounding-box centre (the part origin), then the centre itself.
pub fn keypoints(mesh: &perception::part::TriMesh, seed: u64) -> Vec<Point3<f64>> {
    let samples = sample_surface(mesh, SURFACE_SAMPLES, seed);
    let mut kp = farthest_point_sample(&samples, 8, Point3::origin());
    kp.push(Point3::origin());
    kp
}

/// Prepares one part: keypoints, mass properties, stable poses (dropped with rapier).
pub fn prepare_part(
    catalog: &Catalog,
    part: &PartSpec,
    settings: &DropSettings,
    progress: Option<&ProgressBar>,
) -> Result<PreparedPart, PrepareError> {
    prepare_part_with(DropEngine::Rapier, catalog, part, settings, progress)
}

/// [`prepare_part`] with the stable poses dropped by `engine`.
pub fn prepare_part_with(
    engine: DropEngine,
    catalog: &Catalog,
    part: &PartSpec,
    settings: &DropSettings,
    progress: Option<&ProgressBar>,
) -> Result<PreparedPart, PrepareError> {
    let (mesh, repairs) = catalog.load_mesh_repaired(part)?;
    prepare_loaded(engine, part, mesh, repairs, settings, progress)
}

/// Prepares one part from its loaded mesh.
fn prepare_loaded(
    engine: DropEngine,
    part: &PartSpec,
    mesh: TriMesh,
    repairs: MeshRepairs,
    settings: &DropSettings,
    progress: Option<&ProgressBar>,
) -> Result<PreparedPart, PrepareError> {
    let mut report = stable_poses_with(
        engine,
        &part.name,
        &mesh,
        part.density(),
        settings,
        progress,
    )?;
    // Twin classes merge into the one a grasp names (a peg's ends into its grasped end).
    report.merge_symmetric_keeping(&symmetry_group(&part.symmetries), |name| {
        part.grasp_for(name).is_some()
    });
    let poses: Vec<_> = report.classes.iter().map(|c| c.pose.clone()).collect();
    let tolerance = ALIKE_WITHIN_REL * mesh.extents().max();
    let alike = alike_stable_poses(
        &mesh,
        report.center_of_mass,
        &poses,
        &part.symmetries,
        tolerance,
    );
    Ok(PreparedPart {
        name: part.name.clone(),
        mass: report.mass,
        center_of_mass: report.center_of_mass,
        keypoints: keypoints(&mesh, settings.seed),
        report,
        repairs,
        alike,
    })
}

/// Prepares every non-fixture part of the catalog at `path` and rewrites the file atomically.
///
/// The parts drop with `settings` as given, and their drop height is recorded in the file; to
/// drop from the height the catalog records, pass `settings.with_catalog(&catalog)`.
///
/// Every mesh of the catalog (fixtures too) is loaded and checked before the first drop, so a
/// file that cannot be used fails at once, named with the catalog line that refers to it.
pub fn prepare_catalog(
    path: &Path,
    settings: &DropSettings,
    progress: Option<&ProgressBar>,
) -> Result<Vec<PreparedPart>, PrepareError> {
    prepare_catalog_with(DropEngine::Rapier, path, settings, progress)
}

/// [`prepare_catalog`] with the stable poses dropped by `engine`.
pub fn prepare_catalog_with(
    engine: DropEngine,
    path: &Path,
    settings: &DropSettings,
    progress: Option<&ProgressBar>,
) -> Result<Vec<PreparedPart>, PrepareError> {
    let catalog = Catalog::load(path)?;
    let mut loaded = Vec::new();
    for part in &catalog.parts {
        let (mesh, repairs) = catalog.load_mesh_repaired(part)?;
        if part.role != PartRole::Fixture {
            loaded.push((part, mesh, repairs));
        }
    }
    if let Some(p) = progress {
        p.set_length((loaded.len() * settings.drops) as u64);
    }
    let prepared = loaded
        .into_iter()
        .map(|(part, mesh, repairs)| {
            prepare_loaded(engine, part, mesh, repairs, settings, progress)
        })
        .collect::<Result<Vec<_>, _>>()?;
    let text = std::fs::read_to_string(path).map_err(|source| perception::part::PartError::Io {
        path: path.into(),
        source,
    })?;
    let updated = write_back(&text, &prepared, settings.drop_height).map_err(|message| {
        PrepareError::Write {
            path: path.display().to_string(),
            message,
        }
    })?;
    sim::fsutil::write_atomic(path, updated.as_bytes()).map_err(|e| PrepareError::Write {
        path: path.display().to_string(),
        message: e.to_string(),
    })?;
    Ok(prepared)
}

fn round(x: f64) -> f64 {
    (x * 1e9).round() / 1e9 + 0.0
}

fn vec3(v: [f64; 3]) -> Array {
    v.iter().map(|x| round(*x)).collect()
}

/// The catalog text with each prepared part's computed keys replaced, and the drop height the
/// stable poses were dropped from recorded (`drop_height`), so the file reproduces its table.
pub fn write_back(
    text: &str,
    prepared: &[PreparedPart],
    drop_height: f64,
) -> Result<String, String> {
    let mut doc: DocumentMut = text.parse().map_err(|e| format!("not valid TOML: {e}"))?;
    if let Some(recorded) = doc.get_mut("drop_height") {
        let recorded = recorded
            .as_value_mut()
            .ok_or("drop_height is not a value")?;
        let decor = recorded.decor().clone();
        *recorded = toml_edit::Value::from(drop_height);
        *recorded.decor_mut() = decor;
    } else {
        let mut height = toml_edit::Value::from(drop_height);
        height.decor_mut().set_prefix(" ");
        doc.insert("drop_height", Item::Value(height));
        if let Some(mut key) = doc.key_mut("drop_height") {
            key.leaf_decor_mut().set_prefix(
                "# Lowest point above the table when the stable-pose drops released each part, \
                 metres\n# (written by `cell parts prepare`, whose --drop-height changes it).\n",
            );
        }
    }
    let parts = doc
        .get_mut("part")
        .and_then(Item::as_array_of_tables_mut)
        .ok_or("the catalog has no [[part]] tables")?;
    for table in parts.iter_mut() {
        let name = table
            .get("name")
            .and_then(Item::as_str)
            .unwrap_or_default()
            .to_string();
        let Some(p) = prepared.iter().find(|p| p.name == name) else {
            continue;
        };
        table.insert("mass", value(round(p.mass)));
        table.insert(
            "center_of_mass",
            value(vec3(p.center_of_mass.coords.into())),
        );
        let mut kps = Array::new();
        for k in &p.keypoints {
            kps.push(vec3(k.coords.into()));
        }
        kps.set_trailing_comma(true);
        for (i, v) in kps.iter_mut().enumerate() {
            v.decor_mut()
                .set_prefix(if i == 0 { "\n  " } else { " \n  " }.trim_end_matches(' '));
        }
        kps.set_trailing("\n");
        table.insert("keypoints", value(kps));
        let mut poses = ArrayOfTables::new();
        for class in &p.report.classes {
            poses.push(stable_pose_table(&class.pose));
        }
        table.insert("stable_pose", Item::ArrayOfTables(poses));
    }
    Ok(doc.to_string())
}

fn stable_pose_table(s: &StablePose) -> Table {
    let mut t = Table::new();
    t.insert("name", value(s.name.clone()));
    t.insert("probability", value(round(s.probability)));
    t.insert("up_in_part", value(vec3(s.up_in_part)));
    t.insert("rotation", value(vec3(s.rotation)));
    t.insert("rest_height", value(s.rest_height));
    t
}
