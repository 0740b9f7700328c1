//! One overview image: all parts dropped on the board, the board region at reduced resolution,
//! written as one BOP image (rgb, depth, masks) plus its label fragment.

use std::path::Path;

use nalgebra::Point3;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::bop::{GtInfo, GtPose, SceneCamera, pose_to_bop, row_major};
use super::config::{apply_families, apply_look, item_seed};
use super::families::metering_view;
use super::files::{write_depth, write_json, write_mask, write_png};
use super::{DatasetConfig, DatasetError, FamilyDraw, Split};
use perception::camera::Camera;

use crate::render::{RenderOutput, Window, render};
use crate::scene::{PartModel, SampledScene, SceneRequest, label_instances, sample_scene};

/// The labels of one image, kept until its scene folder's JSON files are assembled.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct Fragment {
    pub camera: SceneCamera,
    pub gt: Vec<GtPose>,
    pub info: Vec<GtInfo>,
}

/// Path of the label fragment of image `im` in a scene folder.
pub(crate) fn fragment_path(scene_dir: &Path, im: usize) -> std::path::PathBuf {
    scene_dir.join(".labels").join(format!("{im:06}.json"))
}

/// Renders and writes overview image `index` of `split`.
pub(crate) fn write_overview(
    cfg: &DatasetConfig,
    models: &[PartModel],
    split: Split,
    index: usize,
) -> Result<(), DatasetError> {
    let scene_dir = cfg
        .out
        .join(split.bop_dir())
        .join(format!("{:06}", index / cfg.images_per_scene));
    let im = index % cfg.images_per_scene;
    let mut rng = ChaCha8Rng::seed_from_u64(item_seed(cfg.seed, 10 + split.code(), index as u64));
    let (lo, hi) = cfg.parts_per_class;
    let counts = models.iter().map(|_| rng.random_range(lo..=hi)).collect();
    let request = SceneRequest {
        counts,
        drop_centre: (0.0, 0.0),
        drop_half: 0.07,
        aim_at_part: None,
        nominal_table_T_camera: cfg.nominal_table_T_camera,
    };
    let mut scene = sample_scene(models, &request, &cfg.randomisation, &mut rng)?;
    let draw = apply_families(
        cfg,
        &mut scene,
        models,
        None,
        10 + split.code(),
        index as u64,
    );
    apply_look(
        cfg,
        &mut scene,
        draw.key_sky,
        10 + split.code(),
        index as u64,
    );
    let camera = cfg
        .camera
        .scaled(cfg.overview_scale)
        .map_err(|e| DatasetError::Config(e.to_string()))?;
    let camera_T_table = scene.table_T_camera.inverse();
    let centre = camera
        .project(&(camera_T_table * Point3::origin()))
        .map_err(|e| DatasetError::Config(format!("the board is not in view: {e}")))?;
    let (w, h) = cfg.overview_size;
    let half = (
        w.min(camera.width) as f64 / 2.0,
        h.min(camera.height) as f64 / 2.0,
    );
    let x0 = (centre.x - half.0 + 0.5)
        .floor()
        .clamp(0.0, (camera.width - w.min(camera.width)) as f64);
    let y0 = (centre.y - half.1 + 0.5)
        .floor()
        .clamp(0.0, (camera.height - h.min(camera.height)) as f64);
    let window = Window {
        x0: x0 as u32,
        y0: y0 as u32,
        width: w.min(camera.width),
        height: h.min(camera.height),
    };
    let out = render(
        &scene.render,
        &camera,
        &scene.table_T_camera,
        window,
        &cfg.render,
    );
    write_bop_image(
        cfg, models, &scene, &camera, window, &out, &scene_dir, im, draw, &mut rng,
    )
}

/// Labels `out` (a render of `window` of `camera` showing `scene`), passes it through the
/// scene's sensor (with the families' white balance, `draw`) and writes it as image `im` of `scene_dir`: rgb, depth, masks and the label
/// fragment (intrinsics shifted to the window origin).
#[allow(clippy::too_many_arguments)]
pub(crate) fn write_bop_image(
    cfg: &DatasetConfig,
    models: &[PartModel],
    scene: &SampledScene,
    camera: &Camera,
    window: Window,
    out: &RenderOutput,
    scene_dir: &Path,
    im: usize,
    draw: FamilyDraw,
    rng: &mut ChaCha8Rng,
) -> Result<(), DatasetError> {
    let camera_T_table = scene.table_T_camera.inverse();
    let labels = label_instances(&scene.parts, models, camera, &scene.table_T_camera, out);
    let image = scene
        .metered_sensor(&metering_view(out, scene.parts.len()))
        .capture_balanced(out, draw.white_balance, rng)
        .map_err(|e| DatasetError::Config(e.to_string()))?;

    let (ww, wh) = (window.width, window.height);
    let stem = format!("{im:06}");
    write_png(
        &scene_dir.join("rgb").join(format!("{stem}.png")),
        image.as_raw(),
        ww,
        wh,
        image::ExtendedColorType::Rgb8,
    )?;
    write_depth(
        &scene_dir.join("depth").join(format!("{stem}.png")),
        &out.depth,
        ww,
        wh,
        cfg.depth_scale,
    )?;
    let mut gt = Vec::new();
    let mut info = Vec::new();
    for (k, label) in labels.iter().enumerate() {
        let mut full = vec![false; window.len()];
        if let Some(mask) = out.full_masks.get(k) {
            for y in 0..wh {
                for x in 0..ww {
                    full[(y * ww + x) as usize] = mask.contains(window.x0 + x, window.y0 + y);
                }
            }
        }
        let id = (k + 1) as u16;
        let visib: Vec<bool> = out.visible.iter().map(|v| *v == id).collect();
        let name = format!("{stem}_{k:06}.png");
        write_mask(&scene_dir.join("mask").join(&name), &full, ww, wh)?;
        write_mask(&scene_dir.join("mask_visib").join(&name), &visib, ww, wh)?;
        let (r, t) = pose_to_bop(&label.camera_T_part);
        gt.push(GtPose {
            cam_R_m2c: r,
            cam_t_m2c: t,
            obj_id: label.obj_id,
        });
        info.push(GtInfo {
            bbox_obj: label.bbox_obj,
            bbox_visib: label.bbox_visib,
            px_count_all: label.px_count_all as u64,
            px_count_valid: full
                .iter()
                .zip(&out.depth)
                .filter(|(f, d)| **f && **d > 0.0)
                .count() as u64,
            px_count_visib: label.px_count_visib as u64,
            visib_fract: label.visib_fract,
        });
    }
    let crop_camera = camera.crop(window.x0 as f64, window.y0 as f64, ww, wh);
    let (r, t) = pose_to_bop(&camera_T_table);
    let fragment = Fragment {
        camera: SceneCamera {
            cam_K: row_major(&crop_camera.k_matrix()),
            depth_scale: cfg.depth_scale,
            cam_R_w2c: r,
            cam_t_w2c: t,
            width: ww,
            height: wh,
            dist_coeffs: crop_camera.distortion.as_array(),
        },
        gt,
        info,
    };
    write_json(&fragment_path(scene_dir, im), &fragment)
}
