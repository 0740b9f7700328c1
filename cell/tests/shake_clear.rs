//! Feeder shakes start only with the arm and the held part away from the feeder, in every mode:
//! a shake decided right after a pick (no usable instance left for the next step) waits for
//! the arm to clear the feeder and, in the simulated cell, starts mid-transit at the first
//! instant it has; every shake is recorded in the events with the arm's joints then, which
//! are checked here against the feeder's clearance. A shake started mid-transit saves time
//! against one held to the end of the move at which the arm is clear (what a cell that cannot
//! replay its arm's motion does).

mod support;

use cell::harness::SimSetup;
use cell::orchestrator::view::{AWAY_HEIGHT, GRIPPER_RADIUS, arm_near_feeder};
use cell::orchestrator::{
    CellIo, CellIoError, Event, InsertionCheck, PerceptionAudit, ShakeStart, Workcell, run_episode,
};
use nalgebra::Point3;
use perception::{DetectedPart, Frame};
use robots::limited::Limited;
use robots::robot::Robot;
use sim::cell::SimCell;
use support::load_variant;

/// Episodes run per test: enough for several shakes decided right after a pick.
const EPISODES: u32 = 8;

fn nominal(tag: &str) -> SimSetup {
    variant(tag, |t| t)
}

/// The nominal scenario with `edit` applied to its text.
fn variant(tag: &str, edit: impl Fn(String) -> String) -> SimSetup {
    let text = std::fs::read_to_string(support::nominal()).unwrap();
    let edited = edit(text.clone());
    SimSetup::new(load_variant(tag, &edited).unwrap()).unwrap()
}

/// The simulated cell with its motion replay withheld: the engine then reads the arm's joints
/// at the end of each motion, as it does on a controller, and a shake starts at the end of
/// the first motion at which the arm is clear of the feeder.
struct NoReplay(Limited<SimCell>);

impl CellIo for NoReplay {
    fn capture(&mut self) -> Result<Frame, CellIoError> {
        CellIo::capture(self.0.inner_mut())
    }
    fn shake_feeder(&mut self) -> Result<(), CellIoError> {
        CellIo::shake_feeder(self.0.inner_mut())
    }
    fn part_in_gripper(&mut self) -> Option<bool> {
        CellIo::part_in_gripper(self.0.inner_mut())
    }
    fn insertion_check(&mut self) -> Option<InsertionCheck> {
        CellIo::insertion_check(self.0.inner_mut())
    }
    fn seating_check(&mut self) -> Option<InsertionCheck> {
        CellIo::seating_check(self.0.inner_mut())
    }
    fn clock(&self) -> f64 {
        CellIo::clock(self.0.inner())
    }
    fn wait_until(&mut self, t: f64) {
        CellIo::wait_until(self.0.inner_mut(), t)
    }
    fn feeder_at_rest(&self) -> Option<bool> {
        CellIo::feeder_at_rest(self.0.inner())
    }
    fn audit(&self, detection: &DetectedPart) -> Option<PerceptionAudit> {
        CellIo::audit(self.0.inner(), detection)
    }
    fn missed(&self, part: &str, detections: &[DetectedPart]) -> Option<usize> {
        CellIo::missed(self.0.inner(), part, detections)
    }
}

impl Workcell for NoReplay {
    fn robot(&mut self) -> &mut dyn Robot {
        &mut self.0
    }
    fn io(&mut self) -> &mut dyn CellIo {
        self
    }
}

/// One episode: its events, its cycle time and how many shakes the simulated feeder saw.
struct Run {
    events: Vec<Event>,
    cycle: f64,
    feeder_shakes: u32,
}

async fn run(setup: &SimSetup, episode: u32, replay: bool) -> Run {
    let mut perception = setup
        .perception
        .for_episode(setup.scenario(), episode)
        .unwrap();
    let cell = setup
        .model
        .limited(setup.sim_cell(episode).unwrap())
        .unwrap();
    let ctx = setup.engine.context(episode);
    let (out, feeder_shakes) = if replay {
        let mut cell = cell;
        let out = run_episode(ctx, &mut cell, &mut perception).await;
        (out, cell.inner().shakes())
    } else {
        let mut cell = NoReplay(cell);
        let out = run_episode(ctx, &mut cell, &mut perception).await;
        (out, cell.0.inner().shakes())
    };
    Run {
        events: out.events.events().to_vec(),
        cycle: out.record.cycle_time_s,
        feeder_shakes,
    }
}

fn shakes(events: &[Event]) -> impl Iterator<Item = (usize, &ShakeStart)> {
    events
        .iter()
        .enumerate()
        .flat_map(|(i, e)| e.shakes.iter().map(move |s| (i, s)))
}

/// Every shake the feeder saw in `r` is in its events, started within the state the event
/// closes, with the arm's recorded pose then clear of the feeder.
#[allow(non_snake_case)]
fn check_clear(setup: &SimSetup, r: &Run, episode: u32) {
    let k = &setup.engine.knowledge;
    let f = &k.spec.feeder;
    let table_T_base = k.geometry.base_T_table.inverse();
    assert_eq!(
        shakes(&r.events).count() as u32,
        r.feeder_shakes,
        "episode {episode}: every shake the feeder saw is in the events"
    );
    for (i, s) in shakes(&r.events) {
        // Started within the state the event closes.
        let (entered, left) = (r.events[i - 1].sim_time_s, r.events[i].sim_time_s);
        assert!(
            s.t_s >= entered - 1e-9 && s.t_s <= left + 1e-9,
            "episode {episode}: {s:?} outside [{entered}, {left}]"
        );
        // The arm's recorded pose then: no link, the gripper nor the held part near the
        // feeder, and the fingertips either beside the feeder's rectangle or above the
        // height a shake throws parts to, with the gripper's (or part's) radius.
        assert_eq!(
            arm_near_feeder(k, &s.joints, s.held_radius_m),
            None,
            "episode {episode}: {}",
            s.describe()
        );
        let tcp =
            table_T_base * Point3::from(k.kinematics.forward_tcp(&s.joints).translation.vector);
        let reach = GRIPPER_RADIUS.max(s.held_radius_m.unwrap_or(0.0));
        let beside = (tcp.x - f.center[0]).abs() > 0.5 * f.size[0] + reach
            || (tcp.y - f.center[1]).abs() > 0.5 * f.size[1] + reach;
        assert!(
            beside || tcp.z - reach >= AWAY_HEIGHT,
            "episode {episode}: fingertips at {tcp:?} within the feeder's clearance: {}",
            s.describe()
        );
    }
}

#[tokio::test]
async fn a_shake_never_starts_near_the_feeder_and_a_held_back_one_starts_mid_transit() {
    let setup = nominal("shake_clear_near");
    let (mut held_back, mut mid_transit) = (0, 0);
    for episode in 0..EPISODES {
        let r = run(&setup, episode, true).await;
        check_clear(&setup, &r, episode);
        for (i, s) in shakes(&r.events) {
            let left = r.events[i].sim_time_s;
            if s.waited_for.is_some() {
                held_back += 1;
                assert!(s.held_back_s > 0.0, "episode {episode}: {}", s.describe());
            }
            // Decided after a pick, started during the move away: strictly inside it.
            if s.waited_for.is_some() && s.into_motion_s > 0.0 && s.t_s < left - 1e-6 {
                mid_transit += 1;
            }
        }
    }
    assert!(
        held_back > 0,
        "no shake was held back in {EPISODES} episodes"
    );
    assert!(mid_transit > 0, "no shake started mid-motion");
}

#[tokio::test]
async fn a_mid_transit_shake_saves_time_against_one_held_to_the_moves_end() {
    let setup = nominal("shake_clear_mid");
    let (mut mid_total, mut end_total, mut compared) = (0.0, 0.0, 0);
    for episode in 0..EPISODES {
        let mid = run(&setup, episode, true).await;
        let end = run(&setup, episode, false).await;
        let a: Vec<_> = shakes(&mid.events).map(|(_, s)| s.clone()).collect();
        let b: Vec<_> = shakes(&end.events).map(|(_, s)| s.clone()).collect();
        // The same shakes, after the same motions: only when they start differs.
        assert_eq!(a.len(), b.len(), "episode {episode}");
        for (m, e) in a.iter().zip(&b) {
            assert_eq!(
                (m.for_step, &m.motion),
                (e.for_step, &e.motion),
                "episode {episode}"
            );
            assert!(
                m.into_motion_s <= e.into_motion_s + 1e-9,
                "episode {episode}: {} against {}",
                m.describe(),
                e.describe()
            );
        }
        if a.iter().any(|s| s.waited_for.is_some()) {
            assert!(
                mid.cycle <= end.cycle + 1e-9,
                "episode {episode}: {} s mid-transit against {} s",
                mid.cycle,
                end.cycle
            );
            mid_total += mid.cycle;
            end_total += end.cycle;
            compared += 1;
        } else {
            assert!((mid.cycle - end.cycle).abs() < 1e-9, "episode {episode}");
        }
    }
    assert!(compared > 0, "no episode shook ahead in {EPISODES}");
    assert!(
        mid_total < end_total - 0.05 * compared as f64,
        "mid-transit {mid_total} s against held to the move's end {end_total} s over {compared} \
         episodes"
    );
}

#[tokio::test]
async fn after_a_missed_grasp_the_arm_rises_clear_before_the_feeder_shakes() {
    // One part of each kind and a calibration error wider than the fingers' margin: a grasp
    // misses, the arm backs 10 mm up over the feeder, and with the only part excluded the step
    // shakes the feeder. The arm first rises clear; the shake starts during that rise.
    let setup = variant("shake_clear_missed", |t| {
        let edited = t
            .replace(
                "parts = { main_shell = 4, insert_mold = 4, top_shell = 4 }",
                "parts = { main_shell = 1, insert_mold = 1, top_shell = 1 }",
            )
            .replace(
                "calibration_translation = 0.00002",
                "calibration_translation = 0.004",
            );
        assert!(
            edited.contains("main_shell = 1,") && edited.contains("translation = 0.004"),
            "the nominal scenario's lines changed"
        );
        edited
    });
    let mut risen = 0;
    for episode in 0..4 {
        let r = run(&setup, episode, true).await;
        check_clear(&setup, &r, episode);
        for (i, s) in shakes(&r.events) {
            if s.motion == "clear the feeder" {
                assert_eq!(r.events[i].from, cell::orchestrator::State::Shake);
                assert!(s.waited_for.is_some(), "{}", s.describe());
                risen += 1;
            }
        }
    }
    assert!(
        risen > 0,
        "no shake after a missed grasp waited for the arm to rise"
    );
}
