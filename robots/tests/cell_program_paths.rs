//! Our program's path commands (`KIND_PATH_ADD_MOVEJ`/`MOVEL`, `KIND_PATH_RUN`) on the virtual
//! controller: a path out of order, with a bad radius or empty is refused before the arm moves;
//! `UrRobot::move_path` runs a blended path to its end.

use nalgebra::Translation3;
use robots::kinematics::UrKinematics;
use robots::program::{CELL_SCRIPT, layout as L};
use robots::robot::{JointMotion, LinearMotion, Robot, Waypoint};
use robots::rtde::client::{ClientConfig, RtdeClient};
use robots::rtde::state::RuntimeState;
use robots::rtde::types::Value;
use robots::ur_robot::{UrRobot, UrRobotConfig, upload_script};
use robots::virtual_ur::{VirtualUr, VirtualUrConfig};
use std::time::{Duration, Instant};

async fn wait_for(what: &str, done: impl Fn() -> bool) {
    let start = Instant::now();
    while !done() {
        assert!(
            start.elapsed() < Duration::from_secs(5),
            "{what} never came"
        );
        tokio::time::sleep(Duration::from_millis(2)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_path_commands_are_refused_and_the_arm_stays() {
    let vur = VirtualUr::start(VirtualUrConfig::ephemeral())
        .await
        .unwrap();
    let mut config = ClientConfig::new(vur.rtde_addr().to_string(), &["timestamp"]);
    config.inputs = vec![
        L::command_recipe(),
        L::heartbeat_recipe(),
        L::blend_recipe(),
    ];
    config.outputs.extend(L::output_registers());
    let client = RtdeClient::connect(config).await.unwrap();
    upload_script(
        &vur.script_addr().to_string(),
        CELL_SCRIPT,
        Duration::from_secs(1),
    )
    .await
    .unwrap();
    wait_for("the program", || {
        vur.controller.snapshot().runtime_state == RuntimeState::Playing
    })
    .await;
    let register = |reg: usize| {
        client
            .latest()
            .and_then(|s| s.i64(&format!("output_int_register_{reg}")))
    };
    let q0 = vur.controller.snapshot().arm.q;
    let mut target = q0;
    target[0] += 0.3;
    // (kind, via-point index, blend radius): out of order, negative, NaN, then running the
    // buffer those refusals left empty.
    let commands = [
        (L::KIND_PATH_ADD_MOVEJ, 1, 0.0),
        (L::KIND_PATH_ADD_MOVEJ, 0, -0.01),
        (L::KIND_PATH_ADD_MOVEJ, 0, f64::NAN),
        (L::KIND_PATH_RUN, 0, 0.0),
    ];
    for (id, (kind, index, blend)) in (1..).zip(commands) {
        client.send_inputs(1, &[Value::Int32(id)]).await.unwrap();
        client
            .send_inputs(2, &[Value::Double(blend)])
            .await
            .unwrap();
        let mut values = vec![Value::Int32(kind), Value::Int32(index), Value::Int32(0)];
        values.extend(target.iter().map(|v| Value::Double(*v)));
        values.extend([
            Value::Double(1.0),
            Value::Double(2.0),
            Value::Double(0.0),
            Value::Int32(id),
        ]);
        client.send_inputs(0, &values).await.unwrap();
        wait_for("the command to finish", || {
            register(L::DONE_ID_REG) == Some(i64::from(id))
        })
        .await;
        assert_eq!(
            register(L::STATUS_REG),
            Some(i64::from(L::STATUS_FAILED)),
            "command {id}"
        );
        assert_eq!(
            register(L::ERROR_REG),
            Some(i64::from(L::ERROR_INVALID_PATH)),
            "command {id}"
        );
    }
    assert_eq!(vur.controller.snapshot().arm.q, q0);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ur_robot_runs_a_blended_path_to_its_end() {
    let vur = VirtualUr::start(VirtualUrConfig::ephemeral())
        .await
        .unwrap();
    let mut robot = UrRobot::connect(UrRobotConfig {
        rtde_port: vur.rtde_addr().port(),
        dashboard_port: vur.dashboard_addr().port(),
        script_port: vur.script_addr().port(),
        command_timeout: Duration::from_secs(10),
        ..UrRobotConfig::new("127.0.0.1", UrKinematics::ur5e())
    })
    .await
    .unwrap();
    let kinematics = UrKinematics::ur5e();
    let q0 = robot.joints().await.unwrap();
    let start = robot.tcp_pose().await.unwrap();
    let up = Translation3::new(0.0, 0.0, 0.08) * start;
    let over = Translation3::new(0.1, 0.0, 0.08) * start;
    let down = Translation3::new(0.1, 0.0, 0.0) * start;
    let over_q = kinematics.inverse_nearest(&over, &q0).unwrap().joints;
    let line = LinearMotion {
        speed: 0.25,
        acceleration: 1.2,
    };
    let joint = JointMotion {
        speed: 1.0,
        acceleration: 1.0,
    };
    robot
        .move_path(vec![
            Waypoint::linear(up, line, 0.02),
            Waypoint::joints(over_q, joint, 0.02),
            Waypoint::linear(down, line, 0.0),
        ])
        .await
        .unwrap();
    let end = robot.tcp_pose().await.unwrap();
    assert!(
        (end.translation.vector - down.translation.vector).norm() < 1e-4,
        "ended at {end:?}"
    );
    assert!(!vur.controller.snapshot().arm.qd.iter().any(|v| *v != 0.0));
}
