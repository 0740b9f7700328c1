//! The keypoint-noise ablation of the seed's Figure 5: how PnP's pose error grows with keypoint
//! noise and object distance, and how much planar refinement onto stable poses removes.
//!
//! Parts are dropped (by their stable-pose probabilities, uniform yaw) onto a table seen by the
//! seed's camera from several distances; their ground-truth keypoints are projected with the full
//! camera model, perturbed by Gaussian noise of σ px along x, along y or in both, and solved by
//! PnP, by PnP + planar refinement, and by PnP + planar refinement + the 3-DOF keypoint fit.
//! Everything is seeded: a trial's noise depends only on (seed, part, distance, axis, level, trial).

use nalgebra::{Isometry3, Point2, Point3, Translation3, UnitQuaternion, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::keypoint_noise::KeypointNoiseModel;
use crate::metrics::{ErrorSummary, PoseErrors, SummaryOptions, pose_errors};
use crate::part::{PartSpec, StablePose};
use crate::planar::{ClassSet, PlanarConfig, PlanarError, PlanarRefiner};
use crate::pnp::solve_pnp;
use crate::symmetry::symmetry_group;
use crate::{Camera, CameraError};

/// Why the ablation cannot run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AblationError {
    /// A part lacks keypoints or stable poses.
    #[error(
        "part {0} is not prepared (needs ≥ 4 keypoints and stable poses); run `cell parts prepare`"
    )]
    Unprepared(String),
    /// A configuration value is unusable.
    #[error("invalid ablation configuration: {0}")]
    InvalidConfig(String),
    /// Planar refinement could not be set up.
    #[error(transparent)]
    Planar(#[from] PlanarError),
    /// The camera is unusable.
    #[error(transparent)]
    Camera(#[from] CameraError),
}

pub use crate::keypoint_noise::NoiseAxis;

/// How a pose was estimated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// SQPnP + Levenberg–Marquardt.
    Pnp,
    /// PnP, then snapped onto the stable pose (closed-form yaw, ray/plane position).
    Planar,
    /// Planar, then x, y, yaw fitted to the keypoints.
    PlanarFit,
}

impl Method {
    /// Every method, in report order.
    pub const ALL: [Method; 3] = [Method::Pnp, Method::Planar, Method::PlanarFit];

    /// Short name.
    pub fn name(self) -> &'static str {
        match self {
            Method::Pnp => "pnp",
            Method::Planar => "planar",
            Method::PlanarFit => "planar_fit",
        }
    }
}

/// A part as the ablation needs it.
#[derive(Debug, Clone, PartialEq)]
pub struct AblationPart {
    /// Name.
    pub name: String,
    /// Keypoints in the part frame, metres (the seed's 8 FPS points + centre).
    pub keypoints: Vec<Point3<f64>>,
    /// Stable poses with probabilities.
    pub stable_poses: Vec<StablePose>,
    /// Exact symmetry group.
    pub group: Vec<UnitQuaternion<f64>>,
}

impl AblationPart {
    /// From a prepared catalog part.
    pub fn from_spec(spec: &PartSpec) -> Result<Self, AblationError> {
        if spec.keypoints.len() < 4 || spec.stable_poses.is_empty() {
            return Err(AblationError::Unprepared(spec.name.clone()));
        }
        Ok(Self {
            name: spec.name.clone(),
            keypoints: spec.keypoint_points(),
            stable_poses: spec.stable_poses.clone(),
            group: symmetry_group(&spec.symmetries),
        })
    }

    /// A stand-in with the main shell's size (8.8 × 9.1 × 3.0 mm), keypoints near its box
    /// corners plus the centre, and the seed's main-shell classes: for running the ablation
    /// before a catalog has been prepared. Say so wherever its results are shown.
    pub fn synthetic_shell() -> Self {
        let stable = |name: &str, up: Vector3<f64>, probability: f64, rest_height: f64| {
            let r = StablePose::canonical_rotation(&up);
            StablePose {
                name: name.into(),
                probability,
                up_in_part: up.into(),
                rotation: r.scaled_axis().into(),
                rest_height,
            }
        };
        Self {
            name: "synthetic_shell".into(),
            keypoints: vec![
                Point3::new(-0.0044, -0.0045, -0.0015),
                Point3::new(0.0044, -0.0043, -0.0014),
                Point3::new(0.0042, 0.0045, -0.0015),
                Point3::new(-0.0043, 0.0044, -0.0013),
                Point3::new(-0.0040, -0.0041, 0.0015),
                Point3::new(0.0041, -0.0044, 0.0015),
                Point3::new(0.0044, 0.0040, 0.0012),
                Point3::new(-0.0001, 0.0045, 0.0015),
                Point3::origin(),
            ],
            stable_poses: vec![
                stable("+z", Vector3::z(), 0.584, 0.00154),
                stable("-z", -Vector3::z(), 0.378, 0.00146),
                stable("+x", Vector3::x(), 0.025, 0.0045),
                stable("-x", -Vector3::x(), 0.013, 0.0045),
            ],
            group: vec![UnitQuaternion::identity()],
        }
    }
}

/// The ablation's grid and setup.
#[derive(Debug, Clone, PartialEq)]
pub struct AblationConfig {
    /// The camera (the seed's Basler by default).
    pub camera: Camera,
    /// Camera-to-table distances along the optical axis, metres (mean object distances).
    pub distances_m: Vec<f64>,
    /// Noise standard deviations, pixels.
    pub noise_px: Vec<f64>,
    /// Noise axis modes.
    pub axes: Vec<NoiseAxis>,
    /// Trials per (part, distance, axis, noise).
    pub trials: usize,
    /// Seed of every random draw.
    pub seed: u64,
    /// Parts are placed uniformly within ± this of the optical axis on the table, metres.
    pub spread_m: f64,
    /// Camera tilt away from straight down, radians.
    pub camera_tilt: f64,
}

impl Default for AblationConfig {
    fn default() -> Self {
        Self {
            camera: Camera::basler_seed(),
            distances_m: vec![1.4, 1.6, 1.8],
            noise_px: (0..=10).map(|i| f64::from(i) * 0.5).collect(),
            axes: NoiseAxis::ALL.to_vec(),
            trials: 200,
            seed: 7,
            spread_m: 0.1,
            camera_tilt: 0.0,
        }
    }
}

impl AblationConfig {
    fn validate(&self) -> Result<(), AblationError> {
        self.camera.validate()?;
        let bad = |m: &str| Err(AblationError::InvalidConfig(m.into()));
        if self.distances_m.is_empty() || self.noise_px.is_empty() || self.axes.is_empty() {
            return bad("distances, noise levels and axes must be non-empty");
        }
        if self
            .distances_m
            .iter()
            .any(|d| !(d.is_finite() && *d > 0.05))
        {
            return bad("distances must be finite and above 5 cm");
        }
        if self.noise_px.iter().any(|n| !(n.is_finite() && *n >= 0.0)) {
            return bad("noise levels must be finite and ≥ 0");
        }
        if self.trials == 0 {
            return bad("trials must be ≥ 1");
        }
        if !(self.spread_m.is_finite() && self.spread_m >= 0.0) {
            return bad("spread must be finite and ≥ 0");
        }
        if !(self.camera_tilt.is_finite() && self.camera_tilt.abs() < 1.2) {
            return bad("camera tilt must be finite and below 1.2 rad");
        }
        Ok(())
    }

    /// The table's pose in the camera frame at `distance`: looking down, tilted about the camera
    /// x axis, the optical axis meeting the table origin `distance` away.
    #[allow(non_snake_case)]
    pub fn camera_T_table(&self, distance: f64) -> Isometry3<f64> {
        let down = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
        let tilt = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), self.camera_tilt);
        Isometry3::from_parts(Translation3::new(0.0, 0.0, distance), tilt * down)
    }
}

/// One solved trial.
#[derive(Debug, Clone, PartialEq)]
#[allow(non_snake_case)]
pub struct Trial {
    /// Part name.
    pub part: String,
    /// Camera distance, metres.
    pub distance_m: f64,
    /// Noise axis.
    pub axis: NoiseAxis,
    /// Noise σ, pixels.
    pub noise_px: f64,
    /// Trial index within its cell.
    pub index: usize,
    /// The table's pose in the camera frame.
    pub camera_T_table: Isometry3<f64>,
    /// Ground truth.
    pub camera_T_part: Isometry3<f64>,
    /// Ground-truth stable-pose class.
    pub class: usize,
    /// Noisy keypoint pixels given to the solvers.
    pub pixels: Vec<Point2<f64>>,
    /// Estimates by method (None where the method failed), in [`Method::ALL`] order.
    pub estimates: [Option<Isometry3<f64>>; 3],
    /// Errors by method, in [`Method::ALL`] order.
    pub errors: [Option<PoseErrors>; 3],
    /// Class chosen by planar refinement.
    pub planar_class: Option<usize>,
}

/// Summary of one (distance, axis, noise, method) cell over all parts and trials.
#[derive(Debug, Clone, PartialEq)]
pub struct AblationRow {
    /// Camera distance, metres.
    pub distance_m: f64,
    /// Noise axis.
    pub axis: NoiseAxis,
    /// Noise σ, pixels.
    pub noise_px: f64,
    /// Method.
    pub method: Method,
    /// Error statistics (outliers kept).
    pub summary: ErrorSummary,
    /// Trials where the method returned no pose.
    pub failures: usize,
    /// Fraction of trials where planar refinement picked the true class (NaN for PnP).
    pub class_accuracy: f64,
}

/// Everything the ablation produced.
#[derive(Debug, Clone, PartialEq)]
pub struct AblationResult {
    /// Every trial.
    pub trials: Vec<Trial>,
    /// Summaries per cell.
    pub rows: Vec<AblationRow>,
}

/// Runs the ablation over `parts`.
pub fn run_ablation(
    config: &AblationConfig,
    parts: &[AblationPart],
) -> Result<AblationResult, AblationError> {
    config.validate()?;
    if parts.is_empty() {
        return Err(AblationError::InvalidConfig("no parts".into()));
    }
    let mut trials = Vec::new();
    for (pi, part) in parts.iter().enumerate() {
        if part.keypoints.len() < 4 || part.stable_poses.is_empty() {
            return Err(AblationError::Unprepared(part.name.clone()));
        }
        let weights: f64 = part
            .stable_poses
            .iter()
            .map(|s| s.probability.max(0.0))
            .sum();
        if !(weights.is_finite() && weights > 0.0) {
            return Err(AblationError::InvalidConfig(format!(
                "part {}: stable-pose probabilities sum to {weights}",
                part.name
            )));
        }
        for (di, &distance) in config.distances_m.iter().enumerate() {
            let camera_t_table = config.camera_T_table(distance);
            let refiner = PlanarRefiner::new(
                camera_t_table,
                &part.stable_poses,
                &part.group,
                PlanarConfig::default(),
            )?;
            for (ai, &axis) in config.axes.iter().enumerate() {
                for (ni, &noise) in config.noise_px.iter().enumerate() {
                    let cell_seed = config.seed
                        ^ ((pi as u64) << 48)
                        ^ ((di as u64) << 32)
                        ^ ((ai as u64) << 24)
                        ^ ((ni as u64) << 8);
                    let mut rng = ChaCha8Rng::seed_from_u64(cell_seed);
                    for index in 0..config.trials {
                        trials.push(run_trial(
                            config,
                            part,
                            &refiner,
                            &mut rng,
                            (distance, axis, noise, index),
                            weights,
                        ));
                    }
                }
            }
        }
    }
    let rows = summarise(config, &trials);
    Ok(AblationResult { trials, rows })
}

fn sample_class(part: &AblationPart, weights: f64, rng: &mut ChaCha8Rng) -> usize {
    let mut u = rng.random_range(0.0..weights);
    for (i, s) in part.stable_poses.iter().enumerate() {
        u -= s.probability.max(0.0);
        if u < 0.0 {
            return i;
        }
    }
    part.stable_poses.len() - 1
}

fn run_trial(
    config: &AblationConfig,
    part: &AblationPart,
    refiner: &PlanarRefiner,
    rng: &mut ChaCha8Rng,
    (distance, axis, noise, index): (f64, NoiseAxis, f64, usize),
    weights: f64,
) -> Trial {
    let camera_t_table = *refiner.camera_T_table();
    let class = sample_class(part, weights, rng);
    let table_t_part = part.stable_poses[class].table_T_part(
        rng.random_range(-config.spread_m..=config.spread_m),
        rng.random_range(-config.spread_m..=config.spread_m),
        rng.random_range(-std::f64::consts::PI..std::f64::consts::PI),
    );
    let truth = camera_t_table * table_t_part;
    let model = KeypointNoiseModel {
        axis,
        ..KeypointNoiseModel::new(noise.max(0.0), 0.0)
    };
    let pixels: Vec<Point2<f64>> = part
        .keypoints
        .iter()
        .map(|p| {
            let px = config
                .camera
                .project(&(truth * p))
                .unwrap_or(Point2::new(f64::NAN, f64::NAN));
            model.perturb(px, rng)
        })
        .collect();
    let cam = &config.camera;
    let pnp = solve_pnp(cam, &part.keypoints, &pixels, None).ok();
    let planar = pnp
        .as_ref()
        .and_then(|s| refiner.refine(&s.camera_T_part).ok());
    let fit = pnp.as_ref().and_then(|s| {
        refiner
            .refine_with_keypoints(
                &s.camera_T_part,
                cam,
                &part.keypoints,
                &pixels,
                None,
                ClassSet::ALL,
            )
            .ok()
    });
    let estimates = [
        pnp.as_ref().map(|s| s.camera_T_part),
        planar.as_ref().map(|p| p.camera_T_part),
        fit.as_ref().map(|p| p.camera_T_part),
    ];
    let errors = estimates
        .map(|e| e.map(|e| pose_errors(cam, &part.keypoints, &part.group, &[], &truth, &e)));
    Trial {
        part: part.name.clone(),
        distance_m: distance,
        axis,
        noise_px: noise,
        index,
        camera_T_table: camera_t_table,
        camera_T_part: truth,
        class,
        pixels,
        estimates,
        errors,
        planar_class: planar.map(|p| p.class),
    }
}

fn summarise(config: &AblationConfig, trials: &[Trial]) -> Vec<AblationRow> {
    let mut rows = Vec::new();
    for &distance in &config.distances_m {
        for &axis in &config.axes {
            for &noise in &config.noise_px {
                let cell: Vec<&Trial> = trials
                    .iter()
                    .filter(|t| t.distance_m == distance && t.axis == axis && t.noise_px == noise)
                    .collect();
                let correct = cell
                    .iter()
                    .filter(|t| t.planar_class == Some(t.class))
                    .count();
                for (mi, &method) in Method::ALL.iter().enumerate() {
                    let errors: Vec<PoseErrors> =
                        cell.iter().filter_map(|t| t.errors[mi]).collect();
                    rows.push(AblationRow {
                        distance_m: distance,
                        axis,
                        noise_px: noise,
                        method,
                        summary: ErrorSummary::of(&errors, SummaryOptions::default()),
                        failures: cell.len() - errors.len(),
                        class_accuracy: if method == Method::Pnp {
                            f64::NAN
                        } else {
                            correct as f64 / cell.len().max(1) as f64
                        },
                    });
                }
            }
        }
    }
    rows
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reproduces_the_seeds_qualitative_findings() {
        let config = AblationConfig {
            distances_m: vec![1.4, 1.8],
            noise_px: vec![0.0, 1.0, 3.0],
            axes: vec![NoiseAxis::Iso],
            trials: 60,
            ..AblationConfig::default()
        };
        let result = run_ablation(&config, &[AblationPart::synthetic_shell()]).unwrap();
        let row = |d: f64, n: f64, m: Method| {
            result
                .rows
                .iter()
                .find(|r| r.distance_m == d && r.noise_px == n && r.method == m)
                .unwrap()
                .clone()
        };
        // Noise-free: every method is exact.
        for m in Method::ALL {
            let r = row(1.4, 0.0, m);
            assert_eq!(r.failures, 0);
            assert!(r.summary.z_mm.max < 1e-3, "{m:?} {}", r.summary.z_mm.max);
        }
        // PnP depth and angle errors grow with noise and with distance; x, y stay sub-mm.
        let (a, b, c) = (
            row(1.4, 1.0, Method::Pnp),
            row(1.4, 3.0, Method::Pnp),
            row(1.8, 3.0, Method::Pnp),
        );
        assert!(b.summary.z_mm.mean > 2.0 * a.summary.z_mm.mean);
        assert!(c.summary.z_mm.mean > b.summary.z_mm.mean);
        assert!(b.summary.angle_deg.mean > 2.0 * a.summary.angle_deg.mean);
        assert!(b.summary.z_mm.mean > 10.0 * b.summary.x_mm.mean);
        // Planar refinement removes most of the depth error and most of the angle error.
        let p = row(1.8, 3.0, Method::Planar);
        assert!(p.summary.z_mm.mean < 0.1 * c.summary.z_mm.mean);
        assert!(p.summary.angle_deg.mean < 0.5 * c.summary.angle_deg.mean);
        assert!(p.class_accuracy > 0.95, "{}", p.class_accuracy);
        let f = row(1.8, 3.0, Method::PlanarFit);
        // The 3-DOF keypoint fit is no worse (the closed form already gets in-plane rotation
        // and x, y from PnP, which observes them well) and keeps x, y sub-millimetre.
        assert!(f.summary.angle_deg.mean < 1.05 * p.summary.angle_deg.mean);
        assert!(f.summary.x_mm.mean < 0.3 && f.summary.y_mm.mean < 0.3);
    }

    #[test]
    fn trials_repeat_by_seed() {
        let config = AblationConfig {
            distances_m: vec![1.5],
            noise_px: vec![2.0],
            axes: vec![NoiseAxis::X],
            trials: 5,
            ..AblationConfig::default()
        };
        let parts = [AblationPart::synthetic_shell()];
        let a = run_ablation(&config, &parts).unwrap();
        let b = run_ablation(&config, &parts).unwrap();
        assert_eq!(a.trials, b.trials);
        // X-only noise leaves the rows untouched.
        for t in &a.trials {
            for (p, k) in t.pixels.iter().zip(&parts[0].keypoints) {
                let ideal = config.camera.project(&(t.camera_T_part * k)).unwrap();
                assert!((p.y - ideal.y).abs() < 1e-9);
            }
        }
        assert!(matches!(
            run_ablation(
                &AblationConfig {
                    trials: 0,
                    ..config.clone()
                },
                &parts
            ),
            Err(AblationError::InvalidConfig(_))
        ));
    }
}
