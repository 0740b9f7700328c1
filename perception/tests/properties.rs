//! Property tests: arbitrary (including hostile) input gives a result or a typed error, never a
//! panic.

use nalgebra::{Isometry3, Matrix2, Point2, Point3, Translation3, UnitQuaternion, Vector3};
use perception::part::StablePose;
use perception::planar::{PlanarConfig, PlanarRefiner};
use perception::pnp::{PnpError, solve_pnp};
use perception::voting::{VectorField, VotingConfig, vote_keypoints};
use perception::{Camera, CameraError};
use proptest::prelude::*;

/// Any f64, weighted towards the troublesome ones.
fn wild() -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => -2.0..2.0f64,
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => Just(f64::NEG_INFINITY),
        1 => Just(0.0),
        1 => prop::num::f64::ANY,
    ]
}

fn point3() -> impl Strategy<Value = Point3<f64>> {
    (wild(), wild(), wild()).prop_map(|(x, y, z)| Point3::new(x * 0.01, y * 0.01, z * 0.01))
}

fn pixel() -> impl Strategy<Value = Point2<f64>> {
    (wild(), wild()).prop_map(|(u, v)| Point2::new(2700.0 + u * 500.0, 1700.0 + v * 500.0))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn pnp_never_panics(
        model in prop::collection::vec(point3(), 0..12),
        pixels in prop::collection::vec(pixel(), 0..12),
        cov in prop::option::of((wild(), wild(), wild())),
    ) {
        let cam = Camera::basler_seed();
        let covs = cov.map(|(a, b, c)| vec![Matrix2::new(a, b, b, c); model.len()]);
        let result = solve_pnp(&cam, &model, &pixels, covs.as_deref());
        if model.len() != pixels.len() {
            prop_assert!(matches!(result, Err(PnpError::LengthMismatch { .. })), "{result:?}");
        } else if model.len() < 4 {
            prop_assert_eq!(result, Err(PnpError::TooFewPoints(model.len())));
        } else if let Ok(sol) = result {
            prop_assert!(sol.rms_px.is_finite());
            prop_assert!(sol.camera_T_part.translation.vector.iter().all(|v| v.is_finite()));
        }
    }

    #[test]
    fn pnp_on_real_projections_with_duplicated_points_never_panics(
        dup in 0usize..9, rx in -3.0..3.0f64, ry in -3.0..3.0f64, z in 0.3..3.0f64,
    ) {
        let cam = Camera::basler_seed();
        let mut model: Vec<Point3<f64>> = (0..9)
            .map(|i| {
                let a = f64::from(i);
                Point3::new(0.004 * a.cos(), 0.004 * a.sin(), 0.001 * (a % 3.0))
            })
            .collect();
        // Coincident points (several copies of one) are legal if the rest are spread.
        for i in 0..dup {
            model[i] = model[8];
        }
        let pose = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, z),
            UnitQuaternion::from_euler_angles(rx, ry, 0.3),
        );
        let px: Vec<Point2<f64>> = model.iter().map(|p| cam.project(&(pose * p)).unwrap()).collect();
        match solve_pnp(&cam, &model, &px, None) {
            Ok(sol) => prop_assert!(sol.rms_px < 1e-3 || dup >= 5, "rms {}", sol.rms_px),
            Err(e) => prop_assert!(
                dup >= 5,
                "a solvable problem ({dup} duplicates) failed: {e}"
            ),
        }
    }

    #[test]
    fn camera_never_panics(p in point3(), px in pixel(), f in wild()) {
        let cam = Camera::basler_seed();
        match cam.project(&p) {
            Ok(_) => prop_assert!(p.z > 0.0 && p.coords.iter().all(|v| v.is_finite())),
            Err(CameraError::BehindCamera { z }) => prop_assert!(z <= 0.0),
            Err(CameraError::NonFinite(_)) => prop_assert!(!p.coords.iter().all(|v| v.is_finite())),
            Err(e) => prop_assert!(false, "unexpected {e}"),
        }
        let _ = cam.pixel_ray(px);
        let _ = cam.scaled(f);
        let _ = Camera::new(f, f, f, f, 10, 10, cam.distortion);
    }

    #[test]
    fn voting_never_panics(
        w in 0usize..12, h in 0usize..12, k in 0usize..3,
        mask_bits in prop::collection::vec(any::<bool>(), 0..150),
        values in prop::collection::vec(wild(), 0..900),
        short in any::<bool>(),
    ) {
        let mask: Vec<u8> = (0..w * h).map(|i| u8::from(*mask_bits.get(i).unwrap_or(&false))).collect();
        let mut vectors: Vec<f32> = (0..2 * k * w * h)
            .map(|i| *values.get(i).unwrap_or(&0.5) as f32)
            .collect();
        if short { vectors.pop(); }
        let field = VectorField { width: w, height: h, keypoints: k, mask: &mask, vectors: &vectors };
        let cfg = VotingConfig { hypotheses_per_round: 16, max_rounds: 2, ..VotingConfig::default() };
        if let Ok(votes) = vote_keypoints(&field, cfg) {
            prop_assert_eq!(votes.len(), k);
            for v in votes {
                prop_assert!(v.position.coords.iter().all(|c| c.is_finite()));
                prop_assert!(v.covariance.iter().all(|c| c.is_finite()));
            }
        }
    }

    #[test]
    fn planar_never_panics(t in (wild(), wild(), wild()), r in (wild(), wild(), wild())) {
        let up = Vector3::z();
        let pose = StablePose {
            name: "+z".into(),
            probability: 1.0,
            up_in_part: up.into(),
            rotation: [0.0; 3],
            rest_height: 0.0015,
        };
        let camera_t_table = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 1.5),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
        );
        let refiner = PlanarRefiner::new(camera_t_table, &[pose], &[], PlanarConfig::default()).unwrap();
        let est = Isometry3::from_parts(
            Translation3::new(t.0, t.1, t.2),
            UnitQuaternion::from_scaled_axis(Vector3::new(r.0, r.1, r.2)),
        );
        if let Ok(p) = refiner.refine(&est) {
            prop_assert!(p.table_T_part.translation.vector.iter().all(|v| v.is_finite()));
            prop_assert_eq!(p.table_T_part.translation.z, 0.0015);
        }
    }
}
