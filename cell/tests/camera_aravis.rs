//! The GenICam source (`--camera aravis:DEVICE`, cargo feature `aravis`) against Aravis's GigE
//! Vision fake camera (`arv-fake-gv-camera-0.8`, from Debian's aravis-tools) on 127.0.0.1: a
//! capture delivers a frame of the camera's size, a wrong size is refused, and a camera that
//! vanishes mid-run gives `Vanished`. Without the fake camera the test says why it skips.
#![cfg(feature = "aravis")]

use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use cell::camera::{AravisCamera, CameraError, CameraSource, Sensor};

/// The fake camera's program.
const FAKE: &str = "arv-fake-gv-camera-0.8";

/// The fake camera on loopback, killed on drop.
struct FakeCamera(Child);

impl Drop for FakeCamera {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts the fake camera on 127.0.0.1, or says why not.
fn start_fake() -> Option<FakeCamera> {
    match Command::new(FAKE)
        .args(["-i", "127.0.0.1"])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
    {
        Ok(c) => Some(FakeCamera(c)),
        Err(e) => {
            eprintln!("skipping: {FAKE} is not available ({e}); install aravis-tools to run this");
            None
        }
    }
}

/// Opens the fake camera by its loopback address, retrying while it starts up.
fn open(sensor: Sensor) -> AravisCamera {
    let t = Instant::now();
    loop {
        match AravisCamera::open(Some("127.0.0.1"), sensor) {
            Ok(c) => return c,
            Err(e) if t.elapsed() < Duration::from_secs(5) => {
                eprintln!("fake camera not up yet: {e}");
                std::thread::sleep(Duration::from_millis(200));
            }
            Err(e) => panic!("the fake camera did not open: {e}"),
        }
    }
}

/// The fake camera's default frame size.
const FAKE_SIZE: Sensor = Sensor {
    width: 512,
    height: 512,
};

#[test]
fn the_fake_genicam_camera_delivers_frames_and_vanishes_cleanly() {
    let Some(fake) = start_fake() else {
        return;
    };
    let mut cam = open(FAKE_SIZE);
    eprintln!("opened {}", cam.describe());
    for _ in 0..2 {
        let shot = cam.capture(Duration::from_secs(2)).unwrap();
        assert_eq!(
            (shot.image.width(), shot.image.height()),
            (FAKE_SIZE.width, FAKE_SIZE.height)
        );
        assert!(shot.path.is_none());
        // The fake camera draws a moving pattern, not a blank frame.
        let px = shot.image.pixels.to_luma8();
        let (lo, hi) = px
            .pixels()
            .fold((255u8, 0u8), |(lo, hi), p| (lo.min(p[0]), hi.max(p[0])));
        assert!(hi > lo, "a uniform frame ({lo})");
    }
    // A scenario whose camera has another sensor size is refused.
    drop(cam);
    let mut wrong = open(Sensor {
        width: 640,
        height: 480,
    });
    let e = wrong.capture(Duration::from_secs(2)).unwrap_err();
    assert!(matches!(e, CameraError::WrongSize { .. }), "{e}");
    drop(wrong);
    // The camera goes away mid-run: the next capture says so, within a bounded time.
    let mut cam = open(FAKE_SIZE);
    cam.capture(Duration::from_secs(2)).unwrap();
    drop(fake);
    let t = Instant::now();
    let e = cam.capture(Duration::from_millis(500)).unwrap_err();
    eprintln!(
        "{:.2} s after the camera went away: {e}",
        t.elapsed().as_secs_f64()
    );
    assert!(
        matches!(
            e,
            CameraError::Vanished { .. } | CameraError::Timeout { .. }
        ),
        "{e}"
    );
    assert!(t.elapsed() < Duration::from_secs(10), "{:?}", t.elapsed());
    // Once gone, it stays gone (no capture from a camera that dropped out).
    let e = cam.capture(Duration::from_millis(500)).unwrap_err();
    assert!(matches!(e, CameraError::Vanished { .. }), "{e}");
}
