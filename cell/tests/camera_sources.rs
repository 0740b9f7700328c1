//! Production camera sources (`cell::camera`): the watched folder, the command per capture,
//! recorded-image replay, decoding of 8/16-bit mono/colour PNG and TIFF, the size check; and the
//! safety path: a camera error aborts the step before any motion, and the record says why.
//! Everything runs in temp dirs and on 127.0.0.1, with sub-second deadlines.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant, SystemTime};

use cell::camera::{
    self, CameraError, CameraSource, CameraSpec, CommandCamera, FilesCamera, FolderCamera, Sensor,
};
use image::{DynamicImage, ImageBuffer, Luma, Rgb, Rgba};

const SENSOR: Sensor = Sensor {
    width: 6,
    height: 4,
};

/// A 6 × 4 8-bit mono image whose pixels encode their position and `seed`.
fn mono8(seed: u8) -> DynamicImage {
    DynamicImage::ImageLuma8(ImageBuffer::from_fn(6, 4, |x, y| {
        Luma([seed.wrapping_add((10 * y + x) as u8)])
    }))
}

/// Writes `img` to `path` (format from the extension).
fn save(img: &DynamicImage, path: &Path) {
    img.save(path).unwrap();
}

/// The bytes of `img` as a PNG file.
fn png_bytes(img: &DynamicImage) -> Vec<u8> {
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).unwrap();
    out.into_inner()
}

/// Sets a file's modification time `ago` into the past.
fn age(path: &Path, ago: Duration) {
    let f = std::fs::File::options().write(true).open(path).unwrap();
    f.set_modified(SystemTime::now() - ago).unwrap();
}

/// Writes `bytes` to `dir/name` by a temporary name and a rename, as grab tools do.
fn write_renamed(dir: &Path, name: &str, bytes: &[u8]) {
    let tmp = dir.join(format!(".{name}.part"));
    std::fs::write(&tmp, bytes).unwrap();
    std::fs::rename(&tmp, dir.join(name)).unwrap();
}

// ---- the watched folder -------------------------------------------------------------------

#[test]
fn a_folder_capture_takes_the_new_image_and_never_an_old_one() {
    let dir = tempfile::tempdir().unwrap();
    save(&mono8(100), &dir.path().join("old.png"));
    let mut cam = FolderCamera::open(dir.path(), SENSOR).unwrap();
    let d = dir.path().to_path_buf();
    let writer = std::thread::spawn(move || {
        std::thread::sleep(Duration::from_millis(60));
        write_renamed(&d, "new.png", &png_bytes(&mono8(7)));
    });
    let shot = cam.capture(Duration::from_millis(800)).unwrap();
    writer.join().unwrap();
    assert_eq!(
        shot.path.as_deref(),
        Some(dir.path().join("new.png").as_path())
    );
    assert_eq!(shot.image.pixels, mono8(7));
    assert_eq!(shot.image.origin, [0, 0]);
    // The next capture again waits for a newer one: both files are old now.
    let t = Instant::now();
    let e = cam.capture(Duration::from_millis(120)).unwrap_err();
    assert!(matches!(e, CameraError::Timeout { .. }), "{e}");
    assert!(t.elapsed() >= Duration::from_millis(120));
    assert!(
        t.elapsed() < Duration::from_millis(600),
        "{:?}",
        t.elapsed()
    );
    assert!(
        e.to_string().contains(&dir.path().display().to_string()),
        "{e}"
    );
}

#[test]
fn a_folder_capture_refuses_an_image_moved_in_with_an_old_time() {
    let dir = tempfile::tempdir().unwrap();
    let outside = tempfile::tempdir().unwrap();
    let old = outside.path().join("grab.png");
    save(&mono8(1), &old);
    age(&old, Duration::from_secs(30));
    let mut cam = FolderCamera::open(dir.path(), SENSOR).unwrap();
    let target = dir.path().join("grab.png");
    let mover = std::thread::spawn(move || {
        std::thread::sleep(Duration::from_millis(40));
        // `mv` keeps the modification time: the picture is 30 s old.
        std::fs::rename(&old, &target).unwrap();
    });
    let e = cam.capture(Duration::from_millis(250)).unwrap_err();
    mover.join().unwrap();
    match &e {
        CameraError::Stale { path, age } => {
            assert_eq!(path, &dir.path().join("grab.png"));
            assert!(
                age.as_secs_f64() > 29.0 && age.as_secs_f64() < 31.0,
                "{age:?}"
            );
        }
        other => panic!("expected a stale image, got {other}"),
    }
    assert!(e.to_string().contains("grab.png"), "{e}");
}

#[test]
fn a_folder_capture_does_not_read_a_partly_written_image() {
    let dir = tempfile::tempdir().unwrap();
    let mut cam = FolderCamera::open(dir.path(), SENSOR).unwrap();
    let bytes = png_bytes(&mono8(42));
    let path = dir.path().join("frame.png");
    let (p, b) = (path.clone(), bytes.clone());
    // Half the file, a pause long enough for several polls, then the rest.
    let writer = std::thread::spawn(move || {
        use std::io::Write;
        std::thread::sleep(Duration::from_millis(30));
        let mut f = std::fs::File::create(&p).unwrap();
        f.write_all(&b[..b.len() / 2]).unwrap();
        f.flush().unwrap();
        std::thread::sleep(Duration::from_millis(150));
        f.write_all(&b[b.len() / 2..]).unwrap();
    });
    let shot = cam.capture(Duration::from_millis(900)).unwrap();
    writer.join().unwrap();
    assert_eq!(shot.image.pixels, mono8(42));
    assert_eq!(shot.path, Some(path.clone()));

    // A file that stays truncated is reported unreadable, naming it, never delivered.
    let cut = dir.path().join("cut.png");
    let c = cut.clone();
    let writer = std::thread::spawn(move || {
        std::thread::sleep(Duration::from_millis(30));
        std::fs::write(&c, &bytes[..bytes.len() / 2]).unwrap();
    });
    let e = cam.capture(Duration::from_millis(300)).unwrap_err();
    writer.join().unwrap();
    match &e {
        CameraError::Unreadable { path, .. } => assert_eq!(path, &cut),
        other => panic!("expected an unreadable image, got {other}"),
    }
}

#[test]
fn a_missing_or_vanished_folder_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("grabs");
    let e = FolderCamera::open(&missing, SENSOR).unwrap_err();
    assert_eq!(
        e,
        CameraError::Missing {
            path: missing.clone()
        }
    );
    assert!(e.to_string().ends_with("grabs: does not exist"), "{e}");
    std::fs::create_dir(&missing).unwrap();
    let mut cam = FolderCamera::open(&missing, SENSOR).unwrap();
    std::fs::remove_dir(&missing).unwrap();
    let e = cam.capture(Duration::from_millis(100)).unwrap_err();
    assert!(matches!(e, CameraError::Vanished { .. }), "{e}");
    assert!(e.to_string().contains("grabs"), "{e}");
}

#[test]
fn a_new_image_of_the_wrong_size_is_refused_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let mut cam = FolderCamera::open(dir.path(), SENSOR).unwrap();
    let d = dir.path().to_path_buf();
    let writer = std::thread::spawn(move || {
        std::thread::sleep(Duration::from_millis(30));
        let small = DynamicImage::ImageLuma8(ImageBuffer::from_pixel(5, 4, Luma([9u8])));
        write_renamed(&d, "small.png", &png_bytes(&small));
    });
    let t = Instant::now();
    let e = cam.capture(Duration::from_secs(2)).unwrap_err();
    writer.join().unwrap();
    assert!(t.elapsed() < Duration::from_secs(1), "{:?}", t.elapsed());
    assert_eq!(
        e,
        CameraError::WrongSize {
            what: dir.path().join("small.png").display().to_string(),
            expected_width: 6,
            expected_height: 4,
            got_width: 5,
            got_height: 4,
        }
    );
    assert!(e.to_string().contains("5 × 4"), "{e}");
    assert!(e.to_string().contains("6 × 4"), "{e}");
}

// ---- the command per capture --------------------------------------------------------------

/// Quotes `p` for the command line.
fn q(p: &Path) -> String {
    format!("'{}'", p.display())
}

#[test]
fn a_command_capture_reads_the_image_the_command_wrote() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("src.tiff");
    let img = DynamicImage::ImageRgb16(ImageBuffer::from_fn(6, 4, |x, y| {
        Rgb([1000 * x as u16, 3000 * y as u16, 65535])
    }));
    save(&img, &src);
    let mut cam = CommandCamera::open(&format!("cp {} {{path}}", q(&src)), SENSOR).unwrap();
    for _ in 0..2 {
        let shot = cam.capture(Duration::from_millis(900)).unwrap();
        assert_eq!(shot.image.pixels, img);
        let path = shot.path.unwrap();
        assert!(path.exists());
        assert!(shot.taken <= SystemTime::now());
    }
    assert!(cam.describe().contains("cp "), "{}", cam.describe());
}

#[test]
fn a_failing_command_reports_its_status_and_stderr() {
    let mut cam =
        CommandCamera::open("sh -c 'echo no camera on bus 2 >&2; exit 3' {path}", SENSOR).unwrap();
    let e = cam.capture(Duration::from_millis(900)).unwrap_err();
    match &e {
        CameraError::CommandFailed { status, stderr, .. } => {
            assert!(status.contains('3'), "{status}");
            assert_eq!(stderr, "no camera on bus 2");
        }
        other => panic!("expected a failed command, got {other}"),
    }
    assert!(e.to_string().contains("no camera on bus 2"), "{e}");
    // Exit 0 without an image is a failure too.
    let mut cam = CommandCamera::open("true {path}", SENSOR).unwrap();
    let e = cam.capture(Duration::from_millis(900)).unwrap_err();
    assert!(e.to_string().contains("wrote no image"), "{e}");
}

#[test]
fn a_hung_command_is_killed_within_the_deadline_with_what_it_started() {
    let dir = tempfile::tempdir().unwrap();
    let pid_file = dir.path().join("pid");
    // The shell starts a long sleep and waits: killing only the shell would leave the sleep.
    let mut cam = CommandCamera::open(
        &format!(
            "sh -c 'sleep 30 & echo $! > {}; wait' {{path}}",
            pid_file.display()
        ),
        SENSOR,
    )
    .unwrap();
    let t = Instant::now();
    let e = cam.capture(Duration::from_millis(500)).unwrap_err();
    let took = t.elapsed();
    assert!(matches!(e, CameraError::CommandHung { .. }), "{e}");
    assert!(took < Duration::from_millis(1500), "{took:?}");
    let pid = std::fs::read_to_string(&pid_file)
        .unwrap()
        .trim()
        .to_string();
    // The sleep is gone (or a zombie waiting to be reaped), not sleeping on.
    std::thread::sleep(Duration::from_millis(50));
    let state = std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .ok()
        .and_then(|s| s.rsplit(')').next().map(|r| r.trim().chars().next()))
        .flatten();
    assert!(matches!(state, None | Some('Z') | Some('X')), "{state:?}");
}

#[test]
fn a_command_that_delivers_an_old_file_is_refused_as_stale() {
    let dir = tempfile::tempdir().unwrap();
    let old = dir.path().join("old.png");
    save(&mono8(3), &old);
    age(&old, Duration::from_secs(60));
    // `cp -p` keeps the old modification time.
    let mut cam = CommandCamera::open(&format!("cp -p {} {{path}}", q(&old)), SENSOR).unwrap();
    let e = cam.capture(Duration::from_millis(900)).unwrap_err();
    assert!(matches!(e, CameraError::Stale { .. }), "{e}");
}

// ---- decoding -----------------------------------------------------------------------------

#[test]
fn png_and_tiff_decode_at_8_and_16_bits_mono_and_colour() {
    let dir = tempfile::tempdir().unwrap();
    let images = [
        mono8(5),
        DynamicImage::ImageLuma16(ImageBuffer::from_fn(6, 4, |x, y| {
            Luma([(x * 9000 + y * 700 + 3) as u16])
        })),
        DynamicImage::ImageRgb8(ImageBuffer::from_fn(6, 4, |x, y| {
            Rgb([x as u8 * 40, y as u8 * 60, 200])
        })),
        DynamicImage::ImageRgb16(ImageBuffer::from_fn(6, 4, |x, y| {
            Rgb([x as u16 * 10000, y as u16 * 20000 + 1, 65535])
        })),
    ];
    for (i, img) in images.iter().enumerate() {
        for ext in ["png", "tif"] {
            let path = dir.path().join(format!("{i}.{ext}"));
            save(img, &path);
            let got = camera::decode_file(&path, SENSOR).unwrap();
            assert_eq!(&got, img, "{}", path.display());
        }
    }
    // An alpha channel is dropped, the colour kept.
    let rgba = DynamicImage::ImageRgba8(ImageBuffer::from_fn(6, 4, |x, _| {
        Rgba([x as u8, 2, 3, 128])
    }));
    let path = dir.path().join("alpha.png");
    save(&rgba, &path);
    let got = camera::decode_file(&path, SENSOR).unwrap();
    assert_eq!(got, DynamicImage::ImageRgb8(rgba.to_rgb8()));
    // Float pixels are not a camera format the pipeline reads.
    let float = DynamicImage::ImageRgb32F(ImageBuffer::from_pixel(6, 4, Rgb([0.5f32; 3])));
    let e = camera::check_image(float, SENSOR, "x.tif").unwrap_err();
    assert!(matches!(e, CameraError::UnsupportedFormat { .. }), "{e}");
    // Not an image at all: unreadable, naming the file.
    let junk = dir.path().join("junk.png");
    std::fs::write(&junk, b"definitely not a png").unwrap();
    let e = camera::decode_file(&junk, SENSOR).unwrap_err();
    assert!(matches!(e, CameraError::Unreadable { .. }), "{e}");
    assert!(e.to_string().contains("junk.png"), "{e}");
}

#[test]
fn recorded_images_replay_in_order_then_end() {
    let dir = tempfile::tempdir().unwrap();
    save(&mono8(2), &dir.path().join("b.png"));
    save(&mono8(1), &dir.path().join("a.tiff"));
    let spec: CameraSpec = format!("files:{}", dir.path().display()).parse().unwrap();
    let mut cam = camera::open(&spec, SENSOR).unwrap();
    let deadline = Duration::from_millis(100);
    assert_eq!(cam.capture(deadline).unwrap().image.pixels, mono8(1));
    assert_eq!(cam.capture(deadline).unwrap().image.pixels, mono8(2));
    let e = cam.capture(deadline).unwrap_err();
    assert!(matches!(e, CameraError::Exhausted { count: 2, .. }), "{e}");
    // The size is checked on replay too.
    let big = Sensor {
        width: 7,
        height: 4,
    };
    let mut cam = FilesCamera::open(dir.path(), big).unwrap();
    assert!(matches!(
        cam.capture(deadline),
        Err(CameraError::WrongSize { .. })
    ));
}

// ---- safety: no motion on a camera error --------------------------------------------------

mod safety {
    use super::*;
    use cell::episode::StepOutcome;
    use cell::harness::{SimSetup, connect_sim_over_rtde, keypoint_noise_for};
    use cell::orchestrator::{
        CellIo, CellIoError, InsertionCheck, ProductionCellIo, SplitCell, State, run_episode,
    };
    use cell::scenario::Scenario;
    use perception::{Frame, FrameContent};
    use robots::observed::{Command, Observed};

    /// The production side channels, noting how many motions the arm had made when each
    /// capture was asked for.
    struct Watched {
        inner: ProductionCellIo,
        motions: Arc<AtomicUsize>,
        at_capture: Vec<usize>,
    }

    impl CellIo for Watched {
        fn capture(&mut self) -> Result<Frame, CellIoError> {
            self.at_capture.push(self.motions.load(Ordering::SeqCst));
            self.inner.capture()
        }
        fn shake_feeder(&mut self) -> Result<(), CellIoError> {
            self.inner.shake_feeder()
        }
        fn part_in_gripper(&mut self) -> Option<bool> {
            self.inner.part_in_gripper()
        }
        fn insertion_check(&mut self) -> Option<InsertionCheck> {
            self.inner.insertion_check()
        }
        fn clock(&self) -> f64 {
            self.inner.clock()
        }
    }

    fn scenario() -> Scenario {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/usbc_nominal.toml");
        Scenario::load(&path).unwrap()
    }

    /// Runs episode 0 through the production client (`UrRobot` over loopback RTDE to the
    /// virtual controller of a simulated cell) with the production side channels on `camera`.
    async fn episode_with(
        camera: Box<dyn CameraSource>,
    ) -> (cell::orchestrator::EpisodeOutput, Vec<usize>, usize) {
        let setup = SimSetup::new(scenario()).unwrap();
        let mut s = connect_sim_over_rtde(&setup, 0, Duration::from_millis(100))
            .await
            .unwrap();
        let motions = Arc::new(AtomicUsize::new(0));
        // Counts every command that moves the arm or the fingers.
        let counted = motions.clone();
        let mut robot = Observed::new(&mut s.robot, move |c: &Command<'_>| {
            if c.moves_arm() || c.moves_fingers() {
                counted.fetch_add(1, Ordering::SeqCst);
            }
        });
        let mut io = Watched {
            inner: ProductionCellIo::new(
                setup.scenario().clone(),
                camera,
                Duration::from_millis(200),
            ),
            motions: motions.clone(),
            at_capture: Vec::new(),
        };
        let mut perception = keypoint_noise_for(setup.scenario(), 0).unwrap();
        let mut cell = SplitCell {
            robot: &mut robot,
            io: &mut io,
        };
        let out = run_episode(setup.engine.context(0), &mut cell, &mut perception).await;
        let total = motions.load(Ordering::SeqCst);
        (out, io.at_capture, total)
    }

    /// Every camera error ends the step at the capture: no motion after it, the step aborted
    /// with the camera's reason, and the episode ends (never on an old picture).
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn no_motion_after_a_camera_error_and_the_record_says_why() {
        let sensor = Sensor::of(&scenario().spec.cell.camera.intrinsics);
        let empty = tempfile::tempdir().unwrap();
        let stale = tempfile::tempdir().unwrap();
        save(&mono8(0), &stale.path().join("yesterday.png"));
        let cases: Vec<(Box<dyn CameraSource>, String)> = vec![
            // Nothing new arrives: timeout.
            (
                Box::new(FolderCamera::open(empty.path(), sensor).unwrap()),
                format!("{}: no new image", empty.path().display()),
            ),
            // Only an old picture there: never used.
            (
                Box::new(FolderCamera::open(stale.path(), sensor).unwrap()),
                "no new image".into(),
            ),
            // The grab tool fails.
            (
                Box::new(
                    CommandCamera::open("sh -c 'echo sensor fault >&2; exit 1' {path}", sensor)
                        .unwrap(),
                ),
                "sensor fault".into(),
            ),
            // A recorded image of the wrong size.
            (
                Box::new(FilesCamera::open(&stale.path().join("yesterday.png"), sensor).unwrap()),
                "the scenario camera's sensor is 5472 × 3648".into(),
            ),
        ];
        for (camera, why) in cases {
            let described = camera.describe();
            let (out, at_capture, total) = episode_with(camera).await;
            assert_eq!(at_capture.len(), 1, "{described}: one capture");
            assert_eq!(
                total, at_capture[0],
                "{described}: the arm moved after the camera error"
            );
            let r = &out.record;
            assert!(!r.success, "{described}");
            assert_eq!(r.steps.len(), 1, "{described}");
            assert_eq!(r.steps[0].outcome, StepOutcome::Aborted, "{described}");
            let cause = r.steps[0].cause.as_deref().unwrap_or_default();
            assert!(cause.starts_with("camera: "), "{described}: {cause}");
            assert!(cause.contains(&why), "{described}: {cause}");
            let last = out.events.events().last().unwrap();
            assert_eq!(
                (last.from, last.to),
                (State::Capture, State::Done),
                "{described}"
            );
        }
    }

    /// The production side channels deliver a new image as a full-sensor frame with the
    /// scenario's calibration.
    #[test]
    fn production_capture_delivers_the_new_image_as_a_frame() {
        let mut s = scenario();
        s.spec.cell.camera.intrinsics.width = 6;
        s.spec.cell.camera.intrinsics.height = 4;
        let dir = tempfile::tempdir().unwrap();
        let spec = CameraSpec::Folder(dir.path().into());
        let source = cell::orchestrator::open_camera(&s, &spec).unwrap();
        let mut io = ProductionCellIo::new(s.clone(), source, Duration::from_millis(800));
        let d: PathBuf = dir.path().into();
        let writer = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(40));
            write_renamed(&d, "f.png", &png_bytes(&mono8(9)));
        });
        let frame = io.capture().unwrap();
        writer.join().unwrap();
        assert_eq!(frame.camera, s.spec.cell.camera.intrinsics);
        match frame.content {
            FrameContent::Image(img) => {
                assert_eq!(img.pixels, mono8(9));
                img.check_on_sensor(&frame.camera).unwrap();
            }
            FrameContent::Simulated(_) => panic!("production frames carry pixels"),
        }
    }
}
