//! PnP on synthetic keypoints of a USB-C-sized part seen by the seed's camera.

use nalgebra::{Isometry3, Matrix2, Point2, Point3, Translation3, UnitQuaternion, Vector3};
use perception::Camera;
use perception::pnp::{PnpError, solve_pnp};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// The stand-in shell's keypoints: eight near its box corners plus the centre, like the seed's.
fn keypoints() -> Vec<Point3<f64>> {
    perception::ablation::AblationPart::synthetic_shell().keypoints
}

/// A random pose of the part in front of the seed's camera at 1.4–1.9 m.
fn random_pose(rng: &mut ChaCha8Rng) -> Isometry3<f64> {
    let axis = Vector3::new(
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
    );
    let r = UnitQuaternion::from_scaled_axis(axis.normalize() * rng.random_range(0.0..3.1));
    let t = Translation3::new(
        rng.random_range(-0.15..0.15),
        rng.random_range(-0.1..0.1),
        rng.random_range(1.4..1.9),
    );
    Isometry3::from_parts(t, r)
}

fn project(cam: &Camera, pose: &Isometry3<f64>, model: &[Point3<f64>]) -> Vec<Point2<f64>> {
    model
        .iter()
        .map(|p| cam.project(&(pose * p)).unwrap())
        .collect()
}

#[test]
fn exact_on_noise_free_data() {
    let cam = Camera::basler_seed();
    let model = keypoints();
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    for _ in 0..200 {
        let truth = random_pose(&mut rng);
        let px = project(&cam, &truth, &model);
        let sol = solve_pnp(&cam, &model, &px, None).unwrap();
        let dt = (sol.camera_T_part.translation.vector - truth.translation.vector).norm();
        let dr = sol.camera_T_part.rotation.angle_to(&truth.rotation);
        assert!(dt < 1e-6, "translation error {dt} m");
        assert!(dr < 1e-6, "rotation error {dr} rad");
        assert!(sol.rms_px < 1e-6, "rms {}", sol.rms_px);
    }
}

#[test]
fn refinement_lowers_reprojection_error_and_pose_error() {
    let cam = Camera::basler_seed();
    let model = keypoints();
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let noise = Normal::new(0.0, 1.0).unwrap();
    let (mut better, mut total) = (0, 0);
    for _ in 0..200 {
        let truth = random_pose(&mut rng);
        let px: Vec<Point2<f64>> = project(&cam, &truth, &model)
            .into_iter()
            .map(|p| p + nalgebra::Vector2::new(noise.sample(&mut rng), noise.sample(&mut rng)))
            .collect();
        let sol = solve_pnp(&cam, &model, &px, None).unwrap();
        assert!(
            sol.rms_px <= sol.initial_rms_px + 1e-12,
            "refined {} > initial {}",
            sol.rms_px,
            sol.initial_rms_px
        );
        // The refined pose is the least-squares optimum: any perturbation raises its error.
        total += 1;
        if sol.rms_px < sol.initial_rms_px - 1e-9 {
            better += 1;
        }
        assert!(sol.covariance.iter().all(|v| v.is_finite()));
        assert!(sol.covariance.symmetric_eigenvalues().min() > 0.0);
    }
    // SQPnP minimises an algebraic error in single precision: refinement strictly helps in most cases.
    assert!(
        better * 10 >= total * 9,
        "refinement helped in only {better}/{total}"
    );
}

#[test]
fn covariance_weighting_discounts_a_bad_keypoint() {
    let cam = Camera::basler_seed();
    let model = keypoints();
    let mut rng = ChaCha8Rng::seed_from_u64(13);
    let (mut weighted_err, mut plain_err) = (0.0, 0.0);
    for _ in 0..100 {
        let truth = random_pose(&mut rng);
        let mut px = project(&cam, &truth, &model);
        px[2] += nalgebra::Vector2::new(8.0, -6.0);
        let mut covs = vec![Matrix2::identity() * 0.25; model.len()];
        covs[2] = Matrix2::identity() * 400.0;
        let w = solve_pnp(&cam, &model, &px, Some(&covs)).unwrap();
        let p = solve_pnp(&cam, &model, &px, None).unwrap();
        weighted_err += w.camera_T_part.rotation.angle_to(&truth.rotation);
        plain_err += p.camera_T_part.rotation.angle_to(&truth.rotation);
    }
    assert!(
        weighted_err < 0.2 * plain_err,
        "weighted {weighted_err} vs plain {plain_err}"
    );
}

#[test]
fn covariance_predicts_the_error_spread() {
    // With calibrated keypoint noise the reported covariance matches the empirical scatter.
    let cam = Camera::basler_seed();
    let model = keypoints();
    let mut rng = ChaCha8Rng::seed_from_u64(14);
    let truth = random_pose(&mut rng);
    let sigma = 0.5;
    let noise = Normal::new(0.0, sigma).unwrap();
    let covs = vec![Matrix2::identity() * sigma * sigma; model.len()];
    let mut sq_z = 0.0;
    let mut predicted = 0.0;
    let trials = 400;
    for _ in 0..trials {
        let px: Vec<Point2<f64>> = project(&cam, &truth, &model)
            .into_iter()
            .map(|p| p + nalgebra::Vector2::new(noise.sample(&mut rng), noise.sample(&mut rng)))
            .collect();
        let sol = solve_pnp(&cam, &model, &px, Some(&covs)).unwrap();
        let dz = sol.camera_T_part.translation.z - truth.translation.z;
        sq_z += dz * dz;
        predicted += sol.covariance[(2, 2)];
    }
    let ratio = (sq_z / predicted).sqrt();
    assert!(
        (0.8..1.25).contains(&ratio),
        "empirical / predicted depth σ = {ratio}"
    );
}

#[test]
fn bad_input_is_typed() {
    let cam = Camera::basler_seed();
    let model = keypoints();
    let truth = Isometry3::translation(0.0, 0.0, 1.5);
    let px = project(&cam, &truth, &model);
    assert_eq!(
        solve_pnp(&cam, &model[..3], &px[..3], None),
        Err(PnpError::TooFewPoints(3))
    );
    assert!(matches!(
        solve_pnp(&cam, &model, &px[..5], None),
        Err(PnpError::LengthMismatch { .. })
    ));
    let line: Vec<Point3<f64>> = (0..6)
        .map(|i| Point3::new(0.001 * f64::from(i), 0.0, 0.0))
        .collect();
    let line_px = project(&cam, &truth, &line);
    assert_eq!(
        solve_pnp(&cam, &line, &line_px, None),
        Err(PnpError::DegenerateModel("collinear"))
    );
    let same = vec![Point3::new(0.001, 0.0, 0.0); 5];
    assert_eq!(
        solve_pnp(&cam, &same, &px[..5], None),
        Err(PnpError::DegenerateModel("coincident"))
    );
    let mut nan = px.clone();
    nan[4].y = f64::NAN;
    assert!(matches!(
        solve_pnp(&cam, &model, &nan, None),
        Err(PnpError::NonFinite(_))
    ));
    let mut inf = model.clone();
    inf[0].z = f64::INFINITY;
    assert!(matches!(
        solve_pnp(&cam, &inf, &px, None),
        Err(PnpError::NonFinite(_))
    ));
    let flat_px = vec![Point2::new(100.0, 100.0); model.len()];
    assert!(matches!(
        solve_pnp(&cam, &model, &flat_px, None),
        Err(PnpError::DegenerateImage(_))
    ));
    let bad_cov = vec![Matrix2::new(1.0, 0.0, 0.0, -1.0); model.len()];
    assert!(matches!(
        solve_pnp(&cam, &model, &px, Some(&bad_cov)),
        Err(PnpError::BadCovariance(0))
    ));
}
