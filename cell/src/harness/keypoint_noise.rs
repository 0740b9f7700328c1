//! Keypoint-noise perception, the simulation's stand-in for the learned pipeline: the true
//! keypoints of each visible part, with the scenario's pixel noise and outliers, go through the
//! real PnP and planar refinement of the `perception` crate (the paper's ablation). It needs the
//! simulated scene ([`FrameContent::Simulated`]), so it lives in the harness.

use std::collections::BTreeMap;

use nalgebra::{Isometry3, Point2, Point3, UnitQuaternion};
use perception::Camera;
use perception::part::{Catalog, PartRole};
use perception::planar::{PlanarConfig, PlanarRefiner};
use perception::pnp::solve_pnp;
use perception::symmetry::symmetry_group;
use rand::{Rng, RngExt};
use rand_chacha::ChaCha8Rng;
use sim::cell::noise::PERCEPTION_STREAM;
use sim::seed::stream_rng;

use super::HarnessError;
use crate::scenario::{PerceptionMode, Scenario};

use perception::{DetectedPart, Frame, FrameContent, PartPerception, PerceptionError};

/// Keypoint-noise settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KeypointNoiseConfig {
    /// Standard deviation of keypoint noise per axis, pixels.
    pub noise_px: f64,
    /// Fraction of keypoints replaced by gross outliers.
    pub outlier_fraction: f64,
    /// Half size of the box around the true keypoint where an outlier lands, pixels.
    pub outlier_radius_px: f64,
    /// Detections whose reprojection RMS exceeds this many noise sigmas (plus 0.5 px) are
    /// rejected as failed estimates.
    pub max_rms_sigmas: f64,
}

impl KeypointNoiseConfig {
    /// Settings for a noise level and outlier fraction, with a 40 px outlier box and a 4σ gate.
    pub fn new(noise_px: f64, outlier_fraction: f64) -> Self {
        Self {
            noise_px,
            outlier_fraction,
            outlier_radius_px: 40.0,
            max_rms_sigmas: 4.0,
        }
    }
}

struct PartModel {
    keypoints: Vec<Point3<f64>>,
    refiner: PlanarRefiner,
}

/// Keypoint-noise perception: true keypoints + noise → PnP → planar refinement.
pub struct KeypointNoise<R: Rng + Send> {
    config: KeypointNoiseConfig,
    models: BTreeMap<String, PartModel>,
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
        config: KeypointNoiseConfig,
        rng: R,
    ) -> Result<Self, PerceptionError> {
        if !(config.noise_px.is_finite() && config.noise_px >= 0.0) {
            return Err(PerceptionError::Settings(format!(
                "keypoint noise must be ≥ 0 px, got {}",
                config.noise_px
            )));
        }
        if !(0.0..=1.0).contains(&config.outlier_fraction) {
            return Err(PerceptionError::Settings(format!(
                "outlier fraction must be in [0, 1], got {}",
                config.outlier_fraction
            )));
        }
        let camera_T_table = base_T_camera.inverse() * base_T_table;
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
            let refiner = PlanarRefiner::new(
                camera_T_table,
                &part.stable_poses,
                &group,
                PlanarConfig::default(),
            )
            .map_err(|e| PerceptionError::Part {
                part: part.name.clone(),
                reason: e.to_string(),
            })?;
            models.insert(
                part.name.clone(),
                PartModel {
                    keypoints: part.keypoint_points(),
                    refiner,
                },
            );
        }
        Ok(Self {
            config,
            models,
            rng,
            base_T_table,
        })
    }

    fn gauss(&mut self) -> f64 {
        // Box–Muller from two uniforms in (0, 1].
        let u1: f64 = 1.0 - self.rng.random::<f64>();
        let u2: f64 = self.rng.random::<f64>();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }

    /// Noisy observed pixels of a part's keypoints; keypoints leaving the image are dropped.
    #[allow(non_snake_case)]
    fn observe(
        &mut self,
        camera: &Camera,
        camera_T_part: &Isometry3<f64>,
        keypoints: &[Point3<f64>],
    ) -> (Vec<Point3<f64>>, Vec<Point2<f64>>) {
        let mut model = Vec::with_capacity(keypoints.len());
        let mut pixels = Vec::with_capacity(keypoints.len());
        for k in keypoints {
            let Ok(p) = camera.project(&(camera_T_part * k)) else {
                continue;
            };
            let observed = if self.rng.random::<f64>() < self.config.outlier_fraction {
                let r = self.config.outlier_radius_px;
                Point2::new(
                    p.x + self.rng.random_range(-r..=r),
                    p.y + self.rng.random_range(-r..=r),
                )
            } else {
                let s = self.config.noise_px;
                Point2::new(p.x + s * self.gauss(), p.y + s * self.gauss())
            };
            if camera.contains(observed) {
                model.push(*k);
                pixels.push(observed);
            }
        }
        (model, pixels)
    }
}

impl<R: Rng + Send> PartPerception for KeypointNoise<R> {
    #[allow(non_snake_case)]
    fn perceive(&mut self, frame: &Frame) -> Result<Vec<DetectedPart>, PerceptionError> {
        let parts = match &frame.content {
            FrameContent::Simulated(parts) => parts,
            FrameContent::Image(_) => {
                return Err(PerceptionError::UnsupportedFrame {
                    mode: "keypoint-noise",
                    what: "images (it needs the simulated scene)",
                });
            }
        };
        let gate = self.config.max_rms_sigmas * self.config.noise_px + 0.5;
        let mut out = Vec::new();
        for (index, seen) in parts.iter().enumerate() {
            let Some(keypoints) = self.models.get(&seen.part).map(|m| m.keypoints.clone()) else {
                continue;
            };
            let (model, pixels) = self.observe(&frame.camera, &seen.camera_T_part, &keypoints);
            let Ok(pnp) = solve_pnp(&frame.camera, &model, &pixels, None) else {
                continue;
            };
            let m = &self.models[&seen.part];
            let Ok(planar) = m.refiner.refine_with_keypoints(
                &pnp.camera_T_part,
                &frame.camera,
                &model,
                &pixels,
                None,
            ) else {
                continue;
            };
            let rms_px = pixel_rms(&frame.camera, &planar.camera_T_part, &model, &pixels);
            if !(rms_px.is_finite() && rms_px <= gate) {
                continue;
            }
            let consistency = (-0.5 * (rms_px / gate).powi(2)).exp();
            let table_T_part = planar.table_T_part;
            out.push(DetectedPart {
                part: seen.part.clone(),
                index,
                truth_instance: Some(seen.instance),
                base_T_part: self.base_T_table * table_T_part,
                table_T_part,
                stable_pose: m.refiner.stable_poses()[planar.class].name.clone(),
                confidence: planar.confidence * consistency,
                rms_px,
                covariance: pnp.covariance,
            });
        }
        Ok(out)
    }
}

/// Root-mean-square pixel distance between observed pixels and the projected model points
/// (infinite when a point does not project).
#[allow(non_snake_case)]
fn pixel_rms(
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
        KeypointNoiseConfig::new(p.keypoint_noise_px, p.outlier_fraction),
        rng,
    )?)
}
