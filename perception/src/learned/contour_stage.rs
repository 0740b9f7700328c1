//! The learned pipeline's last stage: each keypoint estimate is aligned on the part's outline in
//! the frame (and, for a near-symmetric part, so is its turned twin; the one whose outline finds
//! the edges is kept).

use nalgebra::{Isometry3, UnitQuaternion};

use super::LearnedError;
use super::models::CROP_SIZE;
use crate::Camera;
use crate::contour::{ContourAligner, ContourConfig, ContourFit, GreyPatch, PartOutline};
use crate::estimate::{PoseEstimate, PoseEstimator};
use crate::frame::FrameImage;
use crate::part::{Catalog, Symmetry};
use crate::planar::PlanarPose;
use crate::symmetry::symmetry_group;

/// Pixels around the keypoint crop that the outline search may reach.
const MARGIN: i64 = 8;

/// One part's outline and its near-symmetries (the poses vision may confuse with the truth).
struct OutlinedPart {
    outline: PartOutline,
    near: Vec<UnitQuaternion<f64>>,
}

/// Contour alignment of the pipeline's estimates, one outline per detectable part.
pub(super) struct ContourStage {
    config: ContourConfig,
    parts: Vec<OutlinedPart>,
}

impl ContourStage {
    /// Outlines of `parts` (the models' class order) from `catalog`'s meshes.
    pub(super) fn new(
        catalog: &Catalog,
        parts: &[String],
        config: ContourConfig,
    ) -> Result<Self, LearnedError> {
        let parts = parts
            .iter()
            .map(|name| {
                let spec = catalog.part(name).ok_or_else(|| LearnedError::Part {
                    part: name.clone(),
                    reason: "not in the catalog".into(),
                })?;
                let mesh = catalog.load_mesh(spec).map_err(|e| LearnedError::Part {
                    part: name.clone(),
                    reason: format!("mesh for contour alignment: {e}"),
                })?;
                let all: Vec<Symmetry> = spec
                    .symmetries
                    .iter()
                    .map(|s| Symmetry {
                        exact: true,
                        ..s.clone()
                    })
                    .collect();
                Ok(OutlinedPart {
                    outline: PartOutline::new(&mesh),
                    near: symmetry_group(&all).into_iter().skip(1).collect(),
                })
            })
            .collect::<Result<_, LearnedError>>()?;
        Ok(Self { config, parts })
    }

    /// Aligns `estimate` of part `class` (whose keypoint crop starts at sensor pixel
    /// `crop_origin`) on the edges of `image`; keeps the keypoint pose when no hypothesis finds
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
        crop_origin: [i64; 2],
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
        );
        let aligner = ContourAligner::new(*refiner.camera_T_table(), self.config);
        let planar = &estimate.planar;
        // The keypoint pose, then its near-symmetric twins snapped onto their own stable poses.
        let start_of = |p: &PlanarPose| {
            let t = &p.table_T_part.translation;
            (p.class, (t.x, t.y, p.yaw))
        };
        let mut starts = vec![start_of(planar)];
        for g in &outlined.near {
            let twin: Isometry3<f64> = planar.camera_T_part * g;
            if let Ok(p) = refiner.refine(&twin) {
                starts.push(start_of(&p));
            }
        }
        let mut best: Option<(usize, ContourFit)> = None;
        for (class, start) in starts {
            let stable = &refiner.stable_poses()[class];
            let Some(fit) = aligner.align(&outlined.outline, stable, camera, &patch, start) else {
                continue;
            };
            if best.as_ref().is_none_or(|(_, b)| fit.support > b.support) {
                best = Some((class, fit));
            }
        }
        if let Some((class, fit)) = best
            && fit.support >= self.config.min_support
        {
            estimate.adopt_contour(fit, class, refiner);
        }
    }
}
