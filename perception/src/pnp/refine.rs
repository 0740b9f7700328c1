//! Covariance-weighted Levenberg–Marquardt refinement of a pose on the reprojection error.

#[cfg(test)]
use nalgebra::{DVector, Dyn};
use nalgebra::{
    Isometry3, Matrix2, Matrix2x3, Matrix2x6, Matrix3, Matrix6, Point2, Point3, Translation3,
    UnitQuaternion, Vector2, Vector3, Vector6,
};

use super::PnpError;
use crate::Distortion;

/// What maps a normalised ray to pixel offsets from the principal point: focal lengths and lens
/// distortion. Residuals are measured through it, so they are true pixel errors (the maximum
/// likelihood objective for pixel noise).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelScale {
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Lens distortion.
    pub distortion: Distortion,
}

impl PixelScale {
    /// The scale of a camera.
    pub fn of(camera: &crate::Camera) -> Self {
        Self {
            fx: camera.fx,
            fy: camera.fy,
            distortion: camera.distortion,
        }
    }

    /// Pixel residual of camera-frame point `c` against distorted normalised observation `o`.
    fn residual(&self, c: &Vector3<f64>, o: &Point2<f64>) -> Vector2<f64> {
        let d = self.distortion.apply(Vector2::new(c.x / c.z, c.y / c.z));
        Vector2::new(self.fx * (d.x - o.x), self.fy * (d.y - o.y))
    }
}

/// A refined pose with its statistics.
#[derive(Debug, Clone, PartialEq)]
#[allow(non_snake_case)]
pub struct RefineOutcome {
    /// The refined pose of the part in the camera frame.
    pub camera_T_part: Isometry3<f64>,
    /// Reprojection RMS after refinement, pixels.
    pub rms_px: f64,
    /// Covariance of `[δt; δω]` (see [`super::PnpSolution::covariance`]).
    pub covariance: Matrix6<f64>,
    /// Residual evaluations spent.
    pub evaluations: usize,
}

/// Reprojection RMS (pixels, per point) of a pose on distorted normalised observations
/// ((u − cx)/fx, (v − cy)/fy).
pub fn reprojection_rms(
    scale: &PixelScale,
    model: &[Point3<f64>],
    normalized: &[Point2<f64>],
    #[allow(non_snake_case)] camera_T_part: &Isometry3<f64>,
) -> f64 {
    if model.is_empty() {
        return 0.0;
    }
    let sum: f64 = model
        .iter()
        .zip(normalized)
        .map(|(p, o)| {
            let c = camera_T_part * p;
            if c.z <= 0.0 {
                return f64::INFINITY;
            }
            scale.residual(&c.coords, o).norm_squared()
        })
        .sum();
    (sum / model.len() as f64).sqrt()
}

/// Refines `initial` by Levenberg–Marquardt on the (Mahalanobis, when `covariances` are given)
/// reprojection error in pixels; `normalized` are distorted normalised observations.
pub fn refine_pose(
    scale: &PixelScale,
    model: &[Point3<f64>],
    normalized: &[Point2<f64>],
    covariances: Option<&[Matrix2<f64>]>,
    #[allow(non_snake_case)] initial: &Isometry3<f64>,
) -> Result<RefineOutcome, PnpError> {
    let n = model.len();
    if normalized.len() != n {
        return Err(PnpError::LengthMismatch {
            what: "image points",
            expected: n,
            got: normalized.len(),
        });
    }
    if n < 4 {
        return Err(PnpError::TooFewPoints(n));
    }
    let (fx, fy) = (scale.fx, scale.fy);
    if !(fx.is_finite() && fy.is_finite() && fx > 0.0 && fy > 0.0) {
        return Err(PnpError::NonFinite("focal lengths"));
    }
    let whiten = whitening(covariances, n)?;
    let mut problem = PoseProblem::new(*scale, model, normalized, &whiten, initial);
    let initial_cost = problem.cost();
    let evaluations = problem.minimize();
    let mut pose = problem.pose();
    let cost = problem.cost();
    if cost.is_nan() || cost > initial_cost {
        // Never worse than where we started (LM only accepts improving steps; this guards
        // against a failed run leaving the parameters at a rejected trial point).
        pose = *initial;
    }
    let rms = reprojection_rms(scale, model, normalized, &pose);
    let covariance = pose_covariance(
        scale,
        model,
        normalized,
        &whiten,
        &pose,
        covariances.is_some(),
    );
    Ok(RefineOutcome {
        camera_T_part: pose,
        rms_px: rms,
        covariance,
        evaluations,
    })
}

/// Per-point whitening matrices W with Wᵀ W = Σ⁻¹ (identity without covariances).
fn whitening(
    covariances: Option<&[Matrix2<f64>]>,
    n: usize,
) -> Result<Vec<Matrix2<f64>>, PnpError> {
    let Some(covs) = covariances else {
        return Ok(vec![Matrix2::identity(); n]);
    };
    if covs.len() != n {
        return Err(PnpError::LengthMismatch {
            what: "covariances",
            expected: n,
            got: covs.len(),
        });
    }
    covs.iter()
        .enumerate()
        .map(|(i, c)| {
            if !c.iter().all(|v| v.is_finite()) {
                return Err(PnpError::NonFinite("covariances"));
            }
            let sym = (c + c.transpose()) * 0.5;
            let chol = sym.cholesky().ok_or(PnpError::BadCovariance(i))?;
            chol.l()
                .try_inverse()
                .filter(|w| w.iter().all(|v| v.is_finite()))
                .ok_or(PnpError::BadCovariance(i))
        })
        .collect()
}

/// The 6×6 pose covariance at `pose`: (JᵀJ)⁻¹ on whitened residuals, scaled by the residual
/// variance when the keypoint covariances were not given.
fn pose_covariance(
    scale: &PixelScale,
    model: &[Point3<f64>],
    normalized: &[Point2<f64>],
    whiten: &[Matrix2<f64>],
    #[allow(non_snake_case)] pose: &Isometry3<f64>,
    calibrated: bool,
) -> Matrix6<f64> {
    let problem = PoseProblem::new(*scale, model, normalized, whiten, pose);
    let (jtj, _, cost) = problem.normal_equations();
    let Some(inv) = jtj.try_inverse() else {
        return Matrix6::from_diagonal_element(f64::INFINITY);
    };
    let scale = if calibrated {
        1.0
    } else {
        let dof = (2.0 * model.len() as f64 - 6.0).max(1.0);
        cost / dof
    };
    inv * scale
}

/// The left Jacobian of SO(3) at w: exp(w + δ) ≈ exp(J_l(w) δ) exp(w) (series near zero).
pub(crate) fn left_jacobian(w: &Vector3<f64>) -> Matrix3<f64> {
    let theta2 = w.norm_squared();
    let k = w.cross_matrix();
    let (a, b) = if theta2 < 1e-10 {
        (0.5 - theta2 / 24.0, 1.0 / 6.0 - theta2 / 120.0)
    } else {
        let theta = theta2.sqrt();
        (
            (1.0 - theta.cos()) / theta2,
            (theta - theta.sin()) / (theta2 * theta),
        )
    };
    Matrix3::identity() + k * a + k * k * b
}

/// The least-squares problem: parameters `[t; ω]`, pose `(exp(ω)·R₀, t)`.
struct PoseProblem<'a> {
    scale: PixelScale,
    model: &'a [Point3<f64>],
    observed: &'a [Point2<f64>],
    whiten: &'a [Matrix2<f64>],
    reference: UnitQuaternion<f64>,
    params: Vector6<f64>,
    rotation: UnitQuaternion<f64>,
}

impl<'a> PoseProblem<'a> {
    fn new(
        scale: PixelScale,
        model: &'a [Point3<f64>],
        observed: &'a [Point2<f64>],
        whiten: &'a [Matrix2<f64>],
        start: &Isometry3<f64>,
    ) -> Self {
        let mut params = Vector6::zeros();
        params
            .fixed_rows_mut::<3>(0)
            .copy_from(&start.translation.vector);
        Self {
            scale,
            model,
            observed,
            whiten,
            reference: start.rotation,
            params,
            rotation: start.rotation,
        }
    }

    fn translation(&self) -> Vector3<f64> {
        self.params.fixed_rows::<3>(0).into_owned()
    }

    fn pose(&self) -> Isometry3<f64> {
        Isometry3::from_parts(Translation3::from(self.translation()), self.rotation)
    }

    /// Sets `[t; ω]`: pose `(exp(ω)·R₀, t)` (the derivative check varies ω away from zero).
    #[cfg(test)]
    fn set_params(&mut self, x: &Vector6<f64>) {
        self.params = *x;
        let w: Vector3<f64> = x.fixed_rows::<3>(3).into_owned();
        self.rotation = UnitQuaternion::from_scaled_axis(w) * self.reference;
    }

    /// Applies an increment `[δt; δω]` as `(exp(δω)·R, t + δt)` and re-bases ω at zero.
    fn apply_step(&mut self, step: &Vector6<f64>) {
        let w: Vector3<f64> = step.fixed_rows::<3>(3).into_owned();
        let t = self.translation() + step.fixed_rows::<3>(0);
        self.reference = UnitQuaternion::from_scaled_axis(w) * self.rotation;
        self.rotation = self.reference;
        self.params = Vector6::new(t.x, t.y, t.z, 0.0, 0.0, 0.0);
    }

    /// Whitened residual of point i (large when it is behind the camera, so steps there fail).
    fn residual(&self, i: usize, t: &Vector3<f64>) -> Vector2<f64> {
        let c = self.rotation * self.model[i].coords + t;
        if c.z > 1e-9 {
            self.whiten[i] * self.scale.residual(&c, &self.observed[i])
        } else {
            Vector2::new(1e6, 1e6)
        }
    }

    /// Whitened residual and its 2×6 Jacobian for point i; `None` behind the camera.
    fn terms(
        &self,
        i: usize,
        t: &Vector3<f64>,
        jl: &Matrix3<f64>,
    ) -> Option<(Vector2<f64>, Matrix2x6<f64>)> {
        let rp = self.rotation * self.model[i].coords;
        let c = rp + t;
        if c.z <= 1e-9 {
            return None;
        }
        let iz = 1.0 / c.z;
        // d(normalised)/d(c), then through the distortion, then to pixels.
        let dproj = Matrix2x3::new(iz, 0.0, -c.x * iz * iz, 0.0, iz, -c.y * iz * iz);
        let ddist = self
            .scale
            .distortion
            .jacobian(Vector2::new(c.x * iz, c.y * iz));
        let focal = Matrix2::new(self.scale.fx, 0.0, 0.0, self.scale.fy);
        let d = self.whiten[i] * focal * ddist * dproj;
        let drot = d * (-rp.cross_matrix() * jl);
        let mut j = Matrix2x6::zeros();
        j.fixed_columns_mut::<3>(0).copy_from(&d);
        j.fixed_columns_mut::<3>(3).copy_from(&drot);
        Some((
            self.whiten[i] * self.scale.residual(&c, &self.observed[i]),
            j,
        ))
    }

    /// The minimised objective: the sum of squared whitened residuals.
    fn cost(&self) -> f64 {
        let t = self.translation();
        (0..self.model.len())
            .map(|i| self.residual(i, &t).norm_squared())
            .sum()
    }

    /// JᵀJ, Jᵀr and the cost at the current parameters, without allocating.
    fn normal_equations(&self) -> (Matrix6<f64>, Vector6<f64>, f64) {
        let t = self.translation();
        let w: Vector3<f64> = self.params.fixed_rows::<3>(3).into_owned();
        let jl = left_jacobian(&w);
        let (mut h, mut g, mut cost) = (Matrix6::zeros(), Vector6::zeros(), 0.0);
        for i in 0..self.model.len() {
            match self.terms(i, &t, &jl) {
                Some((r, j)) => {
                    h += j.transpose() * j;
                    g += j.transpose() * r;
                    cost += r.norm_squared();
                }
                None => cost += 2e12,
            }
        }
        (h, g, cost)
    }

    /// Levenberg–Marquardt (Marquardt's diagonal scaling) on the 6×6 normal equations; returns
    /// the number of cost evaluations.
    fn minimize(&mut self) -> usize {
        let (mut h, mut g, mut current) = self.normal_equations();
        let mut evaluations = 1;
        let mut lambda = 1e-3;
        for _ in 0..100 {
            if !current.is_finite() || g.amax() <= 1e-15 * (1.0 + current) {
                break;
            }
            let mut accepted = false;
            for _ in 0..16 {
                let mut a = h;
                for k in 0..6 {
                    a[(k, k)] += lambda * h[(k, k)].max(1e-12);
                }
                let Some(step) = a.cholesky().map(|c| -c.solve(&g)) else {
                    lambda *= 10.0;
                    continue;
                };
                let saved = (self.reference, self.rotation, self.params);
                self.apply_step(&step);
                let (h2, g2, cost) = self.normal_equations();
                evaluations += 1;
                if cost < current {
                    let small = (current - cost) <= 1e-15 * current
                        || step.norm() <= 1e-15 * (1.0 + self.translation().norm());
                    (h, g, current) = (h2, g2, cost);
                    lambda = (lambda * 0.2).max(1e-15);
                    accepted = !small;
                    break;
                }
                (self.reference, self.rotation, self.params) = saved;
                lambda *= 10.0;
            }
            if !accepted {
                break;
            }
        }
        evaluations
    }
}

#[cfg(test)]
impl levenberg_marquardt::LeastSquaresProblem<f64, Dyn, nalgebra::U6> for PoseProblem<'_> {
    type ResidualStorage = nalgebra::Owned<f64, Dyn>;
    type JacobianStorage = nalgebra::Owned<f64, Dyn, nalgebra::U6>;
    type ParameterStorage = nalgebra::Owned<f64, nalgebra::U6>;

    fn set_params(&mut self, x: &Vector6<f64>) {
        PoseProblem::set_params(self, x);
    }

    fn params(&self) -> Vector6<f64> {
        self.params
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        let t = self.translation();
        let mut r = DVector::zeros(2 * self.model.len());
        for i in 0..self.model.len() {
            r.fixed_rows_mut::<2>(2 * i)
                .copy_from(&self.residual(i, &t));
        }
        Some(r)
    }

    fn jacobian(&self) -> Option<nalgebra::OMatrix<f64, Dyn, nalgebra::U6>> {
        let t = self.translation();
        let w: Vector3<f64> = self.params.fixed_rows::<3>(3).into_owned();
        let jl = left_jacobian(&w);
        let mut jac = nalgebra::OMatrix::<f64, Dyn, nalgebra::U6>::zeros(2 * self.model.len());
        for i in 0..self.model.len() {
            if let Some((_, j)) = self.terms(i, &t, &jl) {
                jac.fixed_rows_mut::<2>(2 * i).copy_from(&j);
            }
        }
        Some(jac)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use levenberg_marquardt::{LeastSquaresProblem, differentiate_numerically};

    #[test]
    fn jacobian_matches_numeric_differentiation() {
        let model: Vec<Point3<f64>> = (0..6)
            .map(|i| {
                let a = f64::from(i);
                Point3::new(0.004 * a.cos(), 0.003 * a.sin(), 0.001 * (a - 2.5))
            })
            .collect();
        let truth = Isometry3::new(Vector3::new(0.02, -0.01, 1.5), Vector3::new(0.3, -0.2, 1.0));
        let obs: Vec<Point2<f64>> = model
            .iter()
            .map(|p| {
                let c = truth * p;
                Point2::new(c.x / c.z + 1e-5, c.y / c.z)
            })
            .collect();
        let whiten = vec![Matrix2::new(1.0, 0.2, 0.0, 0.7); model.len()];
        let scale = PixelScale::of(&crate::Camera::basler_seed());
        let mut problem = PoseProblem::new(scale, &model, &obs, &whiten, &truth);
        problem.set_params(&Vector6::new(0.02, -0.01, 1.5, 0.05, -0.02, 0.03));
        let numeric = differentiate_numerically(&mut problem).unwrap();
        let analytic = problem.jacobian().unwrap();
        let scale = analytic.amax();
        assert!(
            (numeric - analytic).amax() < 1e-6 * scale,
            "analytic and numeric Jacobians differ"
        );
    }
}
