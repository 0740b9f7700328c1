//! A contact sheet to judge the randomisation at a glance: a grid of a dataset's training crops
//! (columns per part) beside two feeder-window captures of randomised scenes.

use std::path::Path;

use image::RgbImage;
use nalgebra::Point3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::config::{apply_families, apply_look, item_seed};
use super::crops::crop_dir;
use super::families::metering_view;
use super::files::write_png;
use super::{DatasetConfig, DatasetError, Split};
use crate::render::{RenderSettings, capture, window_covering};
use crate::scene::{PartModel, SceneRequest, dress_scene, drop_parts};

/// The nominal feeder region of the usbc scenario: 80 × 60 mm centred at (0, 0.05) m on the
/// board, up to 5 mm above it.
const FEEDER: ([f64; 3], [f64; 3]) = ([-0.04, 0.02, 0.0], [0.04, 0.08, 0.005]);

/// Pixels between tiles.
const GAP: u32 = 6;

/// Writes the contact sheet of the dataset in `cfg.out` (its first `rows` training crops of each
/// part, which must exist) and two feeder captures of four of each part under `cfg`'s
/// randomisation, atomically, as a PNG at `path`.
pub fn write_preview(
    cfg: &DatasetConfig,
    models: &[PartModel],
    rows: usize,
    path: &Path,
) -> Result<(), DatasetError> {
    cfg.validate()?;
    let mut crops = Vec::new();
    for model in models {
        let dir = crop_dir(&cfg.out, &model.name, Split::Train);
        for i in 0..rows {
            let file = dir.join(format!("{i:06}.png"));
            let img = image::open(&file)
                .map_err(|e| DatasetError::Image {
                    path: file.clone(),
                    message: e.to_string(),
                })?
                .to_rgb8();
            crops.push(img);
        }
    }
    let feeders = (0..2)
        .map(|k| feeder_capture(cfg, models, k))
        .collect::<Result<Vec<_>, _>>()?;

    let c = cfg.crop_size;
    let cols = models.len() as u32;
    let grid_w = cols * c + cols.saturating_sub(1) * GAP;
    let grid_h = rows as u32 * (c + GAP) - GAP;
    let feeder_w = feeders.iter().map(|f| f.width()).max().unwrap_or(0);
    let feeder_h: u32 = feeders.iter().map(|f| f.height() + GAP).sum::<u32>() - GAP;
    let mut sheet = RgbImage::from_pixel(
        grid_w + GAP + feeder_w,
        grid_h.max(feeder_h),
        image::Rgb([255, 255, 255]),
    );
    for (k, crop) in crops.iter().enumerate() {
        let (col, row) = ((k / rows) as u32, (k % rows) as u32);
        paste(&mut sheet, crop, col * (c + GAP), row * (c + GAP));
    }
    let mut y = 0;
    for f in &feeders {
        paste(&mut sheet, f, grid_w + GAP, y);
        y += f.height() + GAP;
    }
    write_png(
        path,
        sheet.as_raw(),
        sheet.width(),
        sheet.height(),
        image::ExtendedColorType::Rgb8,
    )
}

/// Feeder capture `k`: four of each part dropped into the feeder, a randomised scene, the feeder
/// window of the full-resolution camera through the metered sensor.
fn feeder_capture(
    cfg: &DatasetConfig,
    models: &[PartModel],
    k: u64,
) -> Result<RgbImage, DatasetError> {
    let mut rng = ChaCha8Rng::seed_from_u64(item_seed(cfg.seed, 900, k));
    let counts = vec![4; models.len()];
    let parts = drop_parts(models, &counts, (0.0, 0.05), 0.03, &mut rng)
        .map_err(crate::scene::SceneError::from)?;
    let request = SceneRequest {
        counts,
        drop_centre: (0.0, 0.05),
        drop_half: 0.03,
        aim_at_part: None,
        nominal_table_T_camera: cfg.nominal_table_T_camera,
    };
    let mut scene = dress_scene(models, parts, &request, &cfg.randomisation, &mut rng)?;
    let draw = apply_families(cfg, &mut scene, models, None, 900, k);
    apply_look(cfg, &mut scene, draw.key_sky, 900, k);
    let (lo, hi) = FEEDER;
    let window = window_covering(
        &cfg.camera,
        &scene.table_T_camera,
        &Point3::from(lo),
        &Point3::from(hi),
    )
    .ok_or_else(|| DatasetError::Config("the feeder is not in view".into()))?;
    let settings = RenderSettings {
        full_masks: false,
        ..cfg.render
    };
    let first = capture(
        &scene.render,
        &cfg.camera,
        &scene.table_T_camera,
        window,
        &settings,
        &scene.sensor,
        &mut rng,
    )
    .map_err(|e| DatasetError::Config(e.to_string()))?;
    // Re-expose the same render through the metered sensor.
    scene
        .metered_sensor(&metering_view(&first.output, scene.parts.len()))
        .capture_balanced(&first.output, draw.white_balance, &mut rng)
        .map_err(|e| DatasetError::Config(e.to_string()))
}

/// Copies `tile` into `sheet` with its top-left corner at (x, y), clipped to the sheet.
fn paste(sheet: &mut RgbImage, tile: &RgbImage, x: u32, y: u32) {
    for (tx, ty, p) in tile.enumerate_pixels() {
        if x + tx < sheet.width() && y + ty < sheet.height() {
            sheet.put_pixel(x + tx, y + ty, *p);
        }
    }
}
