//! Running a dataset: parallel over images and crop drops, resumable, with a progress bar.

use std::collections::BTreeMap;

use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;

use super::bop::{BopCamera, GtInfo, GtPose, SceneCamera, write_models};
use super::crops::{crop_dir, write_crop_group};
use super::feeder::{feeder_dir, feeder_scene_dir, write_feeder};
use super::files::{create_dir, read_json, write_json};
use super::overview::{Fragment, fragment_path, write_overview};
use super::{DatasetConfig, DatasetError, Split};
use crate::scene::PartModel;

/// What a run did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct GenerateSummary {
    /// Overview images rendered by this run.
    pub overviews_rendered: usize,
    /// Feeder frames rendered by this run.
    pub feeders_rendered: usize,
    /// Crop drops rendered by this run.
    pub crop_groups_rendered: usize,
    /// Work items found complete from an earlier run and skipped.
    pub skipped: usize,
}

/// One unit of parallel work.
#[derive(Debug, Clone, Copy)]
enum Work {
    Overview(Split, usize),
    Feeder(Split, usize),
    CropGroup(usize, Split, usize, usize),
}

/// Writes (or completes) the dataset described by `cfg` for `models`.
///
/// Every file is written to a temporary name and renamed; an image counts as done once its
/// label file exists, so re-running continues where a stopped run left off.
pub fn generate(
    cfg: &DatasetConfig,
    models: &[PartModel],
) -> Result<GenerateSummary, DatasetError> {
    cfg.validate()?;
    if models.is_empty() {
        return Err(DatasetError::Config("no parts to render".into()));
    }
    create_dir(&cfg.out)?;
    write_json(
        &cfg.out.join("camera.json"),
        &BopCamera::new(&cfg.camera, cfg.depth_scale),
    )?;
    write_models(&cfg.out, models)?;

    let mut work = Vec::new();
    let mut skipped = 0;
    for (split, n) in [
        (Split::Train, cfg.overviews_train),
        (Split::Test, cfg.overviews_test),
    ] {
        for scene in 0..n.div_ceil(cfg.images_per_scene) {
            let dir = cfg.out.join(split.bop_dir()).join(format!("{scene:06}"));
            for sub in ["rgb", "depth", "mask", "mask_visib", ".labels"] {
                create_dir(&dir.join(sub))?;
            }
        }
        for i in 0..n {
            let dir = cfg
                .out
                .join(split.bop_dir())
                .join(format!("{:06}", i / cfg.images_per_scene));
            if fragment_path(&dir, i % cfg.images_per_scene).exists() {
                skipped += 1;
            } else {
                work.push(Work::Overview(split, i));
            }
        }
    }
    for (split, n) in [
        (Split::Train, cfg.feeder_train),
        (Split::Test, cfg.feeder_test),
    ] {
        for i in 0..n {
            let dir = feeder_scene_dir(cfg, split, i);
            if i % cfg.images_per_scene == 0 {
                for sub in ["rgb", "depth", "mask", "mask_visib", ".labels"] {
                    create_dir(&dir.join(sub))?;
                }
            }
            if fragment_path(&dir, i % cfg.images_per_scene).exists() {
                skipped += 1;
            } else {
                work.push(Work::Feeder(split, i));
            }
        }
    }
    for (m, model) in models.iter().enumerate() {
        for (split, n) in [
            (Split::Train, cfg.crops_train),
            (Split::Test, cfg.crops_test),
        ] {
            if n == 0 {
                continue;
            }
            create_dir(&crop_dir(&cfg.out, &model.name, split))?;
            for g in 0..n.div_ceil(cfg.views_per_drop) {
                work.push(Work::CropGroup(m, split, g, n));
            }
        }
    }
    let bar = if cfg.progress {
        let bar = ProgressBar::new(work.len() as u64);
        if let Ok(style) = ProgressStyle::with_template(
            "{msg} [{elapsed_precise}] {wide_bar} {pos}/{len} ({per_sec}, eta {eta})",
        ) {
            bar.set_style(style);
        }
        bar.set_message("dataset");
        bar
    } else {
        ProgressBar::hidden()
    };
    let done: Vec<(usize, usize, usize)> = work
        .par_iter()
        .map(|w| {
            let r = match *w {
                Work::Overview(split, i) => {
                    write_overview(cfg, models, split, i).map(|_| (1, 0, 0))
                }
                Work::Feeder(split, i) => write_feeder(cfg, models, split, i).map(|_| (0, 0, 1)),
                Work::CropGroup(m, split, g, n) => {
                    write_crop_group(cfg, models, m, split, g, n).map(|k| (0, k, 0))
                }
            };
            bar.inc(1);
            r
        })
        .collect::<Result<_, _>>()?;
    bar.finish_and_clear();
    let overviews_rendered = done.iter().map(|d| d.0).sum();
    let crop_groups_rendered: usize = done.iter().map(|d| d.1).sum();
    let feeders_rendered = done.iter().map(|d| d.2).sum();
    let crop_groups_total = work
        .iter()
        .filter(|w| matches!(w, Work::CropGroup(..)))
        .count();
    assemble_scenes(cfg)?;
    Ok(GenerateSummary {
        overviews_rendered,
        feeders_rendered,
        crop_groups_rendered,
        skipped: skipped + crop_groups_total - crop_groups_rendered,
    })
}

/// Writes each scene folder's (overview and feeder) scene_camera.json, scene_gt.json and scene_gt_info.json from the
/// label fragments of its images.
fn assemble_scenes(cfg: &DatasetConfig) -> Result<(), DatasetError> {
    for (folder, n) in [
        (Split::Train.bop_dir(), cfg.overviews_train),
        (Split::Test.bop_dir(), cfg.overviews_test),
        (feeder_dir(Split::Train), cfg.feeder_train),
        (feeder_dir(Split::Test), cfg.feeder_test),
    ] {
        for scene in 0..n.div_ceil(cfg.images_per_scene) {
            let dir = cfg.out.join(folder).join(format!("{scene:06}"));
            let mut cameras: BTreeMap<usize, SceneCamera> = BTreeMap::new();
            let mut gts: BTreeMap<usize, Vec<GtPose>> = BTreeMap::new();
            let mut infos: BTreeMap<usize, Vec<GtInfo>> = BTreeMap::new();
            let first = scene * cfg.images_per_scene;
            for im in 0..(n - first).min(cfg.images_per_scene) {
                let f: Fragment = read_json(&fragment_path(&dir, im))?;
                cameras.insert(im, f.camera);
                gts.insert(im, f.gt);
                infos.insert(im, f.info);
            }
            write_json(&dir.join("scene_camera.json"), &cameras)?;
            write_json(&dir.join("scene_gt.json"), &gts)?;
            write_json(&dir.join("scene_gt_info.json"), &infos)?;
        }
    }
    Ok(())
}
