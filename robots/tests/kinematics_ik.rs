//! Acceptance tests of the UR5e forward and inverse kinematics.

#![allow(non_snake_case)]

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use robots::kinematics::{
    IkError, JointLimits, Joints, SingularityPolicy, UrKinematics, from_ur_pose, normalize_angle,
    to_ur_pose,
};
use std::f64::consts::{FRAC_PI_2, PI, TAU};

const POS_TOL: f64 = 1e-9;
const ROT_TOL: f64 = 1e-9;

fn pose_error(a: &Isometry3<f64>, b: &Isometry3<f64>) -> (f64, f64) {
    let dp = (a.translation.vector - b.translation.vector).norm();
    let dr = a.rotation.angle_to(&b.rotation);
    (dp, dr)
}

fn random_joints(rng: &mut ChaCha8Rng) -> Joints {
    std::array::from_fn(|_| rng.random_range(-PI..PI))
}

/// Random joints at least `margin` (in sin q5, sin q3 and metres from the shoulder singularity)
/// away from every singularity.
fn random_regular_joints(kin: &UrKinematics, rng: &mut ChaCha8Rng, margin: f64) -> Joints {
    let mut probe = kin.clone();
    probe.singularity_thresholds.wrist_sin_q5 = margin;
    probe.singularity_thresholds.elbow_sin_q3 = margin;
    probe.singularity_thresholds.shoulder_distance = margin;
    loop {
        let q = random_joints(rng);
        if probe.singularities(&q).is_empty() {
            return q;
        }
    }
}

fn same_up_to_wrap(a: &Joints, b: &Joints, tol: f64) -> bool {
    a.iter()
        .zip(b)
        .all(|(x, y)| normalize_angle(x - y).abs() < tol)
}

#[test]
fn forward_kinematics_reproduces_ur_check_values() {
    let kin = UrKinematics::ur5e();
    let zero = kin.forward_flange(&[0.0; 6]).translation.vector;
    let expected = Vector3::new(-0.8172, -0.2329, 0.0628);
    assert!((zero - expected).norm() < 1e-4, "q = 0: {zero:?}");

    let up = kin
        .forward_flange(&[0.0, -FRAC_PI_2, 0.0, -FRAC_PI_2, 0.0, 0.0])
        .translation
        .vector;
    let expected = Vector3::new(0.0, -0.2329, 1.0794);
    assert!((up - expected).norm() < 1e-4, "upright: {up:?}");
}

#[test]
fn ik_round_trips_10000_random_poses() {
    let kin = UrKinematics::ur5e();
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let mut worst = (0.0f64, 0.0f64);
    let mut histogram = [0usize; 9];
    for trial in 0..10_000 {
        let q = random_regular_joints(&kin, &mut rng, 0.05);
        let target = kin.forward_tcp(&q);
        let solutions = kin
            .inverse_all(&target, q[5])
            .unwrap_or_else(|e| panic!("trial {trial}: {q:?}: {e}"));
        histogram[solutions.len()] += 1;
        for s in solutions.iter() {
            let (dp, dr) = pose_error(&kin.forward_tcp(&s.joints), &target);
            worst = (worst.0.max(dp), worst.1.max(dr));
            assert!(
                dp < POS_TOL && dr < ROT_TOL,
                "trial {trial}: {q:?} -> {:?}: {dp:e} m {dr:e} rad",
                s.joints
            );
            assert!(s.joints.iter().all(|v| v.abs() <= PI));
        }
        // Branches are distinct configurations.
        for i in 0..solutions.len() {
            for j in i + 1..solutions.len() {
                assert!(
                    !same_up_to_wrap(&solutions[i].joints, &solutions[j].joints, 1e-6),
                    "trial {trial}: duplicate branches {i} and {j}"
                );
            }
        }
        let found = solutions
            .iter()
            .filter(|s| same_up_to_wrap(&s.joints, &q, 1e-7))
            .count();
        assert_eq!(
            found, 1,
            "trial {trial}: original {q:?} not among {solutions:?}"
        );
    }
    eprintln!(
        "worst FK(IK(T)) error: {:e} m, {:e} rad; solution counts {histogram:?}",
        worst.0, worst.1
    );
    // Generic poses of the regular workspace mostly have all eight branches.
    assert!(histogram[8] > 5_000, "{histogram:?}");
    assert!(histogram.iter().skip(1).step_by(2).all(|&n| n == 0));
}

/// Damped least-squares IK from one start; `Some` when it converges to the target.
fn numeric_ik(kin: &UrKinematics, target: &Isometry3<f64>, start: Joints) -> Option<Joints> {
    let residual = |q: &Joints| {
        let pose = kin.forward_tcp(q);
        let dp = target.translation.vector - pose.translation.vector;
        let dr = (target.rotation * pose.rotation.inverse()).scaled_axis();
        nalgebra::Vector6::new(dp.x, dp.y, dp.z, dr.x, dr.y, dr.z)
    };
    let mut q = start;
    for _ in 0..200 {
        let e = residual(&q);
        if e.norm() < 1e-12 {
            return Some(q.map(normalize_angle));
        }
        let mut jac = nalgebra::Matrix6::zeros();
        for j in 0..6 {
            let (mut plus, mut minus) = (q, q);
            plus[j] += 1e-7;
            minus[j] -= 1e-7;
            // The residual decreases as q moves toward the target: J = -d(residual)/dq.
            jac.set_column(j, &((residual(&minus) - residual(&plus)) / 2e-7));
        }
        let lambda = 1e-4;
        let jt = jac.transpose();
        let step = (jt * jac + nalgebra::Matrix6::identity() * lambda)
            .lu()
            .solve(&(jt * e))?;
        for j in 0..6 {
            q[j] += step[j].clamp(-0.5, 0.5);
        }
    }
    None
}

#[test]
fn every_existing_branch_is_found() {
    // An independent search: numeric IK from many random starts must never converge to a
    // configuration the closed form did not return.
    let kin = UrKinematics::ur5e();
    let mut rng = ChaCha8Rng::seed_from_u64(17);
    let mut converged = 0;
    for trial in 0..150 {
        let q = random_regular_joints(&kin, &mut rng, 0.1);
        let target = kin.forward_tcp(&q);
        let solutions = kin.inverse_all(&target, q[5]).unwrap();
        let mut seen = vec![false; solutions.len()];
        for _ in 0..40 {
            let Some(found) = numeric_ik(&kin, &target, random_joints(&mut rng)) else {
                continue;
            };
            converged += 1;
            let index = solutions
                .iter()
                .position(|s| same_up_to_wrap(&s.joints, &found, 1e-6))
                .unwrap_or_else(|| {
                    panic!("trial {trial}: numeric solution {found:?} missing from {solutions:?}")
                });
            seen[index] = true;
        }
        assert!(
            seen.iter().any(|&s| s),
            "trial {trial}: numeric IK never converged"
        );
    }
    assert!(
        converged > 150 * 10,
        "only {converged} numeric solves converged"
    );
}

#[test]
fn ik_with_tool_offset_round_trips() {
    let tool = Isometry3::from_parts(
        Translation3::new(0.01, -0.02, 0.15),
        UnitQuaternion::from_euler_angles(0.1, -0.2, 0.3),
    );
    let kin = UrKinematics::ur5e().with_tcp(tool);
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    for _ in 0..500 {
        let q = random_regular_joints(&kin, &mut rng, 0.05);
        let target = kin.forward_tcp(&q);
        let solution = kin.inverse_nearest(&target, &q).unwrap();
        let (dp, dr) = pose_error(&kin.forward_tcp(&solution.joints), &target);
        assert!(dp < POS_TOL && dr < ROT_TOL);
        for (a, b) in solution.joints.iter().zip(&q) {
            assert!((a - b).abs() < 1e-7, "{:?} vs {q:?}", solution.joints);
        }
    }
}

#[test]
fn nearest_solution_respects_the_two_pi_wrap() {
    let kin = UrKinematics::ur5e();
    let q = [-0.3, -1.2, 1.4, -1.9, -1.5, 2.8];
    let target = kin.forward_tcp(&q);
    // Current joints one turn away on joints 1 and 6: the answer stays on that turn.
    let current = [-0.3 + TAU, -1.2, 1.4, -1.9, -1.5, 2.8 - TAU];
    let solution = kin.inverse_nearest(&target, &current).unwrap();
    for (a, b) in solution.joints.iter().zip(&current) {
        assert!((a - b).abs() < 1e-7, "{:?} vs {current:?}", solution.joints);
    }
    // A current q6 of -3.1 is nearer to 3.0 - 2π than to 3.0.
    let q = [0.3, -1.2, 1.4, -1.9, -1.5, 3.0];
    let target = kin.forward_tcp(&q);
    let mut current = q;
    current[5] = -3.1;
    let solution = kin.inverse_nearest(&target, &current).unwrap();
    assert!((solution.joints[5] - (3.0 - TAU)).abs() < 1e-7);
    let (dp, dr) = pose_error(&kin.forward_tcp(&solution.joints), &target);
    assert!(dp < POS_TOL && dr < ROT_TOL);
}

#[test]
fn nearest_solution_picks_the_branch_of_the_current_configuration() {
    let kin = UrKinematics::ur5e();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for _ in 0..200 {
        let q = random_regular_joints(&kin, &mut rng, 0.1);
        let target = kin.forward_tcp(&q);
        // Perturb the reference slightly: the same branch must still be the nearest.
        let current: Joints = std::array::from_fn(|i| q[i] + rng.random_range(-0.02..0.02));
        let solution = kin.inverse_nearest(&target, &current).unwrap();
        assert!(same_up_to_wrap(&solution.joints, &q, 1e-7));
        // And it is at least as near as every other branch (after wrapping).
        for other in kin.inverse_all(&target, current[5]).unwrap().iter() {
            let wrapped = kin
                .joint_limits
                .wrap_nearest_all(&other.joints, &current)
                .unwrap();
            let d_other = robots::kinematics::joint_distance(&wrapped, &current);
            let d_best = robots::kinematics::joint_distance(&solution.joints, &current);
            assert!(d_best <= d_other + 1e-12);
        }
    }
}

#[test]
fn joint_limits_are_respected_or_reported() {
    let mut kin = UrKinematics::ur5e();
    // Elbow limited to positive angles: only elbow-up-style (q3 > 0) branches remain.
    kin.joint_limits = JointLimits::symmetric(TAU);
    kin.joint_limits.lower[2] = 0.0;
    kin.joint_limits.upper[2] = PI;
    let q = [0.2, -1.0, -1.2, -1.0, 1.2, 0.4];
    let target = kin.forward_tcp(&q);
    let solution = kin.inverse_nearest(&target, &q).unwrap();
    assert!(kin.joint_limits.contains(&solution.joints));
    assert!(solution.joints[2] > 0.0);
    let (dp, dr) = pose_error(&kin.forward_tcp(&solution.joints), &target);
    assert!(dp < POS_TOL && dr < ROT_TOL);

    // No branch fits a q5 range that excludes both wrist solutions.
    kin.joint_limits.lower[4] = 2.0;
    kin.joint_limits.upper[4] = 2.1;
    match kin.inverse_nearest(&target, &q) {
        Err(IkError::OutsideJointLimits { solutions }) => {
            assert_eq!(solutions, kin.inverse_all(&target, q[5]).unwrap().len())
        }
        other => panic!("expected OutsideJointLimits, got {other:?}"),
    }
}

#[test]
fn wrist_singularity_is_reported_and_solved_without_nan() {
    let kin = UrKinematics::ur5e();
    let q = [0.4, -1.3, 1.5, -1.7, 0.0, 0.9];
    let target = kin.forward_tcp(&q);
    let solutions = kin.inverse_all(&target, 0.9).unwrap();
    let mut singular = 0;
    for s in solutions.iter() {
        assert!(s.joints.iter().all(|v| v.is_finite()));
        let (dp, dr) = pose_error(&kin.forward_tcp(&s.joints), &target);
        assert!(dp < POS_TOL && dr < ROT_TOL, "{s:?}: {dp:e} {dr:e}");
        // The flag matches the configuration (the other shoulder branch is not singular).
        assert_eq!(
            s.singularities.wrist,
            s.joints[4].sin().abs() < 0.01,
            "{s:?}"
        );
        if s.singularities.wrist {
            singular += 1;
            // q6 is free there: it is kept at the hint.
            assert!((s.joints[5] - 0.9).abs() < 1e-12, "{s:?}");
        }
    }
    // On the singular shoulder branch the two wrist branches coincide: 2 elbow solutions.
    assert_eq!(singular, 2, "{solutions:?}");
    let nearest = kin.inverse_nearest(&target, &q).unwrap();
    assert!(same_up_to_wrap(&nearest.joints, &q, 1e-7), "{nearest:?}");
    assert!(nearest.singularities.wrist);

    let mut strict = kin.clone();
    strict.singularity_policy = SingularityPolicy::Reject;
    let regular = strict.inverse_nearest(&target, &q).unwrap();
    assert!(regular.singularities.is_empty());
    assert!(regular.joints[4].sin().abs() > 0.01);

    // Upright arm: every solution is singular somewhere, and Reject refuses them all.
    let upright = [0.0, -FRAC_PI_2, 0.0, -FRAC_PI_2, 0.0, 0.0];
    let target = kin.forward_tcp(&upright);
    match strict.inverse_nearest(&target, &upright) {
        Err(IkError::Singular { singularities }) => {
            assert!(
                singularities.wrist && singularities.shoulder,
                "{singularities}"
            )
        }
        other => panic!("expected Singular, got {other:?}"),
    }
}

#[test]
fn elbow_singularity_is_reported_without_nan() {
    let kin = UrKinematics::ur5e();
    let q = [0.4, -1.3, 0.0, -1.7, 1.1, 0.9];
    let target = kin.forward_tcp(&q);
    let solutions = kin.inverse_all(&target, 0.9).unwrap();
    let stretched: Vec<_> = solutions.iter().filter(|s| s.singularities.elbow).collect();
    // The stretched branch's two elbow solutions coincide: returned once, flagged.
    assert_eq!(stretched.len(), 1, "{solutions:?}");
    assert!(same_up_to_wrap(&stretched[0].joints, &q, 1e-6));
    for s in solutions.iter() {
        assert!(s.joints.iter().all(|v| v.is_finite()));
        assert_eq!(
            s.singularities.elbow,
            s.joints[2].sin().abs() < 0.01,
            "{s:?}"
        );
        let (dp, dr) = pose_error(&kin.forward_tcp(&s.joints), &target);
        assert!(dp < POS_TOL && dr < ROT_TOL);
    }
}

#[test]
fn shoulder_singularity_is_reported_without_nan() {
    let kin = UrKinematics::ur5e();
    // Upright arm: the wrist centre sits on the joint 1 axis in the arm's plane.
    let q = [0.0, -FRAC_PI_2, 0.0, -FRAC_PI_2, 0.7, 0.0];
    // Bend the elbow so only the shoulder is singular: choose q2 so that
    // a2 cos q2 + a3 cos(q2 + q3) + d5 sin(q2 + q3 + q4) = 0.
    let dh = kin.dh;
    let (q3, q4) = (1.0f64, -0.5f64);
    let f = |q2: f64| dh.a2 * q2.cos() + dh.a3 * (q2 + q3).cos() + dh.d5 * (q2 + q3 + q4).sin();
    let (mut lo, mut hi) = (-2.5f64, -0.5f64);
    assert!(f(lo) * f(hi) < 0.0);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if f(lo) * f(mid) <= 0.0 {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    let bent = [0.3, 0.5 * (lo + hi), q3, q4, 0.7, 0.2];
    for q in [q, bent] {
        assert!(kin.singularities(&q).shoulder, "{q:?}");
        let target = kin.forward_tcp(&q);
        let solutions = kin.inverse_all(&target, q[5]).unwrap();
        assert!(!solutions.is_empty());
        for s in solutions.iter() {
            assert!(s.joints.iter().all(|v| v.is_finite()));
            assert!(s.singularities.shoulder);
            let (dp, dr) = pose_error(&kin.forward_tcp(&s.joints), &target);
            assert!(dp < 1e-7 && dr < 1e-7, "{s:?}: {dp:e} {dr:e}");
        }
    }
}

#[test]
fn unreachable_poses_are_typed_errors() {
    let kin = UrKinematics::ur5e();
    let far = Isometry3::translation(2.0, 0.0, 0.3);
    assert!(matches!(
        kin.inverse_all(&far, 0.0),
        Err(IkError::OutOfReach { .. })
    ));
    // Wrist centre on the base axis (inside the shoulder offset cylinder).
    let axis = Isometry3::translation(0.0, 0.0, 0.5 + kin.dh.d6);
    assert!(matches!(
        kin.inverse_all(&axis, 0.0),
        Err(IkError::WristCentreInsideShoulderOffset { .. })
    ));
    let nan = Isometry3::translation(f64::NAN, 0.0, 0.3);
    assert_eq!(
        kin.inverse_all(&nan, 0.0).unwrap_err(),
        IkError::NonFinitePose
    );
    let good = kin.forward_tcp(&[0.1, -1.0, 1.0, -1.0, 1.0, 0.0]);
    assert!(matches!(
        kin.inverse_nearest(&good, &[f64::NAN; 6]),
        Err(IkError::NonFiniteJoints(_))
    ));
}

#[test]
fn ur_pose_vectors_round_trip_through_fk() {
    let kin = UrKinematics::ur5e();
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    for _ in 0..1000 {
        let q = random_joints(&mut rng);
        let pose = kin.forward_tcp(&q);
        let v = to_ur_pose(&pose);
        let angle = Vector3::new(v[3], v[4], v[5]).norm();
        assert!(angle <= PI + 1e-12);
        let (dp, dr) = pose_error(&from_ur_pose(&v), &pose);
        assert!(dp < 1e-12 && dr < 1e-12);
    }
}

#[test]
fn jacobian_matches_finite_differences_and_the_singularity_product() {
    let tool = Isometry3::from_parts(
        Translation3::new(0.0, 0.01, 0.12),
        UnitQuaternion::from_euler_angles(0.0, 0.2, 0.0),
    );
    let kin = UrKinematics::ur5e().with_tcp(tool);
    let dh = kin.dh;
    let mut rng = ChaCha8Rng::seed_from_u64(23);
    for _ in 0..200 {
        let q = random_joints(&mut rng);
        let jac = kin.jacobian(&q);
        let h = 1e-6;
        for j in 0..6 {
            let (mut plus, mut minus) = (q, q);
            plus[j] += h;
            minus[j] -= h;
            let (p, m) = (kin.forward_tcp(&plus), kin.forward_tcp(&minus));
            let linear = (p.translation.vector - m.translation.vector) / (2.0 * h);
            let angular = (p.rotation * m.rotation.inverse()).scaled_axis() / (2.0 * h);
            for r in 0..3 {
                assert!((jac[(r, j)] - linear[r]).abs() < 1e-7, "{q:?} col {j}");
                assert!((jac[(r + 3, j)] - angular[r]).abs() < 1e-7, "{q:?} col {j}");
            }
        }
        let shoulder =
            dh.a2 * q[1].cos() + dh.a3 * (q[1] + q[2]).cos() + dh.d5 * (q[1] + q[2] + q[3]).sin();
        let product = (dh.a2 * dh.a3 * q[2].sin() * q[4].sin() * shoulder).abs();
        let det = robots::kinematics::manipulability(&dh, &q);
        assert!((det - product).abs() < 1e-12, "{q:?}: {det} vs {product}");
        // Twist -> joint speeds -> twist.
        let twist = nalgebra::Vector6::new(0.1, -0.05, 0.02, 0.1, 0.0, -0.2);
        if let Ok(speeds) = kin.joint_speeds_for_twist(&q, &twist) {
            let back = jac * nalgebra::Vector6::from_column_slice(&speeds);
            assert!(
                (back - twist).norm() < 1e-9 * (1.0 + speeds.iter().map(|s| s.abs()).sum::<f64>())
            );
        }
    }
    // Exactly singular: refused with the singularity named.
    let stretched = [0.3, -1.0, 0.0, -1.0, 1.0, 0.0];
    match kin.joint_speeds_for_twist(&stretched, &nalgebra::Vector6::zeros()) {
        Err(IkError::Singular { singularities }) => assert!(singularities.elbow),
        other => panic!("expected Singular, got {other:?}"),
    }
}
