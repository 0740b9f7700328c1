//! The seat check by camera (`[seat_check]`): the simulated fixture window rendered from the true
//! state, the placed part's outline aligned on it from its target pose, the arm-in-view refusal,
//! and the engine running it.

#![allow(non_snake_case)]

mod support;

use nalgebra::{Isometry3, Translation3, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use cell::episode::SeatCheckVerdict;
use cell::harness::{SimSetup, run_sim_episode};
use cell::orchestrator::seat_check::{
    NotSeen, SeatMeasurement, SeatTolerance, arm_in_fixture_view, hidden_by_construction, judge,
    measure_seat, pose_out_of_view,
};
use cell::scenario::SeatCheckSpec;
use perception::{Frame, FrameContent, FrameImage};
use sim::cell::fixture_view::render_fixture;
use support::load_variant;

/// The nominal scenario with every error source off, `[seat_check]` on with `extra`, and
/// `more` appended.
fn setup(tag: &str, extra: &str, more: &str) -> SimSetup {
    let text = std::fs::read_to_string(support::nominal()).unwrap();
    let noise = text.find("[noise]").expect("a noise table");
    let text = format!(
        "{}[noise]\nrobot_repeatability = 0.0\ncalibration_translation = 0.0\n\
         calibration_rotation = 0.0\ngrasp_offset = 0.0\ngrasp_rotation = 0.0\n\n\
         [seat_check]\n{extra}\n{more}\n",
        &text[..noise]
    );
    SimSetup::new(load_variant(tag, &text).unwrap()).unwrap()
}

/// The fixture with `parts` (step index, pose in its insertion frame relative to the target)
/// rendered from the calibrated camera, as a frame the check reads.
fn frame_of(setup: &SimSetup, parts: &[(usize, Isometry3<f64>)], seed: u64) -> Frame {
    let k = &setup.engine.knowledge;
    let placed: Vec<(&str, Isometry3<f64>)> = parts
        .iter()
        .map(|(step, off)| {
            let ins = k.base_T_insertions[*step];
            let target = ins.inverse() * k.base_T_targets[*step];
            (k.steps[*step].part.as_str(), ins * off * target)
        })
        .collect();
    let base_T_camera = k.geometry.base_T_camera_nominal;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let shot = render_fixture(&setup.model, &placed, &base_T_camera, &mut rng).unwrap();
    Frame {
        camera: setup.model.spec.camera.intrinsics,
        base_T_camera,
        content: FrameContent::Image(FrameImage {
            pixels: image::DynamicImage::ImageRgb8(shot.image),
            origin: [shot.window.x0, shot.window.y0],
        }),
    }
}

fn lateral(x: f64, y: f64) -> Isometry3<f64> {
    Isometry3::from(Translation3::new(x, y, 0.0))
}

/// The check of step `step` on the fixture holding `parts`, under the default `[seat_check]`.
fn checked(
    setup: &SimSetup,
    parts: &[(usize, Isometry3<f64>)],
    step: usize,
) -> (
    Result<SeatMeasurement, NotSeen>,
    SeatCheckVerdict,
    Option<String>,
) {
    let k = &setup.engine.knowledge;
    let frame = frame_of(setup, parts, 7 + step as u64);
    let m = measure_seat(k, &setup.engine.scenario.catalog, step, &frame);
    let tol = SeatTolerance::of(&SeatCheckSpec::default(), k, step);
    let (verdict, why) = judge(&m, &tol);
    (m, verdict, why)
}

#[test]
fn a_seated_part_passes_and_one_placed_off_its_seat_fails_with_the_offset_measured() {
    let setup = setup("seat_offsets", "", "");
    let k = &setup.engine.knowledge;
    let tol = SeatTolerance::of(&SeatCheckSpec::default(), k, 0);
    // The step's 0.1 mm plus the measurement's allowance.
    assert!((tol.lateral - 0.00016).abs() < 1e-12, "{tol:?}");
    let id = Isometry3::identity();
    // The main shell in the nest, and the top shell over the shell and the insert mold.
    for (parts, step) in [(vec![(0, id)], 0), (vec![(0, id), (1, id), (2, id)], 2)] {
        let (m, verdict, why) = checked(&setup, &parts, step);
        assert_eq!(
            verdict,
            SeatCheckVerdict::Passed,
            "step {step}: {why:?} {m:?}"
        );
        let m = m.unwrap();
        assert!(m.offset.norm() < 1e-4, "step {step}: {m:?}");
        assert!(m.support > 0.7 && m.samples >= 100, "step {step}: {m:?}");
        // 0.3 mm beside its seat (a part left on the rim, a seat the force misjudged).
        let mut off = parts.clone();
        off.last_mut().unwrap().1 = lateral(3e-4, 0.0);
        let (m, verdict, why) = checked(&setup, &off, step);
        assert_eq!(verdict, SeatCheckVerdict::Failed, "step {step}: {m:?}");
        let m = m.unwrap();
        assert!(
            m.offset.x > 0.18e-3 && m.offset.norm() > tol.lateral,
            "step {step}: measured {m:?}"
        );
        let why = why.unwrap();
        for words in ["lateral offset", "beyond the 0.160 mm tolerance"] {
            assert!(why.contains(words), "step {step}: {why}");
        }
        assert!(
            why.contains(&format!("{:.3} mm", m.offset.norm() * 1e3)),
            "{why}"
        );
    }
    // Sideways too, across the shell's tabs.
    let (m, verdict, _) = checked(&setup, &[(0, lateral(0.0, 3e-4))], 0);
    assert_eq!(verdict, SeatCheckVerdict::Failed, "{m:?}");
    assert!(m.unwrap().offset.y > 0.15e-3);
}

#[test]
fn an_empty_nest_is_not_visible_and_a_part_inside_its_receiver_cannot_be_seen() {
    let setup = setup("seat_unseen", "", "");
    let id = Isometry3::identity();
    // No shell in the nest: the pocket's edges are there, the shell's own (tabs, floor
    // window) are not.
    let (m, verdict, why) = checked(&setup, &[], 0);
    assert_eq!(verdict, SeatCheckVerdict::NotVisible, "{m:?}");
    assert!(!m.as_ref().is_ok_and(|m| m.support >= 0.6), "{m:?}");
    assert!(why.unwrap().contains("not visible"));
    // No top shell over the shell and the mold.
    let (m, verdict, _) = checked(&setup, &[(0, id), (1, id)], 2);
    assert_eq!(verdict, SeatCheckVerdict::NotVisible, "{m:?}");
    // The insert mold sits a clearance inside the shell's walls: its whole outline lies on
    // the shell's edges, so no image shows it, seated, off or absent.
    for parts in [vec![(0, id), (1, id)], vec![(0, id)]] {
        let (m, verdict, why) = checked(&setup, &parts, 1);
        assert_eq!(verdict, SeatCheckVerdict::NotVisible);
        let n = m.unwrap_err();
        assert!(n.by_geometry && n.samples < 12, "{n:?}");
        assert!(why.unwrap().contains("samples of its own"));
    }
    // Known before any capture, from the calibrated camera: the mold only.
    let (k, catalog) = (&setup.engine.knowledge, &setup.engine.scenario.catalog);
    let hidden: Vec<bool> = (0..3)
        .map(|step| hidden_by_construction(k, catalog, step).is_some())
        .collect();
    assert_eq!(hidden, [false, true, false]);
}

#[test]
fn a_capture_with_the_arm_over_the_fixture_is_refused_and_home_is_clear() {
    let setup = setup("seat_arm", "", "");
    let k = &setup.engine.knowledge;
    let home = setup.model.home;
    assert_eq!(arm_in_fixture_view(k, &home, None), None);
    // The retreat after an insertion: the TCP 20 mm above the seated shell, fingers down.
    let above = Isometry3::from_parts(
        Translation3::from(k.base_T_targets[0].translation.vector + Vector3::new(0.0, 0.0, 0.02)),
        cell::orchestrator::top_down(0.0),
    );
    let q = k.kinematics.inverse_nearest(&above, &home).unwrap().joints;
    assert!(arm_in_fixture_view(k, &q, None).is_some());
    // Sideways at that height, the arm leaves the view.
    let (aside, q_aside) = pose_out_of_view(k, &above, &q).expect("a pose out of view");
    let moved = aside.translation.vector - above.translation.vector;
    println!("aside by {:.3} m", moved.norm());
    assert!(moved.z.abs() < 1e-12 && moved.norm() <= 0.2, "{moved}");
    assert_eq!(arm_in_fixture_view(k, &q_aside, None), None);
    // Nor in the feeder's, where the next step's capture is taken from there.
    assert_eq!(
        cell::orchestrator::view::arm_in_feeder_view(k, &q_aside, None),
        None
    );
    // Over the feeder, the arm is out of the fixture's view but in the feeder's.
    let feeder = k.spec.feeder.center;
    let over_feeder = Isometry3::from_parts(
        Translation3::from(
            (k.geometry.base_T_table * nalgebra::Point3::new(feeder[0], feeder[1], 0.03)).coords,
        ),
        cell::orchestrator::top_down(0.0),
    );
    let q = k
        .kinematics
        .inverse_nearest(&over_feeder, &home)
        .unwrap()
        .joints;
    assert_eq!(arm_in_fixture_view(k, &q, None), None);
    assert!(cell::orchestrator::view::arm_in_feeder_view(k, &q, None).is_some());
}

/// Episodes of the nominal cell (every error source on) with the check: every seat is checked
/// after its retreat, the shells pass, the insert mold is recorded not visible and keeps its
/// seat; the check's error against the true offset on 50 seated shells, and its time.
#[tokio::test]
async fn episodes_check_every_seat_and_measure_it_within_the_allowance() {
    let text = std::fs::read_to_string(support::nominal()).unwrap();
    let setup =
        SimSetup::new(load_variant("seat_episodes", &format!("{text}\n[seat_check]\n")).unwrap())
            .unwrap();
    let (mut errors, mut ms) = (Vec::new(), Vec::new());
    let mut episode = 0;
    let mut cycle = 0.0;
    while errors.len() < 50 {
        let out = run_sim_episode(&setup, episode).await.unwrap();
        cycle += out.record.cycle_time_s;
        assert!(out.record.success, "episode {episode}: {:?}", out.record);
        for s in &out.record.steps {
            let c = s.seat_check.expect("every seat is checked");
            if s.part == "insert_mold" {
                assert_eq!(c.verdict, SeatCheckVerdict::NotVisible, "{c:?}");
                assert_eq!(c.samples, 0);
                continue;
            }
            assert_eq!(c.verdict, SeatCheckVerdict::Passed, "{}: {c:?}", s.part);
            let (m, t) = (c.offset_mm.unwrap(), c.true_offset_mm.unwrap());
            errors.push((m[0] - t[0]).hypot(m[1] - t[1]) * 1e3);
        }
        // The two shells' passes are logged with the time each check took.
        let passed: Vec<f64> = out
            .events
            .events()
            .iter()
            .filter_map(|e| {
                let at = e.detail.find("seat check passed")?;
                let text = &e.detail[at..];
                let from = text.find("alignment in ")? + "alignment in ".len();
                let to = from + text[from..].find(" ms")?;
                text[from..to].parse::<f64>().ok()
            })
            .collect();
        assert_eq!(passed.len(), 2, "episode {episode}: two passes logged");
        ms.extend(passed);
        episode += 1;
    }
    let n = errors.len() as f64;
    let mean = errors.iter().sum::<f64>() / n;
    let max = errors.iter().copied().fold(0.0, f64::max);
    let mean_ms = ms.iter().sum::<f64>() / n;
    let max_ms = ms.iter().copied().fold(0.0, f64::max);
    println!(
        "{} seated shells in {episode} episodes: measured against true offset {mean:.1} µm mean, \
         {max:.1} µm max; {mean_ms:.1} ms mean, {max_ms:.1} ms max per check",
        errors.len()
    );
    // What it costs on the cell's clock: the same episodes without the check.
    let plain = SimSetup::new(load_variant("seat_plain", &text).unwrap()).unwrap();
    let mut plain_cycle = 0.0;
    for e in 0..episode {
        plain_cycle += run_sim_episode(&plain, e)
            .await
            .unwrap()
            .record
            .cycle_time_s;
    }
    println!(
        "cycle time {:.2} s with the check, {:.2} s without (mean of {episode} episodes)",
        cycle / f64::from(episode),
        plain_cycle / f64::from(episode)
    );
    // About half a pixel at worst (141 µm a pixel at the fixture).
    assert!(mean < 80.0 && max < 140.0, "{mean:.1} / {max:.1} µm");
    // The record and the report carry it.
    let out = run_sim_episode(&setup, 0).await.unwrap();
    let json = serde_json::to_string(&out.record).unwrap();
    assert!(
        json.contains("\"seat_check\":{\"verdict\":\"passed\""),
        "{json}"
    );
    let back: cell::episode::EpisodeRecord = serde_json::from_str(&json).unwrap();
    // (serde_json may move a float by its last bit: compare what the check wrote.)
    for (b, s) in back.steps.iter().zip(&out.record.steps) {
        let (b, s) = (b.seat_check.unwrap(), s.seat_check.unwrap());
        assert_eq!(
            (b.verdict, b.samples, b.tolerance),
            (s.verdict, s.samples, s.tolerance)
        );
    }
    // The record is deterministic (no wall-clock time in it): a replay equals it.
    let again = run_sim_episode(&setup, 0).await.unwrap();
    assert_eq!(
        again.record.steps, out.record.steps,
        "the same episode checks alike"
    );
    let html = cell::report::seat::seat_section(&[&out.record]);
    assert!(html.contains("Seat checks by camera"), "{html}");
}

/// Without the table, no capture is taken and the records are as before.
#[tokio::test]
async fn without_the_table_no_seat_is_checked() {
    let text = std::fs::read_to_string(support::nominal()).unwrap();
    let setup = SimSetup::new(load_variant("seat_off", &text).unwrap()).unwrap();
    let out = run_sim_episode(&setup, 0).await.unwrap();
    assert!(out.record.steps.iter().all(|s| s.seat_check.is_none()));
    assert!(
        !serde_json::to_string(&out.record)
            .unwrap()
            .contains("seat_check")
    );
}

#[test]
fn bad_seat_check_values_are_refused_at_their_line_and_column() {
    let text = std::fs::read_to_string(support::nominal()).unwrap();
    for (line, key, words) in [
        ("lateral = -0.0001", "seat_check.lateral", "positive"),
        ("yaw = 0.0", "seat_check.yaw", "positive"),
        ("min_support = 1.5", "seat_check.min_support", "at most 1"),
    ] {
        let variant = format!("{text}\n[seat_check]\n{line}\n");
        let err = load_variant("bad_seat", &variant).unwrap_err();
        let p = &err.0[0];
        assert_eq!(p.key.as_deref(), Some(key), "{err}");
        assert_eq!(p.line, support::line_of(&variant, line), "{err}");
        assert_eq!(p.column, line.find('=').unwrap() + 3, "{err}");
        assert!(p.message.contains(words), "{err}");
    }
    let variant = format!("{text}\n[seat_check]\nlaterall = 0.0001\n");
    let err = load_variant("bad_seat_key", &variant).unwrap_err();
    assert_eq!(
        err.0[0].line,
        support::line_of(&variant, "laterall"),
        "{err}"
    );
}

/// Production reads the fixture through the camera source a production run uses: full-sensor
/// images (here recorded files, the fixture window pasted into a flat grey sensor image) read by
/// `ProductionCellIo`, whose `capture_fixture` is its camera capture; the check passes the seated
/// shell and fails the one beside its seat.
#[test]
fn production_checks_the_fixture_in_full_sensor_images_from_its_camera_source() {
    use cell::orchestrator::{CellIo, ProductionCellIo, open_camera};
    let setup = setup("seat_production", "", "");
    let k = &setup.engine.knowledge;
    let camera = setup.model.spec.camera.intrinsics;
    let dir = tempfile::tempdir().unwrap();
    for (name, off) in [
        ("a_seated.png", Isometry3::identity()),
        ("b_beside.png", lateral(3e-4, 0.0)),
    ] {
        let frame = frame_of(&setup, &[(0, off)], 3);
        let FrameContent::Image(window) = frame.content else {
            panic!("a rendered window")
        };
        let mut full = image::GrayImage::from_pixel(camera.width, camera.height, image::Luma([90]));
        image::imageops::replace(
            &mut full,
            &window.pixels.to_luma8(),
            i64::from(window.origin[0]),
            i64::from(window.origin[1]),
        );
        full.save(dir.path().join(name)).unwrap();
    }
    let scenario = setup.engine.scenario.clone();
    let source = open_camera(
        &scenario,
        &cell::camera::CameraSpec::Files(dir.path().to_path_buf()),
    )
    .unwrap();
    let mut io = ProductionCellIo::new(scenario, source, std::time::Duration::from_secs(5));
    let tol = SeatTolerance::of(&SeatCheckSpec::default(), k, 0);
    let catalog = &setup.engine.scenario.catalog;
    let mut verdicts = Vec::new();
    for _ in 0..2 {
        let frame = io.capture_fixture().unwrap();
        let FrameContent::Image(image) = &frame.content else {
            panic!("pixels")
        };
        assert_eq!(image.origin, [0, 0], "the full sensor");
        let m = measure_seat(k, catalog, 0, &frame);
        verdicts.push(judge(&m, &tol).0);
    }
    assert_eq!(
        verdicts,
        [SeatCheckVerdict::Passed, SeatCheckVerdict::Failed]
    );
    // Production knows no true pose.
    assert_eq!(io.placed_truth(0), None);
}

/// A check that does not pass stops the step and says why: with a tolerance no measurement
/// meets (10 µm), the first seat fails with the offset measured and the tolerance, blamed on the
/// seat check, and the episode ends there.
#[tokio::test]
async fn a_failed_check_stops_the_step_and_says_why() {
    let setup = setup("seat_fails", "lateral = 0.00001", "");
    let out = run_sim_episode(&setup, 0).await.unwrap();
    let r = &out.record;
    assert!(!r.success);
    assert_eq!(r.steps.len(), 1, "{r:?}");
    let s = &r.steps[0];
    assert_eq!(s.outcome, cell::episode::StepOutcome::Missed);
    assert_eq!(s.sources, ["seat_check"]);
    let c = s.seat_check.unwrap();
    assert_eq!(c.verdict, SeatCheckVerdict::Failed);
    let [x, y] = c.offset_mm.unwrap();
    let cause = s.cause.as_deref().unwrap();
    for words in [
        "the seat check measured the placed part lateral offset".to_string(),
        format!("{:.3} mm", x.hypot(y)),
        "beyond the 0.010 mm tolerance".to_string(),
    ] {
        assert!(cause.contains(&words), "{cause}");
    }
}
