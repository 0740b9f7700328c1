//! End to end in the in-process simulated cell: the nominal scenario's success rate over 200
//! episodes, determinism, the event log, and the failure paths (empty feeder, every part upside
//! down, perception finding nothing, an unreachable target).

mod e2e_support;

use cell::episode::StepOutcome;
use cell::harness::{SimSetup, run_sim_episode_blocking};
use cell::orchestrator::{Activity, State};
use rayon::prelude::*;
use sim::cell::CellModel;
use sim::cell::insertion::{InsertionCase, InsertionScorer, Scored, Scorer, ScorerError};

use e2e_support::{scenario_with, setup};

#[test]
fn nominal_scenario_assembles_at_least_95_percent_of_200_episodes() {
    let setup = setup(|_| {});
    let outputs: Vec<_> = (0..200u32)
        .into_par_iter()
        .map(|e| run_sim_episode_blocking(&setup, e).expect("episode set up"))
        .collect();
    let successes = outputs.iter().filter(|o| o.record.success).count();
    let cycle: f64 = outputs
        .iter()
        .filter(|o| o.record.success)
        .map(|o| o.record.cycle_time_s)
        .sum::<f64>()
        / successes.max(1) as f64;
    let failures: Vec<String> = outputs
        .iter()
        .filter(|o| !o.record.success)
        .map(|o| {
            let last = o.record.steps.last();
            format!(
                "episode {}: {:?} {:?} {:?}",
                o.record.episode,
                last.map(|s| &s.part),
                last.map(|s| s.outcome),
                last.and_then(|s| s.cause.as_deref())
            )
        })
        .collect();
    println!(
        "success {successes}/200, mean cycle {cycle:.2} s (simulated); failures: {failures:#?}"
    );
    assert!(
        successes >= 190,
        "success {successes}/200 < 95 %: {failures:#?}"
    );
    for o in &outputs {
        let r = &o.record;
        assert!(
            r.abort.is_none(),
            "episode {} aborted: {:?}",
            r.episode,
            r.abort
        );
        assert!(r.cycle_time_s > 0.0 && r.cycle_time_s.is_finite());
        // Every episode starts at Home and ends in Done, and every transition is logged in order.
        let ev = o.events.events();
        assert_eq!(ev.first().map(|e| e.to), Some(State::Home));
        assert_eq!(ev.last().map(|e| e.to), Some(State::Done));
        for w in ev.windows(2) {
            assert_eq!(w[0].to, w[1].from, "transitions chain");
            assert!(w[1].sim_time_s >= w[0].sim_time_s && w[1].wall_time_s >= w[0].wall_time_s);
        }
        // The cycle's time is accounted for state by state: the phases add up to the cycle
        // time, start after Home and carry the step they served.
        let phased: f64 = r.phases.iter().map(|p| p.duration_s).sum();
        assert!(
            (phased - r.cycle_time_s).abs() < 1e-9,
            "episode {}: phases {phased} s against cycle {} s",
            r.episode,
            r.cycle_time_s
        );
        assert!(
            r.phases
                .iter()
                .all(|p| p.duration_s >= 0.0 && p.state != State::Home)
        );
        assert_eq!(
            r.phases.first().map(|p| (p.state, p.step)),
            Some((State::Capture, Some(0)))
        );
        assert!(
            r.phases
                .iter()
                .any(|p| p.state == State::Insert && p.step == Some(2))
        );
        // Each span has an activity, and a whole assembly spends time on every kind of motion.
        assert!(r.phases.iter().all(|p| p.activity.is_some()));
        let by_activity = r.time_by_activity();
        if r.success {
            for a in [
                Activity::Transit,
                Activity::Approach,
                Activity::Grasp,
                Activity::Insertion,
                Activity::Retreat,
            ] {
                assert!(
                    by_activity.get(&a).is_some_and(|s| *s > 0.0),
                    "episode {}: no time on {}: {by_activity:?}",
                    r.episode,
                    a.name()
                );
            }
        }
        if r.success {
            assert_eq!(r.steps.len(), 3);
            for s in &r.steps {
                let p = s
                    .perception_error
                    .expect("perception error measured in simulation");
                assert!(
                    p[0].abs() < 0.5 && p[1].abs() < 0.5,
                    "perception error {p:?} mm"
                );
            }
        }
    }
}

#[test]
fn an_episode_replays_alone_with_the_same_record() {
    let setup = setup(|_| {});
    for e in [3u32, 117] {
        let mut a = run_sim_episode_blocking(&setup, e).unwrap().record;
        let mut b = run_sim_episode_blocking(&setup, e).unwrap().record;
        a.wall_time_s = 0.0;
        b.wall_time_s = 0.0;
        assert_eq!(a, b);
    }
    let mut lines = Vec::new();
    let out = run_sim_episode_blocking(&setup, 5).unwrap();
    out.events.write_jsonl(&mut lines).unwrap();
    let text = String::from_utf8(lines).unwrap();
    assert_eq!(text.lines().count(), out.events.events().len());
    for line in text.lines() {
        let v: serde_json::Value = serde_json::from_str(line).unwrap();
        assert!(v["sim_time_s"].is_f64() && v["wall_time_s"].is_f64() && v["to"].is_string());
    }
}

fn first_step(setup: &SimSetup) -> cell::episode::StepRecord {
    let out = run_sim_episode_blocking(setup, 0).unwrap();
    assert!(!out.record.success);
    assert_eq!(
        out.record.steps.len(),
        1,
        "the episode stops at the failed step"
    );
    out.record.steps[0].clone()
}

#[test]
fn an_empty_feeder_shakes_the_bounded_number_of_times_then_aborts() {
    // A scenario file cannot ask for an empty feeder (validation refuses it), so the simulated
    // cell is built with no main shell in it: the feeder ran empty.
    let base = setup(|_| {});
    let mut spec = base.scenario().spec.clone();
    spec.cell.feeder.parts.insert("main_shell".into(), 0);
    let model = CellModel::new(
        &spec.cell,
        &base.scenario().robot,
        &spec.assembly,
        &spec.noise,
        &base.scenario().catalog,
        Scorer::Analytic,
    )
    .unwrap();
    let setup = SimSetup {
        engine: base.engine.clone(),
        model,
        perception: cell::harness::SimPerception::KeypointNoise,
    };
    let s = first_step(&setup);
    assert_eq!(s.outcome, StepOutcome::Aborted);
    assert_eq!(s.attempts, 0);
    assert_eq!(s.shakes, setup.scenario().spec.cell.feeder.max_shakes);
    let cause = s.cause.unwrap();
    assert!(cause.contains("no usable main_shell"), "{cause}");
    // The error budget names the cause.
    assert_eq!(s.sources, vec!["feeder.parts".to_string()]);
}

#[test]
fn parts_lying_upside_down_are_never_picked() {
    // Every main shell rests on its back ("-z": open side down).
    let setup = scenario_with(
        |_| {},
        |catalog| e2e_support::all_in_pose(catalog, "main_shell", "-z"),
    );
    let s = first_step(&setup);
    assert_eq!(s.outcome, StepOutcome::Aborted);
    assert_eq!(s.attempts, 0, "nothing was picked");
    let cause = s.cause.unwrap();
    assert!(cause.contains("wrong way up"), "{cause}");
    assert_eq!(s.sources, vec!["feeder.max_shakes".to_string()]);
}

/// Insertion statistics of `episodes` episodes: (steps seated after a retry, steps given up
/// after retries, largest insertion count of any step).
fn insertion_retries(setup: &SimSetup, episodes: u32) -> (usize, usize, u32) {
    let outputs: Vec<_> = (0..episodes)
        .into_par_iter()
        .map(|e| run_sim_episode_blocking(setup, e).expect("episode set up"))
        .collect();
    let steps = || outputs.iter().flat_map(|o| o.record.steps.iter());
    let retried_seated = steps()
        .filter(|s| s.insertion_attempts > 1 && s.outcome == StepOutcome::Seated)
        .count();
    let given_up = steps()
        .filter(|s| s.insertion_attempts > 1 && s.outcome != StepOutcome::Seated)
        .count();
    for o in &outputs {
        for s in &o.record.steps {
            // Every step that reached the insertion counts it; failed retries say so.
            if matches!(s.outcome, StepOutcome::Jammed | StepOutcome::Missed) {
                assert!(s.insertion_attempts >= 1);
            }
            if s.insertion_attempts > 1 && s.outcome != StepOutcome::Seated {
                let cause = s.cause.as_deref().unwrap_or_default();
                assert!(cause.contains("insertion attempts"), "{cause}");
            }
        }
        // Each retry is a logged Verify → PlanInsert transition with its reason.
        let retries = o
            .events
            .events()
            .iter()
            .filter(|e| e.from == State::Verify && e.to == State::PlanInsert)
            .count();
        let expected: u32 = o
            .record
            .steps
            .iter()
            .map(|s| s.insertion_attempts.saturating_sub(1))
            .sum();
        assert_eq!(retries, expected as usize, "episode {}", o.record.episode);
    }
    let most = steps().map(|s| s.insertion_attempts).max().unwrap_or(0);
    (retried_seated, given_up, most)
}

#[test]
fn jammed_insertions_are_lifted_and_retried_within_the_bound() {
    // Three times the nominal grasp rotation: the yaw in the fingers often exceeds what the
    // clearances admit, so insertions jam (or miss) before the fingers open.
    let jammy = |doc: &mut toml_edit::DocumentMut, attempts: i64| {
        doc["noise"]["grasp_rotation"] = toml_edit::value(0.006);
        doc["cell"]["feeder"]["max_shakes"] = toml_edit::value(10);
        doc["policy"]["max_insertion_attempts"] = toml_edit::value(attempts);
    };
    let four = setup(|doc| jammy(doc, 4));
    let (seated, given_up, most) = insertion_retries(&four, 120);
    assert!(seated >= 10, "only {seated} steps seated after a retry");
    assert!(most <= 4, "a step made {most} insertions, the bound is 4");
    assert_eq!(
        most, 4,
        "some step should have used every attempt ({given_up} gave up)"
    );
    // With one attempt allowed there is no retry at all.
    let once = setup(|doc| jammy(doc, 1));
    let (seated, given_up, most) = insertion_retries(&once, 60);
    assert_eq!((seated, given_up), (0, 0));
    assert_eq!(most, 1);
}

#[test]
fn perception_that_finds_nothing_aborts_with_the_cause() {
    // Every keypoint an outlier: PnP results fail the reprojection gate, nothing is detected.
    let setup = setup(|doc| {
        doc["perception"]["outlier_fraction"] = toml_edit::value(1.0);
    });
    let s = first_step(&setup);
    assert_eq!(s.outcome, StepOutcome::Aborted);
    assert_eq!(s.attempts, 0);
    let cause = s.cause.unwrap();
    assert!(cause.contains("no instance detected"), "{cause}");
}

#[test]
fn an_unreachable_target_is_refused_before_moving() {
    // The nest target moved 1.2 m away (limits widened so only kinematics refuses it): the
    // scenario check refuses the step at its target's line, before any episode starts.
    let (_dir, scenario) = e2e_support::load_with(
        |doc| {
            let t = toml_edit::Array::from_iter([1.2, 0.0, 0.0035]);
            doc["assembly"][0]["target"]["translation"] = toml_edit::value(t);
            let min = toml_edit::Array::from_iter([-2.0, -2.0, -0.1]);
            let max = toml_edit::Array::from_iter([2.0, 2.0, 1.0]);
            doc["cell"]["limits"]["workspace"]["min"] = toml_edit::value(min);
            doc["cell"]["limits"]["workspace"]["max"] = toml_edit::value(max);
        },
        |_| {},
    );
    let message = scenario
        .expect_err("an unreachable step is refused")
        .to_string();
    assert!(
        message.contains("usbc_nominal.toml:68:10: assembly[0].target")
            && message.contains("out of the ur5e's reach top-down"),
        "{message}"
    );
}

/// `[simulation] insertion_scorer = "contact"` decides every insertion by the rapier contact
/// simulation: the nominal cell still assembles, and each insertion costs the simulated time of
/// the push, so an episode with the same steps takes longer than with the analytic scorer.
#[test]
fn the_contact_scorer_is_chosen_by_the_scenario() {
    let analytic = setup(|_| {});
    let contact = setup(|doc| {
        doc["simulation"] = toml_edit::table();
        doc["simulation"]["insertion_scorer"] = toml_edit::value("contact");
    });
    assert_eq!(
        contact.scenario().spec.simulation.insertion_scorer,
        Scorer::Contact
    );
    assert_eq!(contact.model.scorer, Scorer::Contact);
    let (mut successes, mut longer) = (0, 0);
    for e in 0..6u32 {
        let a = run_sim_episode_blocking(&analytic, e).unwrap().record;
        let c = run_sim_episode_blocking(&contact, e).unwrap().record;
        successes += usize::from(c.success);
        let same_path = |r: &cell::episode::EpisodeRecord| {
            r.steps
                .iter()
                .map(|s| (s.outcome, s.attempts, s.insertion_attempts, s.shakes))
                .collect::<Vec<_>>()
        };
        if a.success && c.success && same_path(&a) == same_path(&c) {
            assert!(
                c.cycle_time_s > a.cycle_time_s,
                "episode {e}: contact {} s vs analytic {} s",
                c.cycle_time_s,
                a.cycle_time_s
            );
            longer += 1;
        }
    }
    assert!(
        successes >= 5,
        "{successes} of 6 assembled with contact scoring"
    );
    assert!(longer >= 3, "only {longer} episodes comparable");
}

/// `[simulation] insertion_scorer = "mujoco"` decides every insertion by the MuJoCo contact
/// simulation (the same pieces and compliant wrist as rapier): the nominal cell still
/// assembles, and each insertion costs the simulated time of the push.
#[test]
fn the_mujoco_scorer_is_chosen_by_the_scenario() {
    let analytic = setup(|_| {});
    let mujoco = setup(|doc| {
        doc["simulation"] = toml_edit::table();
        doc["simulation"]["insertion_scorer"] = toml_edit::value("mujoco");
    });
    assert_eq!(
        mujoco.scenario().spec.simulation.insertion_scorer,
        Scorer::Mujoco
    );
    assert_eq!(mujoco.model.insertion.name(), "mujoco");
    let mut successes = 0;
    for e in 0..3u32 {
        let a = run_sim_episode_blocking(&analytic, e).unwrap().record;
        let m = run_sim_episode_blocking(&mujoco, e).unwrap().record;
        successes += usize::from(m.success);
        if a.success && m.success && a.steps.len() == m.steps.len() {
            assert!(
                m.cycle_time_s > a.cycle_time_s,
                "episode {e}: mujoco {} s vs analytic {} s",
                m.cycle_time_s,
                a.cycle_time_s
            );
        }
    }
    assert!(
        successes >= 2,
        "{successes} of 3 assembled with MuJoCo scoring"
    );
}

/// An insertion engine that fails on a model it accepted (as a diverging simulation does).
#[derive(Debug)]
struct DivergingEngine;

impl InsertionScorer for DivergingEngine {
    fn name(&self) -> &'static str {
        "diverging"
    }

    fn score(&self, _case: &InsertionCase<'_>) -> Result<Scored, ScorerError> {
        Err(ScorerError::Engine {
            scorer: "diverging",
            reason: "the part's velocity diverged after 12 steps".into(),
        })
    }
}

/// When the insertion scorer fails, the step is aborted with the engine's reason and blamed on
/// `simulation.insertion_scorer`: never judged as if the part had been released elsewhere, and
/// the episode goes no further.
#[test]
fn a_failing_insertion_scorer_aborts_the_step_with_its_reason() {
    let mut setup = setup(|_| {});
    std::sync::Arc::get_mut(&mut setup.model)
        .expect("the set-up's model is not shared yet")
        .insertion = std::sync::Arc::new(DivergingEngine);
    let record = run_sim_episode_blocking(&setup, 0).unwrap().record;
    assert!(!record.success);
    assert_eq!(record.steps.len(), 1, "{:#?}", record.steps);
    let step = &record.steps[0];
    assert_eq!(step.outcome, StepOutcome::Aborted, "{step:#?}");
    let cause = step.cause.as_deref().unwrap_or_default();
    assert!(
        cause.contains("insertion scorer") && cause.contains("velocity diverged after 12 steps"),
        "{cause}"
    );
    assert_eq!(step.sources, ["simulation.insertion_scorer"], "{step:#?}");
}
