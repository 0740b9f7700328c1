//! Reading a BOP dataset back: cameras, models, per-scene ground truth, images on demand.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use nalgebra::Isometry3;

use super::DatasetError;
use super::bop::{BopCamera, GtInfo, GtPose, ModelInfo, SceneCamera, pose_from_bop};
use super::files::read_json;

/// One image of a scene with its ground truth.
#[derive(Debug, Clone, PartialEq)]
pub struct BopImage {
    /// Image id within the scene.
    pub id: usize,
    /// Its camera.
    pub camera: SceneCamera,
    /// Ground-truth poses.
    pub gt: Vec<GtPose>,
    /// Ground-truth visibility and boxes.
    pub info: Vec<GtInfo>,
}

/// One scene folder.
#[derive(Debug, Clone, PartialEq)]
pub struct BopScene {
    /// Folder path.
    pub dir: PathBuf,
    /// Scene id.
    pub id: usize,
    /// Images in id order.
    pub images: Vec<BopImage>,
}

/// A BOP dataset: camera.json, models_info.json and the scenes of one split.
#[derive(Debug, Clone, PartialEq)]
pub struct BopDataset {
    /// Root folder.
    pub root: PathBuf,
    /// camera.json.
    pub camera: BopCamera,
    /// models_info.json by object id.
    pub models: BTreeMap<u32, ModelInfo>,
    /// The split's scenes in id order.
    pub scenes: Vec<BopScene>,
}

impl BopDataset {
    /// Loads the dataset at `root`, split folder `split` (e.g. "train_pbr"), checking that every
    /// image has ground truth, every object id has a model, rotations are rotations.
    pub fn load(root: &Path, split: &str) -> Result<Self, DatasetError> {
        let camera: BopCamera = read_json(&root.join("camera.json"))?;
        let models_path = root.join("models").join("models_info.json");
        let models_raw: BTreeMap<String, ModelInfo> = read_json(&models_path)?;
        let mut models = BTreeMap::new();
        for (k, v) in models_raw {
            let id = k.parse().map_err(|_| DatasetError::Format {
                path: models_path.clone(),
                message: format!("object id {k:?} is not an integer"),
            })?;
            models.insert(id, v);
        }
        let split_dir = root.join(split);
        let mut scene_dirs: Vec<(usize, PathBuf)> = std::fs::read_dir(&split_dir)
            .map_err(|e| DatasetError::io(&split_dir, e))?
            .filter_map(|e| e.ok())
            .filter_map(|e| {
                let name = e.file_name().to_str()?.parse::<usize>().ok()?;
                Some((name, e.path()))
            })
            .collect();
        scene_dirs.sort();
        let mut scenes = Vec::new();
        for (id, dir) in scene_dirs {
            let cams: BTreeMap<String, SceneCamera> = read_json(&dir.join("scene_camera.json"))?;
            let gts: BTreeMap<String, Vec<GtPose>> = read_json(&dir.join("scene_gt.json"))?;
            let infos: BTreeMap<String, Vec<GtInfo>> = read_json(&dir.join("scene_gt_info.json"))?;
            let mut images = Vec::new();
            for (key, camera) in cams {
                let bad = |message: String| DatasetError::Format {
                    path: dir.clone(),
                    message,
                };
                let im: usize = key
                    .parse()
                    .map_err(|_| bad(format!("image id {key:?} is not an integer")))?;
                let gt = gts
                    .get(&key)
                    .cloned()
                    .ok_or_else(|| bad(format!("image {im} has no scene_gt entry")))?;
                let info = infos
                    .get(&key)
                    .cloned()
                    .ok_or_else(|| bad(format!("image {im} has no scene_gt_info entry")))?;
                if gt.len() != info.len() {
                    return Err(bad(format!(
                        "image {im}: {} poses but {} info entries",
                        gt.len(),
                        info.len()
                    )));
                }
                for g in &gt {
                    if !models.contains_key(&g.obj_id) {
                        return Err(bad(format!("image {im}: object {} has no model", g.obj_id)));
                    }
                    if pose_from_bop(&g.cam_R_m2c, &g.cam_t_m2c).is_none() {
                        return Err(bad(format!("image {im}: cam_R_m2c is not a rotation")));
                    }
                }
                images.push(BopImage {
                    id: im,
                    camera,
                    gt,
                    info,
                });
            }
            images.sort_by_key(|i| i.id);
            scenes.push(BopScene { dir, id, images });
        }
        Ok(Self {
            root: root.into(),
            camera,
            models,
            scenes,
        })
    }
}

impl BopScene {
    /// The RGB image of image `im`.
    pub fn rgb(&self, im: usize) -> Result<image::RgbImage, DatasetError> {
        let path = self.dir.join("rgb").join(format!("{im:06}.png"));
        Ok(open(&path)?.into_rgb8())
    }

    /// Depth in metres of image `im` (0 where unknown), using its depth_scale.
    pub fn depth(&self, image: &BopImage) -> Result<Vec<f64>, DatasetError> {
        let path = self.dir.join("depth").join(format!("{:06}.png", image.id));
        let img = open(&path)?.into_luma16();
        Ok(img
            .pixels()
            .map(|p| p.0[0] as f64 * image.camera.depth_scale / 1000.0)
            .collect())
    }

    /// The full (`visible = false`) or visible mask of ground-truth instance `k` of image `im`.
    pub fn mask(&self, im: usize, k: usize, visible: bool) -> Result<Vec<bool>, DatasetError> {
        let folder = if visible { "mask_visib" } else { "mask" };
        let path = self.dir.join(folder).join(format!("{im:06}_{k:06}.png"));
        Ok(open(&path)?
            .into_luma8()
            .pixels()
            .map(|p| p.0[0] > 127)
            .collect())
    }
}

impl BopImage {
    /// Pose of ground-truth instance `k` in the camera frame, metres.
    pub fn camera_T_part(&self, k: usize) -> Option<Isometry3<f64>> {
        let g = self.gt.get(k)?;
        pose_from_bop(&g.cam_R_m2c, &g.cam_t_m2c)
    }
}

/// Decodes a PNG.
fn open(path: &Path) -> Result<image::DynamicImage, DatasetError> {
    image::open(path).map_err(|e| DatasetError::Image {
        path: path.into(),
        message: e.to_string(),
    })
}
