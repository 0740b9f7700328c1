//! `[motion] overlap`: the next step's feeder frame captured and perceived while the arm inserts.
//! A capture with the arm or the held part in the camera's view of the feeder is refused (never
//! taken, never used); a shake for the next step waits until the arm is away from the feeder;
//! where the view is clear the frame is used and the clock shows the overlap
//! (perception's time runs during the insertion, the next step waits only for what remains); a
//! bad `[motion] perception_time` is refused at its line and column.

mod support;

use cell::harness::{SimSetup, run_sim_episode};
use cell::orchestrator::view::{arm_in_feeder_view, arm_near_feeder};
use cell::orchestrator::{Event, State};
use support::load_variant;

/// The nominal scenario with `motion` as its `[motion]` table and `edit` applied to its text.
fn variant(tag: &str, motion: &str, edit: impl Fn(String) -> String) -> SimSetup {
    let text = edit(std::fs::read_to_string(support::nominal()).unwrap());
    let text = format!("{text}\n[motion]\n{motion}\n");
    SimSetup::new(load_variant(tag, &text).unwrap()).unwrap()
}

/// The nominal cell rearranged so that the arm over the fixture leaves the camera's view of the
/// feeder clear: the feeder 15 cm to one side of the camera's axis, the fixture 15 cm to the
/// other.
fn side_by_side(text: String) -> String {
    let moved = text
        .replace("center = [0.0, 0.05]", "center = [-0.15, 0.05]")
        .replace(
            "table_T_fixture = { translation = [0.05, -0.05, 0.003]",
            "table_T_fixture = { translation = [0.15, 0.0, 0.003]",
        );
    assert_ne!(moved, text, "the nominal layout's lines changed");
    moved
}

/// The notes of overlapped captures in an episode's events.
fn notes(events: &[Event]) -> Vec<&str> {
    events
        .iter()
        .flat_map(|e| e.detail.split("; "))
        .filter(|d| d.contains("ahead") || d.contains("taken during the last insertion"))
        .collect()
}

#[test]
fn bad_perception_times_are_refused_at_their_line_and_column() {
    let text = std::fs::read_to_string(support::nominal()).unwrap();
    for line in [
        "perception_time = -0.1",
        "perception_time = nan",
        "perception_time = inf",
    ] {
        let variant = format!("{text}\n[motion]\noverlap = true\n{line}\n");
        let err = load_variant("bad_perception_time", &variant).unwrap_err();
        let problem = &err.0[0];
        assert_eq!(
            problem.key.as_deref(),
            Some("motion.perception_time"),
            "{err}"
        );
        assert_eq!(problem.line, support::line_of(&variant, line), "{err}");
        assert_eq!(problem.column, line.find('=').unwrap() + 3, "{err}");
        assert!(
            problem.message.contains("finite number of seconds"),
            "{err}"
        );
    }
    let variant = format!("{text}\n[motion]\noverlap = \"yes\"\n");
    let err = load_variant("bad_overlap", &variant).unwrap_err();
    assert_eq!(
        err.0[0].line,
        support::line_of(&variant, "overlap = \"yes\""),
        "{err}"
    );
}

#[test]
fn the_arm_over_the_feeder_hides_it_or_is_near_it_and_the_arm_over_a_fixture_aside_is_not() {
    // The nominal home puts the TCP above the feeder.
    let nominal = variant("view_nominal", "overlap = true", |t| t);
    let home = nominal.sim_cell(0).unwrap().joints_now();
    let k = &nominal.engine.knowledge;
    assert!(arm_in_feeder_view(k, &home, None).is_some());
    // Above the side-by-side fixture, at the pre-insert height, with a part in the fingers.
    let side = variant("view_side", "overlap = true", side_by_side);
    let k = &side.engine.knowledge;
    let over = nalgebra::Isometry3::from_parts(
        (k.geometry.base_T_fixture.translation.vector + nalgebra::Vector3::new(0.0, 0.0, 0.05))
            .into(),
        nalgebra::UnitQuaternion::from_euler_angles(std::f64::consts::PI, 0.0, 0.0),
    );
    let q = k.kinematics.inverse_nearest(&over, &home).unwrap().joints;
    assert_eq!(arm_in_feeder_view(k, &q, Some(0.02)), None);
    // A held part as large as the distance to the feeder hides it.
    assert_eq!(arm_in_feeder_view(k, &q, Some(0.4)), Some("held part"));
    // Over the fixture the arm is away from the feeder (a shake may start); 1 cm above the
    // feeder's centre, where a pick lifts to, it is not.
    assert_eq!(arm_near_feeder(k, &q, Some(0.02)), None);
    let f = &k.spec.feeder;
    let lifted = k.geometry.base_T_table
        * nalgebra::Isometry3::from_parts(
            nalgebra::Translation3::new(f.center[0], f.center[1], 0.01),
            nalgebra::UnitQuaternion::from_euler_angles(std::f64::consts::PI, 0.0, 0.0),
        );
    let q = k.kinematics.inverse_nearest(&lifted, &home).unwrap().joints;
    assert_eq!(arm_near_feeder(k, &q, None), Some("gripper"));
}

#[tokio::test]
async fn a_capture_with_the_arm_in_view_is_refused_and_the_run_is_unchanged() {
    // In the nominal layout the arm reaches the fixture across the feeder: every overlapped
    // capture is refused, and the episodes run exactly as without overlap.
    let plain = variant("overlap_off", "overlap = false", |t| t);
    let overlap = variant("overlap_on", "overlap = true", |t| t);
    let mut refused = 0;
    for episode in 0..3 {
        let a = run_sim_episode(&plain, episode).await.unwrap();
        let b = run_sim_episode(&overlap, episode).await.unwrap();
        let events = b.events.events();
        for note in notes(events) {
            assert!(
                note.starts_with("capture ahead refused: the ")
                    && note.ends_with("is in the camera's view of the feeder")
                    || note.contains("still settling")
                    || note.starts_with("shake held back: the "),
                "episode {episode}: {note}"
            );
            refused += usize::from(note.starts_with("capture ahead refused"));
        }
        // The same picks and insertions; only a shake held back until the arm left the
        // feeder can make a step longer.
        let timeless = |r: &cell::episode::EpisodeRecord| {
            let mut steps = r.steps.clone();
            steps.iter_mut().for_each(|s| s.sim_time_s = 0.0);
            steps
        };
        assert_eq!(
            timeless(&a.record),
            timeless(&b.record),
            "episode {episode}"
        );
        assert!(b.record.cycle_time_s >= a.record.cycle_time_s - 1e-9);
    }
    assert!(refused > 0, "no capture was refused");
}

#[tokio::test]
async fn a_clear_view_captures_ahead_and_the_clock_shows_the_overlap() {
    let perception = 0.5;
    let time = format!("perception_time = {perception}");
    let plain = variant(
        "side_off",
        &format!("overlap = false\n{time}"),
        side_by_side,
    );
    let overlap = variant("side_on", &format!("overlap = true\n{time}"), side_by_side);
    let (mut used, mut faster) = (0, 0);
    for episode in 0..3 {
        let a = run_sim_episode(&plain, episode).await.unwrap();
        let b = run_sim_episode(&overlap, episode).await.unwrap();
        assert!(a.record.success && b.record.success, "episode {episode}");
        // Without overlap, every perception waits its full time.
        for (i, e) in a.events.events().iter().enumerate() {
            if e.from == State::Perceive {
                let entered = a.events.events()[i - 1].sim_time_s;
                assert!((e.sim_time_s - entered - perception).abs() < 1e-9);
            }
        }
        // With it, a step that uses a frame taken ahead waits only for what remains: its
        // perception is done `perception` seconds after that capture.
        let events = b.events.events();
        let mut taken = None;
        for (i, e) in events.iter().enumerate() {
            for note in e.detail.split("; ") {
                if let Some(rest) = note.strip_prefix("captured ahead for step ") {
                    let at = rest.split(" at ").nth(1).unwrap().trim_end_matches(" s");
                    taken = Some(at.parse::<f64>().unwrap());
                }
            }
            if e.from == State::Capture && e.detail == "the frame taken during the last insertion" {
                let at = taken.take().expect("a capture ahead before its use");
                let perceived = &events[i + 1];
                assert_eq!(perceived.from, State::Perceive);
                // The insertion's rest ran meanwhile (the note's time is rounded to 1 ms).
                assert!(e.sim_time_s > at, "episode {episode}");
                let ready = (at + perception).max(e.sim_time_s);
                assert!(
                    (perceived.sim_time_s - ready).abs() < 1e-3,
                    "episode {episode}: perceived at {} s, ready at {ready} s",
                    perceived.sim_time_s
                );
                assert!(perceived.sim_time_s - e.sim_time_s < perception);
                used += 1;
            }
        }
        faster += usize::from(b.record.cycle_time_s < a.record.cycle_time_s);
    }
    assert!(used >= 3, "frames taken ahead used: {used}");
    assert!(faster >= 2, "overlap faster in {faster} of 3 episodes");
}
