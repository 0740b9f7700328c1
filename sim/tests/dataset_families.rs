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
use sim::scene::{PartModel, Range};

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

/// Mean grey level (0–255) of every metal part's visible pixels, over 100 of them, in the
/// feeder frames of a run at `root`.
fn metal_greys(root: &Path, models: &[PartModel]) -> Vec<f64> {
    let scene = root.join("test_feeder/000000");
    let gt: BTreeMap<String, Vec<serde_json::Value>> =
        serde_json::from_slice(&std::fs::read(scene.join("scene_gt.json")).unwrap()).unwrap();
    let mut out = Vec::new();
    for (im, objs) in &gt {
        let im: usize = im.parse().unwrap();
        let rgb = gray(&std::fs::read(scene.join(format!("rgb/{im:06}.png"))).unwrap());
        for (k, o) in objs.iter().enumerate() {
            let id = o["obj_id"].as_u64().unwrap() as u32;
            let model = models.iter().find(|m| m.obj_id == id).unwrap();
            if model.appearance().metallic < 0.5 {
                continue;
            }
            let mask =
                gray(&std::fs::read(scene.join(format!("mask_visib/{im:06}_{k:06}.png"))).unwrap());
            let px: Vec<f64> = rgb
                .iter()
                .zip(&mask)
                .filter(|(_, m)| **m > 127)
                .map(|(g, _)| f64::from(*g))
                .collect();
            if px.len() >= 100 {
                out.push(px.iter().sum::<f64>() / px.len() as f64);
            }
        }
    }
    out
}

#[test]
fn a_hard_key_light_leaves_metal_tops_dark_where_the_soft_lights_do_not() {
    // Blender Cycles' hard look (one small key 40–55° off the vertical in a dim room) renders
    // some shells near black: the key light of the lights family must reach that regime, and
    // its soft draws must not.
    assert_key_leaves_metal_dark(None, "");
}

#[test]
fn under_the_room_look_the_key_light_dims_the_room_and_leaves_metal_tops_dark() {
    // With `--environment room` the room replaces the key regime's dim sky: its ceiling panels
    // would light the metal tops the key leaves dark. Under the key the room's lights are off
    // (dimmed to the key's sky), so the hard regime keeps its dark tops in the room too.
    assert_key_leaves_metal_dark(Some(sim::dataset::LookOptions::default()), " in the room");
}

/// Renders 4 feeder frames with the lights family's key light always, then never, under `look`,
/// and asserts that the key leaves a fifth or more of the metal tops below grey 40, four times
/// the soft lights' share, at under half their median grey.
fn assert_key_leaves_metal_dark(look: Option<sim::dataset::LookOptions>, context: &str) {
    let tmp = tempfile::tempdir().unwrap();
    let models = support::usbc_models();
    let run = |name: &str, key: f64| {
        let out = tmp.path().join(name);
        let mut cfg = tiny(out.clone());
        cfg.crops_train = 0;
        cfg.feeder_test = 4;
        cfg.families = Families::from_list("lights").unwrap();
        cfg.families.lights.key_probability = key;
        cfg.look = look.clone();
        generate(&cfg, &models).unwrap();
        metal_greys(&out, &models)
    };
    let (hard, soft) = (run("key", 1.0), run("soft", 0.0));
    assert!(hard.len() >= 10 && soft.len() >= 10, "{hard:?} {soft:?}");
    let dark = |g: &[f64]| g.iter().filter(|g| **g < 40.0).count() as f64 / g.len() as f64;
    let median = |g: &[f64]| {
        let mut g = g.to_vec();
        g.sort_by(f64::total_cmp);
        g[g.len() / 2]
    };
    let (d_hard, d_soft) = (dark(&hard), dark(&soft));
    assert!(
        d_hard >= 0.2 && d_hard >= 4.0 * d_soft && median(&hard) < 0.5 * median(&soft),
        "metal parts below grey 40{context}: {:.0} % under the key light ({hard:.0?}), {:.0} % \
         under the soft lights ({soft:.0?})",
        100.0 * d_hard,
        100.0 * d_soft
    );
}
