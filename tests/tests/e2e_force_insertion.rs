//! Force-guided insertion on the production path: the simulated cell behind the virtual UR
//! controller on 127.0.0.1, driven through `UrRobot` over RTDE and our URScript program's
//! guarded move, with the same strategy (`cell::orchestrator::insertion`) as in process.

mod e2e_support;

use std::time::Duration;

use cell::episode::StepOutcome;
use cell::harness::{SimCellIo, connect_sim_over_rtde, keypoint_noise_for};
use cell::orchestrator::{SplitCell, run_episode};

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
    }
}
