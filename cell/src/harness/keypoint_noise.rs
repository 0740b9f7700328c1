//! Keypoint-noise perception, the simulation's stand-in for the learned pipeline: the true
//! keypoints of each visible part, perturbed by the scenario's [`KeypointNoiseModel`], go through
//! the same [`PoseEstimator`] the learned pipeline uses (the paper's ablation). It needs the
//! simulated scene ([`FrameContent::Simulated`]), so it lives in the harness.

use nalgebra::{Isometry3, Point2};
use perception::estimate::{EstimatorConfig, Observation, PoseEstimator};
use perception::keypoint_noise::KeypointNoiseModel;
use perception::part::Catalog;
use perception::{
    Camera, DetectedPart, Frame, FrameContent, PartPerception, Perceived, PerceptionError,
    UnposedPart,
};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use sim::cell::noise::PERCEPTION_STREAM;
use sim::seed::stream_rng;

use super::HarnessError;
use crate::scenario::{PerceptionMode, Scenario};

/// Detections whose reprojection RMS exceeds this many noise sigmas (plus 0.5 px) are rejected.
const MAX_RMS_SIGMAS: f64 = 4.0;

/// Keypoint-noise perception: true keypoints + noise → [`PoseEstimator`].
pub struct KeypointNoise<R: Rng + Send> {
    noise: KeypointNoiseModel,
    estimator: PoseEstimator,
    rng: R,
    #[allow(non_snake_case)]
    base_T_table: Isometry3<f64>,
}

impl<R: Rng + Send> KeypointNoise<R> {
    /// A perceiver for every prepared non-fixture part of `catalog` on the table at
    /// `base_T_table`, seen through a camera calibrated at `base_T_camera`; noise from `rng`.
    #[allow(non_snake_case)]
    pub fn new(
        catalog: &Catalog,
        base_T_table: Isometry3<f64>,
        base_T_camera: Isometry3<f64>,
        noise: KeypointNoiseModel,
        rng: R,
    ) -> Result<Self, PerceptionError> {
        noise.validate().map_err(PerceptionError::Settings)?;
        let gate = MAX_RMS_SIGMAS * noise.noise_px + 0.5;
        let estimator = PoseEstimator::new(
            catalog,
            base_T_camera.inverse() * base_T_table,
            EstimatorConfig::with_gate(gate),
        )?;
        Ok(Self {
            noise,
            estimator,
            rng,
            base_T_table,
        })
    }

    /// Noisy observations of a part's keypoints; keypoints leaving the image are dropped.
    #[allow(non_snake_case)]
    fn observe(
        &mut self,
        camera: &Camera,
        camera_T_part: &Isometry3<f64>,
        part: &str,
    ) -> Vec<Observation> {
        let Some(keypoints) = self.estimator.keypoints(part) else {
            return Vec::new();
        };
        let mut out = Vec::with_capacity(keypoints.len());
        for (keypoint, k) in keypoints.iter().enumerate() {
            let Ok(p) = camera.project(&(camera_T_part * k)) else {
                continue;
            };
            let pixel: Point2<f64> = self.noise.perturb(p, &mut self.rng);
            if camera.contains(pixel) {
                out.push(Observation {
                    keypoint,
                    pixel,
                    covariance: None,
                });
            }
        }
        out
    }
}

impl<R: Rng + Send> PartPerception for KeypointNoise<R> {
    fn perceive(&mut self, frame: &Frame) -> Result<Perceived, PerceptionError> {
        let parts = match &frame.content {
            FrameContent::Simulated(parts) => parts,
            FrameContent::Image(_) => {
                return Err(PerceptionError::UnsupportedFrame {
                    mode: "keypoint-noise",
                    what: "images (it needs the simulated scene)",
                });
            }
        };
        let mut out = Perceived::default();
        let table_T_camera = self.base_T_table.inverse() * frame.base_T_camera;
        for (index, seen) in parts.iter().enumerate() {
            let observed = self.observe(&frame.camera, &seen.camera_T_part, &seen.part);
            if observed.is_empty() {
                continue;
            }
            let Ok(estimate) = self
                .estimator
                .estimate(&seen.part, &frame.camera, &observed)
            else {
                // Seen but not posed: the space it takes up, here the hull of its true
                // keypoints (this mode perturbs the truth; the learned one outlines the mask).
                let table_T_part = table_T_camera * seen.camera_T_part;
                let keypoints = self.estimator.keypoints(&seen.part).unwrap_or_default();
                out.unposed.push(UnposedPart {
                    part: seen.part.clone(),
                    table_points: keypoints.iter().map(|k| table_T_part * k).collect(),
                });
                continue;
            };
            let table_T_part = estimate.planar.table_T_part;
            out.parts.push(DetectedPart {
                part: seen.part.clone(),
                index,
                truth_instance: Some(seen.instance),
                base_T_part: self.base_T_table * table_T_part,
                table_T_part,
                stable_pose: estimate.stable_pose,
                confidence: estimate.confidence,
                rms_px: estimate.rms_px,
                covariance: estimate.pnp.covariance,
            });
        }
        Ok(out)
    }
}

/// The scenario's keypoint-noise perception for `episode`, on the episode's perception stream
/// (`sim::seed::stream_rng`, stream `sim::cell::noise::PERCEPTION_STREAM`).
pub fn keypoint_noise_for(
    scenario: &Scenario,
    episode: u32,
) -> Result<KeypointNoise<ChaCha8Rng>, HarnessError> {
    let p = &scenario.spec.perception;
    if p.mode != PerceptionMode::KeypointNoise {
        return Err(HarnessError::ModeUnavailable(p.mode));
    }
    let rng = stream_rng(scenario.spec.seed, u64::from(episode), PERCEPTION_STREAM);
    Ok(KeypointNoise::new(
        &scenario.catalog,
        scenario.spec.cell.base_T_table.isometry(),
        scenario.spec.cell.camera.base_T_camera.isometry(),
        KeypointNoiseModel::new(p.keypoint_noise_px, p.outlier_fraction),
        rng,
    )?)
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use nalgebra::{Point3, Translation3, UnitQuaternion, Vector3};
    use parry3d_f64::math::Pose;
    use perception::TruePart;
    use rand::SeedableRng;
    use sim::convert::vec_from_point;

    use super::*;
    use crate::orchestrator::UnposedObstacle;

    #[test]
    #[allow(non_snake_case)]
    fn a_part_seen_but_not_posed_comes_out_as_the_space_it_takes_up() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/parts/usbc.toml");
        let catalog = Catalog::load(&path).unwrap();
        // The table is the base frame; the camera looks straight down from 1.5 m.
        let base_T_camera = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 1.5),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
        );
        let noise = KeypointNoiseModel::new(0.5, 0.0);
        let rng = ChaCha8Rng::seed_from_u64(7);
        let mut perception =
            KeypointNoise::new(&catalog, Isometry3::identity(), base_T_camera, noise, rng).unwrap();
        let spec = catalog.part("main_shell").unwrap();
        let resting = spec.stable_pose("+z").unwrap().table_T_part(0.0, 0.0, 0.3);
        // Propped up on a corner, in no stable pose: no planar pose explains its keypoints.
        let propped = Isometry3::from_parts(
            Translation3::new(0.02, 0.01, 0.005),
            UnitQuaternion::from_euler_angles(0.7, 0.5, 0.2),
        );
        let seen = |instance, table_T_part: Isometry3<f64>| TruePart {
            instance,
            part: "main_shell".into(),
            camera_T_part: base_T_camera.inverse() * table_T_part,
        };
        let frame = Frame {
            camera: Camera::basler_seed(),
            base_T_camera,
            content: FrameContent::Simulated(vec![seen(1, resting), seen(2, propped)]),
        };
        let found = perception.perceive(&frame).unwrap();
        assert_eq!(found.parts.len(), 1, "{:?}", found.parts);
        assert_eq!(found.parts[0].truth_instance, Some(1));
        assert_eq!(found.unposed.len(), 1);
        let space = &found.unposed[0];
        assert_eq!(space.part, "main_shell");
        // The table is the base frame: the obstacle the cell's selection keeps the fingers from.
        let hull = UnposedObstacle::new(space, &Isometry3::identity())
            .unwrap()
            .hull;
        let centre = Point3::from(propped.translation.vector);
        assert!(hull.contains_point(&Pose::IDENTITY, vec_from_point(&centre)));
        assert!(!hull.contains_point(&Pose::IDENTITY, vec_from_point(&Point3::origin())));
    }
}
