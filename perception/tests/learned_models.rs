//! The learned pipeline's model loading and a full run on contract-shaped fixture models
//! (`tests/data/onnx/learned`, written by scripts/onnx_fixture/make_learned_fixtures.py: untrained
//! graphs with known weights): the contract and catalog checks, clear errors for missing, corrupt,
//! mis-hashed and mis-shaped models, and the pipeline's geometry (masks, crop origins in sensor
//! pixels, scores) on an image whose segmentation the fixture makes predictable.

use std::path::{Path, PathBuf};

use image::{DynamicImage, Rgb, Rgb32FImage, RgbImage};
use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use perception::learned::{
    InputScale, LearnedError, LearnedModels, LearnedPerception, LearnedPipeline, PipelineConfig,
};
use perception::onnx::{OnnxError, Runtime};
use perception::part::Catalog;
use perception::{Camera, Frame, FrameContent, FrameImage, PartPerception, PerceptionError};

fn fixture_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/onnx/learned")
}

fn catalog() -> Catalog {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenarios/parts/usbc.toml");
    Catalog::load(&path).unwrap_or_else(|e| panic!("{e}"))
}

fn runtime() -> Runtime {
    Runtime::get().unwrap_or_else(|e| panic!("{e}"))
}

/// A copy of the fixture directory that a test may edit.
fn fixture_copy() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for f in [
        "segmenter.onnx",
        "segmenter.toml",
        "keypoints.onnx",
        "keypoints.toml",
    ] {
        std::fs::copy(fixture_dir().join(f), dir.path().join(f)).unwrap();
    }
    dir
}

fn edit(path: &Path, from: &str, to: &str) {
    let text = std::fs::read_to_string(path).unwrap();
    assert!(text.contains(from), "{} lacks {from:?}", path.display());
    std::fs::write(path, text.replacen(from, to, 1)).unwrap();
}

fn load(dir: &Path) -> Result<LearnedPipeline, LearnedError> {
    let models = LearnedModels::in_dir(dir)?;
    LearnedPipeline::load(&models, &catalog(), &runtime())
}

#[allow(non_snake_case)]
fn camera_T_table() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(0.01, -0.02, 1.5),
        UnitQuaternion::from_euler_angles(std::f64::consts::PI, 0.0, 0.3),
    )
}

/// A dark 256 × 192 image with a bright 40 × 40 square at image pixels (100..140, 60..100).
fn square_image() -> DynamicImage {
    DynamicImage::ImageRgb8(RgbImage::from_fn(256, 192, |x, y| {
        let on = (100..140).contains(&x) && (60..100).contains(&y);
        Rgb(if on { [255; 3] } else { [0; 3] })
    }))
}

#[test]
fn the_fixture_models_load_and_a_frame_runs_through_every_stage() {
    let mut pipeline = load(&fixture_dir()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(pipeline.parts(), ["main_shell", "insert_mold", "top_shell"]);
    let origin = [2600, 1500];
    let image = FrameImage {
        pixels: square_image(),
        origin,
    };
    let camera = Camera::basler_seed();
    let found = pipeline
        .detect(&image, &camera, &camera_T_table(), None)
        .unwrap_or_else(|e| panic!("{e}"));
    // The fixture segmenter calls bright cells main_shell with p = e^½ / (e^−½ + e^½ + 2e^−1).
    let p = 0.5f64.exp() / ((-0.5f64).exp() + 0.5f64.exp() + 2.0 * (-1.0f64).exp());
    assert_eq!(found.detections.len(), 1, "{:?}", found.detections);
    let d = &found.detections[0];
    assert_eq!(d.part, "main_shell");
    assert!((d.score - p).abs() < 1e-4, "score {}", d.score);
    // The mask lies on the square (sensor pixels) and covers a good part of it.
    let (sx, sy) = (origin[0] + 100, origin[1] + 60);
    assert!(
        d.mask.area() >= 400 && d.mask.area() <= 1600,
        "{}",
        d.mask.area()
    );
    for y in d.mask.origin[1]..d.mask.origin[1] + d.mask.height {
        for x in d.mask.origin[0]..d.mask.origin[0] + d.mask.width {
            if d.mask.contains(x, y) {
                assert!((sx..sx + 40).contains(&x) && (sy..sy + 40).contains(&y));
            }
        }
    }
    assert!(
        (sx as f64..sx as f64 + 40.0).contains(&d.centre[0]),
        "{:?}",
        d.centre
    );
    assert!(
        (sy as f64..sy as f64 + 40.0).contains(&d.centre[1]),
        "{:?}",
        d.centre
    );
    assert_eq!(
        d.crop_origin,
        [
            d.centre[0].round() as i64 - 64,
            d.centre[1].round() as i64 - 64
        ]
    );
    // The fixture's constant vectors are parallel: voting finds no keypoints, and says so.
    assert!(d.keypoints.is_empty());
    let why = d.pose.as_ref().unwrap_err();
    assert!(why.starts_with("voting: "), "{why}");
    assert!(found.times.total >= found.times.segment + found.times.keypoint_net);

    // A region of interest that excludes the square finds nothing; one that holds it finds it
    // again, with the same sensor coordinates.
    let none = pipeline
        .detect(&image, &camera, &camera_T_table(), Some([0, 0, 90, 192]))
        .unwrap();
    assert!(none.detections.is_empty());
    let again = pipeline
        .detect(&image, &camera, &camera_T_table(), Some([64, 32, 128, 96]))
        .unwrap();
    assert_eq!(again.detections.len(), 1);
    let e = again.detections[0].centre;
    assert!((sx as f64..sx as f64 + 40.0).contains(&e[0]), "{e:?}");
}

#[test]
fn a_frame_shown_to_the_nets_at_half_its_scale_is_reported_in_sensor_pixels() {
    let models = LearnedModels::in_dir(&fixture_dir()).unwrap_or_else(|e| panic!("{e}"));
    let camera = Camera::basler_seed();
    // The table 1.5 m from the camera: fx / 1500 pixels per mm; the nets see half that.
    let sensor_px_per_mm = camera.fx / 1500.0;
    let config = PipelineConfig {
        input_scale: InputScale::PxPerMm(sensor_px_per_mm / 2.0),
        ..PipelineConfig::default()
    };
    let mut pipeline = LearnedPipeline::with_config(&models, &catalog(), &runtime(), config)
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(pipeline.input_px_per_mm(), Some(sensor_px_per_mm / 2.0));
    let origin = [2600, 1500];
    let image = FrameImage {
        pixels: square_image(),
        origin,
    };
    let found = pipeline
        .detect(&image, &camera, &camera_T_table(), Some([16, 8, 224, 176]))
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(found.detections.len(), 1, "{:?}", found.detections);
    let d = &found.detections[0];
    // The 40-pixel square is 20 net pixels, 4 whole cells of 8 × 8 sensor pixels and two half
    // ones: its mask, in sensor pixels, lies on the square grown by at most one cell and
    // covers at least the whole cells.
    let (sx, sy) = (origin[0] + 100, origin[1] + 60);
    let grown = |v: u32, s: u32| (s - 8..s + 48).contains(&v);
    let mut on_square = 0;
    for y in d.mask.origin[1]..d.mask.origin[1] + d.mask.height {
        for x in d.mask.origin[0]..d.mask.origin[0] + d.mask.width {
            if d.mask.contains(x, y) {
                assert!(grown(x, sx) && grown(y, sy), "({x}, {y}) is off the square");
                on_square += usize::from((sx..sx + 40).contains(&x) && (sy..sy + 40).contains(&y));
            }
        }
    }
    assert!(on_square >= 1024, "{on_square} of the square's 1600 pixels");
    for (c, s) in d.centre.iter().zip([sx, sy]) {
        assert!(
            (f64::from(s)..f64::from(s) + 40.0).contains(c),
            "{:?}",
            d.centre
        );
    }
    // The 128-pixel crop of the nets' image covers 256 sensor pixels about the centre.
    for (o, c) in d.crop_origin.iter().zip(d.centre) {
        assert!(
            (*o as f64 - (c - 128.0)).abs() <= 2.0,
            "{:?} {:?}",
            d.crop_origin,
            d.centre
        );
    }
}

#[test]
fn learned_perception_refuses_simulated_frames_and_bad_images() {
    let pipeline = load(&fixture_dir()).unwrap();
    #[allow(non_snake_case)]
    let base_T_camera = camera_T_table().inverse();
    let mut perception = LearnedPerception::new(pipeline, Isometry3::identity());
    let frame = |content| Frame {
        camera: Camera::basler_seed(),
        base_T_camera,
        content,
    };
    let e = perception
        .perceive(&frame(FrameContent::Simulated(Vec::new())))
        .unwrap_err();
    assert!(
        matches!(
            e,
            PerceptionError::UnsupportedFrame {
                mode: "learned",
                ..
            }
        ),
        "{e}"
    );
    let float = DynamicImage::ImageRgb32F(Rgb32FImage::new(64, 64));
    let e = perception
        .perceive(&frame(FrameContent::Image(FrameImage::full(float))))
        .unwrap_err();
    assert!(
        matches!(&e, PerceptionError::Frame(m) if m.contains("Rgb32F")),
        "{e}"
    );
    let off_sensor = FrameImage {
        pixels: square_image(),
        origin: [5400, 0],
    };
    let e = perception
        .perceive(&frame(FrameContent::Image(off_sensor)))
        .unwrap_err();
    assert!(
        e.to_string()
            .contains("does not fit the 5472 × 3648 sensor"),
        "{e}"
    );
    // A good frame: the fixture's keypoints fail to vote, so no part is posed (no error).
    let good = perception
        .perceive(&frame(FrameContent::Image(
            FrameImage::full(square_image()),
        )))
        .unwrap();
    assert!(good.parts.is_empty());
}

#[test]
fn missing_corrupt_and_mis_hashed_models_are_named() {
    let dir = fixture_copy();
    std::fs::remove_file(dir.path().join("keypoints.toml")).unwrap();
    let e = load(dir.path()).err().unwrap();
    assert!(matches!(e, LearnedError::Onnx(OnnxError::Io { .. })), "{e}");
    assert!(e.to_string().contains("keypoints.toml"), "{e}");

    let dir = fixture_copy();
    std::fs::remove_file(dir.path().join("segmenter.onnx")).unwrap();
    let e = load(dir.path()).err().unwrap();
    assert!(e.to_string().contains("segmenter.onnx"), "{e}");

    // One byte changed: the checksum no longer matches.
    let dir = fixture_copy();
    let model = dir.path().join("keypoints.onnx");
    let mut bytes = std::fs::read(&model).unwrap();
    let last = bytes.len() - 1;
    bytes[last] ^= 0x55;
    std::fs::write(&model, &bytes).unwrap();
    let e = load(dir.path()).err().unwrap();
    assert!(
        matches!(e, LearnedError::Onnx(OnnxError::Checksum { .. })),
        "{e}"
    );
    assert!(e.to_string().contains("keypoints.onnx: sha256 is"), "{e}");

    // Garbage with a matching checksum: ONNX Runtime refuses it.
    let dir = fixture_copy();
    let model = dir.path().join("segmenter.onnx");
    std::fs::write(&model, b"not an onnx model").unwrap();
    let manifest = dir.path().join("segmenter.toml");
    let text = std::fs::read_to_string(&manifest).unwrap();
    let old = text
        .lines()
        .find(|l| l.starts_with("sha256"))
        .unwrap()
        .to_string();
    let actual = {
        use sha2::Digest;
        let d = sha2::Sha256::digest(b"not an onnx model");
        d.iter().map(|b| format!("{b:02x}")).collect::<String>()
    };
    edit(&manifest, &old, &format!("sha256 = \"{actual}\""));
    let e = load(dir.path()).err().unwrap();
    assert!(
        matches!(e, LearnedError::Onnx(OnnxError::Model { .. })),
        "{e}"
    );
    assert!(
        e.to_string()
            .contains("segmenter.onnx: ONNX Runtime cannot load"),
        "{e}"
    );
}

#[test]
fn shapes_and_parts_off_the_contract_are_refused() {
    // The manifest promises a shape off the contract: refused before any model is opened.
    let dir = fixture_copy();
    edit(
        &dir.path().join("keypoints.toml"),
        "[-1, 1, 64, 64]",
        "[-1, 1, 32, 32]",
    );
    let e = LearnedModels::in_dir(dir.path()).unwrap_err();
    assert!(matches!(e, LearnedError::Contract { .. }), "{e}");
    let m = e.to_string();
    assert!(
        m.contains("keypoints.toml: output mask: shape [-1, 1, 32, 32]"),
        "{m}"
    );

    let dir = fixture_copy();
    edit(
        &dir.path().join("segmenter.toml"),
        "name = \"offsets\"",
        "name = \"offset\"",
    );
    let e = LearnedModels::in_dir(dir.path()).unwrap_err();
    assert!(
        e.to_string().contains("output \"offsets\" is missing"),
        "{e}"
    );

    // Vector channels for a keypoint count other than the catalog's.
    let dir = fixture_copy();
    edit(
        &dir.path().join("keypoints.toml"),
        "[-1, 18, 64, 64]",
        "[-1, 16, 64, 64]",
    );
    let e = load(dir.path()).err().unwrap();
    assert!(matches!(e, LearnedError::Part { .. }), "{e}");
    assert!(
        e.to_string().contains("has 9 keypoints, the keypoint net"),
        "{e}"
    );

    let dir = fixture_copy();
    let kp = dir.path().join("keypoints.toml");
    edit(&kp, "[-1, 1, 64, 64]", "[-1, 1, -1, 64]");
    let e = LearnedModels::in_dir(dir.path()).unwrap_err();
    assert!(
        e.to_string().contains("the contract needs [-1, 1, 64, 64]"),
        "{e}"
    );

    // Parts in another order than the catalog's.
    let dir = fixture_copy();
    for f in ["segmenter.toml", "keypoints.toml"] {
        edit(
            &dir.path().join(f),
            "[\"main_shell\", \"insert_mold\"",
            "[\"insert_mold\", \"main_shell\"",
        );
    }
    let e = load(dir.path()).err().unwrap();
    assert!(matches!(e, LearnedError::Parts { .. }), "{e}");
    assert!(
        e.to_string()
            .contains("segmenter.toml: parts [\"insert_mold\""),
        "{e}"
    );
}

#[test]
fn a_model_whose_graph_differs_from_its_manifest_is_refused() {
    // keypoints.toml names the segmenter's graph: on the contract on paper, not in the file.
    let dir = fixture_copy();
    let seg = std::fs::read_to_string(dir.path().join("segmenter.toml")).unwrap();
    let sha = seg.lines().find(|l| l.starts_with("sha256")).unwrap();
    let kp = dir.path().join("keypoints.toml");
    let text = std::fs::read_to_string(&kp).unwrap();
    let old = text.lines().find(|l| l.starts_with("sha256")).unwrap();
    let text = text
        .replace(old, sha)
        .replace("file = \"keypoints.onnx\"", "file = \"segmenter.onnx\"");
    std::fs::write(&kp, text).unwrap();
    let e = load(dir.path()).err().unwrap();
    assert!(
        matches!(e, LearnedError::Onnx(OnnxError::Signature { .. })),
        "{e}"
    );
    assert!(
        e.to_string().contains("segmenter.onnx: input 0 differs"),
        "{e}"
    );
}

#[test]
fn a_size_the_graph_leaves_dynamic_is_checked_on_every_run() {
    // The segmenter graph's logits are [n, 4, h4, w4]; a manifest may fix them (as exporters
    // lose static sizes through reshapes) and each run checks the concrete size.
    use perception::onnx::BatchSession;
    let dir = fixture_copy();
    let manifest = dir.path().join("segmenter.toml");
    edit(&manifest, "[-1, 4, -1, -1]", "[-1, 4, 8, 8]");
    let mut session =
        BatchSession::open(&runtime(), &manifest, 1).unwrap_or_else(|e| panic!("{e}"));
    let out = session
        .run_shaped(&[1, 3, 32, 32], &[0.5; 3 * 32 * 32])
        .unwrap();
    assert_eq!(out[0].shape, [1, 4, 8, 8]);
    let e = session
        .run_shaped(&[1, 3, 64, 64], &[0.5; 3 * 64 * 64])
        .unwrap_err();
    assert!(matches!(e, OnnxError::Run { .. }), "{e}");
    assert!(
        e.to_string()
            .contains("output logits has shape [1, 4, 16, 16], the manifest says [-1, 4, 8, 8]"),
        "{e}"
    );
    let e = session.run_shaped(&[1, 3, 32], &[0.5; 96]).unwrap_err();
    assert!(
        e.to_string().contains("does not fit image [-1, 3, -1, -1]"),
        "{e}"
    );
}

#[test]
fn settings_out_of_range_are_refused_and_named() {
    let models = LearnedModels::in_dir(&fixture_dir()).unwrap_or_else(|e| panic!("{e}"));
    let base = PipelineConfig::default();
    for (config, named) in [
        (PipelineConfig { threads: 0, ..base }, "threads"),
        (
            PipelineConfig {
                min_score: 1.5,
                ..base
            },
            "min_score",
        ),
        (
            PipelineConfig {
                stacking_tolerance: Some(-1e-3),
                ..base
            },
            "stacking_tolerance",
        ),
        (
            PipelineConfig {
                max_lean: f64::NAN,
                ..base
            },
            "max_lean",
        ),
        (
            PipelineConfig {
                max_lean: 0.0,
                ..base
            },
            "max_lean",
        ),
        (
            PipelineConfig {
                max_overfill: 0.0,
                ..base
            },
            "max_overfill",
        ),
        (
            PipelineConfig {
                input_scale: InputScale::PxPerMm(-2.0),
                ..base
            },
            "input_scale",
        ),
        (
            PipelineConfig {
                max_overfill: f64::INFINITY,
                ..base
            },
            "max_overfill",
        ),
        (
            PipelineConfig {
                max_joined_fill: -0.5,
                ..base
            },
            "max_joined_fill",
        ),
    ] {
        match LearnedPipeline::with_config(&models, &catalog(), &runtime(), config) {
            Err(LearnedError::Settings(m)) => assert!(m.contains(named), "{named}: {m}"),
            Err(e) => panic!("{named}: another error: {e}"),
            Ok(_) => panic!("{named}: accepted"),
        }
    }
    LearnedPipeline::with_config(&models, &catalog(), &runtime(), base)
        .unwrap_or_else(|e| panic!("the defaults: {e}"));
}
