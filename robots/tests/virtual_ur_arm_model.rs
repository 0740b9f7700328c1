//! The virtual controller and its arm model: every path that sets a digital output (our
//! program's gripper command, RTDE input registers, the script port) reaches
//! `ArmModel::digital_output` once per change; a gripper width output's set-point reaches
//! `ArmModel::analog_output`; our program waits the configured gripper actuation time (and
//! refuses a bad one, or a bad analog output); a `KinematicArm` with a TCP reports and moves that
//! TCP. Loopback only.

use nalgebra::{Isometry3, Translation3, Vector3};
use robots::kinematics::{Joints, UrKinematics};
use robots::program::layout as L;
use robots::robot::{JointMotion, LinearMotion, Robot, RobotError, SafetyStatus};
use robots::rtde::client::{ClientConfig, RtdeClient};
use robots::rtde::state::RuntimeState;
use robots::rtde::types::Value;
use robots::ur_robot::{
    GripperWidthOutput, MAX_GRIPPER_ACTUATION_S, UrConfigError, UrRobot, UrRobotConfig,
    upload_script,
};
use robots::virtual_ur::arm::{ArmCommand, ArmError, ArmModel, ArmState, KinematicArm};
use robots::virtual_ur::{VirtualUr, VirtualUrConfig};
use std::f64::consts::FRAC_PI_2;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

const Q0: Joints = [0.2, -1.4, 1.5, -1.7, -FRAC_PI_2, 0.3];
const GRIPPER_PIN: u32 = 16;
/// The recording arm's gripper stroke (the device's time, which the program cannot know).
const STROKE_S: f64 = 0.3;
/// Controller time a command takes beyond its wait: RTDE in and out, a few 2 ms cycles.
const LATENCY_S: f64 = 0.15;

type Log = Arc<Mutex<Vec<(u32, bool)>>>;
/// Analog output changes: (output, ratio of its range).
type AnalogLog = Arc<Mutex<Vec<(u32, f64)>>>;

/// A kinematic arm that records output changes and has a gripper on tool output 0.
struct Recording {
    arm: KinematicArm,
    log: Log,
    analog: AnalogLog,
    /// Refuse the next motion as a collision.
    collide: Arc<AtomicBool>,
}

impl ArmModel for Recording {
    fn command(&mut self, cmd: ArmCommand) -> Result<(), ArmError> {
        let motion = matches!(cmd, ArmCommand::MoveJ { .. } | ArmCommand::MoveL { .. });
        if motion && self.collide.swap(false, Ordering::Relaxed) {
            return Err(ArmError::ProtectiveStop("the path meets the table".into()));
        }
        self.arm.command(cmd)
    }
    fn step(&mut self, dt: f64, speed_fraction: f64) -> Result<(), ArmError> {
        self.arm.step(dt, speed_fraction)
    }
    fn state(&self) -> ArmState {
        self.arm.state()
    }
    fn is_moving(&self) -> bool {
        self.arm.is_moving()
    }
    fn forward(&self, q: &Joints) -> [f64; 6] {
        self.arm.forward(q)
    }
    fn inverse(&self, pose: &[f64; 6], near: &Joints) -> Result<Joints, ArmError> {
        self.arm.inverse(pose, near)
    }
    fn kinematics(&self) -> &UrKinematics {
        self.arm.kinematics()
    }
    fn digital_output(&mut self, pin: u32, level: bool) {
        self.log.lock().unwrap().push((pin, level));
    }
    fn analog_output(&mut self, index: u32, ratio: f64) {
        self.analog.lock().unwrap().push((index, ratio));
    }
    fn actuation_time(&self, pin: u32) -> f64 {
        if pin == GRIPPER_PIN { STROKE_S } else { 0.0 }
    }
}

fn tcp() -> Isometry3<f64> {
    Isometry3::translation(0.0, 0.0, 0.15)
}

async fn start() -> (VirtualUr, Log) {
    let (vur, log, _, _) = start_recording().await;
    (vur, log)
}

async fn start_colliding() -> (VirtualUr, Log, Arc<AtomicBool>) {
    let (vur, log, _, collide) = start_recording().await;
    (vur, log, collide)
}

async fn start_recording() -> (VirtualUr, Log, AnalogLog, Arc<AtomicBool>) {
    let log = Log::default();
    let analog = AnalogLog::default();
    let collide = Arc::new(AtomicBool::new(false));
    let arm = Recording {
        arm: KinematicArm::new(UrKinematics::ur5e().with_tcp(tcp()), Q0),
        log: log.clone(),
        analog: analog.clone(),
        collide: collide.clone(),
    };
    let config = VirtualUrConfig {
        initial_q: Q0,
        ..VirtualUrConfig::ephemeral()
    };
    let vur = VirtualUr::start_with_arm(config, Box::new(arm))
        .await
        .unwrap();
    (vur, log, analog, collide)
}

fn robot_config(vur: &VirtualUr) -> UrRobotConfig {
    UrRobotConfig {
        rtde_port: vur.rtde_addr().port(),
        dashboard_port: vur.dashboard_addr().port(),
        script_port: vur.script_addr().port(),
        command_timeout: Duration::from_secs(10),
        kinematics: UrKinematics::ur5e().with_tcp(tcp()),
        ..UrRobotConfig::new("127.0.0.1", UrKinematics::ur5e())
    }
}

fn taken(log: &Log) -> Vec<(u32, bool)> {
    std::mem::take(&mut *log.lock().unwrap())
}

async fn wait_for(what: &str, cond: impl Fn() -> bool) {
    let deadline = Instant::now() + Duration::from_secs(2);
    while !cond() {
        assert!(
            Instant::now() < deadline,
            "{what} did not happen within 2 s"
        );
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
}

/// Controller seconds one gripper command takes.
async fn timed_gripper(vur: &VirtualUr, robot: &mut impl Robot, close: bool) -> f64 {
    let t0 = vur.controller.snapshot().timestamp;
    if close {
        robot.close_gripper().await.unwrap();
    } else {
        robot.open_gripper().await.unwrap();
    }
    vur.controller.snapshot().timestamp - t0
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_gripper_command_reaches_the_arm_model_and_waits_the_actuation_time() {
    let (vur, log) = start().await;
    // A wait longer than the device's stroke, so that only the program's sleep explains it.
    let wait = 0.45;
    let mut robot = UrRobot::connect(UrRobotConfig {
        gripper_actuation_s: wait,
        ..robot_config(&vur)
    })
    .await
    .unwrap();

    let took = timed_gripper(&vur, &mut robot, true).await;
    assert_eq!(taken(&log), [(GRIPPER_PIN, true)]);
    // The program reported done only after its sleep (controller time, 2 ms cycles).
    assert!(
        (wait - 1e-9..wait + LATENCY_S).contains(&took),
        "done after {took} s"
    );
    assert_eq!(vur.controller.snapshot().io.tool_do, 1);

    // Closing a closed gripper changes nothing: no call, though the program still waits.
    let took = timed_gripper(&vur, &mut robot, true).await;
    assert_eq!(taken(&log), []);
    assert!(took >= wait - 1e-9, "done after {took} s");

    let took = timed_gripper(&vur, &mut robot, false).await;
    assert_eq!(taken(&log), [(GRIPPER_PIN, false)]);
    assert!(took >= wait - 1e-9, "done after {took} s");
    assert_eq!(vur.controller.snapshot().io.tool_do, 0);

    // The default configuration waits its 0.25 s.
    drop(robot);
    inputs_released(&vur).await;
    let config = robot_config(&vur);
    assert_eq!(config.gripper_actuation_s, 0.25);
    let mut robot = UrRobot::connect(config).await.unwrap();
    let took = timed_gripper(&vur, &mut robot, true).await;
    assert!(
        (0.25 - 1e-9..0.25 + LATENCY_S).contains(&took),
        "done after {took} s"
    );
    assert_eq!(taken(&log), [(GRIPPER_PIN, true)]);

    // No wait: done at once, well before the device's stroke (the program cannot know it).
    drop(robot);
    inputs_released(&vur).await;
    let mut robot = UrRobot::connect(UrRobotConfig {
        gripper_actuation_s: 0.0,
        ..robot_config(&vur)
    })
    .await
    .unwrap();
    let took = timed_gripper(&vur, &mut robot, false).await;
    assert!(took < LATENCY_S.min(STROKE_S), "done after {took} s");
    assert_eq!(taken(&log), [(GRIPPER_PIN, false)]);

    // A standard output reaches the model too.
    let mut config = robot_config(&vur);
    config.gripper = robots::ur_robot::GripperOutput::Standard(5);
    drop(robot);
    inputs_released(&vur).await;
    let mut robot = UrRobot::connect(config).await.unwrap();
    let took = timed_gripper(&vur, &mut robot, true).await;
    assert!(took >= 0.25 - 1e-9, "done after {took} s");
    assert_eq!(taken(&log), [(5, true)]);
    let snap = vur.controller.snapshot();
    assert_eq!(snap.io.standard_do, 1 << 5);
    assert_eq!(snap.regs.output_int[L::ERROR_REG], L::ERROR_NONE);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_gripper_width_output_sets_where_the_fingers_open_to() {
    let (vur, log, analog, _) = start_recording().await;
    let wait = 0.2;
    let mut robot = UrRobot::connect(UrRobotConfig {
        gripper_actuation_s: wait,
        gripper_width: Some(GripperWidthOutput {
            output: 1,
            stroke: 0.014,
        }),
        ..robot_config(&vur)
    })
    .await
    .unwrap();
    let timed_open = async |robot: &mut _, width: f64| {
        let t0 = vur.controller.snapshot().timestamp;
        Robot::open_gripper_to(robot, width).await.unwrap();
        vur.controller.snapshot().timestamp - t0
    };

    robot.close_gripper().await.unwrap();
    assert_eq!(taken(&log), [(GRIPPER_PIN, true)]);
    // The set-point first (its old value unknown: the full stroke's wait), then the output.
    let took = timed_open(&mut robot, 0.007).await;
    assert_eq!(std::mem::take(&mut *analog.lock().unwrap()), [(1, 0.5)]);
    assert_eq!(taken(&log), [(GRIPPER_PIN, false)]);
    assert!(
        (2.0 * wait - 1e-9..2.0 * wait + 2.0 * LATENCY_S).contains(&took),
        "done after {took} s"
    );
    // 4–20 mA by default: half the range is 12 mA.
    assert!((vur.controller.snapshot().io.analog_out[1] - 0.012).abs() < 1e-12);
    // Open fingers move to a new set-point; the wait is the travel's share of the stroke.
    let took = timed_open(&mut robot, 0.0105).await;
    assert_eq!(std::mem::take(&mut *analog.lock().unwrap()), [(1, 0.75)]);
    assert_eq!(taken(&log), []);
    assert!(
        (1.25 * wait - 1e-9..1.25 * wait + 2.0 * LATENCY_S).contains(&took),
        "done after {took} s"
    );
    // Wider than the stroke is the stroke; `open_gripper` opens the full stroke.
    timed_open(&mut robot, 0.02).await;
    assert_eq!(std::mem::take(&mut *analog.lock().unwrap()), [(1, 1.0)]);
    robot.open_gripper_to(0.0).await.unwrap();
    robot.open_gripper().await.unwrap();
    assert_eq!(
        std::mem::take(&mut *analog.lock().unwrap()),
        [(1, 0.0), (1, 1.0)]
    );
    // Not a width: refused before anything is sent.
    let err = robot.open_gripper_to(f64::NAN).await.unwrap_err();
    assert!(matches!(err, RobotError::Rejected { .. }), "{err:?}");
    assert_eq!(std::mem::take(&mut *analog.lock().unwrap()), []);
    assert_eq!(taken(&log), []);
}

#[test]
fn the_gripper_width_output_is_validated() {
    let mut config = UrRobotConfig::new("127.0.0.1", UrKinematics::ur5e());
    for (output, stroke, ok) in [
        (0, 0.014, true),
        (1, 0.085, true),
        (2, 0.014, false),
        (0, 0.0, false),
        (0, f64::NAN, false),
    ] {
        config.gripper_width = Some(GripperWidthOutput { output, stroke });
        assert_eq!(
            config.validate().is_ok(),
            ok,
            "output {output}, stroke {stroke}"
        );
    }
}

#[test]
fn the_gripper_actuation_time_is_validated() {
    let mut config = UrRobotConfig::new("127.0.0.1", UrKinematics::ur5e());
    assert_eq!(config.validate(), Ok(()));
    for good in [0.0, 0.25, MAX_GRIPPER_ACTUATION_S] {
        config.gripper_actuation_s = good;
        assert_eq!(config.validate(), Ok(()), "{good}");
    }
    for bad in [
        f64::NAN,
        f64::INFINITY,
        -0.01,
        MAX_GRIPPER_ACTUATION_S + 0.01,
    ] {
        config.gripper_actuation_s = bad;
        assert!(
            matches!(config.validate(), Err(UrConfigError::GripperActuation(v)) if v.to_bits() == bad.to_bits()),
            "{bad} accepted"
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_output_commands_are_refused_by_connect_and_by_the_program() {
    let (vur, log) = start().await;
    // The client refuses it before uploading anything.
    let err = UrRobot::connect(UrRobotConfig {
        gripper_actuation_s: -0.5,
        ..robot_config(&vur)
    })
    .await
    .err()
    .expect("connect accepted a negative actuation time");
    assert!(matches!(err, RobotError::Rejected { .. }), "{err:?}");
    assert_eq!(
        vur.controller.snapshot().runtime_state,
        RuntimeState::Stopped
    );

    // The program refuses a wait out of range (as the script does) and leaves the output.
    let command: Vec<String> = L::command_recipe();
    let command: Vec<&str> = command.iter().map(String::as_str).collect();
    let heartbeat: Vec<String> = L::heartbeat_recipe();
    let heartbeat: Vec<&str> = heartbeat.iter().map(String::as_str).collect();
    let mut config = ClientConfig::new(vur.rtde_addr().to_string(), &["timestamp"])
        .with_input_recipe(&command)
        .with_input_recipe(&heartbeat);
    config.outputs.extend(L::output_registers());
    let client = RtdeClient::connect(config).await.unwrap();
    upload_script(
        &vur.script_addr().to_string(),
        robots::program::CELL_SCRIPT,
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
    for (id, wait) in [(1, f64::NAN), (2, -0.1), (3, L::MAX_DO_WAIT_S + 0.5)] {
        client.send_inputs(1, &[Value::Int32(id)]).await.unwrap();
        let mut values = vec![
            Value::Int32(L::KIND_SET_TOOL_DO),
            Value::Int32(0),
            Value::Int32(1),
        ];
        values.extend([Value::Double(0.0); 8]);
        values.extend([Value::Double(wait), Value::Int32(id)]);
        client.send_inputs(0, &values).await.unwrap();
        wait_for("the command to finish", || {
            register(L::DONE_ID_REG) == Some(i64::from(id))
        })
        .await;
        assert_eq!(register(L::STATUS_REG), Some(i64::from(L::STATUS_FAILED)));
        assert_eq!(
            register(L::ERROR_REG),
            Some(i64::from(L::ERROR_INVALID_WAIT)),
            "wait {wait}"
        );
    }
    assert_eq!(taken(&log), []);
    assert_eq!(vur.controller.snapshot().io.tool_do, 0);

    // An analog output that does not exist, or a ratio outside 0–1, is refused; the outputs
    // keep their values.
    for (id, pin, ratio) in [(4, 2, 0.5), (5, -1, 0.5), (6, 0, 1.5), (7, 1, f64::NAN)] {
        client.send_inputs(1, &[Value::Int32(id)]).await.unwrap();
        let mut values = vec![
            Value::Int32(L::KIND_SET_STANDARD_AO),
            Value::Int32(pin),
            Value::Int32(0),
            Value::Double(ratio),
        ];
        values.extend([Value::Double(0.0); 7]);
        values.extend([Value::Double(0.0), Value::Int32(id)]);
        client.send_inputs(0, &values).await.unwrap();
        wait_for("the command to finish", || {
            register(L::DONE_ID_REG) == Some(i64::from(id))
        })
        .await;
        assert_eq!(
            register(L::ERROR_REG),
            Some(i64::from(L::ERROR_INVALID_OUTPUT)),
            "output {pin}, ratio {ratio}"
        );
    }
    assert_eq!(vur.controller.snapshot().io.analog_out, [0.004; 2]);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rtde_output_registers_reach_the_arm_model_once_per_change() {
    let (vur, log) = start().await;
    let mut config = ClientConfig::new(vur.rtde_addr().to_string(), &["timestamp"]);
    config.inputs = vec![
        [
            "standard_digital_output_mask",
            "standard_digital_output",
            "configurable_digital_output_mask",
            "configurable_digital_output",
            "tool_digital_output_mask",
            "tool_digital_output",
        ]
        .iter()
        .map(|s| (*s).to_owned())
        .collect(),
    ];
    let client = RtdeClient::connect(config).await.unwrap();
    let send =
        |sm: u8, s: u8, cm: u8, c: u8, tm: u8, t: u8| [sm, s, cm, c, tm, t].map(Value::Uint8);
    // Standard 1 and 3, configurable 2 (pin 10), tool 1 (pin 17) high; masked bits ignored.
    client
        .send_inputs(0, &send(0b1010, 0b1111, 0b100, 0b110, 0b10, 0b11))
        .await
        .unwrap();
    wait_for("the first write", || log.lock().unwrap().len() == 4).await;
    assert_eq!(taken(&log), [(1, true), (3, true), (10, true), (17, true)]);
    // Rewriting the same levels calls nothing; lowering standard 3 calls once.
    client
        .send_inputs(0, &send(0b1010, 0b0010, 0b100, 0b100, 0b10, 0b10))
        .await
        .unwrap();
    wait_for("the second write", || !log.lock().unwrap().is_empty()).await;
    tokio::time::sleep(Duration::from_millis(50)).await;
    assert_eq!(taken(&log), [(3, false)]);
    assert_eq!(
        vur.controller.snapshot().io.digital_output_bits(),
        (1 << 1) | (1 << 10) | (1 << 17)
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn script_port_output_statements_reach_the_arm_model() {
    let (vur, log) = start().await;
    let robot = UrRobot::connect(robot_config(&vur)).await.unwrap();
    let address = vur.script_addr().to_string();
    let timeout = Duration::from_secs(2);

    // A secondary program sets outputs beside the running program.
    upload_script(
        &address,
        "sec outputs():\n  set_standard_digital_out(2, True)\n  set_tool_digital_out(0, True)\nend\n",
        timeout,
    )
    .await
    .unwrap();
    wait_for("the secondary program", || log.lock().unwrap().len() == 2).await;
    assert_eq!(taken(&log), [(2, true), (16, true)]);
    assert_eq!(
        vur.controller.snapshot().runtime_state,
        RuntimeState::Playing
    );

    // Something else than output statements is not executed.
    upload_script(
        &address,
        "set_tool_digital_out(0, False)\nmovej(q)\n",
        timeout,
    )
    .await
    .unwrap();
    tokio::time::sleep(Duration::from_millis(150)).await;
    assert_eq!(taken(&log), []);
    assert_eq!(vur.controller.snapshot().io.tool_do, 1);

    // Bare statements run as a primary program: the running program stops, as on a UR.
    upload_script(&address, "set_configurable_digital_out(7, True)\n", timeout)
        .await
        .unwrap();
    wait_for("the bare statement", || !log.lock().unwrap().is_empty()).await;
    assert_eq!(taken(&log), [(15, true)]);
    // (The snapshot is published on the next control cycle.)
    wait_for("the program to stop", || {
        vur.controller.snapshot().runtime_state == RuntimeState::Stopped
    })
    .await;
    drop(robot);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_kinematic_arm_with_a_tcp_reports_and_moves_the_tcp() {
    let kin = UrKinematics::ur5e().with_tcp(tcp());
    let arm = KinematicArm::new(kin.clone(), Q0);
    let flange = UrKinematics::ur5e().forward_tcp(&Q0);
    let expected = kin.forward_tcp(&Q0);
    let state = arm.state();
    let reported = robots::kinematics::from_ur_pose(&state.tcp_pose);
    assert!((reported.translation.vector - expected.translation.vector).norm() < 1e-12);
    // The TCP is 0.15 m from the flange along the flange z axis.
    let offset = reported.translation.vector - flange.translation.vector;
    assert!((offset - flange.rotation * Vector3::new(0.0, 0.0, 0.15)).norm() < 1e-12);

    // Over RTDE: a movel target is the TCP's, and actual_TCP_pose reports it.
    let (vur, _log) = start().await;
    let mut robot = UrRobot::connect(robot_config(&vur)).await.unwrap();
    let start_pose = robot.tcp_pose().await.unwrap();
    assert!((start_pose.translation.vector - expected.translation.vector).norm() < 1e-9);
    let target = Translation3::new(0.02, -0.03, -0.04) * start_pose;
    robot
        .move_l(
            target,
            LinearMotion {
                speed: 0.25,
                acceleration: 1.2,
            },
        )
        .await
        .unwrap();
    let reached = robot.tcp_pose().await.unwrap();
    assert!((reached.translation.vector - target.translation.vector).norm() < 1e-6);
    assert!(reached.rotation.angle_to(&target.rotation) < 1e-6);
    let q = robot.joints().await.unwrap();
    assert!((kin.forward_tcp(&q).translation.vector - target.translation.vector).norm() < 1e-6);

    // A joint move ends on exactly the commanded joints.
    let q1 = [0.1, -1.3, 1.4, -1.6, -FRAC_PI_2, 0.2];
    robot
        .move_j(
            q1,
            JointMotion {
                speed: 2.0,
                acceleration: 4.0,
            },
        )
        .await
        .unwrap();
    assert_eq!(robot.joints().await.unwrap(), q1);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_collision_reported_by_the_arm_model_is_a_protective_stop() {
    let (vur, _log, collide) = start_colliding().await;
    let mut robot = UrRobot::connect(robot_config(&vur)).await.unwrap();
    let motion = JointMotion {
        speed: 2.0,
        acceleration: 4.0,
    };
    collide.store(true, Ordering::Relaxed);
    let q1 = [0.1, -1.3, 1.4, -1.6, -FRAC_PI_2, 0.2];
    let err = robot.move_j(q1, motion).await.unwrap_err();
    assert!(matches!(err, RobotError::ProtectiveStop), "{err:?}");
    assert_eq!(
        vur.controller.snapshot().safety_mode,
        SafetyStatus::ProtectiveStop
    );
    assert_eq!(robot.joints().await.unwrap(), Q0, "the arm did not move");
    // Motion stays blocked until the stop is unlocked (after the controller's delay).
    let again = robot.move_j(q1, motion).await.unwrap_err();
    assert!(matches!(again, RobotError::ProtectiveStop), "{again:?}");
}

/// Waits until the controller has noticed that the dropped client is gone and freed its input
/// registers, as a reconnecting client must (else its recipe is refused with IN_USE).
async fn inputs_released(vur: &VirtualUr) {
    wait_for("the dropped client's inputs to be freed", || {
        vur.controller.claimed_inputs() == 0
    })
    .await;
}
