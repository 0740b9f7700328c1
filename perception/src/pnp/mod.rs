//! Perspective-n-point: the pose of a part from n ≥ 4 model points and their pixels.
//!
//! [`solve_pnp`] runs SQPnP (the `sqpnp` crate) for a global initial solution, then refines it with
//! covariance-weighted Levenberg–Marquardt on the reprojection error (the `levenberg-marquardt`
//! crate), and returns the pose with its reprojection RMS and a 6×6 covariance.

mod error;
mod initial;
mod refine;

use nalgebra::{Isometry3, Matrix2, Matrix6, Point2, Point3};

pub use error::PnpError;
pub use initial::{check_geometry, initial_pose};
pub(crate) use refine::left_jacobian;
pub use refine::{PixelScale, RefineOutcome, refine_pose, reprojection_rms};

/// A PnP result.
#[derive(Debug, Clone, PartialEq)]
#[allow(non_snake_case)]
pub struct PnpSolution {
    /// The refined pose of the part in the camera frame.
    pub camera_T_part: Isometry3<f64>,
    /// The initial (SQPnP) pose before refinement.
    pub initial_camera_T_part: Isometry3<f64>,
    /// Root-mean-square reprojection error of the refined pose, pixels (per point, both axes).
    pub rms_px: f64,
    /// The same for the initial pose.
    pub initial_rms_px: f64,
    /// Covariance of the pose error `[δt (m); δω (rad)]`, where the true pose is
    /// `(exp(δω) · R̂, t̂ + δt)` in the camera frame. With keypoint covariances it is
    /// (JᵀΣ⁻¹J)⁻¹; without, the reprojection residuals set the noise level (σ̂²·(JᵀJ)⁻¹).
    pub covariance: Matrix6<f64>,
    /// Levenberg–Marquardt residual evaluations.
    pub evaluations: usize,
}

/// Solves PnP for pixels of `camera` (distorted, as observed) and model points in the part frame.
///
/// `covariances`, when given, are the 2×2 pixel covariances of the image points (from keypoint
/// voting); the refinement then minimises the Mahalanobis reprojection error.
pub fn solve_pnp(
    camera: &crate::Camera,
    model: &[Point3<f64>],
    pixels: &[Point2<f64>],
    covariances: Option<&[Matrix2<f64>]>,
) -> Result<PnpSolution, PnpError> {
    let n = model.len();
    if pixels.len() != n {
        return Err(PnpError::LengthMismatch {
            what: "image points",
            expected: n,
            got: pixels.len(),
        });
    }
    if let Some(c) = covariances
        && c.len() != n
    {
        return Err(PnpError::LengthMismatch {
            what: "covariances",
            expected: n,
            got: c.len(),
        });
    }
    if n < 4 {
        return Err(PnpError::TooFewPoints(n));
    }
    if pixels.iter().any(|p| !(p.x.is_finite() && p.y.is_finite())) {
        return Err(PnpError::NonFinite("image points"));
    }
    let normalized = pixels
        .iter()
        .map(|p| camera.unproject(*p).map(Point2::from))
        .collect::<Result<Vec<_>, _>>()?;
    // Refinement measures residuals in pixels through the lens: the observations stay distorted.
    let distorted: Vec<Point2<f64>> = pixels
        .iter()
        .map(|p| Point2::from(camera.pixel_to_normalized(*p)))
        .collect();
    solve(
        &PixelScale::of(camera),
        model,
        &normalized,
        &distorted,
        covariances,
    )
}

fn solve(
    scale: &PixelScale,
    model: &[Point3<f64>],
    undistorted: &[Point2<f64>],
    distorted: &[Point2<f64>],
    covariances: Option<&[Matrix2<f64>]>,
) -> Result<PnpSolution, PnpError> {
    check_geometry(model, undistorted)?;
    let initial = initial_pose(model, undistorted)?;
    let outcome = refine_pose(scale, model, distorted, covariances, &initial)?;
    Ok(PnpSolution {
        camera_T_part: outcome.camera_T_part,
        initial_camera_T_part: initial,
        rms_px: outcome.rms_px,
        initial_rms_px: reprojection_rms(scale, model, distorted, &initial),
        covariance: outcome.covariance,
        evaluations: outcome.evaluations,
    })
}
