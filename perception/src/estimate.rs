//! From observed keypoints to a part pose on the table, in one place: PnP (weighted by keypoint
//! covariances when they are known) → planar refinement onto the part's stable poses → reprojection
//! RMS → confidence. Keypoint-noise perception and the learned pipeline both end here, so they
//! differ only in where the keypoints come from.

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Matrix2, Point2, Point3, UnitQuaternion};

use crate::Camera;
use crate::contour::ContourFit;
use crate::part::{Catalog, PartRole};
use crate::perceive::PerceptionError;
use crate::planar::{ClassSet, PlanarConfig, PlanarError, PlanarPose, PlanarRefiner};
use crate::pnp::{PnpError, PnpSolution, solve_pnp};
use crate::symmetry::symmetry_group;

/// One observed keypoint: which model keypoint, where in the image (distorted pixels of the
/// whole sensor), and how sure (covariance, px²) when the detector knows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    /// Index into the part's keypoints.
    pub keypoint: usize,
    /// Observed pixel.
    pub pixel: Point2<f64>,
    /// Covariance of the pixel, px².
    pub covariance: Option<Matrix2<f64>>,
}

/// Estimation settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EstimatorConfig {
    /// Estimates whose reprojection RMS exceeds this are rejected as failed, pixels.
    pub max_rms_px: f64,
    /// Planar refinement settings.
    pub planar: PlanarConfig,
}

impl EstimatorConfig {
    /// Default refinement with an RMS gate of `max_rms_px`.
    pub fn with_gate(max_rms_px: f64) -> Self {
        Self {
            max_rms_px,
            planar: PlanarConfig::default(),
        }
    }
}

/// A pose estimate of one part, with every stage kept for evaluation.
#[derive(Debug, Clone, PartialEq)]
#[allow(non_snake_case)]
pub struct PoseEstimate {
    /// The raw PnP solution (the paper's Table 1 is about this).
    pub pnp: PnpSolution,
    /// The estimate refined onto a stable pose on the table.
    pub planar: PlanarPose,
    /// Name of the chosen stable pose.
    pub stable_pose: String,
    /// Reprojection RMS of the refined pose over the observed keypoints, pixels.
    pub rms_px: f64,
    /// Stable-pose posterior times reprojection consistency (times the contour fit's quality
    /// where one ran), in [0, 1].
    pub confidence: f64,
    /// The contour alignment that moved `planar` onto the image's edges, when one ran and was
    /// kept (learned perception only: keypoint noise has no pixels).
    pub contour: Option<ContourRefinement>,
}

/// What contour alignment did to a keypoint estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct ContourRefinement {
    /// The fit that now stands as the estimate's `planar` pose.
    pub fit: ContourFit,
    /// The planar pose from the keypoints alone, before the alignment.
    pub keypoint_planar: PlanarPose,
    /// The keypoints failed the reprojection gate and the outline alone placed the part, in a
    /// stable pose whose view repeats on a turn (a featureless face up): its yaw is known only
    /// up to that turn.
    pub outline_only: bool,
}

impl PoseEstimate {
    /// Whether the outline alone placed the part ([`ContourRefinement::outline_only`]).
    pub fn is_outline_only(&self) -> bool {
        self.contour.as_ref().is_some_and(|c| c.outline_only)
    }

    /// Replaces the planar pose by a contour fit on stable pose `class` of `refiner` (the
    /// keypoint pose is kept in `contour`). The class posterior is the keypoints' when the class
    /// stays, and the fit's edge support when contour alignment chose another one; tilt, margin
    /// and runner-up stay those of the keypoint estimate's class decision. The confidence is
    /// then weighed by the fit's `quality` ([`ContourFit::quality`]).
    #[allow(non_snake_case)]
    pub fn adopt_contour(
        &mut self,
        fit: ContourFit,
        class: usize,
        refiner: &PlanarRefiner,
        quality: f64,
    ) {
        let keypoint_planar = self.planar.clone();
        let table_T_part = refiner.stable_poses()[class].table_T_part(fit.x, fit.y, fit.yaw);
        let confidence = if class == keypoint_planar.class {
            keypoint_planar.confidence
        } else {
            fit.support
        };
        self.planar = PlanarPose {
            camera_T_part: refiner.camera_T_table() * table_T_part,
            table_T_part,
            class,
            yaw: fit.yaw,
            confidence,
            ..keypoint_planar.clone()
        };
        self.stable_pose = refiner.stable_poses()[class].name.clone();
        self.confidence *= quality * confidence / keypoint_planar.confidence.max(1e-12);
        self.contour = Some(ContourRefinement {
            fit,
            keypoint_planar,
            outline_only: false,
        });
    }
}

/// Why one part's pose could not be estimated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EstimateError {
    /// The part is not one the estimator knows.
    #[error("unknown part {0:?}")]
    UnknownPart(String),
    /// An observation names a keypoint the part does not have.
    #[error("part {part}: keypoint {keypoint} does not exist (it has {count})")]
    BadKeypoint {
        /// The part.
        part: String,
        /// The keypoint index.
        keypoint: usize,
        /// How many keypoints the part has.
        count: usize,
    },
    /// PnP failed.
    #[error("PnP: {0}")]
    Pnp(#[from] PnpError),
    /// Planar refinement failed.
    #[error("planar refinement: {0}")]
    Planar(#[from] PlanarError),
    /// The refined pose does not explain the keypoints.
    #[error("reprojection RMS {rms_px:.2} px exceeds the gate of {gate_px:.2} px")]
    Rms {
        /// The RMS, pixels.
        rms_px: f64,
        /// The gate, pixels.
        gate_px: f64,
        /// The refused estimate (evaluation still reports its raw PnP, as the paper's Table 1).
        estimate: Box<PoseEstimate>,
    },
}

struct PartModel {
    keypoints: Vec<Point3<f64>>,
    refiner: PlanarRefiner,
}

/// Estimates poses of a catalog's parts lying on a calibrated table.
pub struct PoseEstimator {
    models: BTreeMap<String, PartModel>,
    config: EstimatorConfig,
}

impl PoseEstimator {
    /// An estimator for every non-fixture part of `catalog` with at least four keypoints and a
    /// stable pose, on the table at `camera_T_table` (from extrinsic calibration).
    #[allow(non_snake_case)]
    pub fn new(
        catalog: &Catalog,
        camera_T_table: Isometry3<f64>,
        config: EstimatorConfig,
    ) -> Result<Self, PerceptionError> {
        if !(config.max_rms_px.is_finite() && config.max_rms_px > 0.0) {
            return Err(PerceptionError::Settings(format!(
                "the reprojection gate must be > 0 px, got {}",
                config.max_rms_px
            )));
        }
        let mut models = BTreeMap::new();
        for part in catalog.parts.iter().filter(|p| p.role != PartRole::Fixture) {
            if part.keypoints.len() < 4 || part.stable_poses.is_empty() {
                continue;
            }
            let exact: Vec<_> = part
                .symmetries
                .iter()
                .filter(|s| s.exact)
                .cloned()
                .collect();
            let group: Vec<UnitQuaternion<f64>> = symmetry_group(&exact);
            // Of symmetric twins (a peg on either end), report the one the part is grasped in.
            let refiner =
                PlanarRefiner::new(camera_T_table, &part.stable_poses, &group, config.planar)
                    .map_err(|e| PerceptionError::Part {
                        part: part.name.clone(),
                        reason: e.to_string(),
                    })?
                    .with_preferred(|c| part.grasp_for(&part.stable_poses[c].name).is_some());
            models.insert(
                part.name.clone(),
                PartModel {
                    keypoints: part.keypoint_points(),
                    refiner,
                },
            );
        }
        Ok(Self { models, config })
    }

    /// The parts it can estimate, by name.
    pub fn parts(&self) -> impl Iterator<Item = &str> {
        self.models.keys().map(String::as_str)
    }

    /// A part's model keypoints (part frame, metres).
    pub fn keypoints(&self, part: &str) -> Option<&[Point3<f64>]> {
        self.models.get(part).map(|m| m.keypoints.as_slice())
    }

    /// A part's planar refiner (its stable poses on the calibrated table).
    pub fn refiner(&self, part: &str) -> Option<&PlanarRefiner> {
        self.models.get(part).map(|m| &m.refiner)
    }

    /// Its settings.
    pub fn config(&self) -> &EstimatorConfig {
        &self.config
    }

    /// Estimates the pose of `part` from its observed keypoints in an image of `camera`.
    pub fn estimate(
        &self,
        part: &str,
        camera: &Camera,
        observations: &[Observation],
    ) -> Result<PoseEstimate, EstimateError> {
        self.estimate_in(part, camera, observations, ClassSet::ALL)
    }

    /// [`PoseEstimator::estimate`] with the stable pose one of `classes` (indices into the
    /// part's stable poses).
    pub fn estimate_in(
        &self,
        part: &str,
        camera: &Camera,
        observations: &[Observation],
        classes: ClassSet,
    ) -> Result<PoseEstimate, EstimateError> {
        let m = self
            .models
            .get(part)
            .ok_or_else(|| EstimateError::UnknownPart(part.into()))?;
        let mut model = Vec::with_capacity(observations.len());
        let mut pixels = Vec::with_capacity(observations.len());
        let mut covariances = Vec::with_capacity(observations.len());
        for o in observations {
            let k = m
                .keypoints
                .get(o.keypoint)
                .ok_or_else(|| EstimateError::BadKeypoint {
                    part: part.into(),
                    keypoint: o.keypoint,
                    count: m.keypoints.len(),
                })?;
            model.push(*k);
            pixels.push(o.pixel);
            if let Some(c) = o.covariance {
                covariances.push(c);
            }
        }
        // Weighted only when every observation carries a covariance.
        let weights = (covariances.len() == observations.len()).then_some(covariances.as_slice());
        let pnp = solve_pnp(camera, &model, &pixels, weights)?;
        let planar = m.refiner.refine_with_keypoints(
            &pnp.camera_T_part,
            camera,
            &model,
            &pixels,
            weights,
            classes,
        )?;
        // Keypoints are matched by index, so they are compared in the observed frame, not in the
        // canonical symmetric twin the refiner reports.
        let rms_px = pixel_rms(camera, &planar.camera_T_observed(), &model, &pixels);
        let gate_px = self.config.max_rms_px;
        let consistency = (-0.5 * (rms_px / gate_px).powi(2)).exp();
        let estimate = PoseEstimate {
            stable_pose: m.refiner.stable_poses()[planar.class].name.clone(),
            confidence: planar.confidence * consistency,
            rms_px,
            pnp,
            planar,
            contour: None,
        };
        if !(rms_px.is_finite() && rms_px <= gate_px) {
            return Err(EstimateError::Rms {
                rms_px,
                gate_px,
                estimate: Box::new(estimate),
            });
        }
        Ok(estimate)
    }
}

/// Root-mean-square pixel distance between observed pixels and the projected model points
/// (infinite when a point does not project).
#[allow(non_snake_case)]
pub fn pixel_rms(
    camera: &Camera,
    camera_T_part: &Isometry3<f64>,
    model: &[Point3<f64>],
    pixels: &[Point2<f64>],
) -> f64 {
    let mut sum = 0.0;
    for (k, px) in model.iter().zip(pixels) {
        match camera.project(&(camera_T_part * k)) {
            Ok(p) => sum += (p - px).norm_squared(),
            Err(_) => return f64::INFINITY,
        }
    }
    (sum / model.len().max(1) as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    use super::*;

    #[allow(non_snake_case)]
    fn setup() -> (PoseEstimator, Camera, Isometry3<f64>, Vec<Point3<f64>>) {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/parts/usbc.toml");
        let catalog = Catalog::load(&path).unwrap();
        // The seed's camera 1.5 m above the table, looking down.
        let camera_T_table = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 1.5),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
        );
        let estimator =
            PoseEstimator::new(&catalog, camera_T_table, EstimatorConfig::with_gate(2.0)).unwrap();
        let part = catalog.part("insert_mold").unwrap();
        let table_T_part = part.stable_poses[0].table_T_part(0.01, -0.02, 0.7);
        let keypoints = estimator.keypoints("insert_mold").unwrap().to_vec();
        (
            estimator,
            Camera::basler_seed(),
            camera_T_table * table_T_part,
            keypoints,
        )
    }

    fn observe(
        camera: &Camera,
        pose: &Isometry3<f64>,
        keypoints: &[Point3<f64>],
    ) -> Vec<Observation> {
        keypoints
            .iter()
            .enumerate()
            .map(|(keypoint, k)| Observation {
                keypoint,
                pixel: camera.project(&(pose * k)).unwrap(),
                covariance: None,
            })
            .collect()
    }

    #[test]
    #[allow(non_snake_case)]
    fn exact_keypoints_give_the_pose_and_bad_ones_are_refused_with_their_estimate() {
        let (estimator, camera, camera_T_part, keypoints) = setup();
        let exact = observe(&camera, &camera_T_part, &keypoints);
        let e = estimator.estimate("insert_mold", &camera, &exact).unwrap();
        let dt =
            (e.planar.camera_T_part.translation.vector - camera_T_part.translation.vector).norm();
        assert!(dt < 1e-6 && e.rms_px < 1e-3, "{dt} m, {} px", e.rms_px);
        assert_eq!(
            e.stable_pose,
            estimator.models["insert_mold"].refiner.stable_poses()[0].name
        );
        // Three corners 30 px off: the pose no longer explains them; the gate refuses it but
        // keeps the estimate, so evaluation can still report raw PnP.
        let mut bad = exact.clone();
        for o in bad.iter_mut().take(3) {
            o.pixel.x += 30.0;
        }
        match estimator.estimate("insert_mold", &camera, &bad) {
            Err(EstimateError::Rms {
                rms_px,
                gate_px,
                estimate,
            }) => {
                assert!(rms_px > gate_px && gate_px == 2.0, "{rms_px}");
                assert_eq!(estimate.rms_px, rms_px);
            }
            other => panic!("{other:?}"),
        }
        assert!(matches!(
            estimator.estimate("gasket", &camera, &exact),
            Err(EstimateError::UnknownPart(_))
        ));
        let mut wrong = exact;
        wrong[0].keypoint = 42;
        assert!(matches!(
            estimator.estimate("insert_mold", &camera, &wrong),
            Err(EstimateError::BadKeypoint { keypoint: 42, .. })
        ));
    }
}
