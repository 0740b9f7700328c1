//! A BOP split opened against the part catalog: per part the keypoints, surface samples,
//! symmetries, stable poses and grasps evaluation needs, and each image's camera.

use std::collections::BTreeMap;
use std::path::Path;

use nalgebra::{Point3, Unit, UnitQuaternion, Vector3};
use perception::contour::PartOutline;
use perception::part::{Catalog, PartRole, ROUND_WITHIN_M, StablePose, round_axes};
use perception::symmetry::{ambiguity_group, symmetry_group, view_turns};
use perception::{Camera, Distortion};
use sim::dataset::{BopDataset, BopImage, BopScene, SceneCamera};

use super::{EvalError, EvalOptions};

/// The split read when none is named: full-resolution feeder windows.
pub const DEFAULT_SPLIT: &str = "test_feeder";
/// The split read when [`DEFAULT_SPLIT`] does not exist: the reduced-scale overview test images.
pub const FALLBACK_SPLIT: &str = "test";

/// What evaluation needs of one part.
#[derive(Debug, Clone)]
pub struct PartData {
    /// Catalog name.
    pub name: String,
    /// BOP object id (catalog index + 1, as `cell dataset` writes them).
    pub obj_id: u32,
    /// Model keypoints, part frame, metres.
    pub keypoints: Vec<Point3<f64>>,
    /// Surface samples for the distance metrics, part frame, metres.
    pub points: Vec<Point3<f64>>,
    /// Exact symmetry group (what the metrics and the refiner use).
    pub group: Vec<UnitQuaternion<f64>>,
    /// Group of every declared symmetry, exact or not: an error within the outlier angle of a
    /// near-symmetric equivalent is a symmetry flip.
    pub near_group: Vec<UnitQuaternion<f64>>,
    /// Axes about which the part is round ([`perception::part::round_axes`]): a turn about one
    /// is no error.
    pub round_axes: Vec<Unit<Vector3<f64>>>,
    /// Stable poses, in the order classes refer to.
    pub stable_poses: Vec<StablePose>,
    /// Per stable pose, the turns under which the part looks the same from above
    /// ([`perception::part::ViewSymmetry`]; the identity alone for most).
    pub view_turns: Vec<Vec<UnitQuaternion<f64>>>,
    /// The stable poses the cell has a grasp for (the catalog's `grasp`s): the ways up it picks.
    pub graspable: Vec<String>,
    /// Diameter from models_info.json, mm.
    pub diameter_mm: f64,
    /// Outline model of its mesh, to draw the true and estimated outlines in the gallery.
    pub outline: PartOutline,
}

/// A BOP split opened for evaluation against a catalog.
#[derive(Debug, Clone)]
pub struct EvalDataset {
    /// The dataset (cameras, ground truth, scenes).
    pub bop: BopDataset,
    /// The split read.
    pub split: String,
    /// Parts by BOP object id.
    pub parts: BTreeMap<u32, PartData>,
}

/// The split to read: `requested`, or [`DEFAULT_SPLIT`] when it exists, else [`FALLBACK_SPLIT`].
pub fn resolve_split(root: &Path, requested: Option<&str>) -> String {
    match requested {
        Some(s) => s.to_string(),
        None if root.join(DEFAULT_SPLIT).is_dir() => DEFAULT_SPLIT.into(),
        None => FALLBACK_SPLIT.into(),
    }
}

impl EvalDataset {
    /// Opens split `split` of the dataset at `root` for the parts of `catalog` (object id =
    /// catalog index + 1); checks that each object's model size matches the catalog mesh.
    pub fn open(
        root: &Path,
        split: &str,
        catalog: &Catalog,
        options: &EvalOptions,
    ) -> Result<Self, EvalError> {
        options.validate()?;
        let split_dir = root.join(split);
        if !split_dir.is_dir() {
            return Err(EvalError::Mismatch {
                path: split_dir,
                message: "no such split folder (name one with --split)".into(),
            });
        }
        let bop = BopDataset::load(root, split)?;
        let models_info = root.join("models").join("models_info.json");
        let mut parts = BTreeMap::new();
        for (&obj_id, info) in &bop.models {
            let mismatch = |message: String| EvalError::Mismatch {
                path: models_info.clone(),
                message,
            };
            let spec = obj_id
                .checked_sub(1)
                .and_then(|i| catalog.parts.get(i as usize))
                .ok_or_else(|| {
                    mismatch(format!(
                        "object {obj_id} has no part in catalog {} ({} parts)",
                        catalog.file.display(),
                        catalog.parts.len()
                    ))
                })?;
            if spec.role == PartRole::Fixture {
                return Err(mismatch(format!(
                    "object {obj_id} is {}, a fixture in catalog {}",
                    spec.name,
                    catalog.file.display()
                )));
            }
            let part_err = |message: String| EvalError::Part {
                part: spec.name.clone(),
                message,
            };
            let mesh = catalog
                .load_mesh(spec)
                .map_err(|e| part_err(e.to_string()))?;
            let (lo, hi) = mesh.aabb();
            let size = (hi - lo) * 1000.0;
            for (axis, ours, theirs) in [
                ("x", size.x, info.size_x),
                ("y", size.y, info.size_y),
                ("z", size.z, info.size_z),
            ] {
                if (ours - theirs).abs() > 0.01 {
                    return Err(mismatch(format!(
                        "object {obj_id}: size_{axis} is {theirs:.3} mm but part {} of catalog {} \
                         measures {ours:.3} mm: the dataset was made from another catalog",
                        spec.name,
                        catalog.file.display()
                    )));
                }
            }
            if spec.keypoints.len() < 4 || spec.stable_poses.is_empty() {
                return Err(part_err(format!(
                    "not prepared (keypoints and stable poses); run `cell parts prepare {}`",
                    catalog.file.display()
                )));
            }
            parts.insert(
                obj_id,
                PartData {
                    name: spec.name.clone(),
                    obj_id,
                    keypoints: spec.keypoint_points(),
                    points: perception::part::sample_surface(&mesh, options.model_points, 1),
                    group: symmetry_group(&spec.symmetries),
                    near_group: ambiguity_group(&spec.symmetries),
                    round_axes: round_axes(&mesh, &spec.symmetries, ROUND_WITHIN_M),
                    stable_poses: spec.stable_poses.clone(),
                    view_turns: spec
                        .stable_poses
                        .iter()
                        .map(|s| view_turns(s, spec.view_order(&s.name)))
                        .collect(),
                    graspable: spec
                        .stable_poses
                        .iter()
                        .filter(|s| spec.grasp_for(&s.name).is_some())
                        .map(|s| s.name.clone())
                        .collect(),
                    diameter_mm: info.diameter,
                    outline: PartOutline::new(&mesh),
                },
            );
        }
        Ok(Self {
            bop,
            split: split.into(),
            parts,
        })
    }

    /// Images of the split, in scene and image order.
    pub fn images(&self) -> impl Iterator<Item = (&BopScene, &BopImage)> {
        self.bop
            .scenes
            .iter()
            .flat_map(|s| s.images.iter().map(move |i| (s, i)))
    }

    /// Part names in object-id order.
    pub fn part_names(&self) -> Vec<String> {
        self.parts.values().map(|p| p.name.clone()).collect()
    }
}

/// The camera of an image from its scene_camera.json entry.
pub fn camera_of(cam: &SceneCamera) -> Result<Camera, String> {
    let k = &cam.cam_K;
    if k[1] != 0.0 || k[3] != 0.0 || k[6] != 0.0 || k[7] != 0.0 || k[8] != 1.0 {
        return Err(format!("cam_K {k:?} is not [fx 0 cx; 0 fy cy; 0 0 1]"));
    }
    let d = cam.dist_coeffs;
    Camera::new(
        k[0],
        k[4],
        k[2],
        k[5],
        cam.width,
        cam.height,
        Distortion {
            k1: d[0],
            k2: d[1],
            p1: d[2],
            p2: d[3],
            k3: d[4],
        },
    )
    .map_err(|e| e.to_string())
}
