//! Pixels in the loop: the nominal cell with learned perception. Every capture renders the
//! feeder window from the true world and only those pixels (with the calibrated camera) reach
//! the learned pipeline. A short run must end every episode cleanly with each failure blamed on
//! its cause, and the production path (the virtual UR over loopback RTDE, its captures read as
//! full-sensor image files through the camera interface) must give the in-process outcomes.

mod e2e_support;

use std::time::Duration;

use cell::episode::{EpisodeRecord, PERCEPTION_MISSED, PerceptionVerdict, StepOutcome};
use cell::harness::{connect_sim_over_rtde, run_sim_episode, sim_cell_io};
use cell::orchestrator::{SplitCell, run_episode};

use e2e_support::{Setup, setup};

/// Episodes of the short learned run.
const EPISODES: u32 = 10;
/// Fewest episodes of the short run that must assemble. Measured with the committed models
/// (2026-11-25) at the 12 px gate: 10 of 10 (191 of 200, 95.5 %, in `cell run
/// scenarios/usbc_learned.toml`); one episode of slack for ONNX Runtime's arithmetic differing on
/// another CPU (the previous models gave 8 of 10, keypoint-only poses 1 of 10).
const MIN_ASSEMBLED: usize = 9;

fn learned() -> Setup {
    setup(|doc| {
        doc["perception"]["mode"] = toml_edit::value("learned");
        doc["perception"]["models"] = toml_edit::value("models/usbc");
        // The gate scenarios/usbc_learned.toml ships with.
        doc["perception"]["max_rms_px"] = toml_edit::value(12.0);
    })
}

fn key(r: &EpisodeRecord) -> Vec<(String, cell::episode::StepOutcome, u32, u32)> {
    r.steps
        .iter()
        .map(|s| (s.part.clone(), s.outcome, s.attempts, s.shakes))
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_short_learned_run_ends_cleanly_and_blames_each_failure() {
    let setup = learned();
    assert!(setup.perception.needs_pixels());
    let mut assembled = 0;
    for episode in 0..EPISODES {
        let record = run_sim_episode(&setup, episode).await.unwrap().record;
        assert_eq!(record.abort, None, "episode {episode}: {record:#?}");
        assembled += usize::from(record.success);
        for s in &record.steps {
            if s.outcome == StepOutcome::Seated {
                continue;
            }
            // A failed step names its cause; one that never picked blames what perception
            // missed (the camera saw parts of its kind), not the feeder or the robot.
            assert!(!s.sources.is_empty(), "episode {episode}: {s:?}");
            match s.perception_verdict {
                None => assert_eq!(s.sources, [PERCEPTION_MISSED], "episode {episode}: {s:?}"),
                Some(PerceptionVerdict::Right) => assert!(s.perception_error.is_some()),
                Some(v) => assert_eq!(s.sources, [v.source().unwrap()], "episode {episode}"),
            }
        }
    }
    eprintln!("{assembled} of {EPISODES} learned episodes assembled");
    assert!(
        assembled >= MIN_ASSEMBLED,
        "{assembled} of {EPISODES} learned episodes assembled"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn learned_episodes_over_rtde_match_the_in_process_run() {
    // The link's warnings (a stall, a reconnect, a stopped program) print with a failure.
    let _ = tracing_subscriber::fmt()
        .with_test_writer()
        .with_max_level(tracing_subscriber::filter::LevelFilter::WARN)
        .try_init();
    let setup = learned();
    for episode in 0..2u32 {
        let local = run_sim_episode(&setup, episode).await.unwrap().record;
        let s = connect_sim_over_rtde(&setup, episode, Duration::from_millis(100))
            .await
            .unwrap();
        let (vur, mut robot) = (s.controller, s.robot);
        // Captures reach perception as full-sensor image files, as a production camera's do.
        let mut io = sim_cell_io(&setup, s.cell).unwrap();
        let mut perception = setup
            .perception
            .for_episode(setup.scenario(), episode)
            .unwrap();
        let mut cell = SplitCell {
            robot: &mut robot,
            io: &mut io,
        };
        let remote = run_episode(setup.engine.context(episode), &mut cell, &mut perception)
            .await
            .record;
        let link = robot.inner_mut().rtde();
        eprintln!(
            "episode {episode} over RTDE: {} stalls, {} reconnects",
            link.stalls(),
            link.reconnects()
        );
        drop(robot);
        drop(vur);
        assert_eq!(remote.abort, None, "episode {episode}");
        assert_eq!(remote.success, local.success, "episode {episode}");
        assert_eq!(key(&remote), key(&local), "episode {episode}");
        let verdicts = |r: &EpisodeRecord| {
            r.steps
                .iter()
                .map(|s| s.perception_verdict)
                .collect::<Vec<_>>()
        };
        assert_eq!(verdicts(&remote), verdicts(&local), "episode {episode}");
    }
}

/// The simulated camera of a virtual-UR run writes each capture as a full-sensor TIFF file and
/// reads it back through the camera interface: the sensor's full size, the rendered window's
/// pixels exactly where the in-memory capture of the same episode puts them, black elsewhere.
#[test]
fn the_simulated_camera_delivers_full_sensor_files_of_the_same_pixels() {
    use cell::camera::CameraSource;
    use cell::orchestrator::CellIo;
    use image::GenericImageView;
    use perception::FrameContent;

    let setup = learned();
    let memory = setup.cell(3).unwrap();
    let FrameContent::Image(window) = memory.lock().unwrap().capture().unwrap().content else {
        panic!("learned captures carry pixels");
    };
    let mut camera = cell::harness::SimulatedCamera::new(setup.cell(3).unwrap()).unwrap();
    let shot = camera.capture(Duration::from_secs(5)).unwrap();
    let path = shot.path.expect("read from a file");
    assert_eq!(path.extension().and_then(|e| e.to_str()), Some("tif"));
    let cam = &setup.scenario().spec.cell.camera.intrinsics;
    assert_eq!(shot.image.origin, [0, 0]);
    assert_eq!(
        (shot.image.width(), shot.image.height()),
        (cam.width, cam.height)
    );
    let [x0, y0] = window.origin;
    let inside = shot
        .image
        .pixels
        .view(x0, y0, window.width(), window.height())
        .to_image();
    assert!(
        inside.as_raw() == window.pixels.to_rgba8().as_raw(),
        "the window's pixels differ"
    );
    assert_eq!(shot.image.pixels.get_pixel(x0 - 1, y0).0, [0, 0, 0, 255]);
    assert_eq!(shot.image.pixels.get_pixel(0, 0).0, [0, 0, 0, 255]);
}
