//! `cell virtual-ur --scenario`: the controller serves a scenario's simulated cell on loopback,
//! so a UR client (here our `UrRobot`) drives the cell's arm from the cell's home.

use std::f64::consts::FRAC_PI_2;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

use cell::harness::SimSetup;
use cell::scenario::Scenario;
use robots::robot::{JointMotion, Robot};
use robots::ur_robot::{UrRobot, UrRobotConfig};

/// The port after `name ` in the banner line (`RTDE 127.0.0.1:PORT, ...`).
fn port_after(line: &str, name: &str) -> u16 {
    let rest = &line[line.find(name).unwrap() + name.len()..];
    let addr = rest.split([',', ' ']).find(|s| !s.is_empty()).unwrap();
    addr.rsplit(':').next().unwrap().parse().unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn serves_the_scenario_cell_from_its_home() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/usbc_nominal.toml");
    let scenario = Scenario::load(&path).unwrap();
    let limits = scenario.spec.cell.limits.clone();
    let setup = SimSetup::new(scenario).unwrap();
    let home = setup.cell(3).unwrap().lock().unwrap().joints_now();
    // Not the bare controller's default pose, so the check below tells the two apart.
    let upright = [0.0, -FRAC_PI_2, FRAC_PI_2, -FRAC_PI_2, -FRAC_PI_2, 0.0];
    assert!(home.iter().zip(&upright).any(|(a, b)| (a - b).abs() > 0.01));

    let mut child = Command::new(env!("CARGO_BIN_EXE_cell"))
        .arg("virtual-ur")
        .arg("--scenario")
        .arg(&path)
        .args([
            "--episode",
            "3",
            "--rtde-port",
            "0",
            "--dashboard-port",
            "0",
        ])
        .args(["--script-port", "0", "--duration-s", "60"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut banner = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut banner)
        .unwrap();
    assert!(
        banner.contains("the simulated cell of usbc-nominal, episode 3")
            && banner.contains("127.0.0.1:"),
        "{banner}"
    );
    let mut config = UrRobotConfig::new("127.0.0.1", setup.engine.knowledge.kinematics.clone());
    config.rtde_port = port_after(&banner, "RTDE ");
    config.dashboard_port = port_after(&banner, "dashboard ");
    config.script_port = port_after(&banner, "script ");
    config.limits = limits;
    config.command_timeout = Duration::from_secs(10);
    let mut robot = UrRobot::connect(config).await.unwrap();
    let q = robot.joints().await.unwrap();
    let diff = q
        .iter()
        .zip(&home)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(diff < 1e-6, "served {q:?}, the cell's home is {home:?}");
    // The cell's arm moves under its limits and reports where it went.
    let mut target = home;
    target[5] += 0.2;
    let slow = JointMotion {
        speed: 1.0,
        acceleration: 2.0,
    };
    robot.move_j(target, slow).await.unwrap();
    let q = robot.joints().await.unwrap();
    assert!((q[5] - target[5]).abs() < 1e-4, "{q:?}");
    drop(robot);
    child.kill().unwrap();
    child.wait().unwrap();
}

#[test]
fn initial_joints_and_a_scenario_do_not_mix() {
    let out = Command::new(env!("CARGO_BIN_EXE_cell"))
        .args([
            "virtual-ur",
            "--scenario",
            "x.toml",
            "--initial-q",
            "0,0,0,0,0,0",
        ])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--initial-q") && err.contains("--scenario"),
        "{err}"
    );
}
