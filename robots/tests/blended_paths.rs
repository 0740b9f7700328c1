//! Blended paths ([`robots::robot::Robot::move_path`]) and their limit check
//! ([`robots::limited::check_path`]): every via-point, every blend radius against half of the
//! segments it blends, and the blended motion sampled every millisecond on the virtual UR's arm
//! model.

use nalgebra::{Isometry3, Translation3};
use robots::kinematics::{Joints, UrKinematics};
use robots::limited::{PATH_SAMPLE_PERIOD, check_path};
use robots::limits::{LimitViolation, Limits, WorkspaceBox};
use robots::robot::{JointMotion, LinearMotion, RobotError, Waypoint};
use robots::virtual_ur::arm::{ArmError, KinematicArm};
use robots::virtual_ur::path::{PathCycle, execute_path, waypoint_moves};

/// A UR5e pose over a table, elbow up, tool down.
const START: Joints = [0.0, -1.9, 1.9, -1.57, -1.57, 0.0];

fn limits() -> Limits {
    Limits {
        workspace: WorkspaceBox {
            min: [-0.85, -0.85, 0.0],
            max: [0.85, 0.85, 1.0],
        },
        max_tcp_speed: 0.25,
        max_tcp_acceleration: 1.2,
        max_joint_speed: 1.0,
        max_joint_acceleration: 6.0,
        ..Limits::default()
    }
}

#[allow(non_snake_case)]
fn shifted(base_T_tcp: &Isometry3<f64>, dx: f64, dy: f64, dz: f64) -> Isometry3<f64> {
    Translation3::new(dx, dy, dz) * base_T_tcp
}

/// Lift 10 cm, transit in joint space, come down 10 cm: the orchestrator's chain, blended.
fn lift_transit_approach(kinematics: &UrKinematics, blend: f64) -> Vec<Waypoint> {
    let start = kinematics.forward_tcp(&START);
    let up = shifted(&start, 0.0, 0.0, 0.1);
    let over = shifted(&start, -0.15, 0.1, 0.1);
    let over_q = kinematics.inverse_nearest(&over, &START).unwrap().joints;
    let down = shifted(&start, -0.15, 0.1, 0.0);
    let line = LinearMotion {
        speed: 0.25,
        acceleration: 1.2,
    };
    // A third of the joint acceleration limit: blending superposes the moves' accelerations,
    // and the approach's tool line starts with up to 3.7 rad/s² on the elbow.
    let joint = JointMotion {
        speed: 1.0,
        acceleration: 2.0,
    };
    vec![
        Waypoint::linear(up, line, blend),
        Waypoint::joints(over_q, joint, blend),
        Waypoint::linear(down, line, 0.0),
    ]
}

/// The blended motion, run as the virtual UR runs it, sampled every millisecond.
fn samples(kinematics: &UrKinematics, path: &[Waypoint]) -> (Vec<PathCycle>, f64) {
    let mut arm = KinematicArm::new(kinematics.clone(), START);
    let mut cycles = Vec::new();
    let run = execute_path(
        &mut arm,
        &waypoint_moves(path),
        PATH_SAMPLE_PERIOD,
        |c: &PathCycle| {
            cycles.push(*c);
            Ok::<_, ArmError>(())
        },
    )
    .unwrap();
    assert!(run.warnings.is_empty(), "{:?}", run.warnings);
    (cycles, run.duration)
}

#[test]
fn blending_into_a_move_at_full_joint_acceleration_is_refused() {
    // The transit decelerating at the full 6 rad/s² while the approach's tool line starts:
    // their accelerations add on the elbow.
    let kinematics = UrKinematics::ur5e();
    let mut path = lift_transit_approach(&kinematics, 0.03);
    path[1].acceleration = 6.0;
    assert!(matches!(
        check_path(&limits(), &kinematics, &START, &path),
        Err(RobotError::LimitViolation(
            LimitViolation::JointAcceleration { .. }
        ))
    ));
    path[1].blend = 0.0;
    path[0].blend = 0.0;
    check_path(&limits(), &kinematics, &START, &path).unwrap();
}

#[test]
fn an_accepted_blended_path_respects_every_limit_at_1_ms_and_is_faster() {
    let kinematics = UrKinematics::ur5e();
    let limits = limits();
    let path = lift_transit_approach(&kinematics, 0.03);
    check_path(&limits, &kinematics, &START, &path).unwrap();
    let (cycles, blended) = samples(&kinematics, &path);
    assert!(cycles.len() > 500, "{} samples", cycles.len());
    assert!((cycles[0].t - 1e-3).abs() < 1e-12);
    for w in cycles.windows(2) {
        assert!((w[1].t - w[0].t - 1e-3).abs() < 1e-9, "sampled every 1 ms");
    }
    for c in &cycles {
        let s = &c.state;
        for i in 0..6 {
            assert!(
                s.qd[i].abs() <= limits.max_joint_speed * (1.0 + 1e-6),
                "{c:?}"
            );
            assert!(
                s.target_qdd[i].abs() <= limits.max_joint_acceleration * (1.0 + 1e-6),
                "{c:?}"
            );
        }
        let p = nalgebra::Vector3::new(s.tcp_pose[0], s.tcp_pose[1], s.tcp_pose[2]);
        assert!(limits.workspace.contains(&p), "{c:?}");
    }
    for w in cycles.windows(2) {
        if w[1].tool_lines {
            let (a, b) = (&w[0].state.tcp_pose, &w[1].state.tcp_pose);
            let d = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
            assert!(d / PATH_SAMPLE_PERIOD <= limits.max_tcp_speed * (1.0 + 1e-6));
        }
    }
    // The arm ends where the path does.
    let end = kinematics.forward_tcp(&cycles.last().unwrap().state.q);
    let want = shifted(&kinematics.forward_tcp(&START), -0.15, 0.1, 0.0);
    assert!((end.translation.vector - want.translation.vector).norm() < 1e-9);
    // Blending saves the stops at the two corners.
    let (_, stopped) = samples(&kinematics, &lift_transit_approach(&kinematics, 0.0));
    assert!(
        blended < stopped - 0.05,
        "blended {blended} s, stopping {stopped} s"
    );
}

#[test]
fn a_blend_over_half_a_segment_or_at_the_end_is_refused() {
    let kinematics = UrKinematics::ur5e();
    let limits = limits();
    // The lift is 10 cm: 5 cm is half of it, 5.1 cm is over.
    let mut path = lift_transit_approach(&kinematics, 0.051);
    path[1].blend = 0.0;
    match check_path(&limits, &kinematics, &START, &path) {
        Err(RobotError::LimitViolation(LimitViolation::BlendRadius { index: 0, max, .. })) => {
            assert!((max - 0.05).abs() < 1e-9, "{max}")
        }
        other => panic!("{other:?}"),
    }
    path[0].blend = 0.05 - 1e-9;
    check_path(&limits, &kinematics, &START, &path).unwrap();
    let mut path = lift_transit_approach(&kinematics, 0.02);
    path[2].blend = 0.01;
    assert!(matches!(
        check_path(&limits, &kinematics, &START, &path),
        Err(RobotError::LimitViolation(LimitViolation::BlendRadius {
            index: 2,
            max: 0.0,
            ..
        }))
    ));
    let mut path = lift_transit_approach(&kinematics, 0.02);
    path[1].blend = -0.01;
    assert!(matches!(
        check_path(&limits, &kinematics, &START, &path),
        Err(RobotError::LimitViolation(
            LimitViolation::NotPositive { .. }
        ))
    ));
    path[1].blend = f64::NAN;
    assert!(matches!(
        check_path(&limits, &kinematics, &START, &path),
        Err(RobotError::LimitViolation(LimitViolation::NonFinite { .. }))
    ));
}

#[test]
fn a_blend_that_adds_two_cruising_joint_moves_is_refused_on_joint_speed() {
    let kinematics = UrKinematics::ur5e();
    let limits = Limits {
        max_joint_acceleration: 40.0,
        ..limits()
    };
    // Each move alone cruises at the limit; blended with a 9 cm radius (about 0.2 rad of the
    // base here) the second starts while the first still cruises: their speeds add.
    let motion = JointMotion {
        speed: 1.0,
        acceleration: 40.0,
    };
    let mut q1 = START;
    q1[0] += 0.5;
    let mut q2 = q1;
    q2[0] += 0.5;
    let path = vec![
        Waypoint::joints(q1, motion, 0.09),
        Waypoint::joints(q2, motion, 0.0),
    ];
    match check_path(&limits, &kinematics, &START, &path) {
        Err(RobotError::LimitViolation(LimitViolation::JointSpeed { requested, max })) => {
            assert!(requested > max, "{requested} rad/s")
        }
        other => panic!("{other:?}"),
    }
    // Without the blend each move keeps to the limit.
    let stopped: Vec<Waypoint> = path.iter().map(|w| Waypoint { blend: 0.0, ..*w }).collect();
    check_path(&limits, &kinematics, &START, &stopped).unwrap();
}

#[test]
fn a_blend_of_two_cruising_tool_lines_is_refused_on_tcp_speed() {
    let kinematics = UrKinematics::ur5e();
    // Joint rates aside (two tool lines' brake and start superposed ask over 10 rad/s² of the
    // wrist here): this is about the TCP.
    let limits = Limits {
        max_joint_speed: 3.0,
        max_joint_acceleration: 20.0,
        ..limits()
    };
    let start = kinematics.forward_tcp(&START);
    let line = LinearMotion {
        speed: 0.25,
        acceleration: 1.2,
    };
    // Two 20 cm lines at a right angle, each cruising at the 0.25 m/s limit; an 8 cm blend
    // starts the second while the first still cruises (it brakes over 2.6 cm).
    let path = vec![
        Waypoint::linear(shifted(&start, 0.2, 0.0, 0.0), line, 0.08),
        Waypoint::linear(shifted(&start, 0.2, 0.2, 0.0), line, 0.0),
    ];
    match check_path(&limits, &kinematics, &START, &path) {
        Err(RobotError::LimitViolation(LimitViolation::TcpSpeed { requested, max })) => {
            assert!(requested > max, "{requested} m/s")
        }
        other => panic!("{other:?}"),
    }
    // A blend within the braking distance keeps the TCP under the limit.
    let mut gentle = path.clone();
    gentle[0].blend = 0.02;
    check_path(&limits, &kinematics, &START, &gentle).unwrap();
}

#[test]
fn a_via_point_outside_the_limits_is_refused() {
    let kinematics = UrKinematics::ur5e();
    let limits = limits();
    let mut path = lift_transit_approach(&kinematics, 0.02);
    path[1].speed = 1.5;
    assert!(matches!(
        check_path(&limits, &kinematics, &START, &path),
        Err(RobotError::LimitViolation(
            LimitViolation::JointSpeed { .. }
        ))
    ));
    let mut path = lift_transit_approach(&kinematics, 0.02);
    path[2].acceleration = 2.0;
    assert!(matches!(
        check_path(&limits, &kinematics, &START, &path),
        Err(RobotError::LimitViolation(
            LimitViolation::TcpAcceleration { .. }
        ))
    ));
    let narrow = Limits {
        workspace: WorkspaceBox {
            min: [-0.85, -0.85, 0.0],
            max: [
                0.85,
                0.85,
                kinematics.forward_tcp(&START).translation.z + 0.05,
            ],
        },
        ..limits.clone()
    };
    assert!(matches!(
        check_path(&narrow, &kinematics, &START, &path),
        Err(RobotError::LimitViolation(
            LimitViolation::OutsideWorkspace { .. }
        ))
    ));
    assert!(check_path(&limits, &kinematics, &START, &[]).is_err());
}

#[test]
fn a_path_the_arm_model_cannot_run_is_refused_as_a_limit_violation() {
    // A via-point inside a (wide) workspace box but out of the arm's reach: refused before
    // anything moves, as a limit violation (the orchestrator then moves stop by stop), not as a
    // failed motion.
    let kinematics = UrKinematics::ur5e();
    let wide = Limits {
        workspace: WorkspaceBox {
            min: [-5.0, -5.0, -5.0],
            max: [5.0, 5.0, 5.0],
        },
        ..limits()
    };
    let mut path = lift_transit_approach(&kinematics, 0.0);
    let start = kinematics.forward_tcp(&START);
    path[2] = Waypoint::linear(
        shifted(&start, 2.0, 0.0, 0.0),
        LinearMotion {
            speed: 0.25,
            acceleration: 1.2,
        },
        0.0,
    );
    match check_path(&wide, &kinematics, &START, &path) {
        Err(RobotError::LimitViolation(LimitViolation::PathRefused { detail })) => {
            assert!(detail.contains("unreachable"), "{detail}")
        }
        other => panic!("{other:?}"),
    }
}
