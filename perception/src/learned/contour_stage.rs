//! The learned pipeline's last stage: each keypoint estimate is aligned on the part's outline in
//! the frame (and, for a near-symmetric part, so is its turned twin; the one whose outline finds
//! the edges is kept).

use std::f64::consts::PI;

use nalgebra::{Isometry3, UnitQuaternion};

use crate::Camera;
use crate::contour::{
    ContourAligner, ContourConfig, ContourFit, ContourView, FinalEdge, GreyPatch, Owner,
    PartOutline,
};
use crate::estimate::{PoseEstimate, PoseEstimator};
use crate::frame::FrameImage;
use crate::part::{PartSpec, TriMesh};
use crate::planar::{ClassSet, PlanarRefiner, best_yaw};
use crate::symmetry::ambiguity_group;

/// Pixels around the keypoint crop that the outline search may reach.
const MARGIN: i64 = 8;

/// One part's outline and its near-symmetries (the poses vision may confuse with the truth).
struct OutlinedPart {
    outline: PartOutline,
    near: Vec<UnitQuaternion<f64>>,
    /// Stable poses whose view from above repeats on a turn.
    featureless: Vec<Featureless>,
}

/// A stable pose whose view from above repeats on a turn ([`crate::part::ViewSymmetry`]).
struct Featureless {
    /// Its index among the part's stable poses (the refiner's class).
    class: usize,
    /// The view repeats after 360°/order.
    order: u32,
    /// The area the part covers seen from above in it, mm².
    footprint_mm2: f64,
}

/// Contour alignment of the pipeline's estimates, one outline per detectable part.
pub(super) struct ContourStage {
    config: ContourConfig,
    parts: Vec<OutlinedPart>,
}

impl ContourStage {
    /// Outlines of the detectable parts (`specs` with their `meshes` and their stable poses'
    /// `footprints`, mm², in the models' class order) and their declared near-symmetries.
    pub(super) fn new(
        specs: &[&PartSpec],
        meshes: &[TriMesh],
        footprints: &[Vec<f64>],
        config: ContourConfig,
    ) -> Self {
        let parts = specs
            .iter()
            .zip(meshes)
            .zip(footprints)
            .map(|((spec, mesh), footprints)| OutlinedPart {
                outline: PartOutline::new(mesh)
                    .with_final_edge(FinalEdge::for_material(spec.material))
                    .with_hole_weight(spec.hole_weight.get()),
                near: ambiguity_group(&spec.symmetries)
                    .into_iter()
                    .skip(1)
                    .collect(),
                featureless: spec
                    .view_symmetries
                    .iter()
                    .filter_map(|v| {
                        let class = spec
                            .stable_poses
                            .iter()
                            .position(|s| s.name == v.stable_pose)?;
                        Some(Featureless {
                            class,
                            order: v.order,
                            footprint_mm2: footprints[class],
                        })
                    })
                    .collect(),
            })
            .collect();
        Self { config, parts }
    }

    /// The outline fits of one detection of part `class`, whose keypoint crop covers the sensor
    /// window `crop` (`[x, y, width, height]`), on the edges of `image` except where `owners`
    /// gives a pixel to another part (see [`GreyPatch::with_owners`]); `None` for a part it has
    /// no outline of.
    #[allow(clippy::too_many_arguments)]
    fn fits<'a>(
        &'a self,
        class: usize,
        part: &str,
        estimator: &'a PoseEstimator,
        image: &FrameImage,
        camera: &'a Camera,
        crop: [i64; 4],
        owners: impl Fn(i64, i64, &mut [Owner]),
    ) -> Option<Fits<'a>> {
        let (outlined, refiner) = (self.parts.get(class)?, estimator.refiner(part)?);
        Some(Fits {
            outlined,
            refiner,
            camera,
            patch: GreyPatch::cut(
                &image.pixels,
                image.origin,
                // The crop and the margin the outline search may reach.
                [
                    crop[0] - MARGIN,
                    crop[1] - MARGIN,
                    crop[2] + 2 * MARGIN,
                    crop[3] + 2 * MARGIN,
                ],
            )
            .with_owners(owners)
            .with_mask_outside(self.config.mask_outside_px),
            aligner: ContourAligner::new(*refiner.camera_T_table(), self.config),
        })
    }

    /// Aligns `estimate` of part `class` (whose keypoint crop covers the sensor window `crop`)
    /// on the edges of `image`, except where `owners` gives a pixel to another part, in one of
    /// the `admitted` stable poses (a hypothesis in another stable pose wins only if it also
    /// covers the pixels `owners` gives this part better), and weighs its confidence by the
    /// fit's quality; keeps the keypoint pose, with no confidence, when no hypothesis finds
    /// enough of its outline.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn refine(
        &self,
        estimate: &mut PoseEstimate,
        class: usize,
        part: &str,
        estimator: &PoseEstimator,
        image: &FrameImage,
        camera: &Camera,
        crop: [i64; 4],
        admitted: ClassSet,
        owners: impl Fn(i64, i64, &mut [Owner]),
    ) {
        let Some(fits) = self.fits(class, part, estimator, image, camera, crop, owners) else {
            return;
        };
        let refiner = fits.refiner;
        let planar = &estimate.planar;
        // The keypoint pose and its half-turn, its near-symmetric twins snapped onto their own
        // stable poses, and the runner-up stable pose with its half-turn: the outline decides.
        let t = &planar.table_T_part.translation;
        let (x, y) = (t.x, t.y);
        let mut hypotheses = vec![(planar.class, planar.yaw), (planar.class, planar.yaw + PI)];
        for g in &fits.outlined.near {
            let twin: Isometry3<f64> = planar.camera_T_part * g;
            if let Ok(p) = refiner.refine_in(&twin, admitted) {
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
        let mut best: Option<(usize, ContourFit)> = None;
        // Every hypothesis gets the coarse round; only the best is finished. The keypoint pose
        // (the first) is replaced only by a hypothesis that beats it by the margin, and by one
        // in another stable pose only if it also covers the part's mask better by its margin.
        for (class, start) in starts {
            // A support is at most 1: once the best one is within the margin of it, no other
            // hypothesis can replace it, so the rest need not be screened.
            if best
                .as_ref()
                .is_some_and(|(_, b)| b.support + self.config.switch_margin >= 1.0)
            {
                break;
            }
            let Some(fit) = fits.screen(class, start) else {
                continue;
            };
            let replaces = match &best {
                None => true,
                Some((c, b)) => {
                    fit.support > b.support + self.config.switch_margin
                        && (*c == class || fits.covers_better(class, &fit, *c, b))
                }
            };
            if replaces {
                best = Some((class, fit));
            }
        }
        // A fit that finds too little of its outline may have left part of it beyond the coarse
        // reach: it is screened again from starts around it. One of those replaces it only if it
        // finds more of the outline by the switch margin and also covers the part's mask better:
        // a shell's inner rims can hold a fit a millimetre off as well as its outline holds the
        // true one (on USB-C's cell-density set, 8 poses 0.3–2.3 mm worse without the mask's
        // say, none with it).
        if let Some((class, screened)) = &best
            && screened.support < self.config.ring_below
            && let Some(fit) = fits.screen_around(*class, screened)
            && fit.support > screened.support + self.config.switch_margin
            && fits.covers_by(*class, &fit, *class, screened, 0.0)
        {
            best = Some((*class, fit));
        }
        match best.and_then(|(class, screened)| fits.finish(class, &screened)) {
            Some((class, fit)) if fit.support >= self.config.min_support => {
                let quality = fit.quality(self.config.min_support);
                estimate.adopt_contour(fit, class, refiner, quality);
            }
            // The keypoint pose stands, but a pose whose outline is nowhere in the frame is
            // not one to pick by (on the test frames, the few such poses were all wrong).
            _ => estimate.confidence = 0.0,
        }
    }

    /// Poses a part whose keypoint estimate the reprojection gate refused by its outline alone,
    /// when its keypoints place nothing (their RMS over [`RESCUE_MIN_RMS_MM`] on the table, at
    /// `px_per_mm`) and it may rest in a featureless stable pose ([`crate::part::ViewSymmetry`]:
    /// its view repeats on a turn, so the keypoint net has nothing to place keypoints by). Each
    /// such pose whose footprint the part's visible mask (`visible_mm2` on the table) nearly
    /// fills is screened from yaws spread over one period at the table point seen at
    /// `centre_px` (the voted centre keypoint), the best is finished, and it replaces the
    /// estimate's planar pose when its outline finds at least [`RESCUE_SUPPORT`] of its edges;
    /// the confidence is then the fit's quality. Returns that estimate, if any.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn rescue(
        &self,
        refused: &PoseEstimate,
        class: usize,
        part: &str,
        estimator: &PoseEstimator,
        image: &FrameImage,
        camera: &Camera,
        crop: [i64; 4],
        centre_px: nalgebra::Point2<f64>,
        px_per_mm: f64,
        visible_mm2: f64,
        admitted: ClassSet,
        owners: impl Fn(i64, i64, &mut [Owner]),
    ) -> Option<PoseEstimate> {
        // Keypoints that miss the gate but still fit a pose are the part's (a face-up insert
        // mold with its pins in view): the outline alone cannot tell the two faces apart. A part
        // that shows much less than a pose's footprint lies otherwise (on its side, leaning) or
        // mostly hidden: its outline would not settle it.
        let candidates: Vec<&Featureless> = self.parts.get(class).map_or(Vec::new(), |o| {
            o.featureless
                .iter()
                .filter(|f| {
                    admitted.contains(f.class)
                        && visible_mm2 >= MIN_FOOTPRINT_SHARE * f.footprint_mm2
                })
                .collect()
        });
        if candidates.is_empty() || refused.rms_px <= RESCUE_MIN_RMS_MM * px_per_mm {
            return None;
        }
        let fits = self.fits(class, part, estimator, image, camera, crop, owners)?;
        let mut best: Option<(usize, ContourFit)> = None;
        for f in candidates {
            let height = fits.refiner.stable_poses()[f.class].rest_height;
            let Ok((x, y)) = fits.refiner.table_point(camera, centre_px, height) else {
                continue;
            };
            let period = std::f64::consts::TAU / f64::from(f.order);
            for k in 0..RESCUE_SEEDS {
                let yaw = period * k as f64 / RESCUE_SEEDS as f64;
                let Some(fit) = fits.screen(f.class, (x, y, yaw)) else {
                    continue;
                };
                if best.as_ref().is_none_or(|(_, b)| fit.support > b.support) {
                    best = Some((f.class, fit));
                }
            }
        }
        let (pose, fit) = best.and_then(|(pose, screened)| fits.finish(pose, &screened))?;
        if fit.support < RESCUE_SUPPORT {
            return None;
        }
        let quality = fit.quality(self.config.min_support);
        let mut estimate = refused.clone();
        estimate.adopt_contour(fit, pose, fits.refiner, quality);
        // The keypoints' poor fit says nothing against the outline's pose.
        estimate.confidence = quality;
        if let Some(c) = &mut estimate.contour {
            c.outline_only = true;
        }
        Some(estimate)
    }
}

/// One detection's outline fits: its part's outline, stable poses and table, and the frame's
/// grey levels around its crop.
struct Fits<'a> {
    outlined: &'a OutlinedPart,
    refiner: &'a PlanarRefiner,
    camera: &'a Camera,
    patch: GreyPatch,
    aligner: ContourAligner,
}

impl Fits<'_> {
    /// The part lying in stable pose `class` as the aligner sees it.
    fn view(&self, class: usize) -> ContourView<'_> {
        ContourView {
            outline: &self.outlined.outline,
            stable: &self.refiner.stable_poses()[class],
            camera: self.camera,
            patch: &self.patch,
        }
    }

    /// The coarse round from `start` in stable pose `class` ([`ContourAligner::screen`]).
    fn screen(&self, class: usize, start: (f64, f64, f64)) -> Option<ContourFit> {
        self.aligner.screen(self.view(class), start)
    }

    /// The best screening from starts around `screened` in stable pose `class`
    /// ([`ContourAligner::screen_around`]).
    fn screen_around(&self, class: usize, screened: &ContourFit) -> Option<ContourFit> {
        self.aligner.screen_around(self.view(class), screened)
    }

    /// Whether `fit` in stable pose `class` covers the part's mask better than `other` in stable
    /// pose `other_class`, by [`ContourConfig::mask_margin`] of intersection over union (yes when
    /// the frame gives no mask to judge by).
    fn covers_better(
        &self,
        class: usize,
        fit: &ContourFit,
        other_class: usize,
        other: &ContourFit,
    ) -> bool {
        let margin = self.aligner.config().mask_margin;
        self.covers_by(class, fit, other_class, other, margin)
    }

    /// Whether `fit` in stable pose `class` covers the part's mask better than `other` in
    /// stable pose `other_class` by more than `margin` of intersection over union (yes when
    /// the frame gives no mask to judge by).
    fn covers_by(
        &self,
        class: usize,
        fit: &ContourFit,
        other_class: usize,
        other: &ContourFit,
        margin: f64,
    ) -> bool {
        let agreement = |class, fit| self.aligner.mask_agreement(self.view(class), fit);
        match (agreement(class, fit), agreement(other_class, other)) {
            (Some(a), Some(b)) => a > b + margin,
            _ => true,
        }
    }

    /// The finer rounds of a screened fit in stable pose `class`, with that class.
    fn finish(&self, class: usize, screened: &ContourFit) -> Option<(usize, ContourFit)> {
        Some((class, self.aligner.finish(self.view(class), screened)?))
    }
}

/// Keypoints whose RMS on the table exceeds this, mm, place nothing: only then is a part that
/// may rest in a featureless stable pose posed by its outline. Upside-down insert molds'
/// keypoints miss by 1.9 mm and more (13.3 px at 7.1 px/mm; median 23.5 px); face-up ones that
/// miss a tight gate (4 px) by 0.6–1.5 mm.
const RESCUE_MIN_RMS_MM: f64 = 1.6;

/// Least edge support of an outline-only pose (0.85 posed one more upside-down insert mold of 97
/// on the test set, and two more parts leaning on others).
const RESCUE_SUPPORT: f64 = 0.9;

/// Yaws screened per period of a featureless stable pose's turn (on the test set, 3, 4 and 6
/// posed the same upside-down insert molds, 67 of 97 found; 2 the same ones, but 5 fewer
/// assembly-grade poses).
const RESCUE_SEEDS: usize = 3;

/// Least share of a featureless pose's footprint that a part's visible mask must cover for its
/// outline to be tried (on the test set, 54 of the 63 outline fits above it passed, 7 of the 53
/// below it: dropping those kept every upside-down insert mold posed and one wrong stable pose
/// fewer).
const MIN_FOOTPRINT_SHARE: f64 = 0.7;

/// The absolute difference of two angles, radians in [0, π].
fn angle_between(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(std::f64::consts::TAU);
    d.min(std::f64::consts::TAU - d)
}
