//! The evaluation loop: per image, read the ground truth, run the detector, match its detections
//! to the truth, score the matched poses and offer the worst crops and the detection errors to
//! the galleries.

use std::collections::BTreeMap;

use nalgebra::{Isometry3, UnitQuaternion};
use perception::learned::{InstanceMask, LearnedDetections};
use perception::metrics::pose_errors;
use perception::planar::{PlanarConfig, PlanarPose, PlanarRefiner};
use perception::symmetry::{stable_pose_twins, symmetric_angle_round};
use perception::{Camera, FrameImage};
use sim::dataset::{BopImage, BopScene, pose_from_bop};

use super::causes::{false_positive_cause, miss_cause};
use super::detection_gallery::{DetectionErrorCrop, DetectionErrorKind, draw_window};
use super::fingers::FingerCheck;
use super::gallery::{self, FailedCrop, GalleryItem, GalleryKeeper};
use super::matching::{self, Candidate, Truth, greedy_match, mask_from_raster, touching_flags};
use super::{
    BopPose, DetectionOverlap, DetectionRecord, EvalDataset, EvalError, EvalOptions, EvalRun,
    FrameDetector, FrameRecord, PartData, StageMs, TruthOverlap, TruthRecord, camera_of,
};

/// Runs `detector` over the images of `dataset` (at most `options.limit`), calling `progress`
/// after each with (done, total).
pub fn evaluate(
    dataset: &EvalDataset,
    detector: &mut dyn FrameDetector,
    options: &EvalOptions,
    fingers: Option<&FingerCheck>,
    mut progress: impl FnMut(usize, usize),
) -> Result<EvalRun, EvalError> {
    options.validate()?;
    let total = dataset
        .images()
        .count()
        .min(options.limit.unwrap_or(usize::MAX));
    let mut frames = Vec::with_capacity(total);
    let mut galleries = Galleries {
        worst: GalleryKeeper::new(options.gallery),
        misplaced: GalleryKeeper::new(options.gallery.div_ceil(3)),
        failed: GalleryKeeper::new(options.gallery.div_ceil(3)),
        missed: GalleryKeeper::new(options.gallery.div_ceil(2)),
        false_positives: GalleryKeeper::new(options.gallery.div_ceil(2)),
    };
    for (i, (scene, image)) in dataset.images().take(total).enumerate() {
        frames.push(evaluate_image(
            dataset,
            scene,
            image,
            detector,
            options,
            fingers,
            &mut galleries,
        )?);
        progress(i + 1, total);
    }
    Ok(EvalRun {
        frames,
        gallery: galleries.worst.into_items(),
        misplaced: galleries.misplaced.into_items(),
        failures: galleries.failed.into_items(),
        missed: galleries.missed.into_items(),
        false_positives: galleries.false_positives.into_items(),
    })
}

/// The galleries one evaluation fills (see [`EvalRun`]).
struct Galleries {
    worst: GalleryKeeper,
    misplaced: GalleryKeeper,
    failed: GalleryKeeper<FailedCrop>,
    missed: GalleryKeeper<DetectionErrorCrop>,
    false_positives: GalleryKeeper<DetectionErrorCrop>,
}

/// A frame's ground truth as evaluation needs it, per instance in scene_gt.json order.
struct FrameTruth<'a> {
    /// The part.
    parts: Vec<&'a PartData>,
    /// Its pose in the camera frame.
    poses: Vec<Isometry3<f64>>,
    /// Its visible mask.
    masks: Vec<InstanceMask>,
    /// Its pose snapped onto the nearest stable pose (the refiner's class of the true pose).
    snapped: Vec<Option<PlanarPose>>,
    /// Its record (visibility, touching, resting, stable pose).
    records: Vec<TruthRecord>,
}

impl<'a> FrameTruth<'a> {
    /// Reads the ground truth of `image` (its masks from the scene's mask_visib).
    #[allow(non_snake_case)]
    fn read(
        dataset: &'a EvalDataset,
        scene: &BopScene,
        image: &BopImage,
        camera: &Camera,
        camera_T_table: &Isometry3<f64>,
        options: &EvalOptions,
    ) -> Result<Self, EvalError> {
        let mut truth_masks: Vec<InstanceMask> = Vec::with_capacity(image.gt.len());
        let mut truth_poses = Vec::with_capacity(image.gt.len());
        let mut truth_parts: Vec<&PartData> = Vec::with_capacity(image.gt.len());
        for (k, gt) in image.gt.iter().enumerate() {
            let part = dataset
                .parts
                .get(&gt.obj_id)
                .ok_or_else(|| EvalError::Mismatch {
                    path: scene.dir.join("scene_gt.json"),
                    message: format!(
                        "image {}: object {} is not a known part",
                        image.id, gt.obj_id
                    ),
                })?;
            let bits = scene.mask(image.id, k, true)?;
            if bits.len() != (camera.width * camera.height) as usize {
                return Err(EvalError::Mismatch {
                    path: scene
                        .dir
                        .join("mask_visib")
                        .join(format!("{:06}_{k:06}.png", image.id)),
                    message: format!("the mask is not {} × {}", camera.width, camera.height),
                });
            }
            truth_masks.push(mask_from_raster(&bits, camera.width, camera.height));
            truth_poses.push(
                image
                    .camera_T_part(k)
                    .expect("the reader checked rotations"),
            );
            truth_parts.push(part);
        }
        let touching = touching_flags(&truth_masks, options.touch_gap_px);
        // One refiner per part kind in view; the snap of each true pose gives its stable pose and
        // whether it rests there.
        let mut refiners: BTreeMap<u32, PlanarRefiner> = BTreeMap::new();
        for part in &truth_parts {
            if refiners.contains_key(&part.obj_id) {
                continue;
            }
            // Of symmetric twin stable poses (a peg on either end) the true pose is named as the
            // estimator names it: the one the part is grasped in.
            let refiner = PlanarRefiner::new(
                *camera_T_table,
                &part.stable_poses,
                &part.group,
                PlanarConfig::default(),
            )
            .map_err(|e| EvalError::Part {
                part: part.name.clone(),
                message: e.to_string(),
            })?
            .with_preferred(|c| part.graspable.contains(&part.stable_poses[c].name));
            refiners.insert(part.obj_id, refiner);
        }
        let snapped: Vec<Option<PlanarPose>> = truth_parts
            .iter()
            .zip(&truth_poses)
            .map(|(part, truth)| refiners[&part.obj_id].refine(truth).ok())
            .collect();
        let table_T_camera = camera_T_table.inverse();
        let rests = |k: usize| {
            snapped[k]
                .as_ref()
                .is_some_and(|p| p.rests(&(table_T_camera * truth_poses[k])))
        };
        let records: Vec<TruthRecord> = image
            .gt
            .iter()
            .enumerate()
            .map(|(k, _)| {
                let info = &image.info[k];
                TruthRecord {
                    part: truth_parts[k].name.clone(),
                    visib_fract: info.visib_fract,
                    visible_px: truth_masks[k].area(),
                    touching: touching[k],
                    ignored: info.visib_fract < options.min_visib_fract
                        || truth_masks[k].area() == 0,
                    resting: rests(k),
                    stable_pose: rests(k)
                        .then(|| snapped[k].as_ref())
                        .flatten()
                        .map(|p| truth_parts[k].stable_poses[p.class].name.clone()),
                    detection: None,
                    closest: None,
                }
            })
            .collect();
        Ok(Self {
            parts: truth_parts,
            poses: truth_poses,
            masks: truth_masks,
            snapped,
            records,
        })
    }
}

/// Evaluates one image.
#[allow(non_snake_case)]
fn evaluate_image(
    dataset: &EvalDataset,
    scene: &BopScene,
    image: &BopImage,
    detector: &mut dyn FrameDetector,
    options: &EvalOptions,
    fingers: Option<&FingerCheck>,
    galleries: &mut Galleries,
) -> Result<FrameRecord, EvalError> {
    let scene_camera = scene.dir.join("scene_camera.json");
    let at = |message: String| EvalError::Mismatch {
        path: scene_camera.clone(),
        message: format!("image {}: {message}", image.id),
    };
    let camera = camera_of(&image.camera).map_err(at)?;
    let camera_T_table = pose_from_bop(&image.camera.cam_R_w2c, &image.camera.cam_t_w2c)
        .ok_or_else(|| at("cam_R_w2c is not a rotation".into()))?;
    let rgb = scene.rgb(image.id)?;
    if (rgb.width(), rgb.height()) != (camera.width, camera.height) {
        return Err(EvalError::Mismatch {
            path: scene.dir.join("rgb").join(format!("{:06}.png", image.id)),
            message: format!(
                "the image is {} × {} but scene_camera.json gives {} × {}",
                rgb.width(),
                rgb.height(),
                camera.width,
                camera.height
            ),
        });
    }

    let FrameTruth {
        parts: truth_parts,
        poses: truth_poses,
        masks: truth_masks,
        snapped,
        records: mut truths,
    } = FrameTruth::read(dataset, scene, image, &camera, &camera_T_table, options)?;

    let frame_image = FrameImage::full(image::DynamicImage::ImageRgb8(rgb));
    let found = match detector.detect(&frame_image, &camera, &camera_T_table) {
        Ok(found) => found,
        Err(message) => {
            return Ok(FrameRecord {
                scene: scene.id,
                image: image.id,
                failure: Some(message),
                times: None,
                truths,
                detections: Vec::new(),
            });
        }
    };

    let candidates: Vec<Candidate<'_>> = found
        .detections
        .iter()
        .map(|d| Candidate {
            part: &d.part,
            score: d.score,
            mask: &d.mask,
        })
        .collect();
    let truth_refs: Vec<Truth<'_>> = truths
        .iter()
        .zip(&truth_masks)
        .map(|(t, m)| Truth {
            part: &t.part,
            mask: m,
        })
        .collect();
    let matches = greedy_match(&candidates, &truth_refs, options.min_iou);
    // Why each miss was missed: the detection overlapping it most, of any part.
    let mut matched = vec![false; truths.len()];
    for m in matches.iter().flatten() {
        matched[m.truth] = true;
    }
    for ((truth, mask), _) in truths
        .iter_mut()
        .zip(&truth_masks)
        .zip(&matched)
        .filter(|(_, m)| !**m)
    {
        truth.closest = matching::most_overlapping(candidates.iter().map(|c| c.mask), mask)
            .map(|(detection, iou)| DetectionOverlap { detection, iou });
    }

    // Why each false positive is one: the truth its mask overlaps most, of any part.
    let closest_truth = |c: &Candidate<'_>| {
        matching::most_overlapping(truth_masks.iter(), c.mask)
            .map(|(truth, iou)| TruthOverlap { truth, iou })
    };
    let clearances = fingers.map(|f| f.clearances(&found, &camera, &camera_T_table));
    let mut detections = Vec::with_capacity(found.detections.len());
    for (d, (det, m)) in found.detections.iter().zip(&matches).enumerate() {
        let own_part = dataset.parts.values().find(|p| p.name == det.part);
        let mut rec = DetectionRecord {
            closest_truth: m.is_none().then(|| closest_truth(&candidates[d])).flatten(),
            obj_id: own_part.map(|p| p.obj_id),
            graspable: det
                .pose
                .as_ref()
                .is_ok_and(|p| own_part.is_some_and(|own| own.graspable.contains(&p.stable_pose))),
            finger_clearance_mm: clearances.as_ref().and_then(|c| c[d]).map(|c| c * 1e3),
            part: det.part.clone(),
            score: det.score,
            crop_origin: det.crop_origin,
            keypoints_px: det
                .keypoints
                .iter()
                .map(|k| [k.position.x, k.position.y])
                .collect(),
            keypoint_covariances_px: det
                .keypoints
                .iter()
                .map(|k| {
                    let c = k.covariance;
                    [c[(0, 0)], c[(0, 1)], c[(1, 1)]]
                })
                .collect(),
            truth: m.map(|m| m.truth),
            iou: m.map(|m| m.iou),
            pose_failure: det.pose.as_ref().err().cloned(),
            raw: None,
            refined: None,
            stable_pose: det.pose.as_ref().ok().map(|p| p.stable_pose.clone()),
            true_stable_pose: None,
            raw_flip_deg: None,
            refined_flip_deg: None,
            contour_support: None,
            confidence: det.confidence(),
            keypoint_refined: None,
            pose: det
                .pose
                .as_ref()
                .ok()
                .map(|p| BopPose::of(&p.planar.camera_T_part)),
        };
        if let Some(m) = m {
            truths[m.truth].detection = Some(d);
            let part = truth_parts[m.truth];
            let truth = &truth_poses[m.truth];
            // The class the refiner assigns to the true pose is the true stable pose.
            rec.true_stable_pose = snapped[m.truth]
                .as_ref()
                .map(|p| part.stable_poses[p.class].name.clone());
            // An estimate in a twin of the true stable pose found the same resting state: the
            // truth is named as the estimate names it, in the detection and the truth records.
            if let (Some(true_pose), Ok(estimate)) = (&rec.true_stable_pose, &det.pose)
                && det.part == part.name
                && let Some(twin) = twin_name(part, true_pose, &estimate.stable_pose)
            {
                rec.true_stable_pose = Some(twin.clone());
                let counted = &mut truths[m.truth];
                if counted.stable_pose.is_some() {
                    counted.stable_pose = Some(twin);
                }
            }
            if let (Err(reason), false) = (&det.pose, truths[m.truth].ignored) {
                galleries.failed.offer(det.score, || FailedCrop {
                    scene: scene.id,
                    image: image.id,
                    detection: d,
                    part: part.name.clone(),
                    score: det.score,
                    iou: m.iou,
                    reason: reason.clone(),
                    crop: gallery::draw_crop(&frame_image.pixels, &camera, det, part, truth, None),
                });
            }
            // A part resting in a stable pose whose view repeats on a turn is scored against the
            // turn of its true pose nearest each estimate: vision cannot tell those apart.
            let turns: &[UnitQuaternion<f64>] = match (&snapped[m.truth], truths[m.truth].resting) {
                (Some(p), true) => &part.view_turns[p.class],
                _ => &[],
            };
            let seen = |est: &Isometry3<f64>| seen_truth(truth, turns, est);
            let flip = |est: &Isometry3<f64>| {
                let (group, round) = (&part.near_group, &part.round_axes);
                symmetric_angle_round(&est.rotation, &seen(est).rotation, group, round).to_degrees()
            };
            // Raw PnP is reported for every estimate, also one the reprojection gate refused
            // (the paper's Table 1 is ungated PnP); refined figures only for accepted poses.
            if let Some(estimate) = det.pose.as_ref().ok().or(det.refused.as_ref()) {
                let raw = &estimate.pnp.camera_T_part;
                rec.raw = Some(pose_errors(
                    &camera,
                    &part.points,
                    &part.group,
                    &part.round_axes,
                    &seen(raw),
                    raw,
                ));
                rec.raw_flip_deg = Some(flip(raw));
            }
            if let (Ok(pose), Some(raw_e)) = (&det.pose, rec.raw) {
                let refined = &pose.planar.camera_T_part;
                let truth = &seen(refined);
                let refined_e = pose_errors(
                    &camera,
                    &part.points,
                    &part.group,
                    &part.round_axes,
                    truth,
                    refined,
                );
                rec.refined_flip_deg = Some(flip(refined));
                rec.refined = Some(refined_e);
                if let Some(c) = &pose.contour {
                    rec.contour_support = Some(c.fit.support);
                    rec.keypoint_refined = Some(pose_errors(
                        &camera,
                        &part.points,
                        &part.group,
                        &part.round_axes,
                        &seen(&c.keypoint_planar.camera_T_part),
                        &c.keypoint_planar.camera_T_part,
                    ));
                }
                let item = || GalleryItem {
                    scene: scene.id,
                    image: image.id,
                    detection: d,
                    part: part.name.clone(),
                    iou: m.iou,
                    raw: raw_e,
                    refined: refined_e,
                    stable_pose: pose.stable_pose.clone(),
                    true_stable_pose: rec.true_stable_pose.clone(),
                    crop: gallery::draw_crop(
                        &frame_image.pixels,
                        &camera,
                        det,
                        part,
                        truth,
                        Some(refined),
                    ),
                };
                let counted = &truths[m.truth];
                if !counted.ignored {
                    galleries.worst.offer(refined_e.mssd_mm, item);
                    if counted.resting
                        && rec.true_stable_pose.as_ref() == Some(&pose.stable_pose)
                        && refined_e.sym_angle_deg <= options.outlier_deg
                    {
                        galleries
                            .misplaced
                            .offer(refined_e.x_mm.hypot(refined_e.y_mm), item);
                    }
                }
            }
        }
        detections.push(rec);
    }
    offer_detection_errors(
        galleries,
        (scene.id, image.id),
        &frame_image.pixels,
        (&truths, &truth_masks),
        (&detections, &found),
        options.min_iou,
    );
    Ok(FrameRecord {
        scene: scene.id,
        image: image.id,
        failure: None,
        times: Some(StageMs::from(&found.times)),
        truths,
        detections,
    })
}

/// Offers the frame's missed instances (the most visible first) and false positives (the
/// highest score first) to their galleries, each captioned with its cause.
fn offer_detection_errors(
    galleries: &mut Galleries,
    (scene, image): (usize, usize),
    pixels: &image::DynamicImage,
    (truths, truth_masks): (&[TruthRecord], &[InstanceMask]),
    (records, found): (&[DetectionRecord], &LearnedDetections),
    min_iou: f64,
) {
    let masks: Vec<&InstanceMask> = found.detections.iter().map(|d| &d.mask).collect();
    let others = |own: Option<usize>| -> Vec<&InstanceMask> {
        (masks.iter().enumerate())
            .filter(|(i, _)| Some(*i) != own)
            .map(|(_, m)| *m)
            .collect()
    };
    for (k, t) in truths.iter().enumerate() {
        if t.ignored || t.detection.is_some() {
            continue;
        }
        let closest = t.closest.and_then(|c| Some((records.get(c.detection)?, c)));
        let cause = miss_cause(&t.part, closest.map(|(d, c)| (&d.part, c.iou)), min_iou);
        let caption = match closest {
            Some((d, c)) => format!(
                "{}: the {} detection {} overlaps it most (IoU {:.2})",
                cause.describe(),
                d.part,
                c.detection,
                c.iou
            ),
            None => cause.describe().to_string(),
        };
        let near = closest.map(|(_, c)| c.detection);
        galleries
            .missed
            .offer(t.visible_px as f64, || DetectionErrorCrop {
                scene,
                image,
                kind: DetectionErrorKind::Missed,
                index: k,
                part: t.part.clone(),
                caption: format!("{caption}; {:.0} % visible", 100.0 * t.visib_fract),
                crop: draw_window(
                    pixels,
                    &truth_masks[k],
                    Some(&truth_masks[k]),
                    near.map(|d| masks[d]),
                    &others(near),
                ),
            });
    }
    for (i, d) in records
        .iter()
        .enumerate()
        .filter(|(_, d)| d.truth.is_none())
    {
        let cause = false_positive_cause(d, truths, min_iou);
        let closest = d.closest_truth.filter(|c| c.truth < truth_masks.len());
        let caption = match closest {
            Some(c) => format!(
                "{}: overlaps the {} truth {} most (IoU {:.2}); score {:.2}",
                cause.describe(),
                truths[c.truth].part,
                c.truth,
                c.iou,
                d.score
            ),
            None => format!("{}; score {:.2}", cause.describe(), d.score),
        };
        galleries
            .false_positives
            .offer(d.score, || DetectionErrorCrop {
                scene,
                image,
                kind: DetectionErrorKind::FalsePositive,
                index: i,
                part: d.part.clone(),
                caption,
                crop: draw_window(
                    pixels,
                    masks[i],
                    closest.map(|c| &truth_masks[c.truth]),
                    Some(masks[i]),
                    &others(Some(i)),
                ),
            });
    }
}

/// `truth`, or the turn of it (`turns`, part frame) nearest `estimate` in rotation.
fn seen_truth(
    truth: &Isometry3<f64>,
    turns: &[UnitQuaternion<f64>],
    estimate: &Isometry3<f64>,
) -> Isometry3<f64> {
    turns
        .iter()
        .map(|g| truth * Isometry3::from_parts(Default::default(), *g))
        .min_by(|a, b| {
            let d = |t: &Isometry3<f64>| t.rotation.angle_to(&estimate.rotation);
            d(a).total_cmp(&d(b))
        })
        .unwrap_or(*truth)
}

/// `estimate`'s name when the stable pose it names is a symmetric twin of the one named `truth`
/// (a distinct class that the part's exact symmetries map onto it: the same resting state).
fn twin_name(part: &PartData, truth: &str, estimate: &str) -> Option<String> {
    if truth == estimate || part.group.len() < 2 {
        return None;
    }
    let named = |name: &str| part.stable_poses.iter().find(|s| s.name == name);
    let (t, e) = (named(truth)?, named(estimate)?);
    stable_pose_twins(t, e, &part.group).then(|| e.name.clone())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, Vector3};
    use perception::part::{StablePose, Symmetry};
    use perception::symmetry::symmetry_group;

    #[test]
    fn a_twin_stable_pose_is_named_as_the_estimate_only_for_a_symmetric_part() {
        let pose = |name: &str, up: [f64; 3], h: f64| StablePose {
            name: name.into(),
            probability: 0.2,
            up_in_part: up,
            rotation: [0.0; 3],
            rest_height: h,
        };
        let poses = vec![
            pose("+z", [0.0, 0.0, 1.0], 0.006),
            pose("-z", [0.0, 0.0, -1.0], 0.006),
            pose("+x", [1.0, 0.0, 0.0], 0.004),
            pose("+y", [0.0, 1.0, 0.0], 0.004),
        ];
        let square_peg = [
            Symmetry {
                axis: [0.0, 0.0, 1.0],
                order: 4,
                exact: true,
            },
            Symmetry {
                axis: [1.0, 0.0, 0.0],
                order: 2,
                exact: true,
            },
        ];
        let part = |symmetries: &[Symmetry]| PartData {
            name: "square_8".into(),
            obj_id: 1,
            keypoints: vec![],
            points: vec![],
            group: symmetry_group(symmetries),
            near_group: symmetry_group(symmetries),
            round_axes: vec![],
            stable_poses: poses.clone(),
            view_turns: vec![],
            graspable: vec!["+z".into()],
            diameter_mm: 10.0,
            outline: perception::contour::PartOutline::new(&sim::cad::nist::PEGS[3].mesh()),
        };
        let peg = part(&square_peg);
        assert_eq!(twin_name(&peg, "-z", "+z").as_deref(), Some("+z"));
        assert_eq!(twin_name(&peg, "+y", "+x").as_deref(), Some("+x"));
        assert_eq!(twin_name(&peg, "+z", "+x"), None, "an end is not a side");
        assert_eq!(
            twin_name(&peg, "+z", "+z"),
            None,
            "the same name needs none"
        );
        // Without exact symmetries a flipped part lies in another stable pose.
        let plain = part(&[]);
        assert_eq!(twin_name(&plain, "-z", "+z"), None);
        let near = [Symmetry {
            exact: false,
            ..square_peg[0].clone()
        }];
        assert_eq!(twin_name(&part(&near), "+y", "+x"), None);
    }

    #[test]
    fn a_truth_is_seen_as_its_turn_nearest_the_estimate() {
        let truth = Isometry3::from_parts(
            Translation3::new(0.01, 0.02, 1.5),
            UnitQuaternion::from_euler_angles(3.0, 0.1, 0.2),
        );
        let quarter = |k: f64| {
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), k * std::f64::consts::FRAC_PI_2)
        };
        let turns: Vec<_> = (0..4).map(|k| quarter(k as f64)).collect();
        // An estimate 3 quarter turns and 0.01 rad off the truth is 0.01 rad off its third turn.
        let estimate = truth * Isometry3::from_parts(Default::default(), quarter(3.01));
        let seen = seen_truth(&truth, &turns, &estimate);
        assert!(
            (seen.rotation.angle_to(&estimate.rotation) - 0.005 * std::f64::consts::PI).abs()
                < 1e-9
        );
        assert_eq!(seen.translation, truth.translation);
        // Without turns the truth stands.
        assert_eq!(seen_truth(&truth, &[], &estimate), truth);
    }
}
