//! Cell limits: targets and motions outside them are refused with the reason and the amount.

use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use robots::kinematics::{JointLimits, UrKinematics};
use robots::limits::{LimitViolation, Limits, WorkspaceBox};
use robots::robot::{JointMotion, LinearMotion, RobotError};
use std::f64::consts::FRAC_PI_2;

fn cell_limits() -> Limits {
    Limits {
        workspace: WorkspaceBox {
            min: [-0.6, -0.7, 0.05],
            max: [0.6, 0.2, 0.8],
        },
        max_tcp_speed: 0.25,
        max_tcp_acceleration: 1.0,
        max_joint_speed: 1.0,
        max_joint_acceleration: 2.0,
        joint_positions: JointLimits::default(),
        max_contact_force: 50.0,
    }
}

fn at(x: f64, y: f64, z: f64) -> Isometry3<f64> {
    Isometry3::from_parts(
        Vector3::new(x, y, z).into(),
        UnitQuaternion::from_euler_angles(std::f64::consts::PI, 0.0, 0.0),
    )
}

const SLOW: LinearMotion = LinearMotion {
    speed: 0.1,
    acceleration: 0.5,
};

#[test]
fn linear_targets_inside_the_box_pass() {
    let limits = cell_limits();
    limits.validate().unwrap();
    limits.check_move_l(&at(0.3, -0.4, 0.2), &SLOW).unwrap();
    // On the boundary counts as inside.
    limits.check_move_l(&at(0.6, 0.2, 0.05), &SLOW).unwrap();
}

#[test]
fn targets_outside_the_box_are_rejected_with_axis_and_distance() {
    let limits = cell_limits();
    let err = limits
        .check_move_l(&at(0.3, -0.4, 0.02), &SLOW)
        .unwrap_err();
    match err {
        LimitViolation::OutsideWorkspace {
            axis, value, min, ..
        } => {
            assert_eq!(axis, 'z');
            assert_eq!(value, 0.02);
            assert_eq!(min, 0.05);
        }
        ref other => panic!("{other:?}"),
    }
    assert!((err.excess() - 0.03).abs() < 1e-12);
    assert_eq!(
        err.to_string(),
        "TCP z = 0.0200 m is 0.0300 m outside the workspace [0.0500, 0.8000] m"
    );
    let err = limits.check_move_l(&at(0.75, 0.0, 0.3), &SLOW).unwrap_err();
    assert!(matches!(
        err,
        LimitViolation::OutsideWorkspace { axis: 'x', .. }
    ));
    assert!((err.excess() - 0.15).abs() < 1e-12);
    let nan = at(f64::NAN, 0.0, 0.3);
    assert!(matches!(
        limits.check_move_l(&nan, &SLOW),
        Err(LimitViolation::NonFinite { .. })
    ));
}

#[test]
fn speeds_and_accelerations_over_the_limit_are_rejected() {
    let limits = cell_limits();
    let fast = LinearMotion {
        speed: 0.4,
        acceleration: 0.5,
    };
    let err = limits.check_move_l(&at(0.3, -0.4, 0.2), &fast).unwrap_err();
    assert_eq!(
        err,
        LimitViolation::TcpSpeed {
            requested: 0.4,
            max: 0.25
        }
    );
    assert!((err.excess() - 0.15).abs() < 1e-12);
    assert!(err.to_string().contains("by 0.1500 m/s"), "{err}");
    let hard = LinearMotion {
        speed: 0.1,
        acceleration: 3.0,
    };
    assert!(matches!(
        limits.check_move_l(&at(0.3, -0.4, 0.2), &hard),
        Err(LimitViolation::TcpAcceleration { .. })
    ));
    let zero = LinearMotion {
        speed: 0.0,
        acceleration: 0.5,
    };
    assert!(matches!(
        limits.check_move_l(&at(0.3, -0.4, 0.2), &zero),
        Err(LimitViolation::NotPositive { .. })
    ));

    let kin = UrKinematics::ur5e();
    let home = [0.0, -1.5, 1.5, -1.57, -1.57, 0.0];
    let target = [0.2, -1.4, 1.4, -1.57, -1.57, 0.0];
    assert!(kin.forward_tcp(&home).translation.z > 0.05);
    let ok = JointMotion {
        speed: 0.8,
        acceleration: 1.5,
    };
    let too_fast = JointMotion {
        speed: 1.5,
        acceleration: 1.5,
    };
    let too_hard = JointMotion {
        speed: 0.5,
        acceleration: 2.5,
    };
    // This cell's box is narrow in +y; use a roomy one for the joint rate checks.
    let mut roomy = cell_limits();
    roomy.workspace = WorkspaceBox {
        min: [-1.0; 3],
        max: [1.0; 3],
    };
    roomy.check_move_j(&kin, &home, &target, &ok, 16).unwrap();
    let err = roomy
        .check_move_j(&kin, &home, &target, &too_fast, 16)
        .unwrap_err();
    assert_eq!(
        err,
        LimitViolation::JointSpeed {
            requested: 1.5,
            max: 1.0
        }
    );
    assert!(matches!(
        roomy.check_move_j(&kin, &home, &target, &too_hard, 16),
        Err(LimitViolation::JointAcceleration { .. })
    ));
}

#[test]
fn joint_targets_outside_their_range_or_box_are_rejected() {
    let kin = UrKinematics::ur5e();
    let mut limits = cell_limits();
    limits.workspace = WorkspaceBox {
        min: [-1.0, -1.0, 0.05],
        max: [1.0, 1.0, 1.0],
    };
    limits.joint_positions.lower[2] = -3.0;
    limits.joint_positions.upper[2] = 3.0;
    let motion = JointMotion {
        speed: 0.5,
        acceleration: 1.0,
    };
    let home = [0.0, -1.5, 1.5, -1.57, -1.57, 0.0];
    let mut target = home;
    target[2] = 3.2;
    let err = limits
        .check_move_j(&kin, &home, &target, &motion, 16)
        .unwrap_err();
    assert!(
        matches!(err, LimitViolation::JointPosition { joint: 2, .. }),
        "{err}"
    );
    assert!((err.excess() - 0.2).abs() < 1e-12);
    assert!(
        err.to_string()
            .starts_with("joint 3 = 3.2000 rad is 0.2000 rad outside"),
        "{err}"
    );

    // Both ends are inside the box but the elbow swings the wrist down through the table.
    let start = [0.0, 0.0, 0.2, FRAC_PI_2 - 0.2, -FRAC_PI_2, 0.0];
    let end = [0.0, 0.0, 2.6, FRAC_PI_2 - 2.6, -FRAC_PI_2, 0.0];
    let mid = [0.0, 0.0, 1.4, FRAC_PI_2 - 1.4, -FRAC_PI_2, 0.0];
    for q in [start, end] {
        let z = kin.forward_tcp(&q).translation.z;
        assert!(z > 0.05, "{q:?}: z {z}");
    }
    assert!(kin.forward_tcp(&mid).translation.z < 0.0);
    limits.check_tcp_target(&kin.forward_tcp(&end)).unwrap();
    let err = limits
        .check_move_j(&kin, &start, &end, &motion, 32)
        .unwrap_err();
    assert!(
        matches!(err, LimitViolation::OutsideWorkspace { axis: 'z', .. }),
        "{err}"
    );
}

#[test]
fn limits_are_serde_and_validated() {
    let limits = cell_limits();
    let text = serde_json::to_string(&limits).unwrap();
    let back: Limits = serde_json::from_str(&text).unwrap();
    assert_eq!(back, limits);
    // joint_positions may be omitted.
    let minimal = r#"{"workspace":{"min":[-1,-1,0],"max":[1,1,1]},"max_tcp_speed":0.2,
        "max_tcp_acceleration":1,"max_joint_speed":1,"max_joint_acceleration":2}"#;
    let parsed: Limits = serde_json::from_str(minimal).unwrap();
    assert_eq!(parsed.joint_positions, JointLimits::default());
    let typo = minimal.replace("max_tcp_speed", "max_tcp_sped");
    assert!(serde_json::from_str::<Limits>(&typo).is_err());

    let mut bad = cell_limits();
    bad.workspace.min[1] = 0.5;
    assert_eq!(bad.validate().unwrap_err().field, "workspace");
    let mut bad = cell_limits();
    bad.max_joint_speed = -1.0;
    assert_eq!(bad.validate().unwrap_err().field, "max_joint_speed");
}

#[test]
fn violations_convert_into_robot_errors() {
    let err: RobotError = LimitViolation::TcpSpeed {
        requested: 0.5,
        max: 0.25,
    }
    .into();
    assert!(matches!(err, RobotError::LimitViolation(_)));
    assert!(err.to_string().contains("exceeds the limit"), "{err}");
}

/// The cell's contact force limit: positive and at most the arm's protective stop force, and a
/// guarded move's force limit is checked against it.
#[test]
fn the_contact_force_limit_is_the_cells_and_never_above_the_protective_stop() {
    use robots::limited::{MAX_CONTACT_FORCE, check_contact_force};
    let limits = cell_limits();
    limits.validate().unwrap();
    check_contact_force(50.0, limits.max_contact_force).unwrap();
    assert_eq!(
        check_contact_force(50.5, limits.max_contact_force),
        Err(LimitViolation::ContactForce {
            requested: 50.5,
            max: 50.0
        })
    );
    // A cell limit above the arm's own stop is capped by it.
    assert!(matches!(
        check_contact_force(151.0, 1.0e3),
        Err(LimitViolation::ContactForce { max, .. }) if max == MAX_CONTACT_FORCE
    ));
    for bad in [0.0, -1.0, f64::NAN, MAX_CONTACT_FORCE + 1.0] {
        let refused = Limits {
            max_contact_force: bad,
            ..cell_limits()
        }
        .validate()
        .unwrap_err();
        assert_eq!(refused.field, "max_contact_force", "{bad}: {refused:?}");
    }
    // Omitted in a file: the protective stop force.
    assert_eq!(Limits::default().max_contact_force, MAX_CONTACT_FORCE);
}
