//! A blended path ([`robots::robot::Robot::move_path`]) in process and in production: the
//! simulated cell's own `move_path` against the same path sent by `UrRobot` through our URScript
//! program (`cell_program`'s path commands) to the virtual UR driving the same cell. Both run the
//! virtual UR's blended-path model, so they take the same simulated time (within 2 %) and end on
//! the same joints; a path over the limits is refused before the arm moves on both.

mod e2e_support;

use std::time::Duration;

use cell::harness::connect_sim_over_rtde;
use nalgebra::{Isometry3, Translation3};
use robots::kinematics::UrKinematics;
use robots::limits::LimitViolation;
use robots::robot::{JointMotion, LinearMotion, Robot, RobotError, Waypoint};

use e2e_support::setup;

/// Lift 6 cm, transit 12 cm sideways in joint space, come down 6 cm, from the TCP at
/// `base_T_tcp` (joints `q`), blending both corners with `blend`.
#[allow(non_snake_case)]
fn chain(
    kinematics: &UrKinematics,
    q: &robots::kinematics::Joints,
    base_T_tcp: &Isometry3<f64>,
    blend: f64,
) -> Vec<Waypoint> {
    let at = |dx: f64, dz: f64| Translation3::new(dx, 0.0, dz) * base_T_tcp;
    let over_q = kinematics
        .inverse_nearest(&at(0.12, 0.06), q)
        .unwrap()
        .joints;
    let line = LinearMotion {
        speed: 0.25,
        acceleration: 1.2,
    };
    let joint = JointMotion {
        speed: 1.0,
        acceleration: 1.5,
    };
    vec![
        Waypoint::linear(at(0.0, 0.06), line, blend),
        Waypoint::joints(over_q, joint, blend),
        Waypoint::linear(at(0.12, 0.0), line, 0.0),
    ]
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_blended_path_takes_the_same_time_in_process_and_over_rtde() {
    let setup = setup(|_| {});
    let kinematics = setup.model.kinematics.clone();
    // The home pose lifted 10 cm: clear of the table and the parts.
    let (start_q, start_pose) = {
        let mut cell = setup.model.limited(setup.sim_cell(0).unwrap()).unwrap();
        let pose = Translation3::new(0.0, 0.0, 0.1) * cell.tcp_pose().await.unwrap();
        let q = kinematics
            .inverse_nearest(&pose, &cell.joints().await.unwrap())
            .unwrap()
            .joints;
        (q, pose)
    };
    let to_start = JointMotion {
        speed: 1.0,
        acceleration: 2.0,
    };

    let mut durations = Vec::new();
    for blend in [0.025, 0.0] {
        let path = chain(&kinematics, &start_q, &start_pose, blend);
        // In process.
        let mut local = setup.model.limited(setup.sim_cell(0).unwrap()).unwrap();
        local.move_j(start_q, to_start).await.unwrap();
        let t0 = local.inner().clock();
        local.move_path(path.clone()).await.unwrap();
        let in_process = local.inner().clock() - t0;
        let local_q = local.joints().await.unwrap();

        // Over RTDE, through our program.
        let mut remote = connect_sim_over_rtde(&setup, 0, Duration::from_millis(100))
            .await
            .unwrap();
        remote.robot.move_j(start_q, to_start).await.unwrap();
        let clock = || remote.cell.lock().unwrap().clock();
        let t0 = clock();
        remote.robot.move_path(path.clone()).await.unwrap();
        let over_rtde = clock() - t0;
        let remote_q = remote.robot.joints().await.unwrap();
        drop(remote);

        assert!(in_process > 0.5, "{in_process} s");
        assert!(
            (over_rtde - in_process).abs() <= 0.02 * in_process,
            "blend {blend}: {over_rtde} s over RTDE, {in_process} s in process"
        );
        for i in 0..6 {
            assert!(
                (local_q[i] - remote_q[i]).abs() < 1e-3,
                "blend {blend}: joints {local_q:?} in process, {remote_q:?} over RTDE"
            );
        }
        eprintln!("blend {blend} m: {in_process:.4} s in process, {over_rtde:.4} s over RTDE");
        durations.push(in_process);
    }
    // The program blends: the rounded corners save time over stopping at them.
    assert!(
        durations[0] < durations[1] - 0.05,
        "blended {} s, stopping {} s",
        durations[0],
        durations[1]
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_path_over_the_limits_is_refused_before_the_arm_moves() {
    let setup = setup(|_| {});
    let kinematics = setup.model.kinematics.clone();
    let mut local = setup.model.limited(setup.sim_cell(0).unwrap()).unwrap();
    let q = local.joints().await.unwrap();
    let pose = Translation3::new(0.0, 0.0, 0.1) * local.tcp_pose().await.unwrap();
    // From home: up 16 cm, 12 cm across, down 6 cm; a 4 cm blend is over half of the descent.
    let path = chain(&kinematics, &q, &pose, 0.04);
    let refused = |r: Result<(), RobotError>| {
        assert!(
            matches!(
                r,
                Err(RobotError::LimitViolation(LimitViolation::BlendRadius {
                    index: 1,
                    ..
                }))
            ),
            "{r:?}"
        )
    };

    let t0 = local.inner().clock();
    refused(local.move_path(path.clone()).await);
    assert_eq!(local.joints().await.unwrap(), q);
    assert_eq!(local.inner().clock(), t0);

    let mut remote = connect_sim_over_rtde(&setup, 0, Duration::from_millis(100))
        .await
        .unwrap();
    let t0 = remote.cell.lock().unwrap().clock();
    refused(remote.robot.move_path(path).await);
    tokio::time::sleep(Duration::from_millis(50)).await;
    assert_eq!(remote.cell.lock().unwrap().joints_now(), q);
    assert_eq!(remote.cell.lock().unwrap().clock(), t0);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_blended_episode_takes_the_same_time_over_rtde_within_2_percent() {
    // Blending on; the opening margin set aside as a controller run does (its gripper output
    // opens the full stroke).
    let setup = setup(|doc| {
        doc["cell"]["gripper"]
            .as_table_mut()
            .expect("a gripper table")
            .remove("opening_margin")
            .expect("the scenario sets an opening margin");
        doc["motion"] = toml_edit::table();
        doc["motion"]["blend_radius"] = toml_edit::value(0.003);
    });
    assert_eq!(setup.engine.settings.planning.blend_radius, 0.003);
    let local = cell::harness::run_sim_episode(&setup, 0)
        .await
        .unwrap()
        .record;
    let remote = cell::harness::sim_episode_over_rtde(&setup, 0)
        .await
        .unwrap()
        .record;
    assert!(local.success && remote.success, "{local:?}\n{remote:?}");
    let d = remote.cycle_time_s - local.cycle_time_s;
    assert!(
        d.abs() <= 0.02 * local.cycle_time_s,
        "cycle {} s over RTDE, {} s in process",
        remote.cycle_time_s,
        local.cycle_time_s
    );
}
