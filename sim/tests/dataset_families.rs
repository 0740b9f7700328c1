//! Randomisation families (`DatasetConfig::families`): each one, on alone, changes the rendered
//! crops and feeder frames while the ground truth stays that of the same run without it (poses
//! and full masks equal; visible masks equal, or, with distractors, smaller only where a
//! distractor stands in front); every family off gives the default run's bytes, whatever its
//! ranges.

#![allow(non_snake_case)] // the shared support module names poses a_T_b, the workspace convention

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use sim::dataset::{DatasetConfig, FAMILY_NAMES, Families, generate};
use sim::render::RenderSettings;
use sim::scene::Range;

mod support;

fn tiny(out: PathBuf) -> DatasetConfig {
    let mut cfg = DatasetConfig::new(out, 3);
    cfg.crops_train = 2;
    cfg.crops_test = 0;
    cfg.views_per_drop = 2;
    cfg.overviews_train = 0;
    cfg.overviews_test = 0;
    cfg.feeder_test = 1;
    cfg.images_per_scene = 10;
    cfg.progress = false;
    cfg.render = RenderSettings {
        supersampling: 1,
        ..RenderSettings::default()
    };
    cfg
}

/// Every file under `root` (relative path → bytes).
fn tree(root: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.insert(
                    p.strip_prefix(root).unwrap().to_path_buf(),
                    std::fs::read(&p).unwrap(),
                );
            }
        }
    }
    out
}

fn gray(bytes: &[u8]) -> Vec<u8> {
    image::load_from_memory(bytes)
        .unwrap()
        .to_luma8()
        .into_raw()
}

fn depth(bytes: &[u8]) -> Vec<u16> {
    image::load_from_memory(bytes)
        .unwrap()
        .to_luma16()
        .into_raw()
}

fn is(path: &Path, dir: &str) -> bool {
    path.components().any(|c| c.as_os_str() == dir)
}

#[test]
fn each_family_changes_the_images_and_keeps_the_ground_truth() {
    let tmp = tempfile::tempdir().unwrap();
    let models = support::usbc_models();
    let base = tmp.path().join("off");
    generate(&tiny(base.clone()), &models).unwrap();
    let off = tree(&base);
    let frame = "test_feeder/000000";
    for name in FAMILY_NAMES {
        let out = tmp.path().join(name);
        let mut cfg = tiny(out.clone());
        cfg.families = Families::from_list(name).unwrap();
        // Many tall distractors close to the parts (their shadows and sides reach the parts).
        cfg.families.distractors.count = Range::new(8.0, 8.0);
        cfg.families.distractors.height = Range::new(0.06, 0.1);
        cfg.families.distractors.radius = Range::new(0.008, 0.03);
        generate(&cfg, &models).unwrap();
        let on = tree(&out);
        assert_eq!(
            on.keys().collect::<Vec<_>>(),
            off.keys().collect::<Vec<_>>(),
            "{name}: other files"
        );
        let (mut images, mut changed) = (0, 0);
        for (path, bytes) in &on {
            let before = &off[path];
            let text = path.to_string_lossy();
            let crop = text.starts_with("crops");
            let crop_rgb = crop && text.ends_with(".png") && !text.ends_with("_mask.png");
            let distractors = name == "distractors";
            if is(path, "rgb") || crop_rgb {
                images += 1;
                changed += usize::from(bytes != before);
                if is(path, "rgb") {
                    assert_ne!(bytes, before, "{name}: {text} unchanged");
                }
            } else if distractors && (is(path, "mask_visib") || text.ends_with("_mask.png")) {
                // A part's visible pixels are those it had, less those a distractor hides:
                // there, something is now nearer the camera.
                let (m_on, m_off) = (gray(bytes), gray(before));
                let depths = (!crop).then(|| {
                    let stem = path.file_name().unwrap().to_string_lossy();
                    let d = PathBuf::from(frame)
                        .join("depth")
                        .join(format!("{}.png", &stem[..6]));
                    (depth(&on[&d]), depth(&off[&d]))
                });
                for i in 0..m_on.len() {
                    assert!(m_on[i] == 0 || m_off[i] != 0, "{text}: pixel {i} gained");
                    if let Some((d_on, d_off)) = &depths
                        && m_off[i] != 0
                        && m_on[i] == 0
                    {
                        assert!(
                            d_on[i] < d_off[i],
                            "{text}: pixel {i} lost, nothing in front"
                        );
                    }
                }
            } else if distractors && is(path, "depth") {
                // Distractors stand on the table: depth only ever comes nearer, and somewhere
                // it does.
                let (a, b) = (depth(bytes), depth(before));
                assert!(a.iter().zip(&b).all(|(a, b)| a <= b), "{text}");
                assert!(a != b, "{text}: no distractor in view");
            } else if distractors && (text.ends_with("scene_gt_info.json") || crop) {
                // Visible counts and boxes may shrink under distractors: checked through the
                // masks above.
            } else {
                // Poses, full masks, visible masks, depth, crop labels, cameras.
                assert_eq!(bytes, before, "{name}: {text} changed");
            }
        }
        assert!(images >= 3, "{images} images");
        // Platings, plastics and distractors change the crops that show a metal part, a
        // plastic one or a distractor (the feeder frame, asserted above, shows them all);
        // lights, textures and the sensor change every image.
        if ["plating", "plastic", "distractors"].contains(&name) {
            assert!(changed >= 2, "{name}: {changed} of {images} images changed");
        } else {
            assert_eq!(changed, images, "{name}: images unchanged");
        }
    }
}

#[test]
fn families_that_are_off_change_nothing_whatever_their_ranges() {
    let tmp = tempfile::tempdir().unwrap();
    let models = support::usbc_models();
    let a = tmp.path().join("a");
    generate(&tiny(a.clone()), &models).unwrap();
    let mut families = Families::all();
    families.lights.count = Range::new(5.0, 6.0);
    families.plating.roughness = Range::new(0.5, 0.5);
    families.distractors.count = Range::new(8.0, 8.0);
    families.sensor.gain = Range::new(3.0, 3.0);
    for name in FAMILY_NAMES {
        families.set(name, false).unwrap();
    }
    let b = tmp.path().join("b");
    let mut cfg = tiny(b.clone());
    cfg.families = families;
    generate(&cfg, &models).unwrap();
    assert_eq!(tree(&a), tree(&b), "families off changed the bytes");
}
