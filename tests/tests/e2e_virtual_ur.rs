//! The production path end to end: the simulated cell behind the virtual UR controller
//! (`robots::virtual_ur` with `sim::cell::arm::SimArm`, on 127.0.0.1 free ports), driven by the
//! orchestrator through `UrRobot` over loopback RTDE. It must give the same outcomes as the
//! in-process run with the same seed, and stop safely on a protective stop mid-move and on a
//! lost connection.

mod e2e_support;

use std::sync::{Arc, Mutex};
use std::time::Duration;

use cell::episode::StepOutcome;
use cell::harness::{SimCellIo, connect_sim_over_rtde, keypoint_noise_for};
use cell::orchestrator::{EpisodeOutput, SplitCell, State, run_episode};
use robots::limited::Limited;
use robots::observed::{Command, Observed};
use robots::robot::Robot;
use robots::ur_robot::UrRobot;
use robots::virtual_ur::VirtualUr;
use sim::cell::SimCell;

use e2e_support::{Setup, setup};

async fn start(setup: &Setup, episode: u32) -> (VirtualUr, Limited<UrRobot>, Arc<Mutex<SimCell>>) {
    let s = connect_sim_over_rtde(setup, episode, Duration::from_millis(100))
        .await
        .unwrap();
    (s.controller, s.robot, s.cell)
}

async fn run_over_rtde(
    setup: &Setup,
    robot: &mut dyn Robot,
    cell: Arc<Mutex<SimCell>>,
    episode: u32,
) -> EpisodeOutput {
    let mut io = SimCellIo::new(cell);
    let mut perception = keypoint_noise_for(setup.scenario(), episode).unwrap();
    let mut cell = SplitCell { robot, io: &mut io };
    run_episode(setup.engine.context(episode), &mut cell, &mut perception).await
}

/// The virtual controller's control period.
const PERIOD_S: f64 = 0.002;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn five_episodes_over_rtde_match_the_in_process_run() {
    // A controller's gripper output opens the full stroke, so a controller run sets the
    // scenario's opening margin aside (`cell run --robot virtual-ur` does): both runs plan so.
    let setup = setup(|doc| {
        doc["cell"]["gripper"]
            .as_table_mut()
            .expect("a gripper table")
            .remove("opening_margin")
            .expect("the scenario sets an opening margin");
    });
    assert_runs_match(&setup, 5).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_gripper_width_output_opens_the_fingers_to_the_part_over_rtde_as_in_process() {
    // A gripper with a position input on analog output 0: a controller run keeps the margin,
    // and the controller opens the fingers to the same widths as the in-process run.
    let setup = setup(|doc| {
        doc["cell"]["gripper"]["width_output"] = toml_edit::value(0);
    });
    assert!(setup.scenario().spec.cell.gripper.opening_margin.is_some());
    assert_runs_match(&setup, 3).await;
}

/// Runs `episodes` episodes in process and over RTDE and asserts they match: outcomes, true
/// insertion errors, the simulated clock to a control cycle per move, and the fingers' travel.
async fn assert_runs_match(setup: &Setup, episodes: u32) {
    for episode in 0..episodes {
        let mut local_cell = setup
            .model
            .limited(setup.sim_cell(episode).unwrap())
            .unwrap();
        let mut perception = keypoint_noise_for(setup.scenario(), episode).unwrap();
        let local = run_episode(
            setup.engine.context(episode),
            &mut local_cell,
            &mut perception,
        )
        .await
        .record;
        let local_travel = local_cell.inner().gripper_travel();
        let (vur, mut robot, cell) = start(setup, episode).await;
        // The arm's moves passed on to the controller, counted.
        let mut moves = 0usize;
        let mut counting = Observed::new(&mut robot, |c: &Command<'_>| {
            moves += usize::from(c.moves_arm());
        });
        let remote = run_over_rtde(setup, &mut counting, cell.clone(), episode)
            .await
            .record;
        drop(robot);
        drop(vur);
        let remote_travel = cell.lock().unwrap().gripper_travel();
        assert!(
            (remote_travel - local_travel).abs() < 1e-9,
            "episode {episode}: the fingers travelled {remote_travel} m over RTDE, \
             {local_travel} m in process"
        );
        assert_eq!(remote.abort, None, "episode {episode}");
        assert_eq!(
            remote.success, local.success,
            "episode {episode}: over RTDE {:#?}\nin process {:#?}",
            remote.steps, local.steps
        );
        let key = |r: &cell::episode::EpisodeRecord| {
            r.steps
                .iter()
                .map(|s| (s.part.clone(), s.outcome, s.attempts, s.shakes))
                .collect::<Vec<_>>()
        };
        assert_eq!(key(&remote), key(&local), "episode {episode}");
        for (r, l) in remote.steps.iter().zip(&local.steps) {
            // The same world: the same true insertion errors (the controller's 500 Hz stepping
            // ends each move on exactly the commanded joints).
            match (&r.pose_error, &l.pose_error) {
                (Some(a), Some(b)) => {
                    let d = [
                        a.dx_mm - b.dx_mm,
                        a.dy_mm - b.dy_mm,
                        a.depth_mm - b.depth_mm,
                        a.tilt_deg - b.tilt_deg,
                        a.yaw_deg - b.yaw_deg,
                    ];
                    assert!(
                        d.iter().all(|x| x.abs() < 1e-6),
                        "episode {episode} {}: pose errors differ by {d:?}",
                        r.part
                    );
                }
                (None, None) => {}
                (a, b) => panic!("episode {episode} {}: {a:?} vs {b:?}", r.part),
            }
            // The simulated clock: every move ends on a control cycle over RTDE, so it runs
            // at most a cycle per move longer; never shorter.
            let dt = r.sim_time_s - l.sim_time_s;
            assert!(
                (-1e-9..=moves as f64 * PERIOD_S).contains(&dt),
                "episode {episode} {}: {} s over RTDE, {} s in process ({moves} moves)",
                r.part,
                r.sim_time_s,
                l.sim_time_s
            );
        }
        let dt = remote.cycle_time_s - local.cycle_time_s;
        assert!(
            (-1e-9..=moves as f64 * PERIOD_S).contains(&dt),
            "episode {episode}: cycle {} s over RTDE, {} s in process ({moves} moves)",
            remote.cycle_time_s,
            local.cycle_time_s
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_protective_stop_mid_move_stops_the_episode_safely() {
    let setup = setup(|_| {});
    let (vur, mut robot, cell) = start(&setup, 0).await;
    let vur = Arc::new(vur);
    let fault = {
        let vur = vur.clone();
        tokio::spawn(async move {
            tokio::time::sleep(Duration::from_millis(1500)).await;
            vur.protective_stop();
        })
    };
    let out = run_over_rtde(&setup, &mut robot, cell, 0).await;
    fault.await.unwrap();
    let r = &out.record;
    assert!(!r.success);
    let abort = r.abort.as_deref().expect("the record says why it stopped");
    assert!(abort.contains("protective stop"), "{abort}");
    assert_eq!(
        r.steps.last().map(|s| s.outcome),
        Some(StepOutcome::Aborted)
    );
    assert_eq!(
        out.events.events().last().map(|e| e.to),
        Some(State::SafeStop)
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_lost_connection_stops_the_episode_safely() {
    let setup = setup(|_| {});
    let (vur, mut robot, cell) = start(&setup, 0).await;
    let fault = tokio::spawn(async move {
        tokio::time::sleep(Duration::from_millis(1500)).await;
        // The controller goes away: listeners, connections and control loop.
        drop(vur);
    });
    let out = run_over_rtde(&setup, &mut robot, cell, 0).await;
    fault.await.unwrap();
    let r = &out.record;
    assert!(!r.success);
    let abort = r.abort.as_deref().expect("the record says why it stopped");
    assert!(abort.contains("connection"), "{abort}");
    assert_eq!(
        out.events.events().last().map(|e| e.to),
        Some(State::SafeStop)
    );
}
