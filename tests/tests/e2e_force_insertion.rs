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

/// Item 4 of issue 43: a virtual-UR run of `scenarios/usbc_force.toml` (learned perception, two
/// episodes, the production client over loopback RTDE) records each force-guided step's own
/// verdict (seated, jammed or missed, and the first contact and force that decided it) in the
/// step record, as a simulated run does, and the report shows them in its force-guided table.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_virtual_ur_run_records_and_reports_each_steps_force_verdict() {
    use cell::harness::{SimSetup, sim_episode_over_rtde};
    use cell::run::{LoadedScenario, Shard, Summary};

    let path = e2e_support::prepared_scenarios().join("usbc_force.toml");
    let loaded = LoadedScenario::load(&path).unwrap();
    let mut scenario = loaded.scenario.clone();
    // As `cell run --robot virtual-ur` runs it: the gripper output opens the full stroke.
    scenario.spec.cell.gripper.opening_margin = None;
    let force = scenario
        .spec
        .force_insertion
        .expect("usbc_force inserts by feel");
    let setup = SimSetup::new(scenario).unwrap();
    let mut records = std::collections::BTreeMap::new();
    for episode in 0..2u32 {
        let out = sim_episode_over_rtde(&setup, episode).await.unwrap();
        assert_eq!(out.record.abort, None, "{:#?}", out.record);
        let inserted: Vec<_> = out
            .record
            .steps
            .iter()
            .filter(|s| s.insertion_attempts > 0)
            .collect();
        assert!(!inserted.is_empty(), "{:#?}", out.record);
        for step in inserted {
            let f = step
                .force
                .unwrap_or_else(|| panic!("episode {episode}: no force verdict in {step:?}"));
            assert_eq!(f.verdict, step.outcome, "{step:?}");
            assert!(f.probes >= 1, "{f:?}");
            if f.verdict == StepOutcome::Seated {
                // Confirmed on its seat: first contact within the seat band, pressed with at
                // least half the contact force.
                assert!(f.contact_mm.abs() <= force.seat_band * 1e3, "{f:?}");
                assert!(f.force_n >= force.contact_force / 2.0, "{f:?}");
            }
            // The record round-trips through the results file.
            let line = serde_json::to_string(step).unwrap();
            assert!(line.contains("\"force\":{\"verdict\":"), "{line}");
            let back = serde_json::from_str::<cell::episode::StepRecord>(&line)
                .unwrap()
                .force
                .unwrap();
            assert_eq!((back.verdict, back.probes), (f.verdict, f.probes));
            assert!((back.contact_mm - f.contact_mm).abs() < 1e-12, "{back:?}");
            assert!((back.force_n - f.force_n).abs() < 1e-9, "{back:?}");
        }
        records.insert(episode, out.record);
    }
    // The report's force-guided table: one row per step, its verdicts counted.
    let summary = Summary::new(&loaded.header(Shard::ALL), records.values());
    let html = cell::report::render_html(&summary, &records, &Default::default())
        .unwrap()
        .html;
    assert!(html.contains("<h2>Force-guided verdicts</h2>"), "{html}");
    let recs: Vec<_> = records.values().collect();
    let rows = cell::report::force::force_rows(&recs);
    assert_eq!(rows.len(), summary.steps.len());
    for (row, t) in rows.iter().zip(&summary.steps) {
        assert_eq!((row.index, row.part.as_str()), (t.index, t.part.as_str()));
        assert_eq!(row.seated + row.jammed + row.missed, row.inserted);
        assert_eq!(row.seated, t.seated, "{row:?} {t:?}");
        assert_eq!(row.agree, row.inserted);
        let cells = format!(
            "<td class=l>{}: {}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td>",
            row.index, row.part, row.inserted, row.seated, row.jammed, row.missed, row.agree
        );
        assert!(html.contains(&cells), "{cells} not in the report");
    }
}
