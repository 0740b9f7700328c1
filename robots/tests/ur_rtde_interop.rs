//! Interop with an independent RTDE peer: SDU ur_rtde 1.6.5 (PyPI `ur-rtde`) drives the virtual
//! controller through its receive, control (moveJ, moveL, stopL, servoJ, speedJ, stopScript)
//! and IO interfaces. ur_rtde 1.6.5 cannot be given
//! ports, so this runs on the default ports 30004/29999/30003 of 127.0.0.1: it is the only test
//! in this binary, so nothing else binds them concurrently from this crate.

use nalgebra::Isometry3;
use robots::kinematics::{UrKinematics, from_ur_pose, to_ur_pose};
use robots::rtde::state::RuntimeState;
use robots::virtual_ur::dynamics::ArmDynamics;
use robots::virtual_ur::registers::Payload;
use robots::virtual_ur::{VirtualUr, VirtualUrConfig};
use serde_json::Value as Json;
use std::path::PathBuf;
use std::time::Duration;

fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn provision_python() -> PathBuf {
    let out = std::process::Command::new("bash")
        .arg(repo_root().join("scripts/ur_rtde/venv.sh"))
        .output()
        .expect("run scripts/ur_rtde/venv.sh");
    assert!(
        out.status.success(),
        "provisioning the ur_rtde venv failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    PathBuf::from(String::from_utf8_lossy(&out.stdout).trim())
}

fn f64s(v: &Json) -> Vec<f64> {
    v.as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect()
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

/// ur_rtde 1.6.5 always uses the default ports: one test at a time holds them.
static DEFAULT_PORTS: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

/// Runs a script from `scripts/ur_rtde` against 127.0.0.1; its JSON lines on stdout.
async fn run_script(name: &str, limit: Duration) -> (std::process::Output, Vec<Json>) {
    let python = provision_python();
    let mut child = tokio::process::Command::new(&python)
        .arg(repo_root().join("scripts/ur_rtde").join(name))
        .arg("127.0.0.1")
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .kill_on_drop(true)
        .spawn()
        .expect("run python");
    let (mut so, mut se) = (child.stdout.take().unwrap(), child.stderr.take().unwrap());
    let read = tokio::spawn(async move {
        use tokio::io::AsyncReadExt;
        let (mut a, mut b) = (Vec::new(), Vec::new());
        let _ = tokio::join!(so.read_to_end(&mut a), se.read_to_end(&mut b));
        (a, b)
    });
    let status = match tokio::time::timeout(limit, child.wait()).await {
        Ok(status) => status.expect("wait for python"),
        Err(_) => {
            child.kill().await.expect("kill python");
            let (a, _) = read.await.expect("read output");
            panic!(
                "{name} did not finish within {limit:?}; its output:\n{}",
                String::from_utf8_lossy(&a)
            );
        }
    };
    let (stdout, stderr) = read.await.expect("read output");
    let out = std::process::Output {
        status,
        stdout,
        stderr,
    };
    let lines = String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter(|l| l.starts_with('{'))
        .map(|l| serde_json::from_str(l).expect("json line"))
        .collect();
    (out, lines)
}

/// The conformance suite (`scripts/ur_rtde/conformance.py`): every public method of ur_rtde
/// 1.6.5's control, receive and IO interfaces either has its effect on the arm or the I/O, or
/// is a listed unsupported method that fails loudly (never True without the effect).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ur_rtde_conformance_suite_passes_with_no_silent_success() {
    let _ports = DEFAULT_PORTS.lock().await;
    let vur = VirtualUr::start(VirtualUrConfig {
        unlock_delay: Duration::from_millis(300),
        ..VirtualUrConfig::default()
    })
    .await
    .expect("bind 127.0.0.1:30004/29999/30003");
    let (out, lines) = run_script("conformance.py", Duration::from_secs(150)).await;
    let report = || {
        format!(
            "stdout:\n{}\nstderr (tail):\n{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
                .lines()
                .rev()
                .take(30)
                .collect::<Vec<_>>()
                .join("\n")
        )
    };
    let failed: Vec<&Json> = lines.iter().filter(|l| l["ok"] == false).collect();
    assert!(
        failed.is_empty(),
        "failed cases: {failed:#?}\n{}\ncontroller messages:\n{}",
        report(),
        vur.controller.messages().join("\n")
    );
    let summary = lines
        .iter()
        .find(|l| l["summary"] == true)
        .unwrap_or_else(|| panic!("no summary\n{}", report()));
    for l in &lines {
        println!("{l}");
    }
    assert_eq!(
        summary["untested"],
        serde_json::json!([]),
        "methods neither tested nor listed as unsupported"
    );
    assert!(summary["cases"].as_u64().unwrap_or(0) >= 57, "{summary}");
    assert!(out.status.success(), "{}", report());
    // getForwardKinematics(q) is our own forward kinematics at q with the active TCP (the
    // flange), and with a given 10 cm TCP.
    let detail = |name: &str| {
        lines
            .iter()
            .find(|l| l["case"].as_str().is_some_and(|c| c.starts_with(name)))
            .unwrap_or_else(|| panic!("no case {name}"))["detail"]
            .clone()
    };
    let kin = UrKinematics::ur5e();
    let joints = |v: &Json| -> [f64; 6] { f64s(v).try_into().expect("six joints") };
    let fk = detail("getForwardKinematics");
    let q = joints(&fk["q"]);
    let want = kin.forward_tcp(&q);
    let got = from_ur_pose(&joints(&fk["fk"]));
    assert!(
        (got.translation.vector - want.translation.vector).norm() < 1e-9
            && got.rotation.angle_to(&want.rotation) < 1e-9,
        "getForwardKinematics({q:?}) = {:?}, robots::kinematics says {:?}",
        fk["fk"],
        to_ur_pose(&want)
    );
    let tool = Isometry3::translation(0.0, 0.0, 0.1);
    let want = kin.forward_flange(&q) * tool;
    let got = from_ur_pose(&joints(&fk["fk_tcp_10cm"]));
    assert!((got.translation.vector - want.translation.vector).norm() < 1e-9);
    // The joint currents and moments are the URDF's gravity torques (checked against the URDF
    // in virtual_ur_dynamics.rs) through the modelled torque constants.
    let dynamics = ArmDynamics::ur5e();
    let currents = detail("joint currents and moments");
    for pose in ["q1", "home"] {
        let q = joints(&currents[pose]["q"]);
        let torques = dynamics.gravity_torques(&kin.dh, &q, &Payload::default());
        let moment = f64s(&currents[pose]["moment"]);
        let current = f64s(&currents[pose]["current"]);
        for j in 0..6 {
            assert!(
                (moment[j] - torques[j]).abs() < 1e-9,
                "{pose}: {moment:?} vs {torques:?}"
            );
            assert!(
                (current[j] * dynamics.torque_constants[j] - torques[j]).abs() < 1e-9,
                "{pose}: {current:?} A for {torques:?} N m"
            );
        }
    }
    // PolyScope 5.23's dynamics functions are the URDF's rigid-body model (checked against
    // brute-force kinetic energy and finite differences in robots::virtual_ur::dynamics).
    let mass = detail("getMassMatrix");
    let q = joints(&mass["q"]);
    let want = dynamics.mass_matrix(&kin.dh, &q, &Payload::default());
    let rows: Vec<Vec<f64>> = mass["mass_matrix"]
        .as_array()
        .expect("rows")
        .iter()
        .map(f64s)
        .collect();
    for (i, row) in rows.iter().enumerate() {
        for (j, v) in row.iter().enumerate() {
            assert!(
                (v - want[(i, j)]).abs() < 1e-9,
                "M({q:?}) = {rows:?}, model {want}"
            );
        }
    }
    let moving = detail("getJacobianTimeDerivative");
    let (q, qd) = (joints(&moving["q"]), joints(&moving["qd"]));
    let got = f64s(&moving["coriolis"]);
    // Joint 1 alone turns: the torques do not depend on where it has turned to.
    let want = dynamics.coriolis_and_centrifugal(&kin.dh, &q, &qd, &Payload::default());
    for j in 0..6 {
        assert!(
            (got[j] - want[j]).abs() < 1e-9,
            "C(q, q̇) q̇ at {q:?}, {qd:?}: {got:?} vs {want:?}"
        );
    }
    // setGravity: the holding torques are the rigid-body model's under the set gravity.
    let gravity = detail("setGravity");
    let (q, up) = (joints(&gravity["q"]), f64s(&gravity["up"]));
    let payload = Payload {
        mass: 2.0,
        cog: [0.0, 0.0, 0.05],
        ..Payload::default()
    };
    let want = dynamics.holding_torques(&kin.dh, &q, &payload, &[up[0], up[1], up[2]]);
    let got = f64s(&gravity["moment"]);
    for j in 0..6 {
        assert!(
            (got[j] - want[j]).abs() < 1e-9,
            "set_gravity({up:?}): {got:?} vs {want:?}"
        );
    }
    // Force mode held the commanded 10 N against the table within the sensor's precision, and
    // moveUntilContact stopped within 1 mm of it.
    let force = detail("forceMode pushes down");
    let fz = f64s(&force["force"])[2];
    assert!(
        (fz - 10.0).abs() < robots::virtual_ur::force::UR5E_FORCE_PRECISION,
        "{force}"
    );
    let z = detail("moveUntilContact")["z"].as_f64().expect("z");
    assert!(
        (0.0..1e-3).contains(&z),
        "moveUntilContact stopped at {z} m"
    );
    // setInputIntRegister / setInputDoubleRegister reached the controller's registers.
    let regs = vur.controller.snapshot().regs.clone();
    assert_eq!(regs.input_int[18], 4242);
    assert_eq!(regs.input_double[19], 3.25);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ur_rtde_receive_control_and_io_interfaces_drive_the_virtual_controller() {
    let _ports = DEFAULT_PORTS.lock().await;
    let python = provision_python();
    let vur = VirtualUr::start(VirtualUrConfig::default())
        .await
        .expect("bind 127.0.0.1:30004/29999/30003");
    let script = repo_root().join("scripts/ur_rtde/interop.py");
    let child = tokio::process::Command::new(&python)
        .arg(&script)
        .arg("127.0.0.1")
        .kill_on_drop(true)
        .output();
    let out = tokio::time::timeout(Duration::from_secs(60), child)
        .await
        .expect("ur_rtde script finished within 60 s")
        .expect("run python");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "ur_rtde script failed\nstdout:\n{stdout}\nstderr:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let steps: Vec<Json> = stdout
        .lines()
        .filter(|l| l.starts_with('{'))
        .map(|l| serde_json::from_str(l).expect("json line"))
        .collect();
    let step = |name: &str| {
        steps
            .iter()
            .find(|s| s["step"] == name)
            .unwrap_or_else(|| panic!("no step {name} in\n{stdout}"))
            .clone()
    };
    let kin = UrKinematics::ur5e();

    // Receive: all default variables decoded with the right types and values.
    let r = step("receive");
    assert_eq!(r["connected"], true);
    let home = VirtualUrConfig::default().initial_q;
    assert!(max_abs_diff(&f64s(&r["q"]), &home) < 1e-9);
    let home_pose = to_ur_pose(&kin.forward_tcp(&home));
    assert!(max_abs_diff(&f64s(&r["tcp"]), &home_pose) < 1e-9);
    assert_eq!(r["robot_mode"], 7);
    assert_eq!(r["safety_mode"], 1);
    assert!((r["speed_scaling"].as_f64().unwrap() - 1.0).abs() < 1e-12);
    let elapsed = step("stream")["elapsed"].as_f64().unwrap();
    // Controller time tracks wall time (a loaded host may oversleep the 0.2 s in Python).
    assert!(
        (0.18..0.6).contains(&elapsed),
        "timestamp advanced {elapsed} s in 0.2 s"
    );

    // Control: the script was recognised and runs; moveJ and moveL reach their targets.
    let c = step("control_connected");
    assert_eq!(c["connected"], true);
    assert_eq!(c["running"], true);
    let mj = step("moveJ");
    assert_eq!(mj["ok"], true);
    assert!(
        max_abs_diff(&f64s(&mj["q"]), &f64s(&mj["target"])) < 1e-6,
        "moveJ ended at {:?}, target {:?}",
        mj["q"],
        mj["target"]
    );
    let ml = step("moveL");
    assert_eq!(ml["ok"], true);
    let (tcp, target) = (f64s(&ml["tcp"]), f64s(&ml["target"]));
    assert!(
        max_abs_diff(&tcp[..3], &target[..3]) < 1e-6,
        "moveL ended at {tcp:?}, target {target:?}"
    );

    // stopL interrupts an asynchronous moveL: the arm stops short of the far target and rests.
    let s = step("stopL");
    let (before, after, later, far) = (
        f64s(&s["before"]),
        f64s(&s["after"]),
        f64s(&s["later"]),
        f64s(&s["far"]),
    );
    assert!(before[2] < target[2] - 0.01, "async moveL was moving down");
    assert!(
        later[2] > far[2] + 0.05,
        "stopped well before the far target: z {} vs {}",
        later[2],
        far[2]
    );
    assert!(max_abs_diff(&after, &later) < 1e-9, "at rest after stopL");

    // servoJ tracks the streamed targets; speedJ moves joint 1 at the commanded speed.
    let sj = step("servoJ");
    let (q, last, start) = (f64s(&sj["q"]), f64s(&sj["last_target"]), f64s(&sj["start"]));
    // servoStop is `stopl(a)` in ur_rtde's script: the TCP twist decelerates at 4 m/s² (and
    // 4 rad/s² for its spin about the base z axis) from the tracking speed, so the arm ends at
    // or shortly past the last target. That stop stays horizontal and only turns the tool about
    // base z: joints 2-5 move by the small change of reach, and joint 6 takes the rest of the
    // spin, which grows with the square of the tracking speed at the moment of the stop.
    assert!(
        q[0] > last[0] - 1e-3 && q[0] < last[0] + 0.05,
        "servoJ ended at {} for last target {}",
        q[0],
        last[0]
    );
    assert!(
        max_abs_diff(&q[1..5], &start[1..5]) < 2e-3,
        "only joint 1 moved (beyond the tool-space stop): {q:?} from {start:?}"
    );
    let joints = |v: &[f64]| -> [f64; 6] { v.try_into().expect("six joints") };
    let (tool_start, tool_end) = (
        kin.forward_tcp(&joints(&start)),
        kin.forward_tcp(&joints(&q)),
    );
    let dz = tool_end.translation.z - tool_start.translation.z;
    assert!(dz.abs() < 1e-4, "the TCP stayed level: moved {dz} m in z");
    let turn = (tool_end.rotation * tool_start.rotation.inverse()).scaled_axis();
    assert!(
        turn.x.abs() < 1e-4 && turn.y.abs() < 1e-4,
        "the tool turned only about base z: {turn:?}"
    );
    assert!(q[0] - start[0] > 0.09, "servoJ moved joint 1 by 0.1 rad");
    let sp = step("speedJ");
    let moved = f64s(&sp["after"])[0] - f64s(&sp["before"])[0];
    // 0.2 rad/s for 0.5 s after a 0.2 s ramp at 1 rad/s²: about 0.08 rad.
    assert!(
        (0.05..0.13).contains(&moved),
        "speedJ moved joint 1 by {moved} rad"
    );
    assert!(
        f64s(&sp["qd"]).iter().all(|v| v.abs() < 1e-9),
        "at rest after speedStop"
    );

    // stopScript ends the program.
    assert_eq!(
        step("stopScript")["runtime_state"].as_i64(),
        Some(i64::from(RuntimeState::Stopped.to_u32()))
    );

    // IO: standard digital out 7, tool out 0 and the speed slider.
    let io = step("io");
    assert_eq!(io["ok"], serde_json::json!([true, true, true]));
    assert_eq!(io["do7"], true);
    assert_eq!(io["do6"], false);
    assert_eq!(io["tool0"], true);
    assert!((io["speed_fraction"].as_f64().unwrap() - 0.5).abs() < 1e-12);

    // And the controller's own view agrees.
    let snap = vur.controller.snapshot();
    assert_eq!(snap.io.standard_do, 1 << 7);
    assert_eq!(snap.io.tool_do, 1);
    assert!((snap.io.speed_slider - 0.5).abs() < 1e-12);
}
