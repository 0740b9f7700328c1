//! Planar refinement onto stable poses of a USB-C-sized part seen from above.

use nalgebra::{Isometry3, Point2, Point3, Translation3, Unit, UnitQuaternion, Vector3};
use perception::Camera;
use perception::part::{StablePose, Symmetry};
use perception::planar::{ClassSet, PlanarConfig, PlanarError, PlanarRefiner};
use perception::symmetry::symmetry_group;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn stable(name: &str, up: Vector3<f64>, probability: f64, rest_height: f64) -> StablePose {
    let r = StablePose::canonical_rotation(&up);
    StablePose {
        name: name.into(),
        probability,
        up_in_part: up.into(),
        rotation: r.scaled_axis().into(),
        rest_height,
    }
}

/// The main shell's classes as the seed found them: +z 58 %, −z 38 %, ±x rare.
fn shell_poses() -> Vec<StablePose> {
    vec![
        stable("+z", Vector3::z(), 0.584, 0.00154),
        stable("-z", -Vector3::z(), 0.378, 0.00146),
        stable("+x", Vector3::x(), 0.025, 0.0045),
        stable("-x", -Vector3::x(), 0.013, 0.0045),
    ]
}

/// The seed's camera 1.5 m above the table, looking down, tilted 8° about its x axis.
#[allow(non_snake_case)]
fn camera_T_table() -> Isometry3<f64> {
    let down = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
    let tilt = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 8f64.to_radians());
    let r = tilt * down;
    Isometry3::from_parts(Translation3::from(-(r * Vector3::new(0.0, 0.05, 1.5))), r)
}

/// The stand-in shell's keypoints: eight near its box corners plus the centre, like the seed's.
fn keypoints() -> Vec<Point3<f64>> {
    perception::ablation::AblationPart::synthetic_shell().keypoints
}

fn random_tilt(rng: &mut ChaCha8Rng, degrees: f64) -> UnitQuaternion<f64> {
    let a: f64 = rng.random_range(0.0..std::f64::consts::TAU);
    let axis = Unit::new_normalize(Vector3::new(a.cos(), a.sin(), 0.0));
    UnitQuaternion::from_axis_angle(&axis, degrees.to_radians())
}

#[test]
fn recovers_yaw_height_and_position_from_a_tilted_deep_estimate() {
    let poses = shell_poses();
    let ct = camera_T_table();
    let refiner = PlanarRefiner::new(ct, &poses, &[], PlanarConfig::default()).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for trial in 0..400 {
        let class = trial % 2;
        let (x, y, yaw) = (
            rng.random_range(-0.08..0.08),
            rng.random_range(-0.08..0.08),
            rng.random_range(-3.1..3.1),
        );
        let truth = poses[class].table_T_part(x, y, yaw);
        // PnP's typical failure: the part tilted by 3° and slid 60 mm along its viewing ray.
        let tilted = Isometry3::from_parts(
            truth.translation,
            random_tilt(&mut rng, 3.0) * truth.rotation,
        );
        let mut est = ct * tilted;
        let ray = est.translation.vector.normalize();
        est.translation.vector += ray * rng.random_range(-0.06..0.06);
        let p = refiner.refine(&est).unwrap();
        assert_eq!(p.class, class);
        let dyaw = (p.yaw - yaw + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
            - std::f64::consts::PI;
        assert!(
            dyaw.abs().to_degrees() < 0.1,
            "yaw error {}°",
            dyaw.to_degrees()
        );
        assert_eq!(p.table_T_part.translation.z, poses[class].rest_height);
        let dxy = (p.table_T_part.translation.vector - truth.translation.vector).norm();
        assert!(dxy < 1e-9, "position error {dxy} m");
        assert!(p.table_T_part.rotation.angle_to(&truth.rotation) < 0.1f64.to_radians());
        assert!((p.tilt.to_degrees() - 3.0).abs() < 1e-6);
        assert!(
            p.confidence > 0.9 && p.margin > 2.0,
            "{} {}",
            p.confidence,
            p.margin
        );
    }
}

#[test]
fn keypoint_fit_beats_the_estimate_on_noisy_pixels() {
    let poses = shell_poses();
    let ct = camera_T_table();
    let cam = Camera::basler_seed();
    let model = keypoints();
    let refiner = PlanarRefiner::new(ct, &poses, &[], PlanarConfig::default()).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    let (mut yaw_ray, mut yaw_fit) = (0.0, 0.0);
    for _ in 0..100 {
        let truth = poses[0].table_T_part(
            rng.random_range(-0.05..0.05),
            rng.random_range(-0.05..0.05),
            rng.random_range(-3.0..3.0),
        );
        let px: Vec<Point2<f64>> = model
            .iter()
            .map(|p| {
                cam.project(&(ct * truth * p)).unwrap()
                    + nalgebra::Vector2::new(
                        rng.random_range(-1.0..1.0),
                        rng.random_range(-1.0..1.0),
                    )
            })
            .collect();
        let pnp = perception::pnp::solve_pnp(&cam, &model, &px, None).unwrap();
        let a = refiner.refine(&pnp.camera_T_part).unwrap();
        let b = refiner
            .refine_with_keypoints(&pnp.camera_T_part, &cam, &model, &px, None, ClassSet::ALL)
            .unwrap();
        assert_eq!(b.table_T_part.translation.z, poses[0].rest_height);
        yaw_ray += a.table_T_part.rotation.angle_to(&truth.rotation);
        yaw_fit += b.table_T_part.rotation.angle_to(&truth.rotation);
    }
    assert!(yaw_fit < yaw_ray, "fit {yaw_fit} vs closed form {yaw_ray}");
}

#[test]
fn symmetric_part_is_reported_in_a_canonical_representative() {
    // A part with an exact half-turn symmetry about its z axis: yaw ψ and ψ + π are the same pose.
    let poses = shell_poses();
    let group = symmetry_group(&[Symmetry {
        axis: [0.0, 0.0, 1.0],
        order: 2,
        exact: true,
    }]);
    let ct = camera_T_table();
    let refiner = PlanarRefiner::new(ct, &poses, &group, PlanarConfig::default()).unwrap();
    for yaw in [0.3, 2.0, -2.5, -0.7] {
        let truth = poses[0].table_T_part(0.01, 0.02, yaw);
        let p = refiner.refine(&(ct * truth)).unwrap();
        assert!(
            p.yaw.abs() <= std::f64::consts::FRAC_PI_2 + 1e-9,
            "yaw {}",
            p.yaw
        );
        let d = (p.yaw - yaw).rem_euclid(std::f64::consts::PI);
        assert!(d < 1e-9 || (std::f64::consts::PI - d) < 1e-9);
    }
}

#[test]
fn ruled_out_classes_are_never_chosen_and_the_rest_share_the_confidence() {
    let poses = shell_poses();
    let ct = camera_T_table();
    let refiner = PlanarRefiner::new(ct, &poses, &[], PlanarConfig::default()).unwrap();
    // Lying on its +x side, leaning 20° towards face up: +x is the best class, +z the next.
    let lean = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 20f64.to_radians());
    let truth = poses[2].table_T_part(0.01, -0.02, 0.4);
    let estimate = ct * Isometry3::from_parts(truth.translation, lean * truth.rotation);
    let all = refiner.refine(&estimate).unwrap();
    assert_eq!(all.class, 2);
    let others = ClassSet::filter(poses.len(), |c| c != 2);
    let ruled = refiner.refine_in(&estimate, others).unwrap();
    assert_eq!(Some(ruled.class), all.runner_up);
    assert_ne!(ruled.runner_up, Some(2));
    // +z, 70° off, is far nearer than −z (110°) or −x (180°): the posterior is nearly all its.
    assert!(ruled.confidence > 0.99, "{}", ruled.confidence);
    assert_eq!(
        ruled.table_T_part.translation.z,
        poses[ruled.class].rest_height
    );
    // With +z ruled out, +x stands and has no runner-up: the keypoints' next choice is gone.
    let no_face_up = refiner
        .refine_in(&estimate, ClassSet::filter(poses.len(), |c| c != 0))
        .unwrap();
    assert_eq!((no_face_up.class, no_face_up.runner_up), (2, None));
    assert!(no_face_up.confidence >= all.confidence);
    let none = ClassSet::filter(poses.len(), |_| false);
    assert!(none.is_empty_below(poses.len()) && !ClassSet::ALL.is_empty_below(poses.len()));
    assert_eq!(
        refiner.refine_in(&estimate, none),
        Err(PlanarError::NoAdmittedClass)
    );
}

#[test]
fn bad_input_is_typed() {
    let ct = camera_T_table();
    assert_eq!(
        PlanarRefiner::new(ct, &[], &[], PlanarConfig::default()).err(),
        Some(PlanarError::NoStablePoses)
    );
    let mut bad = shell_poses();
    bad[1].up_in_part = [0.0, 0.0, 2.0];
    assert!(matches!(
        PlanarRefiner::new(ct, &bad, &[], PlanarConfig::default()),
        Err(PlanarError::BadStablePose(1, _))
    ));
    let refiner = PlanarRefiner::new(ct, &shell_poses(), &[], PlanarConfig::default()).unwrap();
    let mut nan = ct;
    nan.translation.vector.x = f64::NAN;
    assert!(matches!(
        refiner.refine(&nan),
        Err(PlanarError::NonFinite(_))
    ));
    // A part "seen" behind the camera: its ray meets the table behind us.
    let behind = Isometry3::translation(0.0, 0.0, -1.0);
    assert_eq!(refiner.refine(&behind), Err(PlanarError::RayMissesPlane));
}
