//! The simulated cell end to end: grasp failures with their cause, determinism and replay,
//! scripted episodes, limits, calibration error in what the camera sees, infeasible scenarios.

#![allow(non_snake_case)]

use std::sync::Arc;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use robots::kinematics::to_ur_pose;
use robots::robot::{LinearMotion, Robot, RobotError};
use robots::virtual_ur::arm::{ArmCommand, ArmError, ArmModel};
use sim::cell::arm::SimArm;
use sim::cell::geometry::PartGeometry;
use sim::cell::gripper::{self, Finger, GraspCandidate, GraspFailure};
use sim::cell::insertion::{Scorer, Verdict};
use sim::cell::{CellModel, SimCell, check_feasible};
use sim::config::NoiseSpec;

mod support;

use support::{Nominal as Scenario, arm, catalog, scenario, script};

fn model(noise: &NoiseSpec, scorer: Scorer) -> Arc<CellModel> {
    let s = scenario();
    CellModel::new(&s.cell, &arm(), &s.assembly, noise, &catalog(), scorer).unwrap()
}

fn zero_noise() -> NoiseSpec {
    NoiseSpec {
        robot_repeatability: 0.0,
        calibration_translation: 0.0,
        calibration_rotation: 0.0,
        grasp_offset: 0.0,
        grasp_rotation: 0.0,
    }
}

/// The main shell's shapes and its upright stable pose.
fn upright_shell(cat: &perception::part::Catalog) -> (PartGeometry, perception::part::StablePose) {
    let shell = PartGeometry::from_catalog(cat, "main_shell").unwrap();
    let upright = shell
        .stable_poses
        .iter()
        .find(|p| p.name == "+z")
        .unwrap()
        .clone();
    (shell, upright)
}

/// The TCP over the table origin at the shell's grip height, z down, the fingers closing along
/// table x.
fn tcp_over_origin() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(0.0, 0.0, 0.0022),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2)
            * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
    )
}

#[test]
fn a_grasp_beside_a_neighbour_fails_with_that_cause() {
    let s = scenario();
    let cat = catalog();
    let (shell, upright) = upright_shell(&cat);
    let at = |x: f64, y: f64| upright.table_T_part(x, y, 0.0);
    let tcp = tcp_over_origin();
    let closing = tcp.rotation * Vector3::y();
    assert!(
        (closing.x.abs() - 1.0).abs() < 1e-9,
        "closing along table x"
    );
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let grasp = |neighbour_x: f64, rng: &mut ChaCha8Rng| {
        let parts = [
            GraspCandidate {
                instance: 1,
                geometry: &shell,
                base_T_part: at(0.0, 0.0),
            },
            GraspCandidate {
                instance: 2,
                geometry: &shell,
                base_T_part: at(neighbour_x, 0.0),
            },
        ];
        gripper::close(&s.cell.gripper, &zero_noise(), &tcp, &parts, rng)
    };
    // The right finger sweeps from the part's face (4.42 mm) to 9 mm: a neighbour 11 mm away
    // reaches into it (its near edge at 6.58 mm).
    match grasp(-0.011, &mut rng) {
        Err(GraspFailure::NeighbourCollision {
            instance: 1,
            neighbour: 2,
            finger,
            ..
        }) => {
            assert!(matches!(finger, Finger::Left | Finger::Right))
        }
        other => panic!("expected a neighbour collision, got {other:?}"),
    }
    // 14 mm away its edge is at 9.58 mm, clear of the finger: the grasp succeeds and centres it.
    let g = grasp(0.014, &mut rng).expect("grasp clear of the neighbour");
    assert_eq!(g.instance, 1);
    assert!(g.tcp_T_part.translation.y.abs() < 1e-9);
    // A part off the finger pads across the closing axis is outside the finger reach.
    let off = [GraspCandidate {
        instance: 3,
        geometry: &shell,
        base_T_part: at(0.0, 0.003),
    }];
    assert!(matches!(
        gripper::close(&s.cell.gripper, &zero_noise(), &tcp, &off, &mut rng),
        Err(GraspFailure::OutsideReach { instance: 3, .. })
    ));
    // Nothing under the fingers.
    assert_eq!(
        gripper::close(&s.cell.gripper, &zero_noise(), &tcp, &[], &mut rng).unwrap_err(),
        GraspFailure::NothingBetweenFingers
    );
}

#[test]
fn a_part_wider_than_the_stroke_cannot_be_grasped() {
    let s = scenario();
    let cat = catalog();
    let (shell, upright) = upright_shell(&cat);
    let tcp = tcp_over_origin();
    let mut spec = s.cell.gripper.clone();
    spec.stroke = 0.008;
    let parts = [GraspCandidate {
        instance: 1,
        geometry: &shell,
        base_T_part: upright.table_T_part(0.0, 0.0, 0.0),
    }];
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    assert!(matches!(
        gripper::close(&spec, &zero_noise(), &tcp, &parts, &mut rng),
        Err(GraspFailure::TooWide { .. })
    ));
}

#[test]
fn same_seed_and_episode_give_the_same_world_and_outcomes_and_replay_alone() {
    let m = model(&NoiseSpec::default(), Scorer::Analytic);
    let run = |episode: u64| {
        let mut cell = SimCell::new(m.clone(), 7, episode).unwrap();
        let feeder = cell.feeder_parts().to_vec();
        let summary = script::run_episode(&mut cell).unwrap();
        (feeder, summary, cell.base_T_camera_true())
    };
    let all: Vec<_> = (0..4).map(run).collect();
    // Replaying episode 2 alone gives what it gave in sequence.
    assert_eq!(run(2), all[2]);
    // Episodes differ from each other.
    assert_ne!(all[0].0, all[1].0);
    assert_ne!(all[0].2, all[1].2);
}

#[test]
fn without_error_sources_every_step_is_seated_and_takes_realistic_time() {
    for scorer in [Scorer::Analytic, Scorer::Contact] {
        let m = model(&zero_noise(), scorer);
        let mut cell = SimCell::new(m, 3, 0).unwrap();
        let summary = script::run_episode(&mut cell).unwrap();
        assert!(summary.success, "{scorer:?}: {summary:?}");
        assert_eq!(summary.steps.len(), 3);
        assert_eq!(cell.placed().len(), 3);
        // Three pick-and-place cycles with 0.25 s gripper actuations: seconds, not milliseconds.
        assert!(
            summary.cycle_time > 3.0 && summary.cycle_time < 30.0,
            "{}",
            summary.cycle_time
        );
        // The insert sits where the seated main shell says it should.
        let shell = cell.placed()[0].base_T_part;
        let insert = cell.placed()[1].base_T_part;
        let expected = shell * m_target(&cell, 1);
        assert!((insert.translation.vector - expected.translation.vector).norm() < 1e-4);
    }
}

fn m_target(cell: &SimCell, step: usize) -> Isometry3<f64> {
    cell.model().steps[step].target.isometry()
}

#[test]
fn large_calibration_error_misses_and_is_attributed_to_it() {
    let mut noise = zero_noise();
    noise.calibration_translation = 1e-3;
    let m = model(&noise, Scorer::Analytic);
    let mut misses = 0;
    for episode in 0..20 {
        let mut cell = SimCell::new(m.clone(), 5, episode).unwrap();
        // A 1 mm error along the camera axis can drive the fingers into the table: a protective
        // stop ends that episode (it is a failure too, but not an insertion to attribute).
        let Ok(summary) = script::run_episode(&mut cell) else {
            continue;
        };
        let first = &summary.steps[0];
        if first.verdict.is_some_and(|v| v != Verdict::Seated) {
            misses += 1;
            let report = cell.last_release().unwrap();
            let budget = report.budget.as_ref().unwrap();
            assert_eq!(
                budget.dominant(),
                Some(sim::cell::noise::ErrorSource::CameraCalibration),
                "{budget:?}"
            );
        }
    }
    // 1 mm (1σ per axis) against a 0.33 mm capture band: most episodes fail the first step.
    assert!(misses >= 10, "{misses} of 20");
}

#[test]
fn the_camera_sees_true_poses_from_the_true_camera() {
    let mut noise = zero_noise();
    noise.calibration_rotation = 1e-3;
    let m = model(&noise, Scorer::Analytic);
    let cell = SimCell::new(m.clone(), 1, 0).unwrap();
    let view = cell.camera_view();
    assert_eq!(
        view.len(),
        cell.feeder_parts().len(),
        "the camera sees the whole feeder"
    );
    for seen in &view {
        let truth = cell
            .feeder_parts()
            .iter()
            .find(|p| p.instance == seen.instance)
            .unwrap();
        let true_base = m.geometry.base_T_table * truth.table_T_part;
        let via_true = cell.base_T_camera_true() * seen.camera_T_part;
        assert!((via_true.translation.vector - true_base.translation.vector).norm() < 1e-9);
        // Through the calibrated pose the part appears off by about 1.5 m × 1 mrad.
        let via_nominal = cell.base_T_camera_nominal() * seen.camera_T_part;
        let off = (via_nominal.translation.vector - true_base.translation.vector).norm();
        assert!(off > 2e-4 && off < 6e-3, "{off}");
    }
}

/// A cell whose workspace box reaches below the table, so the table itself must stop the arm.
fn cell_with_workspace_below_the_table() -> SimCell {
    let mut s = scenario();
    s.cell.limits.workspace.min[2] = -0.05;
    let m = CellModel::new(
        &s.cell,
        &arm(),
        &s.assembly,
        &zero_noise(),
        &catalog(),
        Scorer::Analytic,
    )
    .unwrap();
    SimCell::new(m, 1, 0).unwrap()
}

#[tokio::test]
async fn the_robot_trait_checks_limits_and_the_table() {
    let mut cell = cell_with_workspace_below_the_table();
    let model = cell.model().clone();
    // Driven as a robot, the cell is wrapped in the limits decorator.
    let mut limited = model.limited(&mut cell).unwrap();
    let robot: &mut dyn Robot = &mut limited;
    let home = robot.tcp_pose().await.unwrap();
    let slow = LinearMotion {
        speed: 0.1,
        acceleration: 0.5,
    };
    // Outside the workspace box.
    let far = Translation3::new(0.5, 0.0, 0.0) * home;
    assert!(matches!(
        robot.move_l(far, slow).await,
        Err(RobotError::LimitViolation(_))
    ));
    // Too fast.
    let near = Translation3::new(0.0, 0.0, -0.05) * home;
    let fast = LinearMotion {
        speed: 2.0,
        acceleration: 0.5,
    };
    assert!(matches!(
        robot.move_l(near, fast).await,
        Err(RobotError::LimitViolation(_))
    ));
    // Beside the feeder, down to 0.5 mm above the table, then into it.
    let beside = Translation3::new(0.12, 0.0, 0.0) * home;
    robot.move_l(beside, slow).await.unwrap();
    let mut just_above = beside;
    just_above.translation.vector.z = 0.0005;
    robot.move_l(just_above, slow).await.unwrap();
    let t0 = cell.clock();
    assert!(t0 > 1.0, "two moves of ~0.12 and 0.15 m at 0.1 m/s: {t0} s");
    let mut limited = model.limited(&mut cell).unwrap();
    let robot: &mut dyn Robot = &mut limited;
    let mut below = just_above;
    below.translation.vector.z = -0.001;
    assert!(matches!(
        robot.move_l(below, slow).await,
        Err(RobotError::ProtectiveStop)
    ));
    assert!(matches!(
        robot.move_l(beside, slow).await,
        Err(RobotError::ProtectiveStop)
    ));
    assert!(!robot.status().await.unwrap().ready());
    cell.unlock_protective_stop();
    let mut limited = model.limited(&mut cell).unwrap();
    let robot: &mut dyn Robot = &mut limited;
    robot.move_l(beside, slow).await.unwrap();
}

/// Behind the virtual controller (the arm-model seam), a move into the table protective-stops
/// before the arm moves, as an in-process move does; a clear move runs.
#[tokio::test]
async fn the_arm_model_stops_a_path_into_the_table() {
    let mut cell = cell_with_workspace_below_the_table();
    let home = Robot::tcp_pose(&mut cell).await.unwrap();
    let beside = Translation3::new(0.12, 0.0, 0.0) * home;
    let mut below = beside;
    below.translation.vector.z = -0.001;
    let cell = Arc::new(std::sync::Mutex::new(cell));
    let mut arm = SimArm::new(cell.clone());
    let movel = |pose: &Isometry3<f64>| ArmCommand::MoveL {
        pose: to_ur_pose(pose),
        speed: 0.1,
        accel: 0.5,
    };
    arm.command(movel(&beside)).unwrap();
    while arm.is_moving() {
        arm.step(0.002, 1.0).unwrap();
    }
    let q_beside = arm.state().q;
    assert!(matches!(
        arm.command(movel(&below)),
        Err(ArmError::ProtectiveStop(_))
    ));
    assert!(!arm.is_moving(), "the arm must not start the move");
    assert_eq!(arm.state().q, q_beside);
    let status = cell.lock().unwrap().status_now();
    assert!(!status.ready());
}

/// The controller reads the wrist sensor every 2 ms cycle; while the cell is busy elsewhere (a
/// capture rendering, a shake dropping parts) the arm model answers the last reading at once
/// instead of stalling the control loop, and the RTDE stream with it.
#[test]
fn the_arm_models_sensor_never_waits_for_a_busy_cell() {
    let cell = Arc::new(std::sync::Mutex::new(
        SimCell::new(model(&zero_noise(), Scorer::Analytic), 11, 0).unwrap(),
    ));
    let arm = SimArm::new(cell.clone());
    let free = arm
        .external_wrench()
        .expect("the cell simulates its contacts");
    let busy = cell.lock().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(arm.external_wrench());
    });
    let held = rx
        .recv_timeout(std::time::Duration::from_secs(5))
        .expect("the sensor reading waited for the cell");
    drop(busy);
    assert_eq!(held, Some(free));
}

#[test]
fn impossible_scenarios_are_rejected_with_the_reason() {
    let cat = catalog();
    let ok = scenario();
    assert!(check_feasible(&ok.cell, &arm(), &ok.assembly, &ok.noise, &cat).is_empty());
    let keys = |s: &Scenario| -> Vec<String> {
        check_feasible(&s.cell, &arm(), &s.assembly, &s.noise, &cat)
            .into_iter()
            .map(|(k, _)| k)
            .collect()
    };
    let mut s = ok.clone();
    s.cell.fixture.table_T_fixture.translation = [1.2, 0.0, 0.003];
    s.cell.limits.workspace.max = [2.0, 2.0, 2.0];
    s.cell.limits.workspace.min = [-2.0, -2.0, -2.0];
    assert!(
        keys(&s).contains(&"cell.fixture.table_T_fixture".to_string()),
        "{:?}",
        keys(&s)
    );
    let mut s = ok.clone();
    s.cell.gripper.stroke = 0.008;
    assert!(
        keys(&s)
            .iter()
            .any(|k| k.starts_with("cell.feeder.parts.") || k.ends_with(".part")),
        "{:?}",
        keys(&s)
    );
    let mut s = ok.clone();
    s.assembly[1].tolerances.depth = 0.0;
    assert_eq!(keys(&s), vec!["assembly[1].tolerances.depth".to_string()]);
    let mut s = ok.clone();
    s.cell.feeder.center = [0.05, -0.05];
    assert_eq!(keys(&s), vec!["cell.feeder".to_string()]);
    // The model refuses to build and says why.
    let err = CellModel::new(
        &s.cell,
        &arm(),
        &s.assembly,
        &s.noise,
        &cat,
        Scorer::Analytic,
    )
    .unwrap_err();
    assert!(err.to_string().contains("overlaps the fixture"), "{err}");
}

#[test]
fn shaking_replaces_and_refill_restores_the_feeder() {
    let m = model(&zero_noise(), Scorer::Analytic);
    let mut cell = SimCell::new(m, 9, 0).unwrap();
    let before = cell.feeder_parts().to_vec();
    assert_eq!(before.len(), 12);
    cell.shake().unwrap();
    let after = cell.feeder_parts().to_vec();
    assert_eq!(after.len(), 12);
    assert!(
        before
            .iter()
            .zip(&after)
            .all(|(a, b)| a.instance == b.instance && a.table_T_part != b.table_T_part)
    );
    let summary = script::run_episode(&mut cell).unwrap();
    assert!(summary.success, "{summary:?}");
    assert_eq!(cell.feeder_parts().len(), 9);
    cell.refill().unwrap();
    assert_eq!(cell.feeder_parts().len(), 12);
    assert!(cell.feeder_parts().iter().any(|p| p.instance > 12));
}

/// The arm's last motion replays on the clock: a joint move's trace starts where the arm was
/// when it started and ends at its target when the clock does; a shake started mid-move
/// (`shake_from`) lets the parts rest that much earlier than one started at its end, and is
/// never dated before the move began nor after now.
#[tokio::test]
async fn a_motion_replays_on_the_clock_and_a_shake_can_start_during_it() {
    let m = model(&zero_noise(), Scorer::Analytic);
    let shake_time = m.spec.feeder.shake_time;
    let mut cell = SimCell::new(m.clone(), 9, 0).unwrap();
    assert!(cell.last_motion_trace(0.002).is_empty());
    let from = cell.joints_now();
    let mut to = from;
    to[0] += 0.6;
    to[1] -= 0.2;
    let t0 = cell.clock();
    let motion = robots::robot::JointMotion {
        speed: 1.0,
        acceleration: 2.0,
    };
    cell.move_j(to, motion).await.unwrap();
    let end = cell.clock();
    let trace = cell.last_motion_trace(0.002);
    assert_eq!(trace.first().unwrap(), &(t0, from));
    let (t_last, q_last) = trace.last().unwrap();
    assert!((t_last - end).abs() < 1e-12);
    assert!(q_last.iter().zip(&to).all(|(a, b)| (a - b).abs() < 1e-12));
    // Even steps no longer than asked, the lead joint never faster than the move's speed.
    for w in trace.windows(2) {
        let dt = w[1].0 - w[0].0;
        assert!(dt > 0.0 && dt <= 0.002 + 1e-12);
        assert!((w[1].1[0] - w[0].1[0]).abs() <= motion.speed * dt + 1e-9);
    }
    // A straight line ends at its pose as well.
    let tcp = cell.tcp_pose_now();
    let up = Translation3::new(0.0, 0.0, 0.02) * tcp;
    cell.move_l(
        up,
        LinearMotion {
            speed: 0.1,
            acceleration: 0.5,
        },
    )
    .await
    .unwrap();
    let (_, q) = *cell.last_motion_trace(0.002).last().unwrap();
    let reached = m.kinematics.forward_tcp(&q);
    assert!((reached.translation.vector - up.translation.vector).norm() < 1e-6);
    // Mid-move against at the end.
    let mut early = SimCell::new(m.clone(), 9, 0).unwrap();
    let mut late = SimCell::new(m, 9, 0).unwrap();
    for c in [&mut early, &mut late] {
        c.move_j(to, motion).await.unwrap();
    }
    let mid = t0 + 0.4 * (end - t0);
    early.shake_from(mid).unwrap();
    late.shake().unwrap();
    assert!((early.feeder_rest_at() - (mid + shake_time)).abs() < 1e-12);
    assert!((late.feeder_rest_at() - (end + shake_time)).abs() < 1e-12);
    // Clamped to the move: not before it began, not after now.
    let mut c = SimCell::new(model(&zero_noise(), Scorer::Analytic), 9, 0).unwrap();
    c.move_j(to, motion).await.unwrap();
    c.shake_from(t0 - 5.0).unwrap();
    assert!((c.feeder_rest_at() - (t0 + shake_time)).abs() < 1e-12);
    c.shake_from(end + 5.0).unwrap();
    let expected = (t0 + shake_time).max(end) + shake_time;
    assert!((c.feeder_rest_at() - expected).abs() < 1e-12);
}

/// `cell.gripper.actuation_time` is the gripper's full-stroke time: at 0.5 s instead of the
/// default 0.25 s, the same seed gives the same outcomes and the episode takes exactly 0.25 s
/// longer per stroke the fingers travelled on the simulated clock (an open or close of part of
/// the stroke takes part of the time); the arm model behind the virtual controller reports the
/// full time for the gripper pin (our program sleeps it).
#[test]
fn the_gripper_actuation_time_is_the_scenarios_and_scales_with_the_finger_travel() {
    let s = scenario();
    assert_eq!(
        s.cell.gripper.actuation_time,
        sim::config::DEFAULT_GRIPPER_ACTUATION_TIME
    );
    assert_eq!(sim::config::DEFAULT_GRIPPER_ACTUATION_TIME, 0.25);
    let cat = catalog();
    let run = |actuation_time: f64, episode: u64| {
        let mut spec = s.cell.clone();
        spec.gripper.actuation_time = actuation_time;
        let m =
            CellModel::new(&spec, &arm(), &s.assembly, &s.noise, &cat, Scorer::Analytic).unwrap();
        let arm = SimArm::new(Arc::new(std::sync::Mutex::new(
            SimCell::new(m.clone(), 11, episode).unwrap(),
        )));
        let pin = sim::cell::arm::TOOL_OUTPUT_BASE + sim::cell::arm::GRIPPER_TOOL_PIN;
        assert_eq!(arm.actuation_time(pin), actuation_time);
        assert_eq!(arm.actuation_time(pin + 1), 0.0);
        let mut cell = SimCell::new(m, 11, episode).unwrap();
        let summary = script::run_episode(&mut cell).unwrap();
        (
            summary,
            cell.clock(),
            (cell.gripper_actuations(), cell.gripper_travel()),
        )
    };
    let mut seated = 0;
    for episode in 0..3 {
        let (base, base_clock, (n, travel)) = run(0.25, episode);
        let (slow, slow_clock, (n_slow, travel_slow)) = run(0.5, episode);
        // Same outcomes: steps, grasp attempts, verdicts and causes.
        assert_eq!(base.steps, slow.steps, "episode {episode}");
        assert_eq!(base.success, slow.success);
        assert_eq!(n, n_slow);
        assert_eq!(travel, travel_slow);
        // A pick and a release at least per step tried.
        assert!(n as usize >= 2 * base.steps.len(), "{n} actuations");
        // Each actuation takes the settle time plus the rest of the full-stroke time in
        // proportion to the travel: twice the full-stroke time adds 0.25 s per stroke travelled.
        let stroke = s.cell.gripper.stroke;
        assert!(travel > stroke, "{travel} m travelled");
        let extra = 0.25 * travel / stroke;
        assert!(
            (slow_clock - base_clock - extra).abs() < 1e-9,
            "episode {episode}: {slow_clock} − {base_clock} ≠ 0.25 s × {travel} m / {stroke} m"
        );
        assert!((slow.cycle_time - base.cycle_time - extra).abs() < 1e-9);
        seated += usize::from(base.success);
    }
    // Whole assemblies among them (a grasp and a release per step), not only early failures.
    assert!(seated > 0);
}

/// A negative, non-finite or over-long actuation time is refused with its key.
#[test]
fn a_bad_gripper_actuation_time_is_refused() {
    let s = scenario();
    let cat = catalog();
    for bad in [
        -0.1,
        f64::NAN,
        f64::INFINITY,
        robots::ur_robot::MAX_GRIPPER_ACTUATION_S + 0.01,
    ] {
        let mut spec = s.cell.clone();
        spec.gripper.actuation_time = bad;
        assert!(spec.gripper.actuation_time_problem().is_some(), "{bad}");
        let err = CellModel::new(&spec, &arm(), &s.assembly, &s.noise, &cat, Scorer::Analytic)
            .unwrap_err();
        assert!(
            err.to_string().contains("cell.gripper.actuation_time"),
            "{bad}: {err}"
        );
    }
    for good in [0.0, 0.25, robots::ur_robot::MAX_GRIPPER_ACTUATION_S] {
        let mut spec = s.cell.clone();
        spec.gripper.actuation_time = good;
        assert_eq!(spec.gripper.actuation_time_problem(), None, "{good}");
    }
}

#[test]
fn the_rendered_feeder_window_shows_every_feeder_part_and_repeats_by_seed() {
    let m = model(&zero_noise(), Scorer::Analytic);
    let mut cell = SimCell::new(m.clone(), 4, 2).unwrap().render_captures(true);
    assert!(cell.renders_captures());
    let shot = cell.render_feeder().unwrap();
    let w = shot.window;
    assert_eq!(
        (shot.image.width(), shot.image.height()),
        (w.width, w.height)
    );
    // About the feeder rectangle plus margins at ~0.14 mm/px: hundreds of pixels, not the sensor.
    let feeder = &m.spec.feeder;
    let expect = (feeder.size[0] + 0.016) / 1.4e-4;
    assert!(
        (f64::from(w.width) - expect).abs() < 0.25 * expect,
        "{w:?} vs {expect}"
    );
    for seen in cell.camera_view() {
        let (x, y) = (seen.pixel.x, seen.pixel.y);
        assert!(
            x >= f64::from(w.x0) + 20.0
                && y >= f64::from(w.y0) + 20.0
                && x < f64::from(w.x0 + w.width) - 20.0
                && y < f64::from(w.y0 + w.height) - 20.0,
            "part {} at ({x:.0}, {y:.0}) is not well inside {w:?}",
            seen.instance
        );
    }
    // The same episode renders the same pixels; sensor noise differs between episodes.
    let again = SimCell::new(m.clone(), 4, 2)
        .unwrap()
        .render_feeder()
        .unwrap();
    assert_eq!(again.image, shot.image);
    let other = SimCell::new(m, 4, 3).unwrap().render_feeder().unwrap();
    assert_ne!(other.image, shot.image);
}

/// Empty fingers sent to a width move while the arm does: the clock does not wait for them, a
/// motion ends no earlier than they arrive, and a close waits for them; with nothing to wait for
/// they cost nothing.
#[test]
fn empty_fingers_move_while_the_arm_does() {
    let m = model(&zero_noise(), Scorer::Analytic);
    let g = m.spec.gripper.clone();
    let mut cell = SimCell::new(m, 3, 0).unwrap();
    assert_eq!(cell.finger_opening(), g.stroke);
    let t0 = cell.clock();
    cell.send_fingers_to(0.010);
    assert_eq!(
        cell.clock(),
        t0,
        "the clock does not wait for empty fingers"
    );
    assert_eq!(cell.finger_opening(), 0.010);
    // A short move ends when the fingers have arrived, not before.
    let mut q = cell.joints_now();
    q[5] += 1e-4;
    let motion = robots::robot::JointMotion {
        speed: 1.0,
        acceleration: 6.0,
    };
    cell.move_j_sync(q, motion).unwrap();
    let travel = g.travel_time(g.stroke - 0.010);
    assert!(
        (cell.clock() - (t0 + travel)).abs() < 1e-12,
        "{} vs {}",
        cell.clock() - t0,
        travel
    );
    // Sent again, then closed at once: the close starts when they arrive.
    let t1 = cell.clock();
    cell.send_fingers_to(0.012);
    cell.close_gripper_sync();
    let expected = g.travel_time(0.002) + g.travel_time(0.012);
    assert!(
        (cell.clock() - t1 - expected).abs() < 1e-12,
        "{} vs {expected}",
        cell.clock() - t1
    );
}
