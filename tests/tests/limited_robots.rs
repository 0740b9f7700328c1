//! The limits decorator (`robots::limited::Limited`) refuses out-of-limit targets for every robot
//! implementation, and nothing moves: the simulated cell, the in-process workcell the harness
//! hands the engine, and `UrRobot` against the virtual controller on 127.0.0.1.

mod e2e_support;

use std::time::Duration;

use cell::harness::connect_sim_over_rtde;
use cell::orchestrator::Workcell;
use nalgebra::Translation3;
use robots::robot::{JointMotion, LinearMotion, Robot, RobotError};

use e2e_support::setup;

const SLOW: LinearMotion = LinearMotion {
    speed: 0.05,
    acceleration: 0.5,
};

/// Every kind of out-of-limit target is refused with a limit violation and the arm stays put;
/// a target within the limits then runs.
async fn refuses_out_of_limit_targets(robot: &mut dyn Robot) {
    let limits = robot.limits().clone();
    let q0 = robot.joints().await.unwrap();
    let home = robot.tcp_pose().await.unwrap();
    let refused = |r: Result<(), RobotError>, what: &str| match r {
        Err(RobotError::LimitViolation(_)) => {}
        other => panic!("{what}: {other:?}"),
    };
    // Outside the workspace box (x beyond its upper bound).
    let outside = Translation3::new(
        limits.workspace.max[0] + 0.01 - home.translation.x,
        0.0,
        0.0,
    ) * home;
    refused(robot.move_l(outside, SLOW).await, "outside the box");
    // Faster and harder than the linear limits.
    let near = Translation3::new(0.0, 0.0, 0.01) * home;
    let fast = LinearMotion {
        speed: limits.max_tcp_speed * 1.5,
        acceleration: 0.5,
    };
    refused(robot.move_l(near, fast).await, "TCP speed");
    let hard = LinearMotion {
        speed: 0.05,
        acceleration: limits.max_tcp_acceleration * 1.5,
    };
    refused(robot.move_l(near, hard).await, "TCP acceleration");
    // Joint moves: too fast, too hard, beyond the joint range, and through the box's floor.
    let mut q1 = q0;
    q1[5] += 0.1;
    let quick = JointMotion {
        speed: limits.max_joint_speed * 1.5,
        acceleration: 1.0,
    };
    refused(robot.move_j(q1, quick).await, "joint speed");
    let jerky = JointMotion {
        speed: 0.5,
        acceleration: limits.max_joint_acceleration * 1.5,
    };
    refused(robot.move_j(q1, jerky).await, "joint acceleration");
    let ok = JointMotion {
        speed: 0.5,
        acceleration: 1.0,
    };
    let mut wound = q0;
    wound[5] = limits.joint_positions.upper[5] + 0.1;
    refused(robot.move_j(wound, ok).await, "joint range");
    let mut down = q0;
    down[1] += 0.8; // the shoulder swings the TCP down through the table
    refused(robot.move_j(down, ok).await, "TCP path below the box");
    let q = robot.joints().await.unwrap();
    let moved = q
        .iter()
        .zip(&q0)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(moved < 1e-9, "the arm moved by {moved} rad");
    // Within the limits it moves.
    robot.move_l(near, SLOW).await.unwrap();
    let at = robot.tcp_pose().await.unwrap();
    assert!((at.translation.vector - near.translation.vector).norm() < 1e-3);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_robot_refuses_out_of_limit_targets() {
    let setup = setup(|_| {});
    // The simulated cell itself, wrapped.
    let model = setup.model.clone();
    let mut sim = sim::cell::SimCell::new(model.clone(), 1, 0).unwrap();
    // Unwrapped, the cell runs a move faster than the limits: the decorator does the checking.
    let home = Robot::tcp_pose(&mut sim).await.unwrap();
    let fast = LinearMotion {
        speed: setup.scenario().spec.cell.limits.max_tcp_speed * 1.5,
        acceleration: 0.5,
    };
    sim.move_l_sync(Translation3::new(0.0, 0.0, 0.01) * home, fast)
        .unwrap();
    let mut sim = sim::cell::SimCell::new(model.clone(), 1, 0).unwrap();
    refuses_out_of_limit_targets(&mut model.limited(&mut sim).unwrap()).await;

    // The in-process workcell the harness hands the engine.
    let mut cell = setup.model.limited(setup.sim_cell(2).unwrap()).unwrap();
    refuses_out_of_limit_targets(Workcell::robot(&mut cell)).await;

    // UrRobot over loopback RTDE to the virtual controller backed by the simulated cell.
    let mut over = connect_sim_over_rtde(&setup, 3, Duration::from_millis(100))
        .await
        .unwrap();
    refuses_out_of_limit_targets(&mut over.robot).await;
}
