//! Every shipped UR arm (UR3e, UR5e, UR10e, UR16e, UR20), with kinematics derived from its URDF:
//! IK of FK round-trips on random reachable poses, and poses beyond each arm's reach are refused.

#![allow(non_snake_case)]

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use robots::kinematics::{IkError, Joints, UrKinematics, normalize_angle};
use robots::ur_arm::UrArm;
use std::f64::consts::PI;
use std::path::PathBuf;

/// Each arm and its datasheet reach (m).
const ARMS: [(&str, f64); 5] = [
    ("ur3e", 0.5),
    ("ur5e", 0.85),
    ("ur10e", 1.3),
    ("ur16e", 0.9),
    ("ur20", 1.75),
];

fn arm(name: &str) -> UrArm {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(format!("../scenarios/robots/{name}.urdf"));
    UrArm::from_file(path).unwrap_or_else(|e| panic!("{e}"))
}

/// A TCP a few centimetres off the flange, as with a gripper.
fn with_tool(kin: UrKinematics) -> UrKinematics {
    kin.with_tcp(Isometry3::translation(0.0, 0.0, 0.12))
}

fn pose_error(a: &Isometry3<f64>, b: &Isometry3<f64>) -> f64 {
    (a.translation.vector - b.translation.vector)
        .norm()
        .max(a.rotation.angle_to(&b.rotation))
}

/// Top-down TCP at (x, y, z) in the base frame.
fn down(x: f64, y: f64, z: f64) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), PI),
    )
}

#[test]
fn ik_of_fk_round_trips_on_every_arm() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    for (name, _) in ARMS {
        let kin = with_tool(arm(name).kinematics);
        let mut regular = 0;
        for _ in 0..2000 {
            let q: Joints = std::array::from_fn(|_| rng.random_range(-PI..PI));
            let target = kin.forward_tcp(&q);
            let all = kin
                .inverse_all(&target, q[5])
                .unwrap_or_else(|e| panic!("{name} {q:?}: {e}"));
            assert!(!all.is_empty(), "{name} {q:?}");
            for s in all.iter() {
                let err = pose_error(&kin.forward_tcp(&s.joints), &target);
                assert!(err < 1e-9, "{name} {q:?}: a solution misses by {err:e}");
            }
            if !kin.singularities(&q).is_empty() {
                continue;
            }
            regular += 1;
            // Away from singularities the joints we started from are among the solutions, and
            // the nearest one to them is them.
            let found = all.iter().any(|s| {
                s.joints
                    .iter()
                    .zip(&q)
                    .all(|(a, b)| normalize_angle(a - b).abs() < 1e-7)
            });
            assert!(found, "{name} {q:?}: not among {all:?}");
            let nearest = kin.inverse_nearest(&target, &q).unwrap().joints;
            let gap = nearest
                .iter()
                .zip(&q)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(gap < 1e-7, "{name} {q:?}: nearest {nearest:?}");
        }
        assert!(regular > 1500, "{name}: only {regular} regular samples");
    }
}

#[test]
fn each_arm_reaches_inside_its_datasheet_reach_and_refuses_beyond_it() {
    for (name, reach) in ARMS {
        let kin = arm(name).kinematics;
        let dh = kin.dh;
        // Top-down flange poses around the base at shoulder height: reachable at 70 % of the
        // datasheet reach, refused at 110 %.
        for k in 0..12 {
            let angle = k as f64 * PI / 6.0;
            let (s, c) = angle.sin_cos();
            let near = down(0.7 * reach * c, 0.7 * reach * s, dh.d1);
            let solutions = kin
                .inverse_all(&near, 0.0)
                .unwrap_or_else(|e| panic!("{name} at 70 % reach, {angle:.2} rad: {e}"));
            assert!(!solutions.is_empty(), "{name}");
            let far = down(1.1 * reach * c, 1.1 * reach * s, dh.d1);
            match kin.inverse_all(&far, 0.0) {
                Err(IkError::OutOfReach { .. }) => {}
                other => panic!("{name} at 110 % reach, {angle:.2} rad: {other:?}"),
            }
        }
        // Any orientation: a flange farther from the shoulder than every link length together
        // is out of reach.
        let bound = dh.a2.abs() + dh.a3.abs() + dh.d4 + dh.d5 + dh.d6;
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        for _ in 0..200 {
            let dir = Vector3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            )
            .normalize();
            let p = Vector3::new(0.0, 0.0, dh.d1) + 1.01 * bound * dir;
            let rotation = UnitQuaternion::from_scaled_axis(Vector3::new(
                rng.random_range(-PI..PI),
                rng.random_range(-PI..PI),
                rng.random_range(-PI..PI),
            ));
            let pose = Isometry3::from_parts(Translation3::from(p), rotation);
            assert!(kin.inverse_all(&pose, 0.0).is_err(), "{name}: {pose}");
        }
    }
    // Where a UR5e reaches, a UR3e does not, and a UR10e reaches farther still.
    let at = |x: f64| down(x, 0.0, 0.05);
    assert!(arm("ur5e").kinematics.inverse_all(&at(0.7), 0.0).is_ok());
    assert!(arm("ur3e").kinematics.inverse_all(&at(0.7), 0.0).is_err());
    assert!(arm("ur5e").kinematics.inverse_all(&at(1.1), 0.0).is_err());
    assert!(arm("ur10e").kinematics.inverse_all(&at(1.1), 0.0).is_ok());
}
