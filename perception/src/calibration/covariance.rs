//! Pose covariances through composition: the camera in the base from the board in the base and
//! the board in the camera.
//!
//! Convention (perception's PnP): a pose `T̂ = (R̂, t̂)` with covariance Σ over `[δt; δω]` means
//! the true pose is `(exp(δω)·R̂, t̂ + δt)`; both errors are expressed in the pose's parent frame.

use nalgebra::{Isometry3, Matrix6, SMatrix, Translation3, UnitQuaternion, Vector3, Vector6};

/// A pose perturbed by `[δt; δω]` in the convention above.
pub fn perturb(pose: &Isometry3<f64>, d: &Vector6<f64>) -> Isometry3<f64> {
    let dt = Vector3::new(d[0], d[1], d[2]);
    let dw = Vector3::new(d[3], d[4], d[5]);
    Isometry3::from_parts(
        Translation3::from(pose.translation.vector + dt),
        UnitQuaternion::from_scaled_axis(dw) * pose.rotation,
    )
}

/// The `[δt; δω]` that takes `nominal` to `actual` (the inverse of [`perturb`]).
pub fn difference(nominal: &Isometry3<f64>, actual: &Isometry3<f64>) -> Vector6<f64> {
    let dt = actual.translation.vector - nominal.translation.vector;
    let dw = (actual.rotation * nominal.rotation.inverse()).scaled_axis();
    Vector6::new(dt.x, dt.y, dt.z, dw.x, dw.y, dw.z)
}

/// Covariance of `a · b⁻¹` (e.g. `base_T_camera = base_T_board · camera_T_board⁻¹`) from
/// independent covariances of `a` and `b`, to first order (central differences of the
/// composition, which is smooth; steps far below any pose error that matters).
pub fn compose_covariance(
    a: &Isometry3<f64>,
    cov_a: &Matrix6<f64>,
    b: &Isometry3<f64>,
    cov_b: &Matrix6<f64>,
) -> Matrix6<f64> {
    let nominal = a * b.inverse();
    let mut jacobian = SMatrix::<f64, 6, 12>::zeros();
    const H: f64 = 1e-7;
    for k in 0..12 {
        let mut d = Vector6::zeros();
        d[k % 6] = H;
        let at = |sign: f64| {
            let (pa, pb) = if k < 6 {
                (perturb(a, &(d * sign)), *b)
            } else {
                (*a, perturb(b, &(d * sign)))
            };
            difference(&nominal, &(pa * pb.inverse()))
        };
        jacobian.set_column(k, &((at(1.0) - at(-1.0)) / (2.0 * H)));
    }
    let ja = jacobian.fixed_columns::<6>(0);
    let jb = jacobian.fixed_columns::<6>(6);
    ja * cov_a * ja.transpose() + jb * cov_b * jb.transpose()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};

    /// The first-order covariance matches the sample covariance of 20 000 perturbed
    /// compositions (board 1.5 m below a camera, errors of tens of µm and µrad).
    #[test]
    fn composed_covariance_matches_monte_carlo() {
        let a = Isometry3::new(Vector3::new(0.0, -0.45, 0.0), Vector3::new(0.0, 0.0, 0.3));
        let b = Isometry3::new(Vector3::new(0.01, -0.02, 1.5), Vector3::new(3.1, 0.02, 0.0));
        let sa = Vector6::new(2e-5, 2e-5, 1e-5, 5e-5, 5e-5, 1e-4);
        let sb = Vector6::new(1e-5, 1e-5, 8e-5, 6e-5, 6e-5, 1e-5);
        let cov_a = Matrix6::from_diagonal(&sa.component_mul(&sa));
        let cov_b = Matrix6::from_diagonal(&sb.component_mul(&sb));
        let predicted = compose_covariance(&a, &cov_a, &b, &cov_b);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut gauss = || -> f64 { StandardNormal.sample(&mut rng) };
        let nominal = a * b.inverse();
        let n = 20_000;
        let mut sample = Matrix6::zeros();
        for _ in 0..n {
            let da = Vector6::from_fn(|i, _| sa[i] * gauss());
            let db = Vector6::from_fn(|i, _| sb[i] * gauss());
            let d = difference(&nominal, &(perturb(&a, &da) * perturb(&b, &db).inverse()));
            sample += d * d.transpose();
        }
        sample /= n as f64;
        for i in 0..6 {
            let (p, s) = (predicted[(i, i)].sqrt(), sample[(i, i)].sqrt());
            assert!(
                (p - s).abs() < 0.03 * p,
                "axis {i}: predicted σ {p:e}, sampled {s:e}"
            );
        }
        // The camera's height error is dominated by the board pose's depth error; its lateral
        // error gains the board tilt's lever over 1.5 m.
        assert!(predicted[(2, 2)].sqrt() > 7e-5 && predicted[(0, 0)].sqrt() > 8e-5);
    }

    #[test]
    fn difference_inverts_perturb() {
        let p = Isometry3::new(Vector3::new(0.1, 0.2, 0.3), Vector3::new(0.4, -0.2, 1.0));
        let d = Vector6::new(1e-4, -2e-4, 3e-5, 1e-3, -5e-4, 2e-4);
        assert!((difference(&p, &perturb(&p, &d)) - d).norm() < 1e-12);
    }
}
