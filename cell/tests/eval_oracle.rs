//! `cell::eval` end to end without networks: a tiny BOP test split is rendered at test time from
//! the committed catalog, a stand-in detector built from its ground truth (visible masks, exact
//! keypoint projections, the real `PoseEstimator`) is evaluated, with one instance left out and
//! one false detection added, and the counts, pose errors and written report are checked. Bad
//! datasets give errors naming the file.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};

use cell::eval::fingers::FingerCheck;
use cell::eval::gallery::GalleryItem;
use cell::eval::matching::mask_from_raster;
use cell::eval::report_html::{EvalMeta, write_eval_report};
use cell::eval::summary::summarise;
use cell::eval::{EvalDataset, EvalOptions, FrameDetector, camera_of, evaluate, resolve_split};
use cell::scenario::Scenario;
use nalgebra::{Isometry3, Matrix2, Point3, Vector3};
use perception::estimate::{EstimatorConfig, Observation, PoseEstimator};
use perception::learned::{InstanceMask, LearnedDetection, LearnedDetections, StageTimes};
use perception::part::Catalog;
use perception::voting::KeypointVote;
use perception::{Camera, FrameImage};
use sim::dataset::{BopDataset, DatasetConfig, generate, pose_from_bop};
use sim::render::RenderSettings;
use sim::scene::PartModel;

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

fn catalog() -> Catalog {
    Catalog::load(&workspace().join("scenarios/parts/usbc.toml")).unwrap()
}

/// Two overview test images of every part at reduced scale.
fn tiny_dataset(out: &Path, catalog: &Catalog) {
    let mut cfg = DatasetConfig::new(out.to_path_buf(), 11);
    cfg.crops_train = 0;
    cfg.crops_test = 0;
    cfg.overviews_train = 0;
    cfg.overviews_test = 2;
    cfg.parts_per_class = (2, 2);
    cfg.overview_scale = 0.4;
    cfg.overview_size = (640, 480);
    cfg.progress = false;
    cfg.render = RenderSettings {
        supersampling: 1,
        ..RenderSettings::default()
    };
    let names: Vec<String> = catalog
        .parts
        .iter()
        .filter(|p| p.role != perception::part::PartRole::Fixture)
        .map(|p| p.name.clone())
        .collect();
    let models = PartModel::from_catalog(catalog, &names).unwrap();
    generate(&cfg, &models).unwrap();
}

/// What the oracle did, to check the evaluation against.
#[derive(Debug, Default)]
struct Expect {
    counted: usize,
    detected: usize,
}

/// Detections made from the ground truth, one frame per call, in the evaluation's image order.
struct Oracle {
    frames: VecDeque<LearnedDetections>,
}

impl FrameDetector for Oracle {
    #[allow(non_snake_case)]
    fn detect(
        &mut self,
        image: &FrameImage,
        camera: &Camera,
        _camera_T_table: &Isometry3<f64>,
    ) -> Result<LearnedDetections, String> {
        assert_eq!(image.width(), camera.width);
        self.frames
            .pop_front()
            .ok_or_else(|| "no more frames".into())
    }
}

/// Per image: every visible enough instance detected with exact keypoints except the last one of
/// the first image; the first instance of the second image gets the keypoints of the part turned
/// 180° about its z axis (its near-symmetry: an outlier and a symmetry flip); plus one false
/// detection per image (a box of background labelled as the first part).
#[allow(non_snake_case)]
fn oracle(root: &Path, split: &str, catalog: &Catalog, options: &EvalOptions) -> (Oracle, Expect) {
    let bop = BopDataset::load(root, split).unwrap();
    let mut frames = VecDeque::new();
    let mut expect = Expect::default();
    for (s, scene) in bop.scenes.iter().enumerate() {
        for (i, image) in scene.images.iter().enumerate() {
            let camera = camera_of(&image.camera).unwrap();
            let camera_T_table =
                pose_from_bop(&image.camera.cam_R_w2c, &image.camera.cam_t_w2c).unwrap();
            let estimator =
                PoseEstimator::new(catalog, camera_T_table, EstimatorConfig::with_gate(5.0))
                    .unwrap();
            let mut detections = Vec::new();
            let counted: Vec<usize> = (0..image.gt.len())
                .filter(|&k| image.info[k].visib_fract >= options.min_visib_fract)
                .filter(|&k| image.info[k].px_count_visib > 0)
                .collect();
            expect.counted += counted.len();
            for (n, &k) in counted.iter().enumerate() {
                if s == 0 && i == 0 && n + 1 == counted.len() {
                    continue; // missed on purpose
                }
                let part = &catalog.parts[image.gt[k].obj_id as usize - 1];
                let truth = image.camera_T_part(k).unwrap();
                let shown = if s == 0 && i == 1 && n == 0 {
                    truth * Isometry3::rotation(Vector3::z() * std::f64::consts::PI)
                } else {
                    truth
                };
                let bits = scene.mask(image.id, k, true).unwrap();
                let keypoints: Vec<KeypointVote> = part
                    .keypoint_points()
                    .iter()
                    .map(|p| KeypointVote {
                        position: camera.project(&(shown * p)).unwrap(),
                        covariance: Matrix2::identity() * 0.25,
                        inliers: 100,
                        inlier_ratio: 0.9,
                        hypotheses: 128,
                    })
                    .collect();
                let observations: Vec<Observation> = keypoints
                    .iter()
                    .enumerate()
                    .map(|(j, v)| Observation {
                        keypoint: j,
                        pixel: v.position,
                        covariance: Some(v.covariance),
                    })
                    .collect();
                let centre = camera.project(&(truth * Point3::origin())).unwrap();
                detections.push(LearnedDetection {
                    part: part.name.clone(),
                    score: 0.95 - 0.01 * n as f64,
                    mask: mask_from_raster(&bits, camera.width, camera.height),
                    centre: [centre.x, centre.y],
                    crop_origin: [centre.x.round() as i64 - 64, centre.y.round() as i64 - 64],
                    keypoints,
                    pose: estimator
                        .estimate(&part.name, &camera, &observations)
                        .map_err(|e| e.to_string()),
                    refused: None,
                });
                expect.detected += 1;
            }
            detections.push(LearnedDetection {
                part: catalog.parts[0].name.clone(),
                score: 0.3,
                mask: InstanceMask {
                    origin: [0, 0],
                    width: 6,
                    height: 6,
                    bits: vec![true; 36],
                },
                centre: [3.0, 3.0],
                crop_origin: [-61, -61],
                keypoints: Vec::new(),
                pose: Err("voting found no keypoints".into()),
                refused: None,
            });
            frames.push_back(LearnedDetections {
                detections,
                times: StageTimes {
                    total: std::time::Duration::from_millis(20),
                    segment: std::time::Duration::from_millis(8),
                    ..StageTimes::default()
                },
            });
        }
    }
    (Oracle { frames }, expect)
}

#[test]
fn ground_truth_detections_score_perfectly_and_the_report_is_written() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("ds");
    let catalog = catalog();
    tiny_dataset(&root, &catalog);
    let options = EvalOptions {
        gallery: 3,
        ..EvalOptions::default()
    };
    let split = resolve_split(&root, None);
    assert_eq!(split, "test", "no test_feeder here: the fallback");
    let dataset = EvalDataset::open(&root, &split, &catalog, &options).unwrap();
    assert_eq!(dataset.part_names().len(), 3);
    let (mut detector, expect) = oracle(&root, &split, &catalog, &options);
    assert!(expect.counted >= 4, "{expect:?}");
    let mut calls = 0;
    let run = evaluate(&dataset, &mut detector, &options, None, |_, _| calls += 1).unwrap();
    assert_eq!((run.frames.len(), calls), (2, 2));
    let parts: Vec<(String, f64)> = dataset
        .parts
        .values()
        .map(|p| (p.name.clone(), p.diameter_mm))
        .collect();
    let s = summarise(&run.frames, &parts, &options);
    let p = &s.pooled;
    assert_eq!(p.truths, expect.counted);
    assert_eq!(p.true_positives, expect.detected);
    assert_eq!(p.false_positives, 2, "one false detection per frame");
    assert!((p.recall - expect.detected as f64 / expect.counted as f64).abs() < 1e-12);
    assert!((p.precision - expect.detected as f64 / (expect.detected + 2) as f64).abs() < 1e-12);
    // Exact keypoints: PnP recovers the truth; every matched mask is the truth's own (IoU 1).
    for f in &run.frames {
        for d in f.detections.iter().filter(|d| d.truth.is_some()) {
            assert_eq!(d.iou, Some(1.0));
        }
    }
    assert_eq!(p.poses + p.pose_failures, p.true_positives);
    assert_eq!(
        p.poses, expect.detected,
        "every exact estimate passes the gate"
    );
    // The flipped one is the only outlier, counted, explained by the near-symmetry, and dropped
    // seed-style; it turns about its own origin, so its translation is still exact.
    for stats in [&p.raw, &p.refined] {
        assert_eq!((stats.all.outliers, stats.symmetry_flips), (1, 1));
        assert_eq!(stats.seed_style.angle_deg.count, p.poses - 1);
        assert!(stats.all.angle_deg.max > 179.0);
    }
    let raw = &p.raw.seed_style;
    assert!(raw.x_mm.max < 1e-3 && raw.y_mm.max < 1e-3, "{raw:?}");
    assert!(raw.z_mm.max < 0.01 && raw.angle_deg.max < 0.01, "{raw:?}");
    assert!(p.raw.all.z_mm.max < 0.01);
    // Refinement snaps onto the catalog's rest poses: the physics rest differs a little.
    let refined = &p.refined.seed_style;
    assert!(
        refined.angle_deg.max < 0.5 && refined.z_mm.max < 0.1,
        "{refined:?}"
    );
    // Every exact estimate lands in the truth's stable pose (the flip may not: turning a part
    // that rests on a side about its z axis changes the resting face).
    for (f, frame) in run.frames.iter().enumerate() {
        for (d, det) in frame.detections.iter().enumerate() {
            if det.truth.is_some() && (f, d) != (1, 0) {
                assert!(det.stable_pose.is_some() && det.stable_pose == det.true_stable_pose);
            }
        }
    }
    assert!(p.stable_pose_right >= p.poses - 1, "{p:?}");
    // MSSD recall: every exact estimate, not the flip (its surface moves by about the part size).
    let hits = (p.poses - 1) as f64 / p.truths as f64;
    assert!(
        (p.raw.mssd_recall[0] - hits).abs() < 1e-12,
        "{:?}",
        p.raw.mssd_recall
    );
    // Table 1, seed-style: the flip counted, not summarised.
    let t = s
        .table1
        .iter()
        .find(|e| e.part == "average" && e.method == "pnp" && e.outliers_dropped)
        .unwrap();
    assert_eq!((t.row.n, t.row.outliers), (p.poses - 1, 1));
    let total = s.stages.iter().find(|t| t.stage == "total").unwrap();
    assert!((total.mean_ms - 20.0).abs() < 1e-9 && (s.frames_per_s - 50.0).abs() < 1e-9);

    let out = tmp.path().join("report");
    let meta = EvalMeta {
        dataset: root.clone(),
        split: split.clone(),
        catalog: workspace().join("scenarios/parts/usbc.toml"),
        models: PathBuf::from("none (ground truth)"),
        options,
    };
    let files = write_eval_report(&out, &meta, &s, &run).unwrap();
    let page = std::fs::read_to_string(&files.html).unwrap();
    assert!(page.contains("Table 1") && page.contains("seed paper"));
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&files.json).unwrap()).unwrap();
    assert_eq!(json["frames"].as_array().unwrap().len(), 2);
    assert_eq!(json["summary"]["pooled"]["false_positives"], 2);
    assert_eq!(run.gallery.len(), 3.min(p.poses));
    for item in &run.gallery {
        let png = image::open(out.join("gallery").join(item.file_name())).unwrap();
        assert_eq!((png.width(), png.height()), (256, 256));
        assert!(page.contains(&item.file_name()));
    }
    // Each miss and false positive has its picture: the missed truth outlined green, the false
    // detection yellow; the oracle's false detections overlap no instance.
    assert_eq!(run.missed.len(), expect.counted - expect.detected);
    assert_eq!(run.false_positives.len(), 2);
    for (item, colour, cause) in (run.missed.iter().map(|i| (i, [0, 230, 70], ""))).chain(
        run.false_positives
            .iter()
            .map(|i| (i, [255, 220, 0], "empty table")),
    ) {
        let png = image::open(out.join("gallery").join(item.file_name()))
            .unwrap()
            .to_rgb8();
        assert_eq!(png.dimensions(), (256, 256));
        assert!(png.pixels().any(|p| p.0 == colour), "{}", item.file_name());
        assert!(item.caption.contains(cause), "{}", item.caption);
        assert!(page.contains(&item.file_name()));
    }
    for plot in ["angle_cdf", "depth_cdf"] {
        let png = image::open(out.join("plots").join(format!("{plot}.png"))).unwrap();
        assert!(png.width() >= 800);
    }
    // Worst first: the flip.
    assert_eq!((run.gallery[0].image, run.gallery[0].detection), (1, 0));
    let keys: Vec<f64> = run.gallery.iter().map(|g| g.refined.mssd_mm).collect();
    assert!(keys.windows(2).all(|w| w[0] >= w[1]), "{keys:?}");
    // The BOP results file: one row per pose, each (but the flip's) on its ground truth.
    assert_eq!(files.bop_results, out.join("cell-learned_ds-test.csv"));
    let csv = std::fs::read_to_string(&files.bop_results).unwrap();
    let mut rows = csv.lines();
    assert_eq!(rows.next(), Some("scene_id,im_id,obj_id,score,R,t,time"));
    let rows: Vec<&str> = rows.collect();
    assert_eq!(rows.len(), p.poses, "the false detections have no pose");
    let bop = BopDataset::load(&root, &split).unwrap();
    let mut on_truth = 0;
    for row in &rows {
        let cols: Vec<&str> = row.split(',').collect();
        assert_eq!(cols.len(), 7, "{row}");
        let numbers = |c: &str| -> Vec<f64> { c.split(' ').map(|x| x.parse().unwrap()).collect() };
        let (r, t) = (numbers(cols[4]), numbers(cols[5]));
        let pose = pose_from_bop(&r.try_into().unwrap(), &t.try_into().unwrap()).unwrap();
        assert!(
            (cols[6].parse::<f64>().unwrap() - 0.02).abs() < 1e-9,
            "20 ms a frame"
        );
        let image = bop.scenes[cols[0].parse::<usize>().unwrap()]
            .images
            .iter()
            .find(|i| i.id == cols[1].parse::<usize>().unwrap())
            .unwrap();
        let obj_id: u32 = cols[2].parse().unwrap();
        on_truth += usize::from((0..image.gt.len()).any(|k| {
            let truth = image.camera_T_part(k).unwrap();
            image.gt[k].obj_id == obj_id
                && (pose.translation.vector - truth.translation.vector).norm() < 1e-4
                && pose.rotation.angle_to(&truth.rotation) < 0.5f64.to_radians()
        }));
    }
    assert_eq!(on_truth, p.poses - 1, "all but the flip");
    // The flip's picture shows the true outline (green) and the estimate's (magenta) apart.
    let has = |item: &GalleryItem, colour: [u8; 3]| item.crop.pixels().any(|p| p.0 == colour);
    assert!(has(&run.gallery[0], [0, 230, 70]) && has(&run.gallery[0], [255, 0, 255]));
    // The worst placed are parts in the right stable pose, not the flip.
    assert_eq!(run.misplaced.len(), 1, "capacity: a third of the gallery");
    for item in &run.misplaced {
        assert_eq!(Some(&item.stable_pose), item.true_stable_pose.as_ref());
        assert!(item.refined.angle_deg <= 10.0, "{:?}", item.refined);
        assert!(page.contains(&item.file_name()));
    }
}

#[test]
fn picks_need_room_for_the_open_fingers() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("ds");
    let catalog = catalog();
    tiny_dataset(&root, &catalog);
    let scenario = Scenario::load(&workspace().join("scenarios/usbc_nominal.toml")).unwrap();
    let fingers = FingerCheck::new(&scenario).unwrap();
    let checked = EvalOptions {
        finger_margin: Some(fingers.margin()),
        ..EvalOptions::default()
    };
    let split = resolve_split(&root, None);
    let dataset = EvalDataset::open(&root, &split, &catalog, &checked).unwrap();
    let (mut detector, _) = oracle(&root, &split, &catalog, &checked);
    let run = evaluate(&dataset, &mut detector, &checked, Some(&fingers), |_, _| {}).unwrap();
    let parts: Vec<(String, f64)> = dataset
        .parts
        .values()
        .map(|p| (p.name.clone(), p.diameter_mm))
        .collect();
    // The open fingers reach at most this far from the grasped part's origin, metres.
    let g = &scenario.spec.cell.gripper;
    let reach = (g.stroke / 2.0 + g.finger_thickness).hypot(g.finger_width / 2.0) + 0.005;
    let mut measured = 0;
    for f in &run.frames {
        let centres: Vec<Option<[f64; 3]>> = (f.detections.iter())
            .map(|d| d.pose.map(|p| p.t_mm))
            .collect();
        for (i, d) in f.detections.iter().enumerate() {
            let Some(clearance) = d.finger_clearance_mm else {
                assert!(!d.graspable || f.detections.len() == 1, "{d:?}");
                continue;
            };
            assert!(d.graspable && clearance >= 0.0, "{d:?}");
            measured += 1;
            // No nearer than the nearest other posed part's origin allows.
            let own = centres[i].unwrap();
            let nearest = (centres.iter().enumerate())
                .filter(|(j, _)| *j != i)
                .filter_map(|(_, c)| *c)
                .map(|c| (0..3).map(|a| (c[a] - own[a]).powi(2)).sum::<f64>().sqrt())
                .fold(f64::INFINITY, f64::min);
            assert!(
                clearance <= nearest + reach * 1e3,
                "{clearance} mm, {nearest} mm"
            );
        }
    }
    assert!(measured >= 4, "{measured} picks measured");
    // The same picks without the check: those without room are the difference.
    let unchecked = EvalOptions::default();
    let with = summarise(&run.frames, &parts, &checked).pooled.picks;
    let without = summarise(&run.frames, &parts, &unchecked).pooled.picks;
    assert_eq!(without.crowded, 0);
    assert_eq!(
        with.picks + with.crowded,
        without.picks,
        "{with:?} {without:?}"
    );
    // The cell's first pick: one per frame and part that has any pick at all.
    let margin_mm = fingers.margin() * 1e3;
    let wanted: usize = (run.frames.iter())
        .map(|f| {
            let mut picked: Vec<&str> = (f.detections.iter())
                .filter(|d| d.graspable && d.stable_pose.is_some())
                .filter(|d| d.confidence.is_some_and(|c| c >= checked.pick_confidence))
                .filter(|d| d.finger_clearance_mm.is_none_or(|c| c >= margin_mm))
                .filter(|d| d.truth.is_none_or(|t| !f.truths[t].ignored))
                .map(|d| d.part.as_str())
                .collect();
            picked.sort_unstable();
            picked.dedup();
            picked.len()
        })
        .sum();
    let first = summarise(&run.frames, &parts, &checked).pooled.first_picks;
    assert!(wanted >= 2, "{wanted} first picks");
    assert_eq!(first.picks, wanted, "{first:?}");
    assert_eq!(first.crowded, 0);
    // A wider margin than these sparse frames need turns the picks with less room away.
    let mut room: Vec<f64> = (run.frames.iter().flat_map(|f| &f.detections))
        .filter(|d| d.graspable && d.confidence.is_some_and(|c| c >= checked.pick_confidence))
        .filter_map(|d| d.finger_clearance_mm)
        .collect();
    room.sort_by(f64::total_cmp);
    let median = room[room.len() / 2];
    let wide = EvalOptions {
        finger_margin: Some(median / 1e3),
        ..checked
    };
    let crowded = summarise(&run.frames, &parts, &wide).pooled.picks;
    assert_eq!(crowded.crowded, room.len() / 2, "{room:?}");
    assert_eq!(crowded.picks + crowded.crowded, without.picks);
}

#[test]
fn bad_datasets_name_the_file() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("ds");
    let catalog = catalog();
    tiny_dataset(&root, &catalog);
    let options = EvalOptions::default();

    let err = EvalDataset::open(&root, "test_feeder", &catalog, &options).unwrap_err();
    let text = err.to_string();
    assert!(
        text.contains("test_feeder") && text.contains("no such split"),
        "{text}"
    );

    let gt = root.join("test/000000/scene_gt.json");
    let good = std::fs::read_to_string(&gt).unwrap();
    std::fs::write(&gt, good.replacen("\"obj_id\"", "\"obj_idx\"", 1)).unwrap();
    let text = EvalDataset::open(&root, "test", &catalog, &options)
        .unwrap_err()
        .to_string();
    assert!(
        text.contains("scene_gt.json") && text.contains("obj_id") && text.contains("line"),
        "{text}"
    );
    std::fs::write(&gt, &good).unwrap();

    // A catalog that does not match the dataset's models.
    let info = root.join("models/models_info.json");
    let good_info = std::fs::read_to_string(&info).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&good_info).unwrap();
    v["1"]["size_x"] = serde_json::json!(20.0);
    std::fs::write(&info, serde_json::to_string(&v).unwrap()).unwrap();
    let text = EvalDataset::open(&root, "test", &catalog, &options)
        .unwrap_err()
        .to_string();
    assert!(
        text.contains("models_info.json") && text.contains("size_x"),
        "{text}"
    );
    std::fs::write(&info, &good_info).unwrap();

    // A missing image fails when it is read, naming it.
    std::fs::remove_file(root.join("test/000000/rgb/000000.png")).unwrap();
    let dataset = EvalDataset::open(&root, "test", &catalog, &options).unwrap();
    let mut none = Oracle {
        frames: VecDeque::new(),
    };
    let text = evaluate(&dataset, &mut none, &options, None, |_, _| {})
        .unwrap_err()
        .to_string();
    assert!(text.contains("rgb/000000.png"), "{text}");
}
