//! The keypoint crop set: 128 × 128 crops at full resolution centred on one part, with the
//! shifted intrinsics, pose, keypoints and masks PVNet trains on.

use std::path::{Path, PathBuf};

use nalgebra::{Point3, UnitQuaternion, Vector3};
use perception::part::StablePose;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::bop::{pose_to_bop, row_major};
use super::config::{apply_families, apply_look, item_seed};
use super::families::metering_view;
use super::files::{write_json, write_mask, write_png};
use super::{DatasetConfig, DatasetError, Split};
use crate::render::{RenderSettings, Window, instance_mask, render};
use crate::scene::{
    HeldPart, PartModel, PlacedPart, SceneRequest, dress_scene, drop_parts_around, label_instance,
};
use crate::stable_poses::{CLASS_ANGLE_RAD, DropOutcome, leaning};

/// Labels of one crop (crops/PART/SPLIT/NNNNNN.json); units mm and px, OpenCV camera frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CropLabel {
    /// Part name.
    pub part: String,
    /// BOP object id.
    pub obj_id: u32,
    /// Intrinsics of the crop (principal point shifted), row-major.
    pub cam_K: [f64; 9],
    /// Distortion (k1, k2, p1, p2, k3) of the lens.
    pub dist_coeffs: [f64; 5],
    /// Crop width, px.
    pub width: u32,
    /// Crop height, px.
    pub height: u32,
    /// Top-left pixel of the crop in the full image.
    pub origin: [u32; 2],
    /// Model to camera rotation, row-major.
    pub cam_R_m2c: [f64; 9],
    /// Model to camera translation, mm.
    pub cam_t_m2c: [f64; 3],
    /// The 9 keypoints in crop pixels (8 surface points, then the centre).
    pub keypoints: Vec<[f64; 2]>,
    /// The stable pose the part lies in on the table (`None`: leaning on a neighbour, or tilted
    /// off every pose), so that training and checks can count the crops of each.
    #[serde(default)]
    pub stable_pose: Option<String>,
    /// Visible fraction of the part within the crop (visible / full silhouette pixels).
    pub visib_fract: f64,
    /// Visible pixels of the part in the crop.
    pub px_count_visib: u64,
    /// Box of the full silhouette in the crop.
    pub bbox_obj: [i64; 4],
    /// Box of the visible part in the crop.
    pub bbox_visib: [i64; 4],
    /// The RGB image file, beside this one.
    pub rgb: String,
    /// The visible-mask file, beside this one.
    pub mask: String,
}

/// Drops of a crop group redone at most this often while the target leans on a neighbour.
const LEAN_RETRIES: usize = 30;

/// Whether a placed part rests on a neighbour rather than on the table (see
/// [`crate::stable_poses::leaning`]).
pub(crate) fn target_leans(part: &PlacedPart, model: &PartModel) -> bool {
    let outcome = DropOutcome {
        rotation: part.table_T_part.rotation,
        height: part.table_T_part.translation.z,
        settled: true,
        trapped: false,
        time: 0.0,
    };
    leaning(&[outcome], &model.mesh)[0]
}

/// Folder of a part's crops of a split.
pub(crate) fn crop_dir(out: &Path, part: &str, split: Split) -> PathBuf {
    out.join("crops").join(part).join(split.name())
}

/// Renders and writes the crops of one drop: indices `group · views ..` of `model`'s `split`,
/// skipping those already complete.
pub(crate) fn write_crop_group(
    cfg: &DatasetConfig,
    models: &[PartModel],
    model: usize,
    split: Split,
    group: usize,
    total: usize,
) -> Result<usize, DatasetError> {
    let dir = crop_dir(&cfg.out, &models[model].name, split);
    let first = group * cfg.views_per_drop;
    let indices: Vec<usize> = (first..(first + cfg.views_per_drop).min(total))
        .filter(|i| !dir.join(format!("{i:06}.json")).exists())
        .collect();
    if indices.is_empty() {
        return Ok(0);
    }
    let tag = 100 + 10 * model as u64 + split.code();
    let mut rng = ChaCha8Rng::seed_from_u64(item_seed(cfg.seed, tag, group as u64));
    // The target part plus up to one of each other part nearby, dropped together.
    let counts: Vec<usize> = (0..models.len())
        .map(|m| {
            if m == model {
                1
            } else {
                rng.random_range(0..=1)
            }
        })
        .collect();
    let target = counts[..model].iter().sum::<usize>();
    let centre = (
        rng.random_range(-0.06..=0.06),
        rng.random_range(-0.06..=0.06),
    );
    // A share of the drops hold the target lying in a stable pose drawn uniformly (no draw at
    // all when the share is 0: those drops keep the random stream they had without the option).
    let stable_poses = &models[model].spec.stable_poses;
    let posed = (cfg.posed_crop_share > 0.0
        && !stable_poses.is_empty()
        && rng.random_bool(cfg.posed_crop_share))
    .then(|| &stable_poses[rng.random_range(0..stable_poses.len())]);
    // A target that came to rest on a neighbour is dropped again, up to LEAN_RETRIES times: the
    // crops must show the parts' stable poses on the table, not the leaning poses a crowded drop
    // adds (a quarter of the crops otherwise).
    let (mut parts, mut leans) = (Vec::new(), false);
    for _ in 0..=LEAN_RETRIES {
        let held = posed.map(|pose| HeldPart {
            index: target,
            rotation: UnitQuaternion::from_axis_angle(
                &Vector3::z_axis(),
                rng.random_range(0.0..std::f64::consts::TAU),
            ) * pose.rest_rotation(),
        });
        parts = drop_parts_around(models, &counts, centre, 0.012, held, &mut rng)
            .map_err(crate::scene::SceneError::from)?;
        // A target held in its pose stays in it.
        leans = posed.is_none() && target_leans(&parts[target], &models[model]);
        if !leans {
            break;
        }
    }
    // The stable pose the target lies in: the nearest (up to its exact symmetries: a peg on
    // either end) within the classes' own spread.
    let group = perception::symmetry::symmetry_group(&models[model].spec.symmetries);
    let stable_pose =
        StablePose::nearest_up_to(stable_poses, &parts[target].table_T_part.rotation, &group)
            .filter(|(_, tilt)| !leans && *tilt < CLASS_ANGLE_RAD)
            .map(|(s, _)| s.name.clone());
    let request = SceneRequest {
        counts,
        drop_centre: centre,
        drop_half: 0.012,
        aim_at_part: Some(target),
        nominal_table_T_camera: cfg.nominal_table_T_camera,
    };
    for index in indices {
        let mut rng = ChaCha8Rng::seed_from_u64(item_seed(cfg.seed, tag + 50_000, index as u64));
        let mut scene = dress_scene(
            models,
            parts.clone(),
            &request,
            &cfg.randomisation,
            &mut rng,
        )?;
        let draw = apply_families(
            cfg,
            &mut scene,
            models,
            Some(target),
            tag + 50_000,
            index as u64,
        );
        apply_look(cfg, &mut scene, draw.key_sky, tag + 50_000, index as u64);
        let camera_T_table = scene.table_T_camera.inverse();
        let part_centre = Point3::from(scene.parts[target].table_T_part.translation.vector);
        let c = cfg
            .camera
            .project(&(camera_T_table * part_centre))
            .map_err(|e| DatasetError::Config(format!("the part is not in view: {e}")))?;
        let jitter = 0.1 * cfg.crop_size as f64;
        let (u, v) = (
            c.x + rng.random_range(-jitter..=jitter),
            c.y + rng.random_range(-jitter..=jitter),
        );
        let window = Window::centred(u, v, cfg.crop_size, cfg.camera.width, cfg.camera.height);
        // Only the target's full silhouette is used: the other parts' masks are not rendered.
        let settings = RenderSettings {
            full_masks: false,
            ..cfg.render
        };
        let out = render(
            &scene.render,
            &cfg.camera,
            &scene.table_T_camera,
            window,
            &settings,
        );
        let full = cfg.render.full_masks.then(|| {
            instance_mask(
                &scene.render,
                target,
                &cfg.camera,
                &scene.table_T_camera,
                &out,
            )
        });
        let label = &label_instance(
            target,
            &scene.parts,
            models,
            &cfg.camera,
            &scene.table_T_camera,
            &out,
            full.as_ref(),
        );
        let image = scene
            .metered_sensor(&metering_view(&out, scene.parts.len()))
            .capture_balanced(&out, draw.white_balance, &mut rng)
            .map_err(|e| DatasetError::Config(e.to_string()))?;
        let id = (target + 1) as u16;
        let mask: Vec<bool> = out.visible.iter().map(|v| *v == id).collect();
        let stem = format!("{index:06}");
        let (w, h) = (window.width, window.height);
        write_png(
            &dir.join(format!("{stem}.png")),
            image.as_raw(),
            w,
            h,
            image::ExtendedColorType::Rgb8,
        )?;
        write_mask(&dir.join(format!("{stem}_mask.png")), &mask, w, h)?;
        let crop_camera = cfg.camera.crop(window.x0 as f64, window.y0 as f64, w, h);
        let (r, t) = pose_to_bop(&label.camera_T_part);
        let record = CropLabel {
            part: models[model].name.clone(),
            obj_id: models[model].obj_id,
            cam_K: row_major(&crop_camera.k_matrix()),
            dist_coeffs: crop_camera.distortion.as_array(),
            width: w,
            height: h,
            origin: [window.x0, window.y0],
            cam_R_m2c: r,
            cam_t_m2c: t,
            keypoints: label.keypoints.iter().map(|p| [p.x, p.y]).collect(),
            stable_pose: stable_pose.clone(),
            visib_fract: label.visib_fract,
            px_count_visib: label.px_count_visib as u64,
            bbox_obj: label.bbox_obj,
            bbox_visib: label.bbox_visib,
            rgb: format!("{stem}.png"),
            mask: format!("{stem}_mask.png"),
        };
        write_json(&dir.join(format!("{stem}.json")), &record)?;
    }
    Ok(1)
}
