//! Force-guided insertion (`[force_insertion]`): the strategy of `cell::orchestrator::insertion`
//! on the simulated cell through the `Robot` seam, and the engine running it.

#![allow(non_snake_case)]

mod support;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use robots::limited::Limited;
use robots::robot::LinearMotion;
use sim::cell::SimCell;
use sim::cell::insertion::{InsertionCause, Verdict};

use cell::episode::StepOutcome;
use cell::harness::{SimSetup, run_sim_episode};
use cell::orchestrator::insertion::{InsertionGeometry, force_insert, rim_landings};
use cell::orchestrator::{Motion, Planner, Speeds, grasped_offset};
use cell::scenario::ForceInsertionSpec;
use support::load_variant;

/// The nominal scenario with every error source off, `[force_insertion]` on, and `extra`
/// appended.
fn setup(tag: &str, extra: &str) -> SimSetup {
    let text = std::fs::read_to_string(support::nominal()).unwrap();
    let noise = text.find("[noise]").expect("a noise table");
    let text = format!(
        "{}[noise]\nrobot_repeatability = 0.0\ncalibration_translation = 0.0\n\
         calibration_rotation = 0.0\ngrasp_offset = 0.0\ngrasp_rotation = 0.0\n\n\
         [force_insertion]\n{extra}\n",
        &text[..noise]
    );
    SimSetup::new(load_variant(tag, &text).unwrap()).unwrap()
}

/// A cell of `setup` holding a main shell (picked with a perfect grasp), with the planned
/// insertion into the fixture moved by `correction` (insertion frame): the moves to the
/// pre-insert pose, and the insertion's geometry.
fn holding_a_shell(
    setup: &SimSetup,
    correction: Isometry3<f64>,
) -> (
    Limited<SimCell>,
    Vec<(&'static str, Motion)>,
    InsertionGeometry,
) {
    let mut cell = setup.model.limited(setup.sim_cell(0).unwrap()).unwrap();
    let sim = cell.inner_mut();
    let camera = sim.base_T_camera_nominal();
    let (grasp, base_T_part) = sim
        .camera_view()
        .into_iter()
        .filter(|c| c.part == "main_shell")
        .find_map(|c| {
            let base_T_part = camera * c.camera_T_part;
            Some((sim.model().grasp_tcp(&c.part, &base_T_part)?, base_T_part))
        })
        .expect("a graspable main shell in view");
    let fast = LinearMotion {
        speed: 0.2,
        acceleration: 1.0,
    };
    sim.move_l_sync(Translation3::new(0.0, 0.0, 0.01) * grasp, fast)
        .unwrap();
    sim.move_l_sync(grasp, fast).unwrap();
    sim.close_gripper_sync();
    assert!(sim.held().is_some(), "the shell is in the fingers");
    sim.move_l_sync(Translation3::new(0.0, 0.0, 0.01) * grasp, fast)
        .unwrap();
    let tcp_T_part = grasped_offset(&(grasp.inverse() * base_T_part));
    let k = &setup.engine.knowledge;
    let config = setup.engine.settings.planning;
    let planner = Planner {
        knowledge: k,
        config,
        speeds: Speeds::within(&setup.model.spec.limits, config.slow_speed),
    };
    let fixture = k.part(&k.geometry.fixture_part).unwrap();
    let plan = planner
        .insert(
            0,
            ((k.part("main_shell").unwrap(), &tcp_T_part), 0.012),
            &correction,
            &sim.joints_now(),
            &[(fixture, k.geometry.base_T_fixture)],
        )
        .unwrap();
    let at = plan
        .motions
        .iter()
        .position(|(n, _)| *n == "insert")
        .unwrap();
    let Motion::MoveL(seated, slow) = plan.motions[at].1 else {
        panic!("the insert is a straight move")
    };
    let s = &k.steps[0];
    let capture = s.clearance / 2.0 + s.lead_in;
    let geometry = InsertionGeometry {
        seated,
        base_T_ins: k.base_T_insertions[0],
        engagement: plan.engagement,
        capture,
        lead_in: s.lead_in,
        slow,
        rims: rim_landings(
            k.part("main_shell").unwrap(),
            &k.base_T_targets[0],
            &k.base_T_insertions[0],
            &[(fixture, k.geometry.base_T_fixture)],
            (capture, s.lead_in),
            ForceInsertionSpec::default().seat_band,
        ),
    };
    (cell, plan.motions[..at].to_vec(), geometry)
}

/// Runs the planner's moves on the cell.
fn run(cell: &mut Limited<SimCell>, motions: &[(&'static str, Motion)]) {
    for (_, m) in motions {
        match m {
            Motion::MoveJ(q, s) => cell.inner_mut().move_j_sync(*q, *s).unwrap(),
            Motion::MoveL(p, s) => cell.inner_mut().move_l_sync(*p, *s).unwrap(),
            Motion::Open(w) => cell.inner_mut().open_gripper_to_sync(*w),
            Motion::Close => cell.inner_mut().close_gripper_sync(),
        }
    }
}

/// A sideways error of the planned insertion: `by` times the main shell's capture band along
/// the insertion frame's x (and a third of that along y), as a correction.
fn sideways(setup: &SimSetup, by: f64) -> Isometry3<f64> {
    let s = &setup.engine.knowledge.steps[0];
    let d = by * (s.clearance / 2.0 + s.lead_in);
    Isometry3::translation(d, d / 3.0, 0.0)
}

#[tokio::test]
async fn a_part_landing_just_beyond_the_capture_band_is_found_by_the_spiral_and_seated() {
    let setup = setup("spiral", "");
    // Plain, position-controlled: the same offset lands on the rim and is released there.
    let offset = sideways(&setup, 1.1);
    let (mut plain, approach, g) = holding_a_shell(&setup, offset);
    run(&mut plain, &approach);
    plain.inner_mut().move_l_sync(g.seated, g.slow).unwrap();
    plain.inner_mut().open_gripper_to_sync(0.012);
    let r = plain.inner().last_release().cloned().unwrap();
    assert_eq!(r.verdict, Verdict::Missed, "{r:?}");
    assert!(
        matches!(r.cause, InsertionCause::LateralBeyondCapture { .. }),
        "{r:?}"
    );

    // Force-guided: the descent stops on the rim, a spiral probe finds the hole.
    let spec = ForceInsertionSpec::default();
    let (mut cell, approach, g) = holding_a_shell(&setup, offset);
    run(&mut cell, &approach);
    let v = force_insert(&mut cell, &g, &spec).await.unwrap();
    assert_eq!(v.outcome, StepOutcome::Seated, "{}", v.describe());
    assert_eq!(v.probes[0].outcome, StepOutcome::Missed, "{}", v.describe());
    assert!(v.probes[0].contact);
    assert!(
        (v.probes[0].height - g.engagement).abs() < 0.1e-3,
        "the first descent stopped on the rim: {}",
        v.describe()
    );
    assert!(v.probes.len() > 1 && v.probes.len() <= 1 + spec.search_points as usize);
    assert!(v.cause.contains("spiral probes"), "{}", v.cause);
    // The wrench trace is the contact model sampled along every descent: free down to the
    // rim, then the press up to the stop on the rim; the last descent presses on the seat.
    let t = &v.trace;
    assert_eq!(t.contact_force_n, spec.contact_force);
    assert!(t.samples.len() <= cell::orchestrator::insertion::TRACE_BUDGET);
    let probes: std::collections::BTreeSet<u32> = t.samples.iter().map(|s| s.probe).collect();
    assert_eq!(probes.len(), v.probes.len(), "every descent traced");
    let first: Vec<_> = t.samples.iter().filter(|s| s.probe == 0).collect();
    assert!(first.len() >= 8, "{first:?}");
    for s in &first {
        if s.height_mm > g.engagement * 1e3 + 1e-3 {
            assert_eq!(s.force_n, 0.0, "free above the rim: {s:?}");
        }
    }
    let stop = first.last().unwrap();
    assert!(stop.force_n >= spec.contact_force, "{stop:?}");
    assert!(
        (stop.height_mm - g.engagement * 1e3).abs() < 0.1,
        "{stop:?}"
    );
    assert!(
        first
            .windows(2)
            .all(|w| w[0].t_s < w[1].t_s && w[0].height_mm > w[1].height_mm)
    );
    let last = t.samples.last().unwrap();
    assert!(last.force_n >= spec.contact_force, "{last:?}");
    assert!(last.height_mm.abs() < spec.seat_band * 1e3, "{last:?}");
    // And the seat is real: released, the simulator scores it seated.
    cell.inner_mut().open_gripper_to_sync(0.012);
    let r = cell.inner().last_release().cloned().unwrap();
    assert_eq!(r.verdict, Verdict::Seated, "{r:?}");
}

#[tokio::test]
async fn nothing_under_the_tool_is_a_miss_and_a_yawed_part_a_jam() {
    let setup = setup("told_apart", "");
    let spec = ForceInsertionSpec::default();

    // 30 mm beside the fixture's pocket: the descent reaches its end without contact.
    let (mut cell, approach, g) = holding_a_shell(&setup, Isometry3::translation(0.0, 0.03, 0.0));
    run(&mut cell, &approach);
    let v = force_insert(&mut cell, &g, &spec).await.unwrap();
    assert_eq!(v.outcome, StepOutcome::Missed, "{}", v.describe());
    assert!(v.cause.contains("nothing under the tool"), "{}", v.cause);
    assert_eq!(v.probes.len(), 1, "no search where nothing was met");
    assert!(!v.probes[0].contact);

    // Turned 3° about the insertion axis: it enters the chamfer and sticks there.
    let yaw = Isometry3::from_parts(
        Translation3::identity(),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 3f64.to_radians()),
    );
    let (mut cell, approach, g) = holding_a_shell(&setup, yaw);
    run(&mut cell, &approach);
    let v = force_insert(&mut cell, &g, &spec).await.unwrap();
    assert_eq!(v.outcome, StepOutcome::Jammed, "{}", v.describe());
    assert!(v.probes[0].contact);
    assert!(
        v.probes[0].height > spec.seat_band && v.probes[0].height < g.engagement,
        "{}",
        v.describe()
    );
    // The spiral tried every point of the band (a sideways step cannot undo a yaw), and the
    // planned descent's reading is the verdict the retries search by.
    assert_eq!(
        v.probes.len(),
        1 + spec.search_points as usize,
        "{}",
        v.describe()
    );
    assert!(v.probes.iter().all(|p| p.outcome != StepOutcome::Seated));
    // Still in the fingers: the strategy never opens them.
    assert!(cell.inner().held().is_some());
}

/// With a contact engine as the scenario's scorer, the simulated cell's guarded descent stops
/// where that engine's push stops the part (not at the analytic model's height), the wrist reads
/// the engine's load there, and the insertion is scored by that very push: the force verdict
/// and the engine's own agree.
#[tokio::test]
async fn with_rapier_as_the_scorer_the_descent_stops_where_rapier_stops_the_part() {
    // The planned descent alone (no spiral), so the part stays where it stopped.
    let spec = ForceInsertionSpec {
        search_points: 0,
        ..ForceInsertionSpec::default()
    };
    // Turned 3° about the insertion axis: jammed in the chamfer by both models, at heights
    // of their own.
    let yaw = Isometry3::from_parts(
        Translation3::identity(),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 3f64.to_radians()),
    );
    let mut stops = Vec::new();
    for scorer in ["analytic", "contact"] {
        let setup = setup(
            &format!("felt_{scorer}"),
            &format!("\n[simulation]\ninsertion_scorer = \"{scorer}\"\n"),
        );
        let (mut cell, approach, g) = holding_a_shell(&setup, yaw);
        run(&mut cell, &approach);
        let started = std::time::Instant::now();
        let v = force_insert(&mut cell, &g, &spec).await.unwrap();
        let took = started.elapsed();
        let truth = cell.inner().held_insertion().unwrap_or_else(|| {
            panic!(
                "{scorer}: not scored at the stop ({:?}): {}",
                cell.inner().scorer_failure(),
                v.describe()
            )
        });
        let end = truth.insertion.as_ref().unwrap().end.height;
        let p = &v.probes[0];
        assert!(p.contact, "{}", v.describe());
        // First contact read back from force and depth is the scorer's stop, to within the
        // sensor's noise through the contact stiffness (±4 N is ±20 µm) and a micron.
        assert!(
            (p.height - end).abs() < 4.0 / spec.contact_stiffness + 1e-6,
            "{scorer}: first contact {:.1} µm, the scorer's stop {:.1} µm",
            p.height * 1e6,
            end * 1e6
        );
        // Seated or not, the force verdict is the scorer's (jammed and missed are told apart
        // by the rim height, which a jam high in the chamfer can pass).
        assert_eq!(
            p.outcome == StepOutcome::Seated,
            truth.verdict == Verdict::Seated,
            "{scorer}: {}",
            v.describe()
        );
        assert_ne!(truth.verdict, Verdict::Seated, "{scorer}");
        eprintln!(
            "{scorer}: stop {:.1} µm above seated, wrench {:?}, {:.1} ms",
            end * 1e6,
            p.wrench,
            took.as_secs_f64() * 1e3
        );
        stops.push((end, p.wrench));
    }
    let ((analytic, analytic_wrench), (rapier, rapier_wrench)) = (stops[0], stops[1]);
    assert!(
        (analytic - rapier).abs() > 4.0 / spec.contact_stiffness + 1e-6,
        "the two models stop this part at heights of their own: {analytic} {rapier}"
    );
    // Both cells read through the same sensor noise: what differs is the load. Rapier's at its
    // stop carries the yaw spring's moment; the analytic press is along the axis only.
    let moment = |w: [f64; 6]| Vector3::new(w[3], w[4], w[5]);
    let extra = (moment(rapier_wrench) - moment(analytic_wrench)).norm();
    assert!(extra > 1e-3, "rapier's moment at the stop adds {extra} N·m");
}

#[tokio::test]
async fn the_engine_never_releases_a_part_whose_seat_was_not_confirmed() {
    // No search and one attempt: every insertion that lands off the band fails; a large
    // calibration error makes some do.
    let text = std::fs::read_to_string(support::nominal()).unwrap();
    let noise = text.find("[noise]").unwrap();
    let text = format!(
        "{}[noise]\nrobot_repeatability = 0.00001\ncalibration_translation = 0.0005\n\
         calibration_rotation = 0.00002\ngrasp_offset = 0.00002\ngrasp_rotation = 0.002\n\n\
         [policy]\nmax_insertion_attempts = 1\n\n[force_insertion]\nsearch_points = 0\n",
        &text[..noise]
    );
    let setup = SimSetup::new(load_variant("refuse_noisy", &text).unwrap()).unwrap();
    let mut refused = 0;
    for episode in 0..12 {
        // The cell is inspected after the episode, so it is built here, not by the harness.
        let mut cell = setup
            .model
            .limited(setup.sim_cell(episode).unwrap())
            .unwrap();
        let mut perception = setup
            .perception
            .for_episode(setup.scenario(), episode)
            .unwrap();
        let out = cell::orchestrator::run_episode(
            setup.engine.context(episode),
            &mut cell,
            &mut perception,
        )
        .await;
        let Some(last) = out.record.steps.last() else {
            continue;
        };
        if matches!(last.outcome, StepOutcome::Jammed | StepOutcome::Missed) {
            refused += 1;
            let cause = last.cause.clone().unwrap_or_default();
            assert!(cause.contains("not released"), "{cause}");
            // The part is still in the fingers, lifted clear, and no release was scored.
            let sim = cell.inner();
            assert!(sim.held().is_some(), "episode {episode}: {cause}");
            assert_eq!(
                sim.placed().len(),
                out.record.steps.len() - 1,
                "episode {episode}: only the seated parts were released"
            );
        }
    }
    assert!(refused > 0, "some insertion failed and was refused");
}

#[tokio::test]
async fn force_guided_nominal_episodes_assemble_and_log_their_readings() {
    let text = std::fs::read_to_string(support::nominal()).unwrap();
    let setup = SimSetup::new(
        load_variant("nominal_force", &format!("{text}\n[force_insertion]\n")).unwrap(),
    )
    .unwrap();
    for episode in 0..5 {
        let out = run_sim_episode(&setup, episode).await.unwrap();
        assert!(out.record.success, "episode {episode}: {:?}", out.record);
        let readings = out
            .events
            .events()
            .iter()
            .filter(|e| e.detail.starts_with("force-guided:") && e.detail.contains("wrench ["))
            .count();
        assert_eq!(readings, 3, "episode {episode}: one force log per step");
        // Each of those events carries its wrench trace, and it survives the event file.
        for e in out.events.events() {
            assert_eq!(
                e.wrench_trace.is_some(),
                e.detail.starts_with("force-guided:"),
                "{e:?}"
            );
        }
        let mut jsonl = Vec::new();
        out.events.write_jsonl(&mut jsonl).unwrap();
        let read: Vec<cell::orchestrator::Event> = std::str::from_utf8(&jsonl)
            .unwrap()
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect();
        assert_eq!(read.len(), out.events.events().len());
        for (r, e) in read.iter().zip(out.events.events()) {
            let (Some(a), Some(b)) = (&r.wrench_trace, &e.wrench_trace) else {
                assert_eq!(r.wrench_trace.is_some(), e.wrench_trace.is_some());
                continue;
            };
            assert_eq!(a.samples.len(), b.samples.len());
            for (x, y) in a.samples.iter().zip(&b.samples) {
                assert_eq!(x.probe, y.probe);
                assert!(
                    (x.height_mm - y.height_mm).abs() < 1e-9
                        && (x.force_n - y.force_n).abs() < 1e-9
                );
            }
        }
    }
    // The rims were swept once per step, for all five episodes, and a cold sweep reads the
    // same: the last episode again on a fresh set-up records the same steps and traces.
    let rims = &setup.engine.rims;
    assert_eq!((rims.swept(), rims.lookups()), (3, 15));
    let warm = run_sim_episode(&setup, 4).await.unwrap();
    let fresh = SimSetup::new(setup.scenario().clone()).unwrap();
    let cold = run_sim_episode(&fresh, 4).await.unwrap();
    assert_eq!(fresh.engine.rims.swept(), 3);
    assert_eq!(warm.record.steps, cold.record.steps);
    let traces = |o: &cell::orchestrator::EpisodeOutput| -> Vec<_> {
        o.events
            .events()
            .iter()
            .filter_map(|e| e.wrench_trace.clone())
            .collect()
    };
    assert_eq!(traces(&warm), traces(&cold));
    assert!(traces(&warm).iter().all(|t| !t.landings_mm.is_empty()));
    // An event file from before traces were kept still loads, without one.
    let old: cell::orchestrator::Event = serde_json::from_str(
        r#"{"episode":0,"step":0,"from":"insert","to":"verify","sim_time_s":3.2,"wall_time_s":0.1,"detail":"force-guided: ..."}"#,
    )
    .unwrap();
    assert_eq!(old.wrench_trace, None);
}

#[test]
fn bad_force_insertion_values_are_refused_at_their_line_and_column() {
    let text = std::fs::read_to_string(support::nominal()).unwrap();
    for (line, key, words) in [
        (
            "contact_force = 2.0",
            "force_insertion.contact_force",
            "precision",
        ),
        (
            "contact_speed = 5.0",
            "force_insertion.contact_speed",
            "max_tcp_speed",
        ),
        (
            "seat_band = -0.001",
            "force_insertion.seat_band",
            "positive",
        ),
        (
            "search_points = 100",
            "force_insertion.search_points",
            "at most 32",
        ),
    ] {
        let variant = format!("{text}\n[force_insertion]\n{line}\n");
        let err = load_variant("bad_force", &variant).unwrap_err();
        let p = &err.0[0];
        assert_eq!(p.key.as_deref(), Some(key), "{err}");
        assert_eq!(p.line, support::line_of(&variant, line), "{err}");
        let value_column = line.find('=').unwrap() + 3;
        assert_eq!(p.column, value_column, "{err}");
        assert!(p.message.contains(words), "{err}");
    }
    // An unknown key in the table is refused too.
    let variant = format!("{text}\n[force_insertion]\ncontact_forse = 10.0\n");
    let err = load_variant("bad_force_key", &variant).unwrap_err();
    assert_eq!(
        err.0[0].line,
        support::line_of(&variant, "contact_forse"),
        "{err}"
    );
}

/// The verdict bench of `cell scorers --force-verdicts` on boundary insertions scored by the
/// rapier contact engine: read from the engine's stop, seated-or-not agrees with the engine on
/// every insertion and the seat band lies between the seated and the unseated stops; a seat band
/// above the receivers' rims would call misses seated, and the bench says so.
#[test]
fn force_verdicts_agree_with_the_contact_engine_on_boundary_insertions() {
    use cell::orchestrator::insertion::agreement::force_agreement;
    use sim::cell::geometry::CellGeometry;
    use sim::cell::insertion::Scorer;
    use sim::cell::insertion::agreement::StepGeometry;

    let setup = setup("verdict_bench", "");
    let spec = &setup.scenario().spec;
    let geometry =
        CellGeometry::new(&spec.cell, &spec.assembly, &setup.scenario().catalog).unwrap();
    let steps: Vec<StepGeometry<'_>> = (0..spec.assembly.len())
        .map(|i| StepGeometry::nominal(&geometry, &spec.assembly, i).unwrap())
        .collect();
    let rapier = Scorer::from_name("rapier").unwrap().build().unwrap();
    let analytic = Scorer::Analytic.build().unwrap();
    let force = spec.force_insertion.unwrap();
    let a = force_agreement(&steps, 60, 3, &rapier, &analytic, &force).unwrap();
    assert_eq!((a.truth.as_str(), a.cell.as_str()), ("contact", "analytic"));
    assert_eq!(a.all.samples, 60);
    assert_eq!(a.steps.iter().map(|(_, c)| c.samples).sum::<usize>(), 60);
    assert!(
        a.all.truth_seated > 0 && a.all.truth_seated < 60,
        "{:?}",
        a.all
    );
    assert_eq!(a.all.engine_seating, 60, "{:#?}", a.disagreements);
    // The top shell's rim misses land below its engagement depth and still read missed.
    let (_, top) = a.steps.iter().find(|(p, _)| p == "top_shell").unwrap();
    assert!(top.confusion[2][2] > 0, "{top:?}");
    assert_eq!(top.confusion[2][1], 0, "no rim miss reads jammed: {top:?}");
    assert_eq!(
        top.confusion.iter().flatten().sum::<usize>(),
        top.samples,
        "{top:?}"
    );
    let (seated, unseated) = (
        a.all.seated_stop_max.unwrap(),
        a.all.unseated_stop_min.unwrap(),
    );
    assert!(
        seated < force.seat_band && force.seat_band < unseated,
        "{seated} {unseated}"
    );
    // Every case where a verdict differs from the truth is listed, and only those.
    let listed = a
        .disagreements
        .iter()
        .filter(|c| (c.engine == StepOutcome::Seated) != (c.truth == StepOutcome::Seated))
        .count();
    assert_eq!(listed, 60 - a.all.engine_seating);
    assert_eq!(
        a.disagreements.len(),
        a.disagreements
            .iter()
            .filter(|c| c.engine != c.truth || c.cell != c.truth)
            .count()
    );

    let wide = ForceInsertionSpec {
        seat_band: 0.003,
        ..force
    };
    let b = force_agreement(&steps, 60, 3, &rapier, &analytic, &wide).unwrap();
    assert!(
        b.all.engine_seating < 60,
        "a 3 mm seat band calls parts on a rim seated"
    );
    // A cell scored by rapier feels rapier's stop: its verdicts are the engine's, case by case.
    let c = force_agreement(&steps, 60, 3, &rapier, &rapier, &force).unwrap();
    assert_eq!(c.all.cell_seating, c.all.engine_seating);
    assert_eq!(c.all.cell_outcome, c.all.engine_outcome);
    assert!(
        c.disagreements
            .iter()
            .all(|d| d.cell_stop == d.truth_stop && d.cell == d.engine)
    );
    assert!(
        a.disagreements.iter().any(|d| d.cell_stop != d.truth_stop),
        "the analytic stop is not rapier's"
    );
    assert_eq!(
        b.disagreements
            .iter()
            .filter(|c| c.engine == StepOutcome::Seated && c.truth != StepOutcome::Seated)
            .count(),
        60 - b.all.engine_seating
    );
}

/// `cell scorers --force-verdicts` through the real binary: the table of every step, the
/// seated and unseated stops around the seat band, the JSON of the counts and disagreements,
/// and the exit status against `--min-agreement`.
#[test]
fn the_scorers_command_measures_the_force_verdicts() {
    let out = std::env::temp_dir().join(format!("cell_force_verdicts_{}.json", std::process::id()));
    let o = support::cell(&[
        "scorers",
        &support::nominal(),
        "--force-verdicts",
        "--samples",
        "45",
        "--min-agreement",
        "0.99",
        "--out",
        &out.display().to_string(),
    ]);
    let t = support::text(&o);
    assert!(o.status.success(), "{t}");
    for part in ["main_shell", "insert_mold", "top_shell"] {
        assert!(
            t.contains(&format!("{part}: contact stops seated parts up to")),
            "{t}"
        );
    }
    assert!(t.contains("45 insertions in"), "{t}");
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap();
    std::fs::remove_file(&out).unwrap();
    assert_eq!(json["all"]["samples"], 45);
    assert_eq!(json["all"]["engine_seating"], 45, "{json}");
    assert_eq!(json["truth"], "contact");
    // Seated-or-not agrees on every insertion, so even a minimum of 100 % passes.
    let o = support::cell(&[
        "scorers",
        &support::nominal(),
        "--force-verdicts",
        "--samples",
        "45",
        "--engines",
        "analytic,rapier",
        "--min-agreement",
        "1.0",
    ]);
    assert!(
        o.status.success(),
        "seating agrees on all 45: {}",
        support::text(&o)
    );
}

/// `cell replay` of a force-guided episode draws each insertion's wrench trace.
#[test]
fn replay_plots_the_wrench_trace_of_each_force_guided_insertion() {
    struct Scenario(std::path::PathBuf);
    impl Drop for Scenario {
        fn drop(&mut self) {
            std::fs::remove_file(&self.0).ok();
        }
    }
    let text = std::fs::read_to_string(support::nominal()).unwrap();
    let scenario = Scenario(support::root().join(format!(
        "scenarios/.replay_force_{}.toml",
        std::process::id()
    )));
    std::fs::write(&scenario.0, format!("{text}\n[force_insertion]\n")).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let o = support::cell(&[
        "run",
        &scenario.0.display().to_string(),
        "--episodes",
        "1",
        "--pictures",
        "0",
        "--out",
        &tmp.path().display().to_string(),
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", support::text(&o));
    let dir = tmp.path().join("usbc-nominal/all");
    // The stored events carry the traces.
    let events = std::fs::read_to_string(dir.join("events/episode-000000.jsonl")).unwrap();
    assert_eq!(events.matches("\"wrench_trace\"").count(), 3, "{events}");
    let o = support::cell(&["replay", &dir.display().to_string(), "--episode", "0"]);
    let t = support::text(&o);
    assert!(o.status.success(), "{t}");
    assert!(t.contains("the replay matches the stored record"), "{t}");
    for step in 0..3 {
        let name = format!("episode-000000-step-{step}-insertion-1-wrench.svg");
        assert!(t.contains(&name), "{t}");
        let svg = std::fs::read_to_string(dir.join("pictures").join(&name)).unwrap();
        for text in [
            "seat band 0.200 mm",
            "top of the receiver from",
            "miss lands here",
            "stop at 10.0 N",
            "planned descent",
        ] {
            assert!(svg.contains(text), "{name}: {text} missing");
        }
        // The legend's heights are the event's own landing bands.
        let trace = events
            .lines()
            .filter_map(|l| serde_json::from_str::<cell::orchestrator::Event>(l).ok())
            .filter(|e| e.step == Some(step))
            .find_map(|e| e.wrench_trace)
            .unwrap();
        let first = trace.landings_mm[0];
        let band = format!("{:.3}–{:.3}", first[0], first[1]);
        assert!(svg.contains(&band), "{name}: {band} missing");
    }
}

/// On the top shell a miss lands below the engagement depth: offset across its open sides it
/// comes down onto what the main shell holds 1.35 mm above seated, and along its skirts onto the
/// main shell's rim 2.49 mm up, both under the 2.69 mm at which the engagement depth's rim
/// begins. Rapier calls them missed, and so do force and depth, through the sensor's ±4 N
/// either way; a part tilted beyond its jam angle stops inside and reads jammed.
#[test]
fn a_top_shell_rim_miss_below_its_engagement_depth_reads_missed_and_a_jam_jammed() {
    use cell::orchestrator::insertion::agreement::step_rims;
    use cell::orchestrator::insertion::verdict_at;
    use nalgebra::Vector2;
    use sim::cell::geometry::CellGeometry;
    use sim::cell::insertion::agreement::StepGeometry;
    use sim::cell::insertion::{InsertionCase, Scorer};

    let setup = setup("top_shell_rims", "");
    let spec = &setup.scenario().spec;
    let force = spec.force_insertion.unwrap();
    let geometry =
        CellGeometry::new(&spec.cell, &spec.assembly, &setup.scenario().catalog).unwrap();
    let i = spec
        .assembly
        .iter()
        .position(|s| s.part == "top_shell")
        .unwrap();
    let step = StepGeometry::nominal(&geometry, &spec.assembly, i).unwrap();
    let rims = step_rims(&step, &force);
    let rapier = Scorer::from_name("rapier").unwrap().build().unwrap();
    let m = &step.mating;
    let push = |lateral: Vector2<f64>, tilt: f64, toward: Vector2<f64>| {
        let case = InsertionCase {
            mating: m,
            held: step.held,
            receivers: &step.receivers,
            ins_T_part: m.pose_with_error(lateral, 0.0, 0.0, tilt, toward),
        };
        rapier.score(&case).unwrap().result
    };
    let noise = 4.0 / force.contact_stiffness;
    let x = Vector2::x();
    for lateral in [
        Vector2::new(0.0, 1.2),
        Vector2::new(0.0, -1.2),
        Vector2::new(1.2, 0.0),
    ] {
        let r = push(lateral * m.capture(), 0.0, x);
        assert_eq!(r.verdict, Verdict::Missed, "{lateral:?}: {r:?}");
        let stop = r.end.height;
        assert!(
            stop < rims.rim,
            "{lateral:?}: lands at {stop}, below the receiver's top {}",
            rims.rim
        );
        for h in [stop - noise, stop, stop + noise] {
            assert_eq!(
                verdict_at(h, &rims, &force),
                StepOutcome::Missed,
                "{lateral:?}: first contact {h} against {:?}",
                rims.bands
            );
        }
    }
    // Tilted 50 mrad, beyond its 35 mrad jam angle, centred: it wedges half a millimetre up.
    let r = push(Vector2::zeros(), 0.05, x);
    assert_eq!(r.verdict, Verdict::Jammed, "{r:?}");
    for h in [r.end.height - noise, r.end.height + noise] {
        assert_eq!(
            verdict_at(h, &rims, &force),
            StepOutcome::Jammed,
            "first contact {h} against {:?}",
            rims.bands
        );
    }
}

/// A step given up after the spiral is blamed on the error sources that explain the lateral
/// error the search could not recover (the planned descent's, before any search offset), as a
/// plain cell's missed insertion is: here a 0.5 mm calibration error, beyond what eight probes
/// within the capture band and three attempts reach.
#[tokio::test]
async fn a_step_given_up_after_the_search_is_blamed_on_the_error_that_put_it_off_the_band() {
    let text = std::fs::read_to_string(support::nominal()).unwrap();
    let noise = text.find("[noise]").unwrap();
    let text = format!(
        "{}[noise]\nrobot_repeatability = 0.00001\ncalibration_translation = 0.0005\n\
         calibration_rotation = 0.00002\ngrasp_offset = 0.00002\ngrasp_rotation = 0.002\n\n\
         [force_insertion]\n",
        &text[..noise]
    );
    let setup = SimSetup::new(load_variant("blame_given_up", &text).unwrap()).unwrap();
    let mut given_up = 0;
    for episode in 0..6 {
        let out = run_sim_episode(&setup, episode).await.unwrap();
        for s in &out.record.steps {
            let cause = s.cause.clone().unwrap_or_default();
            if !cause.contains("not released") {
                continue;
            }
            given_up += 1;
            eprintln!(
                "GIVEUP {episode} {} {:?} {cause} {:?}",
                s.part, s.sources, s.pose_error
            );
            assert!(
                s.sources.iter().any(|x| x == "calibration_translation"),
                "episode {episode} {}: {cause}: blamed on {:?}",
                s.part,
                s.sources
            );
        }
    }
    assert!(given_up > 0, "some step was given up after the search");
}
