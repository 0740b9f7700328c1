//! Force-guided insertion on the production path: the simulated cell behind the virtual UR
//! controller on 127.0.0.1, driven through `UrRobot` over RTDE and our URScript program's
//! guarded move, with the same strategy (`cell::orchestrator::insertion`) as in process.

mod e2e_support;

use std::time::Duration;

use cell::episode::StepOutcome;
use cell::harness::{SimCellIo, connect_sim_over_rtde, keypoint_noise_for};
use cell::orchestrator::{SplitCell, force_sensor_preflight, insertion, run_episode};
use robots::rtde::ControllerVersion;
use robots::ur_robot::{UrRobot, UrRobotConfig};
use robots::virtual_ur::{VirtualUr, VirtualUrConfig};

use e2e_support::setup;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn force_guided_episodes_over_rtde_seat_every_part_on_a_confirmed_seat() {
    let setup = setup(|doc| {
        // A controller's gripper output opens the full stroke (as `cell run --robot
        // virtual-ur` plans).
        doc["cell"]["gripper"]
            .as_table_mut()
            .expect("a gripper table")
            .remove("opening_margin");
        doc["force_insertion"] = toml_edit::table();
    });
    for episode in 0..2u32 {
        let s = connect_sim_over_rtde(&setup, episode, Duration::from_millis(100))
            .await
            .unwrap();
        let (_controller, mut robot) = (s.controller, s.robot);
        let mut io = SimCellIo::new(s.cell.clone());
        let mut perception = keypoint_noise_for(setup.scenario(), episode).unwrap();
        let mut cell = SplitCell {
            robot: &mut robot,
            io: &mut io,
        };
        let out = run_episode(setup.engine.context(episode), &mut cell, &mut perception).await;
        assert!(out.record.success, "episode {episode}: {:#?}", out.record);
        assert_eq!(out.record.abort, None);
        for step in &out.record.steps {
            assert_eq!(step.outcome, StepOutcome::Seated, "{step:?}");
        }
        // Each insertion stopped on contact at the seat over RTDE, and its reading is logged.
        let logs: Vec<&str> = out
            .events
            .events()
            .iter()
            .filter(|e| e.detail.starts_with("force-guided:"))
            .map(|e| e.detail.as_str())
            .collect();
        assert_eq!(logs.len(), 3, "episode {episode}: {logs:#?}");
        for log in logs {
            assert!(log.contains(": contact at"), "{log}");
            assert!(log.contains("seated (confirmed"), "{log}");
        }
        // Each insertion's wrench trace is the controller's stream along the guarded descent:
        // from above the seat, free, down to the stop at the contact force, bounded.
        let traces: Vec<_> = out
            .events
            .events()
            .iter()
            .filter_map(|e| e.wrench_trace.as_ref())
            .collect();
        assert_eq!(traces.len(), 3, "episode {episode}");
        for t in traces {
            assert!(t.samples.len() >= 8, "{} samples", t.samples.len());
            assert!(
                t.samples.len() <= insertion::TRACE_BUDGET,
                "{}",
                t.samples.len()
            );
            let first = t.samples.first().unwrap();
            let last = t.samples.last().unwrap();
            assert!(first.height_mm > t.seat_band_mm, "{first:?}");
            assert!(first.force_n.abs() < 12.0, "free above the seat: {first:?}");
            assert!(last.force_n >= t.contact_force_n, "{last:?}");
            assert!(last.height_mm.abs() < 0.2, "{last:?}");
            assert!(t.samples.windows(2).all(|w| w[0].t_s <= w[1].t_s));
        }
    }
}

/// Pre-flight: a scenario with `[force_insertion]` is refused on an arm without a wrist force
/// sensor (a CB-series controller, software 3.x), naming why, and accepted on an e-Series; a
/// scenario without it runs on either.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn force_guided_insertion_needs_an_arm_that_reports_a_force_sensor() {
    let force = setup(|doc| doc["force_insertion"] = toml_edit::table());
    let plain = setup(|_| {});
    for major in [3u32, 5] {
        let config = VirtualUrConfig {
            version: ControllerVersion {
                major,
                minor: if major == 3 { 15 } else { 21 },
                bugfix: 0,
                build: 0,
            },
            ..VirtualUrConfig::ephemeral()
        };
        let controller = VirtualUr::start(config).await.unwrap();
        let mut rc = UrRobotConfig::new("127.0.0.1", force.engine.knowledge.kinematics.clone());
        rc.rtde_port = controller.rtde_addr().port();
        rc.dashboard_port = controller.dashboard_addr().port();
        rc.script_port = controller.script_addr().port();
        rc.limits = force.scenario().spec.cell.limits.clone();
        let robot = UrRobot::connect(rc).await.unwrap();
        let answer = robot.inner().force_sensor();
        let checked = force_sensor_preflight(force.scenario(), answer.clone());
        if major == 3 {
            let why = checked.unwrap_err().to_string();
            for text in ["[force_insertion]", "force/torque sensor", "3.15.0"] {
                assert!(why.contains(text), "{text} missing from: {why}");
            }
        } else {
            assert_eq!(answer, Ok(()));
            checked.unwrap();
        }
        force_sensor_preflight(plain.scenario(), answer).unwrap();
    }
}
