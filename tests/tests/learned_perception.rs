//! The learned pipeline end to end on rendered feeder frames: a dozen parts dropped close together
//! (several touching), rendered at full resolution through the window covering them and passed
//! through the simulated sensor, then perceived from pixels only. Nearly every part must be detected
//! with its pose within bounds measured on these frames.
//!
//! Runs with the committed models (`scenarios/models/usbc/`, or `LEARNED_MODELS_DIR`); without
//! them it says so and passes.
//! `cargo test -p cell-tests --test learned_perception -- --ignored` rewrites the benchmark frame
//! (`perception/tests/data/learned/feeder.png` + `feeder.toml`).

mod feeder_support;

use std::path::Path;

use cell::orchestrator::UnposedObstacle;
use cell_tests::repo_root;
use feeder_support::{catalog, render_feeder, snapped};
use nalgebra::{Isometry3, Point3};
use parry3d_f64::math::Pose;
use perception::learned::{LearnedModels, LearnedPerception, LearnedPipeline};
use perception::onnx::Runtime;
use perception::part::Catalog;
use perception::symmetry::view_turns;
use perception::{Frame, FrameContent, PartPerception};
use sim::convert::vec_from_point;

/// The pipeline with the committed models, or `None` (with a note) when they are not in the tree
/// yet.
fn committed_pipeline(catalog: &Catalog) -> Option<LearnedPipeline> {
    let dir = LearnedModels::dir_from_env();
    if !dir.join("segmenter.toml").exists() {
        eprintln!(
            "no trained models in {}: the learned end-to-end test has nothing to run",
            dir.display()
        );
        return None;
    }
    let models = LearnedModels::in_dir(&dir).unwrap_or_else(|e| panic!("{e}"));
    let runtime = Runtime::get().unwrap_or_else(|e| panic!("{e}"));
    Some(LearnedPipeline::load(&models, catalog, &runtime).unwrap_or_else(|e| panic!("{e}")))
}

#[test]
#[allow(non_snake_case)]
fn learned_perception_finds_every_feeder_part_from_pixels() {
    let catalog = catalog();
    let Some(pipeline) = committed_pipeline(&catalog) else {
        return;
    };
    // The table is the base frame here: base_T_camera = table_T_camera.
    let mut perception = LearnedPerception::new(pipeline, Isometry3::identity());
    let (mut found, mut parts, mut accepted) = (0, 0, 0);
    // Detections without a pose matched to a part, and those whose space holds its origin.
    let (mut unposed_parts, mut unposed_held) = (0, 0);
    let mut centre_px = Vec::new();
    // Per found part, the median over its nine keypoints of the distance to the projected truth.
    let mut keypoints_px = Vec::new();
    for seed in 11..23 {
        let feeder = render_feeder(&catalog, seed);
        let frame = Frame {
            camera: feeder.camera,
            base_T_camera: feeder.table_T_camera,
            content: FrameContent::Image(feeder.image.clone()),
        };
        let camera_T_table = feeder.table_T_camera.inverse();
        // What each stage found, for the log.
        let stages = perception
            .pipeline()
            .detect(&feeder.image, &feeder.camera, &camera_T_table, None)
            .unwrap_or_else(|e| panic!("{e}"));
        for d in &stages.detections {
            eprintln!(
                "seed {seed}: {} score {:.2} at ({:.0}, {:.0}), {} mask px: {}",
                d.part,
                d.score,
                d.centre[0],
                d.centre[1],
                d.mask.area(),
                match &d.pose {
                    Ok(p) => format!("{} rms {:.2} px", p.stable_pose, p.rms_px),
                    Err(e) => e.clone(),
                }
            );
        }
        eprintln!("seed {seed}: {:?}", stages.times);
        // Segmentation and grouping: a part is found when an instance of its class has its
        // voted centre within 16 px of the projected part origin; its centre keypoint (voted from
        // the keypoint net's field) is then compared with that projection.
        let mut missed = Vec::new();
        for (part, table_T_part) in &feeder.truth {
            let origin = Point3::from((camera_T_table * table_T_part).translation.vector);
            let px = feeder.camera.project(&origin).unwrap();
            let near = |x: f64, y: f64| ((x - px.x).powi(2) + (y - px.y).powi(2)).sqrt();
            let hit = stages
                .detections
                .iter()
                .filter(|d| &d.part == part && near(d.centre[0], d.centre[1]) < 16.0)
                .min_by(|a, b| {
                    near(a.centre[0], a.centre[1]).total_cmp(&near(b.centre[0], b.centre[1]))
                });
            match hit {
                Some(d) => {
                    found += 1;
                    if let Some(c) = d.keypoints.last() {
                        centre_px.push(near(c.position.x, c.position.y));
                    }
                    let spec = catalog.part(part).expect("a catalog part");
                    let mut errs: Vec<f64> = spec
                        .keypoints
                        .iter()
                        .zip(&d.keypoints)
                        .map(|(k, v)| {
                            let p = camera_T_table * table_T_part * Point3::from(*k);
                            let px = feeder.camera.project(&p).unwrap();
                            (v.position - px).norm()
                        })
                        .collect();
                    if !errs.is_empty() {
                        errs.sort_by(f64::total_cmp);
                        keypoints_px.push(errs[errs.len() / 2]);
                    }
                    accepted += usize::from(d.pose.is_ok());
                }
                None => missed.push(format!("{part} at ({:.0}, {:.0})", px.x, px.y)),
            }
        }
        eprintln!("seed {seed}: not found {missed:?}");
        // Through the seam: exactly the instances with an accepted pose become detected parts.
        let seen = perception
            .perceive(&frame)
            .unwrap_or_else(|e| panic!("{e}"));
        let posed = stages.detections.iter().filter(|d| d.pose.is_ok()).count();
        assert_eq!(seen.parts.len(), posed, "seed {seed}");
        // The rest come out as the space they may take up, and that space holds the part.
        let unposed: Vec<_> = stages
            .detections
            .iter()
            .filter(|d| d.pose.is_err())
            .collect();
        assert_eq!(seen.unposed.len(), unposed.len(), "seed {seed}");
        for (d, u) in unposed.iter().zip(&seen.unposed) {
            assert_eq!(d.part, u.part, "seed {seed}");
            let obstacle = UnposedObstacle::new(u, &Isometry3::identity())
                .unwrap_or_else(|| panic!("seed {seed}: the {} spans no volume", u.part));
            // Its part: the truth of its class whose projected origin is nearest its centre.
            let truth = feeder
                .truth
                .iter()
                .filter(|(part, _)| part == &d.part)
                .map(|(_, table_T_part)| {
                    let origin = camera_T_table * Point3::from(table_T_part.translation.vector);
                    let px = feeder.camera.project(&origin).unwrap();
                    let off = (px.x - d.centre[0]).hypot(px.y - d.centre[1]);
                    (off, table_T_part)
                })
                .min_by(|a, b| a.0.total_cmp(&b.0));
            if let Some((off, table_T_part)) = truth.filter(|(off, _)| *off < 16.0) {
                let origin = vec_from_point(&Point3::from(table_T_part.translation.vector));
                let held = obstacle.hull.contains_point(&Pose::IDENTITY, origin);
                eprintln!(
                    "seed {seed}: unposed {} {off:.1} px from its truth, which it holds: {held}",
                    d.part
                );
                unposed_parts += 1;
                unposed_held += usize::from(held);
            }
        }
        parts += feeder.truth.len();
        // At most two more instances than parts (a part split in two, a neighbour's edge):
        // seed 17 has 14 detections of 12 parts, 13 before the drops weighed each part as itself.
        assert!(
            stages.detections.len() <= feeder.truth.len() + 2,
            "seed {seed}: {} detections of {} parts",
            stages.detections.len(),
            feeder.truth.len()
        );
    }
    centre_px.sort_by(f64::total_cmp);
    let median = centre_px[centre_px.len() / 2];
    keypoints_px.sort_by(f64::total_cmp);
    let keypoints_median = keypoints_px[keypoints_px.len() / 2];
    eprintln!(
        "{found} of {parts} parts found; centre keypoint median {median:.2} px, max {:.2} px; \
         all nine keypoints median {keypoints_median:.2} px; {accepted} poses under the \
         reprojection gate",
        centre_px.last().copied().unwrap_or(f64::NAN)
    );
    eprintln!("{unposed_held} of {unposed_parts} unposed parts held by their space");
    assert!(found >= MIN_FOUND, "{found} of {parts} parts found");
    assert!(
        unposed_held as f64 >= MIN_UNPOSED_HELD * unposed_parts as f64,
        "{unposed_held} of {unposed_parts} unposed parts held by their space"
    );
    assert!(
        accepted >= MIN_ACCEPTED,
        "{accepted} poses under the reprojection gate"
    );
    assert!(
        median <= CENTRE_MEDIAN_PX,
        "centre keypoint median {median:.2} px"
    );
    assert!(
        keypoints_median <= KEYPOINTS_MEDIAN_PX,
        "all nine keypoints: median {keypoints_median:.2} px"
    );
}

// Bounds measured with the committed models on 12 frames. The CPU-trained pair (2026-11-25):
// 131 of 144 parts found (the misses: parts mostly under others), centre keypoint median
// 3.10 px, all nine keypoints median 12.5 px (the keypoint net's own test crops: 5.9 px), 9 poses
// under the pipeline's default 4 px reprojection gate (the learned scenario runs at 12 px:
// e2e_learned). The GPU-trained pair (2026-11-26: the segmenter from scratch, the keypoint net a
// fourth cycle; test crops 4.8 px): 136 found, 2.74 px, 11.5 px, 25 poses under the gate. The
// wider segmenter with class-wise grouping (2026-11-26): 137 found, 2.92 px, 10.9 px, 25 poses;
// 46 once upside-down insert molds are posed by their outline. Since the drops weigh each part
// as itself (2026-11-27; before, as its filled hull), these 12 frames hold other scenes: 136
// found, 3.01 px, 10.95 px, 32 poses, 103 of 104 unposed parts held; with the keypoint net's
// fifth cycle (2026-11-27, on the fixed drops): 136, 3.03 px, 10.67 px, 30 poses. Since the
// drops' contacts between parts are stiff (2026-11-27; before, heaped parts sank up to 3 mm
// into each other), other scenes again: 137 found, 2.79 px, 8.80 px, 31 poses, 104 of 106
// unposed parts held. The pair of 2026-11-30 (a cycle on the randomisation families, then on
// those and our plain look): 136 found, 2.72 px, 9.05 px, 33 poses, 102 of 103 held; its
// keypoint net before the plain look's cycle failed here (3.50 px, 10.65 px).
const MIN_FOUND: usize = 135;
const CENTRE_MEDIAN_PX: f64 = 3.1;
const KEYPOINTS_MEDIAN_PX: f64 = 10.0;
const MIN_ACCEPTED: usize = 20;
/// Share of the detections without a pose (matched to a part) whose space on the table, the one
/// the cell keeps its fingers out of, holds the part's origin: 89 of 90 (2026-11-27).
const MIN_UNPOSED_HELD: f64 = 0.97;

/// Upside down, an insert mold shows only its plain floor, a square: the keypoint net has nothing
/// to place keypoints by and the reprojection gate refuses them, so the outline alone poses the
/// part. Nearly every such part must be posed so, in place and turned right up to a quarter turn
/// (which no camera can tell apart); the outline poses of parts resting otherwise are counted.
#[test]
#[allow(non_snake_case)]
fn upside_down_insert_molds_are_posed_by_their_outline() {
    let catalog = catalog();
    let Some(mut pipeline) = committed_pipeline(&catalog) else {
        return;
    };
    let spec = catalog.part("insert_mold").expect("a catalog part");
    let turns = view_turns(spec.stable_pose("-z").expect("an upside-down pose"), 4);
    let (mut upside_down, mut right, mut other) = (0, 0, 0);
    for seed in 11..35 {
        let feeder = render_feeder(&catalog, seed);
        let camera_T_table = feeder.table_T_camera.inverse();
        let resting_upside_down = |part: &str, table_T_part: &Isometry3<f64>| {
            let snap = snapped(&catalog, &camera_T_table, part, table_T_part);
            part == "insert_mold"
                && spec.stable_poses[snap.class].name == "-z"
                && snap.rests(table_T_part)
        };
        upside_down += feeder
            .truth
            .iter()
            .filter(|(p, t)| resting_upside_down(p, t))
            .count();
        let found = pipeline
            .detect(&feeder.image, &feeder.camera, &camera_T_table, None)
            .unwrap_or_else(|e| panic!("{e}"));
        for d in &found.detections {
            let Ok(pose) = &d.pose else { continue };
            let Some(fit) = pose.contour.as_ref().filter(|c| c.outline_only) else {
                continue;
            };
            assert_eq!(pose.stable_pose, "-z", "seed {seed}: {}", d.part);
            let estimate = feeder.table_T_camera * pose.planar.camera_T_part;
            let (part, truth) = feeder
                .truth
                .iter()
                .min_by(|a, b| {
                    let d = |t: &Isometry3<f64>| {
                        (t.translation.vector - estimate.translation.vector).norm()
                    };
                    d(&a.1).total_cmp(&d(&b.1))
                })
                .expect("parts were dropped");
            let mm = 1e3
                * (truth.translation.vector - estimate.translation.vector)
                    .xy()
                    .norm();
            let deg = turns
                .iter()
                .map(|g| {
                    (truth.rotation * g)
                        .angle_to(&estimate.rotation)
                        .to_degrees()
                })
                .fold(f64::INFINITY, f64::min);
            let rests = resting_upside_down(part, truth);
            eprintln!(
                "seed {seed}: {} posed upside down by its outline (support {:.2}), {mm:.3} mm and \
                 {deg:.2}° from the {part}{}",
                d.part,
                fit.fit.support,
                if rests {
                    " resting upside down"
                } else {
                    ", which rests otherwise"
                }
            );
            if rests {
                assert!(mm < MAX_OUTLINE_MM && deg < MAX_OUTLINE_DEG, "seed {seed}");
                right += 1;
            } else {
                other += 1;
            }
        }
    }
    eprintln!(
        "{right} of {upside_down} upside-down insert molds posed by their outline; {other} \
         outline poses of parts resting otherwise"
    );
    assert!(right >= MIN_OUTLINE_RIGHT, "{right} of {upside_down}");
    assert!(
        other <= MAX_OUTLINE_OTHER,
        "{other} outline poses of parts resting otherwise"
    );
}

// Measured on frames 11–34 (2026-11-27, the drops weighing each part as itself, the keypoint
// net's fifth cycle): all 12 upside-down insert molds posed by their outline, within 0.121 mm and
// 0.38° up to a quarter turn; 14 more outline poses are of insert molds resting otherwise: 7
// leaning on a neighbour (22–42°, whose outline from above is nearly square too), 5 face up
// (135–180° off: their keypoints missed the gate too) and 2 lying on an edge about 1° off their
// pose (13 with the fourth cycle). A known weakness: the outline's support cannot tell these
// apart. On frames 11–22 with the drops weighing parts as their filled hulls (2026-11-26), the
// scenes held 19 upside-down insert molds, all posed, and 2 leaning ones posed so; the same
// frames now hold 6 and 7. Since the drops' contacts between parts are stiff (2026-11-27) the
// frames hold 15 upside-down insert molds, all posed so, and 7 outline poses of insert molds
// resting otherwise.
const MIN_OUTLINE_RIGHT: usize = 14;
const MAX_OUTLINE_OTHER: usize = 8;
const MAX_OUTLINE_MM: f64 = 0.15;
const MAX_OUTLINE_DEG: f64 = 1.0;

#[test]
#[ignore = "rewrites the benchmark frame in perception/tests/data/learned"]
#[allow(non_snake_case)]
fn write_the_benchmark_feeder_frame() {
    let catalog = catalog();
    let feeder = render_feeder(&catalog, 11);
    let dir = repo_root().join("perception/tests/data/learned");
    std::fs::create_dir_all(&dir).unwrap();
    feeder.image.pixels.save(dir.join("feeder.png")).unwrap();
    let camera_T_table = feeder.table_T_camera.inverse();
    let t = camera_T_table.translation.vector;
    let q = camera_T_table.rotation.quaternion();
    let text = format!(
        "# The benchmark feeder frame (feeder.png), written by\n\
         # `cargo test -p cell-tests --test learned_perception -- --ignored`: {} parts, Basler seed camera.\n\
         origin = [{}, {}]\n\
         camera_T_table_translation = [{:.9}, {:.9}, {:.9}]\n\
         camera_T_table_quaternion_xyzw = [{:.12}, {:.12}, {:.12}, {:.12}]\n",
        feeder.truth.len(),
        feeder.image.origin[0],
        feeder.image.origin[1],
        t.x,
        t.y,
        t.z,
        q.i,
        q.j,
        q.k,
        q.w
    );
    std::fs::write(dir.join("feeder.toml"), text).unwrap();
    let size = std::fs::metadata(dir.join("feeder.png")).unwrap().len();
    eprintln!(
        "wrote {} ({size} bytes, {} × {})",
        Path::new("perception/tests/data/learned/feeder.png").display(),
        feeder.image.width(),
        feeder.image.height()
    );
    assert!(size < 1 << 20, "the frame is {size} bytes");
}
