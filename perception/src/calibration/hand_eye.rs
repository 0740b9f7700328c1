//! Hand-eye calibration, eye-to-hand: the fixed camera in the robot base from views of a board
//! carried by the arm (AX = XB).
//!
//! At view i the robot reads `base_T_flange_i` (Fᵢ) and the camera sees `camera_T_board_i` (Cᵢ);
//! the unknowns are X = `base_T_camera` and Y = `flange_T_board`, with Fᵢ Y = X Cᵢ. For two views,
//! A = Fᵢ Fⱼ⁻¹ and B = Cᵢ Cⱼ⁻¹ satisfy A X = X B. The closed form is Park & Martin's: the rotation
//! vectors of A are those of B turned by R_X (an orthogonal Procrustes problem, solved by SVD),
//! then t_X from (R_A − I) t_X = R_X t_B − t_A by linear least squares, and Y as the mean of
//! Fᵢ⁻¹ X Cᵢ. A joint Levenberg–Marquardt refinement (the `levenberg-marquardt` crate) then fits X
//! and Y to every view, each weighted by its board-pose covariance plus the arm's repeatability.

use crate::pnp::left_jacobian;
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{
    Cholesky, DVector, Dyn, Isometry3, Matrix3, Matrix6, OMatrix, Owned, Rotation3, SMatrix,
    SVector, Translation3, U12, UnitQuaternion, Vector3, Vector6,
};

use super::CalibrationError;
use super::rigid_fit::UR_REPEATABILITY_SIGMA;

/// One view: where the robot says the flange is, and where the camera sees the board.
#[derive(Debug, Clone, PartialEq)]
#[allow(non_snake_case)]
pub struct HandEyeView {
    /// The flange in the robot base, as the robot reads it.
    pub base_T_flange: Isometry3<f64>,
    /// The board in the camera, from one image.
    pub camera_T_board: Isometry3<f64>,
    /// Covariance of `camera_T_board`, `[δt (m); δω (rad)]` in the convention of
    /// [`crate::pnp::PnpSolution::covariance`].
    pub covariance: Matrix6<f64>,
}

/// The arm's noise and the spread of rotation a pose set must have.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HandEyeSettings {
    /// 1σ per axis of the flange position the robot reads, metres.
    pub robot_translation_sigma: f64,
    /// 1σ per axis of the flange orientation the robot reads, radians.
    pub robot_rotation_sigma: f64,
    /// The least rms relative rotation, radians, the pose set must have about each of two
    /// independent axes.
    pub min_rotation_spread: f64,
}

impl Default for HandEyeSettings {
    /// A UR e-Series arm: ±0.03 mm repeatability ([`UR_REPEATABILITY_SIGMA`] per axis), and as
    /// orientation that position over a UR5e's 0.85 m reach (≈ 12 µrad); 2° of spread.
    fn default() -> Self {
        Self {
            robot_translation_sigma: UR_REPEATABILITY_SIGMA,
            robot_rotation_sigma: UR_REPEATABILITY_SIGMA / 0.85,
            min_rotation_spread: 2f64.to_radians(),
        }
    }
}

/// How far one view lies from the solution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewResidual {
    /// Predicted minus measured board position in the camera, metres.
    pub translation: Vector3<f64>,
    /// Rotation from the measured to the predicted board orientation, camera frame, radians.
    pub rotation: Vector3<f64>,
    /// The residual's Mahalanobis length under the view's covariance (≈ √6 on average).
    pub mahalanobis: f64,
}

/// A hand-eye solution.
#[derive(Debug, Clone, PartialEq)]
#[allow(non_snake_case)]
pub struct HandEyeSolution {
    /// The camera in the robot base.
    pub base_T_camera: Isometry3<f64>,
    /// The board on the flange.
    pub flange_T_board: Isometry3<f64>,
    /// The closed-form (Park & Martin) camera pose before refinement.
    pub closed_form_base_T_camera: Isometry3<f64>,
    /// The closed-form board pose before refinement.
    pub closed_form_flange_T_board: Isometry3<f64>,
    /// Per view, its residual at the solution.
    pub residuals: Vec<ViewResidual>,
    /// Covariance of `base_T_camera`, `[δt (m); δω (rad)]` in the base frame, where the true pose
    /// is `(exp(δω) · R̂, t̂ + δt)` (the PnP convention, in the base frame).
    pub covariance: Matrix6<f64>,
    /// The same for `flange_T_board`, in the flange frame.
    pub board_covariance: Matrix6<f64>,
    /// Levenberg–Marquardt residual evaluations.
    pub evaluations: usize,
}

/// Solves for the camera in the base and the board on the flange from three or more views.
///
/// Refuses a pose set whose relative rotations do not span two axes (naming the missing ones),
/// and views with a non-finite reading or a covariance that is not positive definite.
pub fn solve_hand_eye(
    views: &[HandEyeView],
    settings: &HandEyeSettings,
) -> Result<HandEyeSolution, CalibrationError> {
    check_views(views)?;
    check_spread(views, settings.min_rotation_spread)?;
    #[allow(non_snake_case)]
    let (x0, y0) = closed_form(views);
    let whiten = whitening(views, settings, &x0, &y0)?;
    let problem = Problem::new(views, &whiten, x0, y0);
    let (problem, report) = LevenbergMarquardt::new().minimize(problem);
    let (x, y) = problem.poses();
    // The covariance at the solution, with the perturbations based there.
    let at = Problem::new(views, &whiten, x, y);
    let jacobian = at
        .jacobian()
        .unwrap_or_else(|| OMatrix::<f64, Dyn, U12>::zeros(6 * views.len()));
    let jtj = jacobian.transpose() * &jacobian;
    let full = jtj
        .try_inverse()
        .unwrap_or_else(|| SMatrix::<f64, 12, 12>::from_diagonal_element(f64::INFINITY));
    let residuals = views
        .iter()
        .zip(&whiten)
        .map(|(v, w)| {
            let r = view_residual(v, &x, &y);
            ViewResidual {
                translation: r.fixed_rows::<3>(0).into_owned(),
                rotation: r.fixed_rows::<3>(3).into_owned(),
                mahalanobis: (w * r).norm(),
            }
        })
        .collect();
    Ok(HandEyeSolution {
        base_T_camera: x,
        flange_T_board: y,
        closed_form_base_T_camera: x0,
        closed_form_flange_T_board: y0,
        residuals,
        covariance: full.fixed_view::<6, 6>(0, 0).into_owned(),
        board_covariance: full.fixed_view::<6, 6>(6, 6).into_owned(),
        evaluations: report.number_of_evaluations,
    })
}

/// `n` flange poses for a hand-eye calibration around `center` (a `base_T_flange` at which the
/// board faces the camera along the flange's z axis): each is `center` turned about the flange's
/// origin by a tilt of up to `tilt` radians about a flange x–y axis (directions and sizes spread
/// by a golden-angle spiral) and a spin of up to ±`spin` radians about flange z. The rotations
/// span all three axes, so the set is never degenerate; the caller checks each pose against the
/// robot's limits and the camera's view.
pub fn plan_hand_eye_poses(
    center: &Isometry3<f64>,
    n: usize,
    tilt: f64,
    spin: f64,
) -> Vec<Isometry3<f64>> {
    let golden_angle = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let golden_ratio = (5f64.sqrt() - 1.0) / 2.0;
    (0..n)
        .map(|k| {
            let phi = k as f64 * golden_angle;
            let size = tilt * ((k as f64 + 0.5) / n as f64).sqrt();
            let turn = spin * (2.0 * ((k as f64 * golden_ratio + 0.5) % 1.0) - 1.0);
            let r = UnitQuaternion::from_scaled_axis(Vector3::z() * turn)
                * UnitQuaternion::from_scaled_axis(Vector3::new(phi.cos(), phi.sin(), 0.0) * size);
            center * Isometry3::from_parts(Translation3::identity(), r)
        })
        .collect()
}

/// Refuses views with non-finite numbers and fewer than three views.
fn check_views(views: &[HandEyeView]) -> Result<(), CalibrationError> {
    for (i, v) in views.iter().enumerate() {
        let finite = |p: &Isometry3<f64>| {
            p.translation.vector.iter().all(|x| x.is_finite())
                && p.rotation.coords.iter().all(|x| x.is_finite())
        };
        let what = if !finite(&v.base_T_flange) {
            "the robot's flange pose is not finite"
        } else if !finite(&v.camera_T_board) {
            "the board pose in the camera is not finite"
        } else if !v.covariance.iter().all(|x| x.is_finite()) {
            "the board pose covariance is not finite"
        } else {
            continue;
        };
        return Err(CalibrationError::BadHandEyeView {
            index: i + 1,
            what: what.into(),
        });
    }
    if views.len() < 3 {
        return Err(CalibrationError::DegenerateHandEye {
            missing: format!(
                "only {} view(s), and at least three poses are needed for rotations about two \
                 axes",
                views.len()
            ),
        });
    }
    Ok(())
}

/// The relative robot motions A = Fᵢ Fⱼ⁻¹ and board motions B = Cᵢ Cⱼ⁻¹ of every pair of views.
fn motions(views: &[HandEyeView]) -> Vec<(Isometry3<f64>, Isometry3<f64>)> {
    let mut out = Vec::with_capacity(views.len() * (views.len() - 1) / 2);
    for i in 0..views.len() {
        for j in i + 1..views.len() {
            out.push((
                views[i].base_T_flange * views[j].base_T_flange.inverse(),
                views[i].camera_T_board * views[j].camera_T_board.inverse(),
            ));
        }
    }
    out
}

/// Refuses a set whose relative robot rotations (in the base frame) have an rms spread below
/// `min` about the second of their principal axes, naming the axes that are missing.
fn check_spread(views: &[HandEyeView], min: f64) -> Result<(), CalibrationError> {
    let pairs = motions(views);
    let mut scatter = Matrix3::zeros();
    for (a, _) in &pairs {
        let w = a.rotation.scaled_axis();
        scatter += w * w.transpose();
    }
    scatter /= pairs.len() as f64;
    let eigen = scatter.symmetric_eigen();
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eigen.eigenvalues[b].total_cmp(&eigen.eigenvalues[a]));
    let spread = |k: usize| eigen.eigenvalues[order[k]].max(0.0).sqrt();
    if spread(0) < min {
        return Err(CalibrationError::DegenerateHandEye {
            missing: format!(
                "the poses barely rotate ({:.2}° rms between poses, at least {:.1}° needed): \
                 rotations about base x, y and z are missing",
                spread(0).to_degrees(),
                min.to_degrees()
            ),
        });
    }
    if spread(1) < min {
        let axis: Vector3<f64> = eigen.eigenvectors.column(order[0]).into_owned();
        let missing: Vec<&str> = ["x", "y", "z"]
            .into_iter()
            .enumerate()
            .filter(|(k, _)| axis[*k].abs() < 0.5)
            .map(|(_, name)| name)
            .collect();
        return Err(CalibrationError::DegenerateHandEye {
            missing: format!(
                "all rotations are about one axis ({}; {:.2}° rms about any other, at least \
                 {:.1}° needed): rotations about base {} are missing",
                axis_name(&axis),
                spread(1).to_degrees(),
                min.to_degrees(),
                missing.join(" and ")
            ),
        });
    }
    Ok(())
}

/// A direction in words: a base axis when within 15° of one, else its components.
fn axis_name(axis: &Vector3<f64>) -> String {
    let k = axis.iamax();
    if axis[k].abs() > 15f64.to_radians().cos() {
        format!("base {}", ["x", "y", "z"][k])
    } else {
        let a = if axis[k] < 0.0 { -axis } else { *axis };
        format!("({:.2}, {:.2}, {:.2}) in the base", a.x, a.y, a.z)
    }
}

/// Park & Martin's closed form for X, then Y as the mean of Fᵢ⁻¹ X Cᵢ.
#[allow(non_snake_case)]
fn closed_form(views: &[HandEyeView]) -> (Isometry3<f64>, Isometry3<f64>) {
    let pairs = motions(views);
    // Rotation: α = R_X β for the rotation vectors of A and B (Procrustes by SVD).
    let mut h = Matrix3::zeros();
    for (a, b) in &pairs {
        h += b.rotation.scaled_axis() * a.rotation.scaled_axis().transpose();
    }
    let r_x = nearest_rotation_procrustes(&h);
    // Translation: (R_A − I) t_X = R_X t_B − t_A, stacked.
    let mut m = nalgebra::DMatrix::zeros(3 * pairs.len(), 3);
    let mut rhs = DVector::zeros(3 * pairs.len());
    for (k, (a, b)) in pairs.iter().enumerate() {
        let ra = a.rotation.to_rotation_matrix().into_inner() - Matrix3::identity();
        m.fixed_view_mut::<3, 3>(3 * k, 0).copy_from(&ra);
        let v = r_x * b.translation.vector - a.translation.vector;
        rhs.fixed_rows_mut::<3>(3 * k).copy_from(&v);
    }
    let t_x = m
        .svd(true, true)
        .solve(&rhs, 1e-12)
        .map(|t| Vector3::new(t[0], t[1], t[2]))
        .unwrap_or_else(|_| Vector3::zeros());
    let x = Isometry3::from_parts(Translation3::from(t_x), r_x);
    // Y: the mean of the per-view estimates (chordal mean of the rotations).
    let mut sum_r = Matrix3::zeros();
    let mut sum_t = Vector3::zeros();
    for v in views {
        let y = v.base_T_flange.inverse() * x * v.camera_T_board;
        sum_r += y.rotation.to_rotation_matrix().into_inner();
        sum_t += y.translation.vector;
    }
    let r_y = nearest_rotation(&sum_r);
    let y = Isometry3::from_parts(Translation3::from(sum_t / views.len() as f64), r_y);
    (x, y)
}

/// The rotation R maximising Σ αᵀ R β given H = Σ β αᵀ (Kabsch, reflection guarded).
fn nearest_rotation_procrustes(h: &Matrix3<f64>) -> UnitQuaternion<f64> {
    let svd = h.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return UnitQuaternion::identity();
    };
    let v = v_t.transpose();
    let d = (v * u.transpose()).determinant().signum();
    let r = v * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * u.transpose();
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r))
}

/// The rotation nearest (Frobenius) to a matrix.
fn nearest_rotation(m: &Matrix3<f64>) -> UnitQuaternion<f64> {
    // Procrustes with H = Mᵀ: R = V Uᵀ of H = U S Vᵀ maximises tr(R H) = tr(R Mᵀ).
    nearest_rotation_procrustes(&m.transpose())
}

/// Per view, W with Wᵀ W = (Σ_C + G Σ_F Gᵀ)⁻¹, where G carries the flange's reading error into
/// the predicted board pose in the camera (at the closed-form X and Y).
#[allow(non_snake_case)]
fn whitening(
    views: &[HandEyeView],
    settings: &HandEyeSettings,
    x: &Isometry3<f64>,
    y: &Isometry3<f64>,
) -> Result<Vec<Matrix6<f64>>, CalibrationError> {
    let rx_t = x.rotation.to_rotation_matrix().into_inner().transpose();
    let sigma_f = Matrix6::from_diagonal(&Vector6::new(
        settings.robot_translation_sigma.powi(2),
        settings.robot_translation_sigma.powi(2),
        settings.robot_translation_sigma.powi(2),
        settings.robot_rotation_sigma.powi(2),
        settings.robot_rotation_sigma.powi(2),
        settings.robot_rotation_sigma.powi(2),
    ));
    views
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let lever = v.base_T_flange.rotation * y.translation.vector;
            let mut g = Matrix6::zeros();
            g.fixed_view_mut::<3, 3>(0, 0).copy_from(&rx_t);
            g.fixed_view_mut::<3, 3>(0, 3)
                .copy_from(&(-rx_t * lever.cross_matrix()));
            g.fixed_view_mut::<3, 3>(3, 3).copy_from(&rx_t);
            let total = v.covariance + g * sigma_f * g.transpose();
            let total = (total + total.transpose()) * 0.5;
            let bad = || CalibrationError::BadHandEyeView {
                index: i + 1,
                what: "the board pose covariance is not positive definite".into(),
            };
            let l = Cholesky::new(total).ok_or_else(bad)?.l();
            // Σ = L Lᵀ, so W = L⁻¹ gives Wᵀ W = Σ⁻¹.
            l.try_inverse().ok_or_else(bad)
        })
        .collect()
}

/// `[t_pred − t_meas; log(R_pred R_measᵀ)]` of a view, with pred = X⁻¹ F Y.
#[allow(non_snake_case)]
fn view_residual(v: &HandEyeView, x: &Isometry3<f64>, y: &Isometry3<f64>) -> Vector6<f64> {
    let pred = x.inverse() * v.base_T_flange * y;
    let t = pred.translation.vector - v.camera_T_board.translation.vector;
    let e = (pred.rotation * v.camera_T_board.rotation.inverse()).scaled_axis();
    let mut r = Vector6::zeros();
    r.fixed_rows_mut::<3>(0).copy_from(&t);
    r.fixed_rows_mut::<3>(3).copy_from(&e);
    r
}

/// The inverse left Jacobian of SO(3) at φ: log(exp(η) exp(φ)) ≈ φ + J_l(φ)⁻¹ η.
fn inverse_left_jacobian(phi: &Vector3<f64>) -> Matrix3<f64> {
    let theta2 = phi.norm_squared();
    let k = phi.cross_matrix();
    let c = if theta2 < 1e-10 {
        1.0 / 12.0 + theta2 / 720.0
    } else {
        let theta = theta2.sqrt();
        1.0 / theta2 - (1.0 + theta.cos()) / (2.0 * theta * theta.sin())
    };
    Matrix3::identity() - k * 0.5 + k * k * c
}

/// The joint refinement: parameters `[δt_X; δω_X; δt_Y; δω_Y]`, poses
/// `X = (exp(δω_X) R_X₀, t_X₀ + δt_X)` and likewise Y, residuals whitened per view.
struct Problem<'a> {
    views: &'a [HandEyeView],
    whiten: &'a [Matrix6<f64>],
    x0: Isometry3<f64>,
    y0: Isometry3<f64>,
    params: SVector<f64, 12>,
}

impl<'a> Problem<'a> {
    fn new(
        views: &'a [HandEyeView],
        whiten: &'a [Matrix6<f64>],
        x0: Isometry3<f64>,
        y0: Isometry3<f64>,
    ) -> Self {
        Self {
            views,
            whiten,
            x0,
            y0,
            params: SVector::zeros(),
        }
    }

    /// X and Y at the current parameters.
    fn poses(&self) -> (Isometry3<f64>, Isometry3<f64>) {
        let p = &self.params;
        let at = |base: &Isometry3<f64>, o: usize| {
            let t: Vector3<f64> = p.fixed_rows::<3>(o).into_owned();
            let w: Vector3<f64> = p.fixed_rows::<3>(o + 3).into_owned();
            Isometry3::from_parts(
                Translation3::from(base.translation.vector + t),
                UnitQuaternion::from_scaled_axis(w) * base.rotation,
            )
        };
        (at(&self.x0, 0), at(&self.y0, 6))
    }
}

impl LeastSquaresProblem<f64, Dyn, U12> for Problem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, U12>;
    type ParameterStorage = Owned<f64, U12>;

    fn set_params(&mut self, x: &SVector<f64, 12>) {
        self.params = *x;
    }

    fn params(&self) -> SVector<f64, 12> {
        self.params
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        let (x, y) = self.poses();
        let mut r = DVector::zeros(6 * self.views.len());
        for (i, (v, w)) in self.views.iter().zip(self.whiten).enumerate() {
            r.fixed_rows_mut::<6>(6 * i)
                .copy_from(&(w * view_residual(v, &x, &y)));
        }
        Some(r)
    }

    fn jacobian(&self) -> Option<OMatrix<f64, Dyn, U12>> {
        let (x, y) = self.poses();
        let jl_x = left_jacobian(&self.params.fixed_rows::<3>(3).into_owned());
        let jl_y = left_jacobian(&self.params.fixed_rows::<3>(9).into_owned());
        let rx_t = x.rotation.to_rotation_matrix().into_inner().transpose();
        let mut jac = OMatrix::<f64, Dyn, U12>::zeros(6 * self.views.len());
        for (i, (v, w)) in self.views.iter().zip(self.whiten).enumerate() {
            let f = &v.base_T_flange;
            let rf = f.rotation.to_rotation_matrix().into_inner();
            let lever = rf * y.translation.vector + f.translation.vector - x.translation.vector;
            let e = view_residual(v, &x, &y).fixed_rows::<3>(3).into_owned();
            let jinv = inverse_left_jacobian(&e);
            let mut j = SMatrix::<f64, 6, 12>::zeros();
            // X: translation, then rotation (left perturbation, chained through J_l).
            j.fixed_view_mut::<3, 3>(0, 0).copy_from(&(-rx_t));
            j.fixed_view_mut::<3, 3>(0, 3)
                .copy_from(&(rx_t * lever.cross_matrix() * jl_x));
            j.fixed_view_mut::<3, 3>(3, 3)
                .copy_from(&(-jinv * rx_t * jl_x));
            // Y: translation, then rotation.
            j.fixed_view_mut::<3, 3>(0, 6).copy_from(&(rx_t * rf));
            j.fixed_view_mut::<3, 3>(3, 9)
                .copy_from(&(jinv * rx_t * rf * jl_y));
            jac.fixed_rows_mut::<6>(6 * i).copy_from(&(w * j));
        }
        Some(jac)
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::{Matrix2, Point2, Point3};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    use super::*;
    use crate::Camera;
    use crate::calibration::rigid_fit::{DEFAULT_TOUCH_BOUND, TouchPoint, fit_rigid};
    use crate::calibration::{Board, BoardSpec};
    use crate::pnp::solve_pnp;

    /// Corner noise of the refined detector, pixels (1σ per axis).
    const CORNER_SIGMA: f64 = 0.05;

    /// The camera 1.5 m above the table origin, looking down, a little tilted.
    fn base_t_camera() -> Isometry3<f64> {
        let down = UnitQuaternion::from_euler_angles(std::f64::consts::PI, 0.0, 0.0);
        Isometry3::from_parts(
            Translation3::new(0.45, -0.12, 1.52),
            UnitQuaternion::from_euler_angles(0.03, -0.02, 0.4) * down,
        )
    }

    /// The table board's pose in the base: the table 2 cm below the base origin.
    fn base_t_table_board() -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(0.43, -0.1, -0.02),
            UnitQuaternion::from_euler_angles(0.002, -0.001, 0.3),
        )
    }

    /// A 2 × 2 board of 3 cm tags on an 8 cm plate, for the flange.
    fn flange_board() -> Board {
        Board::new(BoardSpec {
            grid: [2, 2],
            removed: None,
            plate: [0.08, 0.08],
            ..BoardSpec::seed()
        })
        .unwrap()
    }

    /// The flange board 4 cm out along flange z, its print facing along flange z.
    fn flange_t_board() -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(0.003, -0.002, 0.04),
            UnitQuaternion::from_euler_angles(0.0, 0.0, 0.2),
        )
    }

    /// The flange pose at which the board faces the camera from 1.5 m below it.
    fn center_flange() -> Isometry3<f64> {
        let x = base_t_camera();
        // Board 1.45 m in front of the camera, its z towards the camera.
        let camera_t_board = Isometry3::from_parts(
            Translation3::new(0.01, -0.02, 1.45),
            UnitQuaternion::from_euler_angles(std::f64::consts::PI, 0.0, 0.1),
        );
        x * camera_t_board * flange_t_board().inverse()
    }

    fn sample(rng: &mut ChaCha8Rng, sigma: f64) -> Vector3<f64> {
        let n = Normal::new(0.0, sigma).unwrap();
        Vector3::from_fn(|_, _| n.sample(rng))
    }

    /// The board in the camera from one image: its corners projected, 0.05 px of noise added,
    /// and the project's PnP with that corner covariance.
    fn observe(
        camera: &Camera,
        board: &Board,
        camera_t_board: &Isometry3<f64>,
        rng: &mut ChaCha8Rng,
    ) -> (Isometry3<f64>, Matrix6<f64>) {
        observe_with(camera, board, camera_t_board, CORNER_SIGMA, rng)
    }

    /// [`observe`] with corner noise `sigma`, pixels.
    fn observe_with(
        camera: &Camera,
        board: &Board,
        camera_t_board: &Isometry3<f64>,
        sigma: f64,
        rng: &mut ChaCha8Rng,
    ) -> (Isometry3<f64>, Matrix6<f64>) {
        let noise = Normal::new(0.0, sigma).unwrap();
        let model: Vec<Point3<f64>> = board
            .tags()
            .iter()
            .flat_map(|t| board.corners(t.id).unwrap())
            .collect();
        let pixels: Vec<Point2<f64>> = model
            .iter()
            .map(|p| {
                let q = camera.project(&(camera_t_board * p)).unwrap();
                Point2::new(q.x + noise.sample(rng), q.y + noise.sample(rng))
            })
            .collect();
        let cov = vec![Matrix2::identity() * sigma.powi(2); model.len()];
        let s = solve_pnp(camera, &model, &pixels, Some(&cov)).unwrap();
        (s.camera_T_part, s.covariance)
    }

    /// Views of the flange board at `poses`, with the arm's and the image's noise.
    fn views(poses: &[Isometry3<f64>], rng: &mut ChaCha8Rng) -> Vec<HandEyeView> {
        views_of(&flange_board(), poses, &HandEyeSettings::default(), rng)
    }

    /// Views of `board` on the flange at `poses`, with the noise of `arm` and the image's.
    fn views_of(
        board: &Board,
        poses: &[Isometry3<f64>],
        arm: &HandEyeSettings,
        rng: &mut ChaCha8Rng,
    ) -> Vec<HandEyeView> {
        let camera = Camera::basler_seed();
        poses
            .iter()
            .map(|f| {
                let truth = base_t_camera().inverse() * f * flange_t_board();
                let (camera_t_board, covariance) = observe(&camera, board, &truth, rng);
                let read = Isometry3::from_parts(
                    Translation3::from(
                        f.translation.vector + sample(rng, arm.robot_translation_sigma),
                    ),
                    UnitQuaternion::from_scaled_axis(sample(rng, arm.robot_rotation_sigma))
                        * f.rotation,
                );
                HandEyeView {
                    base_T_flange: read,
                    camera_T_board: camera_t_board,
                    covariance,
                }
            })
            .collect()
    }

    /// Error of a camera pose where it matters: the rms distance, over points of the feeder
    /// region (±10 cm around the table board, 0–1 cm high), between where the estimate and the
    /// truth put a point the camera sees.
    fn feeder_error(estimate: &Isometry3<f64>) -> f64 {
        region_error(estimate, 0.0)
    }

    /// [`feeder_error`] for the region ±10 cm around the table point `x` metres along the
    /// table board's x axis.
    fn region_error(estimate: &Isometry3<f64>, x: f64) -> f64 {
        let truth = base_t_camera();
        let table = base_t_table_board();
        let mut sum = 0.0;
        let mut n = 0;
        for i in -2..=2 {
            for j in -2..=2 {
                for z in [0.0, 0.01] {
                    let p = table * Point3::new(x + i as f64 * 0.05, j as f64 * 0.05, z);
                    let seen = truth.inverse() * p;
                    sum += (estimate * seen - p).norm_squared();
                    n += 1;
                }
            }
        }
        (sum / n as f64).sqrt()
    }

    #[test]
    fn the_closed_form_and_the_refinement_recover_exact_views_exactly() {
        let poses = plan_hand_eye_poses(&center_flange(), 8, 0.35, 0.5);
        let views: Vec<HandEyeView> = poses
            .iter()
            .map(|f| HandEyeView {
                base_T_flange: *f,
                camera_T_board: base_t_camera().inverse() * f * flange_t_board(),
                covariance: Matrix6::from_diagonal(&Vector6::new(
                    1e-8, 1e-8, 1e-7, 1e-8, 1e-8, 1e-9,
                )),
            })
            .collect();
        let s = solve_hand_eye(&views, &HandEyeSettings::default()).unwrap();
        for (got, want) in [
            (s.closed_form_base_T_camera, base_t_camera()),
            (s.base_T_camera, base_t_camera()),
            (s.closed_form_flange_T_board, flange_t_board()),
            (s.flange_T_board, flange_t_board()),
        ] {
            let e = got.inverse() * want;
            assert!(e.translation.vector.norm() < 1e-9, "{e}");
            assert!(e.rotation.angle() < 1e-9, "{e}");
        }
        assert!(s.residuals.iter().all(|r| r.mahalanobis < 1e-6));
    }

    #[test]
    fn the_jacobian_matches_finite_differences() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let poses = plan_hand_eye_poses(&center_flange(), 5, 0.3, 0.4);
        let views = views(&poses, &mut rng);
        let (x0, y0) = closed_form(&views);
        let whiten = whitening(&views, &HandEyeSettings::default(), &x0, &y0).unwrap();
        let mut p = Problem::new(&views, &whiten, x0, y0);
        let mut at = SVector::<f64, 12>::zeros();
        for k in 0..12 {
            at[k] = 1e-3 * ((k as f64 * 0.7).sin());
        }
        p.set_params(&at);
        let analytic = p.jacobian().unwrap();
        let numeric = levenberg_marquardt::differentiate_numerically(&mut p).unwrap();
        let scale = analytic.abs().max();
        let diff = (analytic - numeric).abs().max();
        assert!(diff < 1e-6 * scale, "{diff} of {scale}");
    }

    /// Twelve views of the 2 × 2 flange board at 1.45 m (0.05 px corners, the UR's repeatability),
    /// over 200 trials: the refined base_T_camera puts feeder points 46 µm rms from the truth (the
    /// unweighted closed form: 780 µm), its covariance predicts the rotation scatter (306 µrad
    /// rms, predicted 313 µrad: the error is mostly a turn about the board that moves the feeder
    /// little), and the residuals are as large as the noise says (χ² 60.7 for 60 dof).
    #[test]
    fn noisy_views_give_the_camera_within_what_their_noise_allows() {
        let mut rng = ChaCha8Rng::seed_from_u64(42);
        let poses = plan_hand_eye_poses(&center_flange(), 12, 0.35, 0.6);
        let trials = 200;
        let (mut feeder, mut feeder_closed, mut rot_sq, mut rot_pred, mut chi2) =
            (0.0, 0.0, 0.0, 0.0, 0.0);
        for _ in 0..trials {
            let v = views(&poses, &mut rng);
            let s = solve_hand_eye(&v, &HandEyeSettings::default()).unwrap();
            feeder += feeder_error(&s.base_T_camera).powi(2);
            feeder_closed += feeder_error(&s.closed_form_base_T_camera).powi(2);
            rot_sq += (s.base_T_camera.rotation * base_t_camera().rotation.inverse())
                .scaled_axis()
                .norm_squared();
            rot_pred += s.covariance.fixed_view::<3, 3>(3, 3).trace();
            chi2 += s
                .residuals
                .iter()
                .map(|r| r.mahalanobis.powi(2))
                .sum::<f64>();
        }
        let n = trials as f64;
        let (feeder, feeder_closed) = ((feeder / n).sqrt(), (feeder_closed / n).sqrt());
        let (rot, rot_pred) = ((rot_sq / n).sqrt(), (rot_pred / n).sqrt());
        let chi2 = chi2 / n;
        eprintln!(
            "hand-eye feeder rms {:.1} µm (closed form {:.1} µm); rotation {:.1} µrad \
             (predicted {:.1} µrad); χ² {chi2:.1} for {} dof",
            feeder * 1e6,
            feeder_closed * 1e6,
            rot * 1e6,
            rot_pred * 1e6,
            6 * poses.len() - 12
        );
        assert!((feeder - 46.0e-6).abs() < 2.5e-6, "{feeder}");
        assert!(feeder_closed > 10.0 * feeder, "{feeder_closed}");
        assert!((rot / rot_pred - 1.0).abs() < 0.15, "{rot} vs {rot_pred}");
        assert!(
            (chi2 / (6 * poses.len() - 12) as f64 - 1.0).abs() < 0.15,
            "{chi2}"
        );
    }

    /// Touch points against hand-eye for the camera at the feeder, each with its noise model,
    /// over 100 trials: touch = the seed board on the table, PnP from one image (0.05 px corners)
    /// and eight touches (σ = 10 µm per axis): 30.1 µm rms at the feeder, nearly all of it the
    /// one image's depth error; hand-eye = twelve views of the 2 × 2 flange board: 45.1 µm.
    #[test]
    fn touch_points_place_the_feeder_better_than_hand_eye() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let camera = Camera::basler_seed();
        let seed = Board::seed();
        let marks = seed.touch_marks();
        let poses = plan_hand_eye_poses(&center_flange(), 12, 0.35, 0.6);
        let trials = 100;
        let (mut touch, mut hand_eye) = (0.0, 0.0);
        for _ in 0..trials {
            let truth = base_t_camera().inverse() * base_t_table_board();
            let (camera_t_board, _) = observe(&camera, &seed, &truth, &mut rng);
            let points: Vec<TouchPoint> = marks
                .iter()
                .map(|m| TouchPoint {
                    name: m.name.clone(),
                    board: m.point,
                    base: base_t_table_board() * m.point + sample(&mut rng, UR_REPEATABILITY_SIGMA),
                })
                .collect();
            let fit = fit_rigid(&points, DEFAULT_TOUCH_BOUND, UR_REPEATABILITY_SIGMA).unwrap();
            touch += feeder_error(&(fit.base_T_board * camera_t_board.inverse())).powi(2);
            let s = solve_hand_eye(&views(&poses, &mut rng), &HandEyeSettings::default()).unwrap();
            hand_eye += feeder_error(&s.base_T_camera).powi(2);
        }
        let (touch, hand_eye) = (
            (touch / trials as f64).sqrt(),
            (hand_eye / trials as f64).sqrt(),
        );
        eprintln!(
            "feeder rms: touch points {:.1} µm, hand-eye {:.1} µm",
            touch * 1e6,
            hand_eye * 1e6
        );
        assert!((touch - 30.1e-6).abs() < 2.5e-6, "{touch}");
        assert!((hand_eye - 45.1e-6).abs() < 3.5e-6, "{hand_eye}");
    }

    #[test]
    fn rotations_about_one_axis_are_refused_naming_the_missing_axes() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        // Spin only, about flange z, which points along base z here: rotations about base z.
        let upright =
            Isometry3::from_parts(center_flange().translation, UnitQuaternion::identity());
        let poses = plan_hand_eye_poses(&upright, 8, 0.0, 0.8);
        let v: Vec<HandEyeView> = poses
            .iter()
            .map(|f| HandEyeView {
                base_T_flange: *f,
                camera_T_board: base_t_camera().inverse() * f * flange_t_board(),
                covariance: Matrix6::identity() * 1e-10,
            })
            .collect();
        let _ = &mut rng;
        let e = solve_hand_eye(&v, &HandEyeSettings::default()).unwrap_err();
        let text = e.to_string();
        assert!(
            text.contains("all rotations are about one axis (base z")
                && text.contains("rotations about base x and y are missing"),
            "{text}"
        );
        // No rotation at all.
        let still = vec![v[0].clone(), v[0].clone(), v[0].clone()];
        let text = solve_hand_eye(&still, &HandEyeSettings::default())
            .unwrap_err()
            .to_string();
        assert!(
            text.contains("barely rotate") && text.contains("x, y and z"),
            "{text}"
        );
        // Two views.
        let text = solve_hand_eye(&v[..2], &HandEyeSettings::default())
            .unwrap_err()
            .to_string();
        assert!(text.contains("only 2 view(s)"), "{text}");
    }

    #[test]
    fn bad_views_are_named() {
        let poses = plan_hand_eye_poses(&center_flange(), 4, 0.3, 0.3);
        let mut v: Vec<HandEyeView> = poses
            .iter()
            .map(|f| HandEyeView {
                base_T_flange: *f,
                camera_T_board: base_t_camera().inverse() * f * flange_t_board(),
                covariance: Matrix6::identity() * 1e-10,
            })
            .collect();
        v[2].covariance[(4, 4)] = -1.0;
        let text = solve_hand_eye(&v, &HandEyeSettings::default())
            .unwrap_err()
            .to_string();
        assert!(
            text.starts_with("hand-eye view 3: the board pose covariance is not positive"),
            "{text}"
        );
        v[2].covariance = Matrix6::identity() * 1e-10;
        v[1].base_T_flange.translation.vector.x = f64::NAN;
        let text = solve_hand_eye(&v, &HandEyeSettings::default())
            .unwrap_err()
            .to_string();
        assert!(
            text.starts_with("hand-eye view 2: the robot's flange pose"),
            "{text}"
        );
    }

    #[test]
    fn planned_poses_rotate_about_all_three_axes_within_the_tilt() {
        let c = center_flange();
        let poses = plan_hand_eye_poses(&c, 12, 0.35, 0.6);
        assert_eq!(poses.len(), 12);
        let mut scatter = Matrix3::zeros();
        for p in &poses {
            assert!((p.translation.vector - c.translation.vector).norm() < 1e-12);
            let local = (c.inverse() * p).rotation;
            let z = local * Vector3::z();
            assert!(z.angle(&Vector3::z()) <= 0.35 + 1e-9);
            let w = local.scaled_axis();
            scatter += w * w.transpose();
        }
        let e = (scatter / 12.0).symmetric_eigenvalues();
        // Rms rotation about each principal axis: 0.37 rad (the spin), 0.16 and 0.098 rad (tilts).
        let mut spread: Vec<f64> = e.iter().map(|v| v.sqrt()).collect();
        spread.sort_by(f64::total_cmp);
        assert!((spread[0] - 0.098).abs() < 0.005, "{spread:?}");
        assert!((spread[2] - 0.37).abs() < 0.01, "{spread:?}");
    }

    /// The study behind the choice between touch points and hand-eye: the rms error, over 200
    /// trials, of feeder points (±10 cm around the table board) and of a region 30 cm away
    /// (where a fixture may stand), mapped from the camera into the base. Print the table with
    /// `cargo test -p perception --lib calibration::hand_eye::tests::touch_points_against -- --nocapture`:
    ///
    /// | method | feeder rms, µm | 30 cm away rms, µm |
    /// |---|---|---|
    /// | touch: 8 marks, table board from 1 image | 30.5 | 80.0 |
    /// | touch: 4 marks, table board from 1 image | 31.5 | 85.8 |
    /// | touch: 8 marks, table board from 4 images | 16.9 | 42.6 |
    /// | touch: 8 marks, table board from 16 images | 11.0 | 26.0 |
    /// | hand-eye: 2 × 2 flange board, 6 poses | 62.3 | 118.3 |
    /// | hand-eye: 2 × 2 flange board, 12 poses | 44.6 | 85.1 |
    /// | hand-eye: 2 × 2 flange board, 24 poses | 32.9 | 62.3 |
    /// | hand-eye: 2 × 2 flange board, arm without noise, 12 poses | 26.8 | 41.4 |
    /// | hand-eye: seed board (21 cm) held, 12 poses | 22.5 | 29.5 |
    #[test]
    fn touch_points_against_hand_eye_near_and_away_from_the_board() {
        let camera = Camera::basler_seed();
        let seed = Board::seed();
        let trials = 200;
        let arm = HandEyeSettings::default();
        let still = HandEyeSettings {
            robot_translation_sigma: 1e-9,
            robot_rotation_sigma: 1e-9,
            ..arm
        };
        let row = |name: &str, estimate: &mut dyn FnMut(&mut ChaCha8Rng) -> Isometry3<f64>| {
            let mut rng = ChaCha8Rng::seed_from_u64(77);
            let (mut near, mut far) = (0.0, 0.0);
            for _ in 0..trials {
                let x = estimate(&mut rng);
                near += region_error(&x, 0.0).powi(2);
                far += region_error(&x, 0.3).powi(2);
            }
            let n = trials as f64;
            let (near, far) = ((near / n).sqrt(), (far / n).sqrt());
            eprintln!("| {name} | {:.1} | {:.1} |", near * 1e6, far * 1e6);
            (near, far)
        };
        eprintln!("| method | feeder rms, µm | 30 cm away rms, µm |\n|---|---|---|");
        let mut touch = Vec::new();
        for (marks, images) in [(8, 1), (4, 1), (8, 4), (8, 16)] {
            touch.push(row(
                &format!("touch: {marks} marks, table board from {images} image(s)"),
                &mut |rng| {
                    let truth = base_t_camera().inverse() * base_t_table_board();
                    // Averaging the corners of k images of the still board is one image with
                    // corner noise σ/√k.
                    let sigma = CORNER_SIGMA / (images as f64).sqrt();
                    let (camera_t_board, _) = observe_with(&camera, &seed, &truth, sigma, rng);
                    let points: Vec<TouchPoint> = seed
                        .touch_marks()
                        .into_iter()
                        .take(marks)
                        .map(|m| TouchPoint {
                            base: base_t_table_board() * m.point
                                + sample(rng, UR_REPEATABILITY_SIGMA),
                            name: m.name,
                            board: m.point,
                        })
                        .collect();
                    let fit =
                        fit_rigid(&points, DEFAULT_TOUCH_BOUND, UR_REPEATABILITY_SIGMA).unwrap();
                    fit.base_T_board * camera_t_board.inverse()
                },
            ));
        }
        let mut hand_eye = Vec::new();
        for (name, board, n, settings) in [
            ("2 × 2 flange board", flange_board(), 6, arm),
            ("2 × 2 flange board", flange_board(), 12, arm),
            ("2 × 2 flange board", flange_board(), 24, arm),
            (
                "2 × 2 flange board, arm without noise",
                flange_board(),
                12,
                still,
            ),
            ("seed board (21 cm) held", seed.clone(), 12, arm),
        ] {
            let poses = plan_hand_eye_poses(&center_flange(), n, 0.35, 0.6);
            hand_eye.push(row(&format!("hand-eye: {name}, {n} poses"), &mut |rng| {
                let v = views_of(&board, &poses, &settings, rng);
                solve_hand_eye(&v, &settings).unwrap().base_T_camera
            }));
        }
        let measured_touch = [(30.5, 80.0), (31.5, 85.8), (16.9, 42.6), (11.0, 26.0)];
        let measured_hand_eye = [
            (62.3, 118.3),
            (44.6, 85.1),
            (32.9, 62.3),
            (26.8, 41.4),
            (22.5, 29.5),
        ];
        for (got, want) in touch
            .iter()
            .zip(&measured_touch)
            .chain(hand_eye.iter().zip(&measured_hand_eye))
        {
            assert!(
                (got.0 * 1e6 / want.0 - 1.0).abs() < 0.03,
                "{got:?} vs {want:?} µm"
            );
            assert!(
                (got.1 * 1e6 / want.1 - 1.0).abs() < 0.03,
                "{got:?} vs {want:?} µm"
            );
        }
        // At the feeder, one image and eight touches beat twelve poses of a small flange board;
        // 30 cm away, a large held board beats one image and touches.
        assert!(touch[0].0 < hand_eye[1].0);
        assert!(hand_eye[4].1 < touch[0].1);
    }
}
