//! Production capture-to-poses latency (issue goal ≤ 50 ms for 12 parts on 2 cores): a
//! full-sensor camera image on disk → `camera::decode_file` (what the folder, files and command
//! sources do) → `LearnedPerception` over the feeder window → poses. The image is the rendered
//! 12-part feeder frame of perception's test data pasted at its sensor origin into a noisy
//! grey 20 MP sensor, written once as 8-bit mono TIFF (uncompressed), mono PNG and colour PNG;
//! each is timed as a whole and split into decode and perceive. Uses the committed models (`scenarios/models/usbc/`, or `LEARNED_MODELS_DIR`).

use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use cell::camera::{Sensor, decode_file};
use criterion::{Criterion, criterion_group, criterion_main};
use image::{DynamicImage, GrayImage, ImageFormat};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use perception::estimate::EstimatorConfig;
use perception::learned::{LearnedModels, LearnedPerception, LearnedPipeline, PipelineConfig};
use perception::onnx::Runtime;
use perception::part::Catalog;
use perception::{Camera, Frame, FrameContent, FrameImage, PartPerception};
use serde::Deserialize;

/// Where the feeder frame sits on the sensor and the table's pose (perception's test data).
#[derive(Deserialize)]
#[allow(non_snake_case)]
struct FrameSpec {
    origin: [u32; 2],
    camera_T_table_translation: [f64; 3],
    camera_T_table_quaternion_xyzw: [f64; 4],
}

/// The full-sensor image with the feeder frame pasted in, and the feeder window `[x, y, w, h]`.
#[allow(non_snake_case)]
fn sensor_image(data: &Path, camera: &Camera) -> (GrayImage, [u32; 4], Isometry3<f64>) {
    let spec: FrameSpec = toml::from_str(
        &std::fs::read_to_string(data.join("feeder.toml")).unwrap_or_else(|e| panic!("{e}")),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let window = image::open(data.join("feeder.png"))
        .unwrap_or_else(|e| panic!("{e}"))
        .to_luma8();
    let mean = window.pixels().map(|p| u64::from(p.0[0])).sum::<u64>() / window.len() as u64;
    // Grey with ±4 levels of sensor noise, so that PNG compresses as badly as a real image.
    let mut state = 0x9e37_79b9_u32;
    let mut full = GrayImage::from_fn(camera.width, camera.height, |_, _| {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        image::Luma([(mean as u32 + state % 9).saturating_sub(4).min(255) as u8])
    });
    image::imageops::replace(
        &mut full,
        &window,
        i64::from(spec.origin[0]),
        i64::from(spec.origin[1]),
    );
    let [x, y, z] = spec.camera_T_table_translation;
    let [qi, qj, qk, qw] = spec.camera_T_table_quaternion_xyzw;
    let camera_T_table = Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_quaternion(Quaternion::new(qw, qi, qj, qk)),
    );
    let roi = [
        spec.origin[0],
        spec.origin[1],
        window.width(),
        window.height(),
    ];
    (full, roi, camera_T_table)
}

fn median(mut v: Vec<Duration>) -> f64 {
    v.sort();
    v[v.len() / 2].as_secs_f64() * 1e3
}

#[allow(non_snake_case)]
fn bench(c: &mut Criterion) {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let dir = LearnedModels::dir_from_env();
    if !dir.join("segmenter.toml").exists() {
        eprintln!("no models in {}: nothing to benchmark", dir.display());
        return;
    }
    let models = LearnedModels::in_dir(&dir).unwrap_or_else(|e| panic!("{e}"));
    let catalog =
        Catalog::load(&root.join("scenarios/parts/usbc.toml")).unwrap_or_else(|e| panic!("{e}"));
    let runtime = Runtime::get().unwrap_or_else(|e| panic!("{e}"));
    let pipeline = LearnedPipeline::with_config(
        &models,
        &catalog,
        &runtime,
        // The learned scenario's reprojection gate (12 px): the poses production uses are timed.
        PipelineConfig {
            threads: 2,
            estimator: EstimatorConfig::with_gate(12.0),
            ..PipelineConfig::default()
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let camera = Camera::basler_seed();
    let (full, roi, camera_T_table) =
        sensor_image(&root.join("perception/tests/data/learned"), &camera);
    // The table is the base frame here: base_T_camera is the inverse of camera_T_table.
    let mut perception = LearnedPerception::new(pipeline, Isometry3::identity()).with_roi(roi);
    let base_T_camera = camera_T_table.inverse();
    let sensor = Sensor::of(&camera);

    let tmp = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let files = [
        (
            "mono8_tiff",
            "sensor.tiff",
            DynamicImage::ImageLuma8(full.clone()),
            ImageFormat::Tiff,
        ),
        (
            "mono8_png",
            "sensor.png",
            DynamicImage::ImageLuma8(full.clone()),
            ImageFormat::Png,
        ),
        (
            "rgb8_png",
            "sensor_rgb.png",
            DynamicImage::ImageRgb8(DynamicImage::ImageLuma8(full).to_rgb8()),
            ImageFormat::Png,
        ),
    ];
    let mut capture_to_poses = |path: &Path| -> (Duration, Duration, usize) {
        let t = Instant::now();
        let pixels = decode_file(path, sensor).unwrap_or_else(|e| panic!("{e}"));
        let decoded = t.elapsed();
        let frame = Frame {
            camera,
            base_T_camera,
            content: FrameContent::Image(FrameImage {
                pixels,
                origin: [0, 0],
            }),
        };
        let seen = perception
            .perceive(&frame)
            .unwrap_or_else(|e| panic!("{e}"));
        (decoded, t.elapsed() - decoded, seen.parts.len())
    };
    eprintln!(
        "{} × {} sensor, feeder window {roi:?}; median of 10 captures:",
        camera.width, camera.height
    );
    let mut group = c.benchmark_group("capture_to_poses");
    for (name, file, pixels, format) in files {
        let path = tmp.path().join(file);
        pixels
            .save_with_format(&path, format)
            .unwrap_or_else(|e| panic!("{e}"));
        let runs: Vec<_> = (0..10).map(|_| capture_to_poses(&path)).collect();
        let size_mb = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0) as f64 / 1e6;
        eprintln!(
            "  {name:>10} ({size_mb:5.1} MB): decode {:7.2} ms + perceive {:6.2} ms ({} poses)",
            median(runs.iter().map(|r| r.0).collect()),
            median(runs.iter().map(|r| r.1).collect()),
            runs[0].2
        );
        group.bench_function(name, |b| b.iter(|| black_box(capture_to_poses(&path))));
    }
    group.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10);
    targets = bench
}
criterion_main!(benches);
