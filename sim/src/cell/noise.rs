//! Error sources: per-episode random streams and the named errors a failure is attributed to.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector2, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use crate::config::NoiseSpec;

/// A zero-mean normal draw with standard deviation `sigma` (0 when `sigma` ≤ 0 or not finite).
pub fn gauss(rng: &mut (impl Rng + ?Sized), sigma: f64) -> f64 {
    if !(sigma.is_finite() && sigma > 0.0) {
        return 0.0;
    }
    let z: f64 = StandardNormal.sample(rng);
    sigma * z
}

/// A vector of three independent normal draws.
pub fn gauss3(rng: &mut (impl Rng + ?Sized), sigma: f64) -> Vector3<f64> {
    Vector3::new(gauss(rng, sigma), gauss(rng, sigma), gauss(rng, sigma))
}

/// The ChaCha stream ids of an episode's random streams ([`crate::seed::stream_rng`]), listed
/// together so no two uses share one: feeder placement and shakes.
pub const FEEDER_STREAM: u64 = 1;
/// Camera calibration error.
pub const CALIBRATION_STREAM: u64 = 2;
/// Robot repeatability.
pub const ROBOT_STREAM: u64 = 3;
/// Grasp residuals.
pub const GRASP_STREAM: u64 = 4;
/// Perception noise, drawn outside the simulated cell by the orchestrator's keypoint-noise
/// perception.
pub const PERCEPTION_STREAM: u64 = 5;
/// Sensor noise of rendered camera captures.
pub const CAMERA_STREAM: u64 = 6;

/// Independent random streams of one episode, so a change in one (more feeder parts, another
/// motion) does not shift the others, and any episode replays alone from (seed, index).
#[derive(Debug, Clone)]
pub struct EpisodeStreams {
    /// Feeder placement and shakes.
    pub feeder: ChaCha8Rng,
    /// Camera calibration error.
    pub calibration: ChaCha8Rng,
    /// Robot repeatability.
    pub robot: ChaCha8Rng,
    /// Grasp residuals.
    pub grasp: ChaCha8Rng,
    /// Sensor noise of rendered captures.
    pub camera: ChaCha8Rng,
}

impl EpisodeStreams {
    /// The streams of episode `index` of a run seeded with `seed`.
    pub fn new(seed: u64, index: u64) -> Self {
        let make = |stream: u64| crate::seed::stream_rng(seed, index, stream);
        Self {
            feeder: make(FEEDER_STREAM),
            calibration: make(CALIBRATION_STREAM),
            robot: make(ROBOT_STREAM),
            grasp: make(GRASP_STREAM),
            camera: make(CAMERA_STREAM),
        }
    }
}

/// The true camera pose: the nominal (calibrated) pose perturbed by the calibration error.
#[allow(non_snake_case)]
pub fn true_camera_pose(
    base_T_camera_nominal: &Isometry3<f64>,
    noise: &NoiseSpec,
    rng: &mut impl Rng,
) -> Isometry3<f64> {
    let dt = gauss3(rng, noise.calibration_translation);
    let dr = gauss3(rng, noise.calibration_rotation);
    Isometry3::from_parts(Translation3::from(dt), UnitQuaternion::from_scaled_axis(dr))
        * base_T_camera_nominal
}

/// A named error source.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ErrorSource {
    /// `noise.robot_repeatability`.
    RobotRepeatability,
    /// `noise.calibration_translation` / `calibration_rotation`.
    CameraCalibration,
    /// `noise.grasp_offset` / `grasp_rotation`, and jaws that did not square the part.
    GraspResidual,
    /// What none of the above explains: pose estimation (camera noise, outliers) and planning.
    PerceptionAndPlanning,
}

/// Lateral error at the start of an insertion split into its sources (insertion frame, metres).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ErrorBudget {
    /// Contribution of each source.
    pub contributions: Vec<(ErrorSource, Vector2<f64>)>,
    /// Share of each source along the total error (they sum to 1; negative: it reduced it).
    pub shares: Vec<(ErrorSource, f64)>,
}

impl ErrorBudget {
    /// A budget from the named contributions and the total; the remainder is
    /// [`ErrorSource::PerceptionAndPlanning`].
    pub fn new(named: Vec<(ErrorSource, Vector2<f64>)>, total: Vector2<f64>) -> Self {
        let explained: Vector2<f64> = named.iter().map(|(_, v)| *v).sum();
        let mut contributions = named;
        contributions.push((ErrorSource::PerceptionAndPlanning, total - explained));
        let n2 = total.norm_squared();
        let shares = contributions
            .iter()
            .map(|(s, v)| (*s, if n2 > 0.0 { v.dot(&total) / n2 } else { 0.0 }))
            .collect();
        Self {
            contributions,
            shares,
        }
    }

    /// The source with the largest share.
    pub fn dominant(&self) -> Option<ErrorSource> {
        self.shares
            .iter()
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(s, _)| *s)
    }
}
