//! The production pre-flight's camera check on rendered boards: a camera where the calibration
//! put it passes; a camera bumped by a fraction of a milliradian is refused with the size of
//! the shift, and the refusal holds for every later capture of the run.

#![allow(non_snake_case)]

use std::sync::Arc;

use cell::calibrate::preflight::{CameraCheck, CameraCheckError, DEFAULT_TOLERANCE};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use perception::FrameImage;
use perception::calibration::Board;
use perception::camera::Camera;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sim::scene::{Randomisation, board_render_settings, embed_in_full_frame, sample_board_view};

/// The scenarios' camera: 1.51 m above the board, looking down.
fn base_T_camera() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(0.0, -0.45, 1.51),
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
    )
}

fn base_T_table() -> Isometry3<f64> {
    Isometry3::translation(0.0, -0.45, 0.0)
}

/// A full-sensor image of the board from the camera at `table_T_camera`.
fn shot(table_T_camera: Isometry3<f64>, seed: u64) -> FrameImage {
    let camera = Camera::basler_seed();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut view = sample_board_view(
        &Board::seed(),
        &camera,
        &Randomisation::default().without_overexposure(),
        &mut rng,
    )
    .unwrap();
    view.scene.table_T_camera = table_T_camera;
    let window = view.window().unwrap();
    let image = view
        .render(window, &board_render_settings(), &mut rng)
        .unwrap()
        .image;
    embed_in_full_frame(&image, &camera, 90, 6)
}

fn check() -> CameraCheck {
    CameraCheck::new(
        Arc::new(Board::seed()),
        Camera::basler_seed(),
        &base_T_camera(),
        &base_T_table(),
        DEFAULT_TOLERANCE,
    )
}

#[test]
fn a_camera_where_the_calibration_put_it_passes_and_a_bumped_one_is_refused() {
    let table_T_camera = base_T_table().inverse() * base_T_camera();
    let shift = check().check(&shot(table_T_camera, 1)).unwrap();
    assert!(shift < 0.02e-3, "an unmoved camera appears {shift} m off");
    // Tilted by 0.3 mrad about its x axis: table points move by about 0.3 mrad × 1.51 m.
    let bumped = table_T_camera * Isometry3::rotation(Vector3::x() * 3e-4);
    match check().check(&shot(bumped, 2)) {
        Err(CameraCheckError::Moved { shift_mm, .. }) => {
            assert!((shift_mm - 0.453).abs() < 0.03, "{shift_mm} mm");
        }
        other => panic!("a bumped camera passed: {other:?}"),
    }
}

#[test]
fn a_capture_without_the_board_is_refused_by_name() {
    let camera = Camera::basler_seed();
    let blank = FrameImage::full(image::DynamicImage::ImageLuma8(
        image::GrayImage::from_pixel(camera.width, camera.height, image::Luma([120])),
    ));
    let e = check().check(&blank).unwrap_err().to_string();
    assert!(
        e.contains("could not check the camera") && e.contains("no tag"),
        "{e}"
    );
}

/// Through a production run's side channels: the first capture of a bumped camera fails with
/// the shift, and so does every later one, without a new check: nothing moves on that
/// calibration again.
#[test]
fn a_production_run_refuses_every_capture_after_a_bumped_first_one() {
    use cell::camera::{FilesCamera, Sensor};
    use cell::orchestrator::{CellIo, ProductionCellIo};
    let scenario = cell::run::LoadedScenario::load(
        &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/usbc_learned.toml"),
    )
    .unwrap()
    .scenario;
    let dir = tempfile::tempdir().unwrap();
    let table_T_camera = base_T_table().inverse() * base_T_camera();
    let bumped = table_T_camera * Isometry3::rotation(Vector3::y() * 4e-4);
    let image = shot(bumped, 3);
    image.pixels.save(dir.path().join("frame-1.png")).unwrap();
    std::fs::copy(
        dir.path().join("frame-1.png"),
        dir.path().join("frame-2.png"),
    )
    .unwrap();
    let camera = Camera::basler_seed();
    let source = FilesCamera::open(dir.path(), Sensor::of(&camera)).unwrap();
    let mut io = ProductionCellIo::new(
        scenario,
        Box::new(source),
        std::time::Duration::from_secs(5),
    )
    .with_camera_check(check());
    for attempt in 1..=2 {
        let e = io.capture().unwrap_err().to_string();
        assert!(
            e.contains("camera appears moved") && e.contains("mm off"),
            "capture {attempt}: {e}"
        );
    }
}
