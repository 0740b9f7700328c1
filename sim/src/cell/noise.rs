//! Error sources: per-episode random streams and the named errors a failure is attributed to.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector2, Vector3, Vector6};
use perception::calibration::covariance::perturb;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use crate::config::{CalibrationSpec, NoiseSpec, PoseCovariance};

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
///
/// Without a measured calibration the error is the typed one, as it always was: three
/// independent translation draws of `noise.calibration_translation` and three rotation draws of
/// `noise.calibration_rotation`, applied as `Iso(δt, exp(δr)) · nominal`, a perturbation in the
/// base frame that turns the camera about the base origin.
///
/// With `[cell.calibration]` the error is drawn from its measured `camera_covariance`
/// ([`measured_camera_error`]), whose convention is perception's PnP one: the rotation turns the
/// camera about its own centre, so it moves the camera's orientation only.
#[allow(non_snake_case)]
pub fn true_camera_pose(
    base_T_camera_nominal: &Isometry3<f64>,
    noise: &NoiseSpec,
    calibration: Option<&CalibrationSpec>,
    rng: &mut impl Rng,
) -> Isometry3<f64> {
    if let Some(c) = calibration {
        return measured_camera_error(base_T_camera_nominal, &c.camera_covariance, rng);
    }
    let dt = gauss3(rng, noise.calibration_translation);
    let dr = gauss3(rng, noise.calibration_rotation);
    Isometry3::from_parts(Translation3::from(dt), UnitQuaternion::from_scaled_axis(dr))
        * base_T_camera_nominal
}

/// A true `base_T_camera` drawn around the calibrated one from the covariance the calibration
/// measured: e = L z with z six standard normal draws and L the covariance's Cholesky factor
/// (a correlated normal with exactly that covariance), read as `[δt; δω]` in the PnP convention
/// ([`PoseCovariance`]): true = `(exp(δω) · R̂, t̂ + δt)`, δt and δω along base axes.
///
/// The covariance is about the camera's centre, not the base origin: turning the camera by δω
/// about the base origin would also move its centre by δω × t̂ (≈ 1.5 m · δω, 30 µm at 20 µrad)
/// and count that twice. A covariance measured in the camera's own axes (`Σ_c` of
/// `base_T_camera · exp([δt_c; δω_c])`) is this one after rotating both blocks by R̂:
/// `Σ = diag(R̂, R̂) Σ_c diag(R̂, R̂)ᵀ`, since R̂ exp(δω_c) = exp(R̂ δω_c) R̂.
#[allow(non_snake_case)]
pub fn measured_camera_error(
    base_T_camera_nominal: &Isometry3<f64>,
    covariance: &PoseCovariance,
    rng: &mut impl Rng,
) -> Isometry3<f64> {
    let z = Vector6::from_fn(|_, _| StandardNormal.sample(rng));
    perturb(base_T_camera_nominal, &(covariance.factor() * z))
}

/// A named error source.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ErrorSource {
    /// `noise.robot_repeatability`.
    RobotRepeatability,
    /// `noise.calibration_translation` / `calibration_rotation`, or the covariance
    /// `[cell.calibration]` measured.
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

#[cfg(test)]
mod tests {
    use nalgebra::Matrix6;

    use super::*;

    #[allow(non_snake_case)]
    fn base_T_camera() -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(0.4, -0.1, 1.5),
            UnitQuaternion::from_scaled_axis(Vector3::new(3.1, 0.05, -0.02)),
        )
    }

    /// A covariance like a board calibration's: µm and µrad, rotation about x coupled with
    /// translation along y (a tilt looks like a shift), and tx with ty.
    fn measured() -> PoseCovariance {
        let sigma = [8e-6, 9e-6, 30e-6, 15e-6, 14e-6, 6e-6];
        let mut corr = Matrix6::identity();
        for (i, j, r) in [(1, 3, -0.8), (0, 4, 0.7), (0, 1, 0.3), (2, 5, -0.2)] {
            corr[(i, j)] = r;
            corr[(j, i)] = r;
        }
        let s = Matrix6::from_diagonal(&Vector6::from(sigma));
        PoseCovariance::new(s * corr * s).unwrap()
    }

    #[test]
    fn without_a_measured_calibration_the_draw_is_the_typed_one_bit_for_bit() {
        // The bits this function gave before `[cell.calibration]` existed: the regression
        // baselines of every scenario without it depend on them.
        let mut rng = crate::seed::stream_rng(7, 3, CALIBRATION_STREAM);
        let p = true_camera_pose(&base_T_camera(), &NoiseSpec::default(), None, &mut rng);
        let q = p.rotation.coords;
        let bits = [
            p.translation.x,
            p.translation.y,
            p.translation.z,
            q.x,
            q.y,
            q.z,
            q.w,
        ]
        .map(f64::to_bits);
        assert_eq!(
            bits,
            [
                4600875697057582120,
                13815240685586667861,
                4609434527064462734,
                4607179148535368943,
                4580327173114478298,
                13797402396315712961,
                4581581915376181273
            ]
        );
    }

    #[test]
    fn measured_errors_have_the_measured_covariance() {
        let cov = measured();
        let nominal = base_T_camera();
        let mut rng = crate::seed::stream_rng(1, 0, CALIBRATION_STREAM);
        let n = 40_000;
        let samples: Vec<Vector6<f64>> = (0..n)
            .map(|_| {
                let p = measured_camera_error(&nominal, &cov, &mut rng);
                perception::calibration::covariance::difference(&nominal, &p)
            })
            .collect();
        let mean: Vector6<f64> = samples.iter().sum::<Vector6<f64>>() / n as f64;
        let sample: Matrix6<f64> = samples
            .iter()
            .map(|e| (e - mean) * (e - mean).transpose())
            .sum::<Matrix6<f64>>()
            / (n - 1) as f64;
        let c = cov.matrix();
        for i in 0..6 {
            // The mean is zero within 4 standard errors.
            assert!(
                mean[i].abs() < 4.0 * (c[(i, i)] / n as f64).sqrt(),
                "mean {i}"
            );
            for j in 0..6 {
                // Standard error of a sample covariance entry of a normal: sqrt((σii σjj + σij²)/n).
                let se = ((c[(i, i)] * c[(j, j)] + c[(i, j)].powi(2)) / n as f64).sqrt();
                let d = sample[(i, j)] - c[(i, j)];
                assert!(
                    d.abs() < 4.0 * se,
                    "entry ({i}, {j}): {:e} vs {:e} (se {se:e})",
                    sample[(i, j)],
                    c[(i, j)]
                );
            }
        }
    }

    #[test]
    fn a_measured_rotation_turns_the_camera_about_its_own_centre() {
        let mut only_rotation = Matrix6::zeros();
        only_rotation
            .fixed_view_mut::<3, 3>(0, 0)
            .fill_with_identity();
        only_rotation *= 1e-30;
        for i in 3..6 {
            only_rotation[(i, i)] = 4e-10;
        }
        let cov = PoseCovariance::new(only_rotation).unwrap();
        let nominal = base_T_camera();
        let mut rng = crate::seed::stream_rng(2, 0, CALIBRATION_STREAM);
        let p = measured_camera_error(&nominal, &cov, &mut rng);
        let moved = (p.translation.vector - nominal.translation.vector).norm();
        let turned = p.rotation.angle_to(&nominal.rotation);
        assert!(moved < 1e-14, "the centre moved {moved:e} m");
        assert!(turned > 1e-6, "the camera did not turn ({turned:e} rad)");
    }

    #[test]
    fn a_measured_calibration_replaces_the_typed_numbers() {
        let nominal = base_T_camera();
        let spec = CalibrationSpec {
            method: crate::config::CalibrationMethod::Touch,
            date: "2026-11-28T03:30:00Z".into(),
            camera_covariance: measured(),
            table_covariance: measured(),
            reprojection_rms_px: 0.05,
            tags: 16,
            board: None,
        };
        let mut a = crate::seed::stream_rng(3, 1, CALIBRATION_STREAM);
        let mut b = a.clone();
        let typed = true_camera_pose(&nominal, &NoiseSpec::default(), Some(&spec), &mut a);
        let direct = measured_camera_error(&nominal, &spec.camera_covariance, &mut b);
        assert_eq!(typed, direct);
    }
}
