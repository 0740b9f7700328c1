//! Our program's guarded move (`Robot::move_until_contact` on `UrRobot`) against the virtual UR
//! on free loopback ports, its tool meeting the table plane.

use nalgebra::{Isometry3, Translation3};
use robots::kinematics::UrKinematics;
use robots::limits::LimitViolation;
use robots::robot::{JointMotion, LinearMotion, Robot, RobotError};
use robots::ur_robot::{UrRobot, UrRobotConfig};
use robots::virtual_ur::{VirtualUr, VirtualUrConfig};
use std::f64::consts::FRAC_PI_2;
use std::time::Duration;

const CONTACT: LinearMotion = LinearMotion {
    speed: 0.02,
    acceleration: 1.2,
};

/// The tool pointing down `z` metres above the table (the base frame's xy plane).
fn above_table(z: f64) -> Isometry3<f64> {
    let kin = UrKinematics::ur5e();
    let down = kin.forward_tcp(&[0.2, -1.4, 1.5, -1.7, -FRAC_PI_2, 0.3]);
    let t = down.translation.vector;
    Translation3::new(t.x, t.y, z) * Isometry3::from_parts(Translation3::identity(), down.rotation)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_guarded_move_stops_on_the_table_within_a_millimetre_and_reports_the_force() {
    let vur = VirtualUr::start(VirtualUrConfig::ephemeral())
        .await
        .unwrap();
    let mut config = UrRobotConfig {
        rtde_port: vur.rtde_addr().port(),
        dashboard_port: vur.dashboard_addr().port(),
        script_port: vur.script_addr().port(),
        command_timeout: Duration::from_secs(10),
        ..UrRobotConfig::new("127.0.0.1", UrKinematics::ur5e())
    };
    config.limits.workspace.min[2] = -0.02;
    // What this cell's parts may take: below the arm's own 150 N protective stop.
    config.limits.max_contact_force = 30.0;
    let mut robot = UrRobot::connect(config).await.unwrap();
    robot
        .move_j(
            [0.2, -1.4, 1.5, -1.7, -FRAC_PI_2, 0.3],
            JointMotion {
                speed: 2.0,
                acceleration: 4.0,
            },
        )
        .await
        .unwrap();
    let fast = LinearMotion {
        speed: 0.25,
        acceleration: 1.2,
    };
    robot.move_l(above_table(0.005), fast).await.unwrap();

    // Down towards 5 mm below the table: stopped on contact near its surface, pressing.
    let down = robot
        .move_until_contact(above_table(-0.005), CONTACT, 10.0)
        .await
        .unwrap();
    assert!(down.contact, "{down:?}");
    let z = down.stopped_at.translation.z;
    assert!(z.abs() < 1e-3, "stopped {z} m from the table");
    assert!(z < 0.0, "stopped pressing into the table: {z}");
    // The table pushes up: the reading's force against the descent is over the limit, less the
    // sensor's precision.
    assert!(down.wrench[2] > 10.0 - 4.0, "{down:?}");
    let still = robot.wrench().await.unwrap();
    assert!(still[2] > 10.0 - 4.0, "still pressing: {still:?}");

    // Up and away: nothing resists the motion, so it runs to its target without contact.
    let up = robot
        .move_until_contact(above_table(0.004), CONTACT, 10.0)
        .await
        .unwrap();
    assert!(!up.contact, "{up:?}");
    assert!((up.stopped_at.translation.z - 0.004).abs() < 1e-6, "{up:?}");

    // A force limit beyond the cell's limit, or the arm's protective stop, never leaves the
    // client; one that reaches the program unchecked is refused there, and the arm does not move.
    let before = robot.tcp_pose().await.unwrap();
    for (asked, max) in [(40.0, 30.0), (200.0, 30.0)] {
        let refused = robot
            .move_until_contact(above_table(-0.005), CONTACT, asked)
            .await;
        assert!(
            matches!(
                &refused,
                Err(RobotError::LimitViolation(LimitViolation::ContactForce { requested, max: m }))
                    if *requested == asked && *m == max
            ),
            "{refused:?}"
        );
    }
    let refused = robot
        .inner_mut()
        .move_until_contact(above_table(-0.005), CONTACT, f64::NAN)
        .await;
    assert!(
        matches!(&refused, Err(RobotError::Rejected { detail }) if detail.contains("force limit")),
        "{refused:?}"
    );
    let after = robot.tcp_pose().await.unwrap();
    assert!((after.translation.vector - before.translation.vector).norm() < 1e-9);
}
