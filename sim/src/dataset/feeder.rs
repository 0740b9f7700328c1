//! Feeder frames: a dozen parts of every kind dropped close together (several touching), seen at
//! the full camera resolution through a window covering them, like the cell's feeder capture;
//! written as BOP scenes for training and testing segmentation (`train_feeder/`, `test_feeder/`).

use std::path::PathBuf;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::config::{apply_families, apply_look, item_seed};
use super::overview::write_bop_image;
use super::{DatasetConfig, DatasetError, Split};
use crate::render::{Window, render, window_covering};
use crate::scene::{PartModel, Range, SceneRequest, sample_scene};

/// Background kept around the parts' footprint in a feeder window, metres.
const FEEDER_MARGIN: f64 = 0.003;
/// Window sides are rounded up to a multiple of this (the segmenter's input stride).
const FEEDER_ALIGN: u32 = 16;

/// BOP split folder of the feeder frames of `split`.
pub(crate) fn feeder_dir(split: Split) -> &'static str {
    match split {
        Split::Train => "train_feeder",
        Split::Test => "test_feeder",
    }
}

/// Folder of the scene holding feeder frame `index` of `split`.
pub(crate) fn feeder_scene_dir(cfg: &DatasetConfig, split: Split, index: usize) -> PathBuf {
    cfg.out
        .join(feeder_dir(split))
        .join(format!("{:06}", index / cfg.images_per_scene))
}

/// Grows `window` to sides that are multiples of [`FEEDER_ALIGN`] about its centre, kept inside
/// a `width` × `height` image (sides stay unaligned only when the image itself is smaller).
pub(crate) fn aligned(window: Window, width: u32, height: u32) -> Window {
    let grow = |x0: u32, len: u32, n: u32| -> (u32, u32) {
        let len2 = len.div_ceil(FEEDER_ALIGN) * FEEDER_ALIGN;
        let len2 = if len2 > n {
            n / FEEDER_ALIGN * FEEDER_ALIGN
        } else {
            len2
        }
        .max(len.min(n));
        let extra = len2.saturating_sub(len);
        let start = x0.saturating_sub(extra / 2).min(n - len2);
        (start, len2)
    };
    let (x0, w) = grow(window.x0, window.width, width);
    let (y0, h) = grow(window.y0, window.height, height);
    Window {
        x0,
        y0,
        width: w,
        height: h,
    }
}

/// Renders and writes feeder frame `index` of `split`.
pub(crate) fn write_feeder(
    cfg: &DatasetConfig,
    models: &[PartModel],
    split: Split,
    index: usize,
) -> Result<(), DatasetError> {
    let scene_dir = feeder_scene_dir(cfg, split, index);
    let im = index % cfg.images_per_scene;
    let mut rng = ChaCha8Rng::seed_from_u64(item_seed(cfg.seed, 20 + split.code(), index as u64));
    let (lo, hi) = cfg.feeder_per_class;
    let counts = models.iter().map(|_| rng.random_range(lo..=hi)).collect();
    let drop_centre = (
        rng.random_range(-0.05..=0.05),
        rng.random_range(-0.05..=0.05),
    );
    let request = SceneRequest {
        counts,
        drop_centre,
        drop_half: cfg.feeder_drop_half,
        aim_at_part: Some(0),
        nominal_table_T_camera: cfg.nominal_table_T_camera,
    };
    let mut rand = cfg.randomisation.clone();
    if let (Split::Test, Some(d)) = (split, cfg.feeder_camera_distance) {
        rand.camera_height = Range::new(d, d);
    }
    let mut scene = sample_scene(models, &request, &rand, &mut rng)?;
    let draw = apply_families(
        cfg,
        &mut scene,
        models,
        None,
        20 + split.code(),
        index as u64,
    );
    apply_look(
        cfg,
        &mut scene,
        draw.key_sky,
        20 + split.code(),
        index as u64,
    );
    let (lo_p, hi_p) = scene.footprint(models, FEEDER_MARGIN);
    let window = window_covering(&cfg.camera, &scene.table_T_camera, &lo_p, &hi_p)
        .ok_or_else(|| DatasetError::Config(format!("feeder frame {index}: parts not in view")))?;
    let window = aligned(window, cfg.camera.width, cfg.camera.height);
    let out = render(
        &scene.render,
        &cfg.camera,
        &scene.table_T_camera,
        window,
        &cfg.render,
    );
    write_bop_image(
        cfg,
        models,
        &scene,
        &cfg.camera,
        window,
        &out,
        &scene_dir,
        im,
        draw,
        &mut rng,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn aligned_windows_grow_to_multiples_of_16_inside_the_image() {
        let w = aligned(
            Window {
                x0: 100,
                y0: 5,
                width: 570,
                height: 433,
            },
            5472,
            3648,
        );
        assert_eq!((w.width, w.height), (576, 448));
        assert_eq!((w.x0, w.y0), (97, 0));
        let edge = aligned(
            Window {
                x0: 5460,
                y0: 3640,
                width: 12,
                height: 8,
            },
            5472,
            3648,
        );
        assert_eq!((edge.width, edge.height), (16, 16));
        assert_eq!((edge.x0 + edge.width, edge.y0 + edge.height), (5472, 3648));
    }
}
