//! The learned pipeline on one rendered feeder frame of 12 parts (tests/data/learned/feeder.png,
//! written by the cell-tests `learned_perception` test): the whole frame through criterion, and
//! the median time of each stage (goal ≤ 30 ms per frame on 2 cores). Uses the committed models
//! (`scenarios/models/usbc/`, or `LEARNED_MODELS_DIR`); without them it says so and measures
//! nothing.

use std::hint::black_box;
use std::path::PathBuf;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use perception::estimate::EstimatorConfig;
use perception::learned::{LearnedModels, LearnedPipeline, PipelineConfig, StageTimes};
use perception::onnx::Runtime;
use perception::part::Catalog;
use perception::{Camera, FrameImage};
use serde::Deserialize;

#[derive(Deserialize)]
#[allow(non_snake_case)]
struct FrameSpec {
    origin: [u32; 2],
    camera_T_table_translation: [f64; 3],
    camera_T_table_quaternion_xyzw: [f64; 4],
}

fn median(mut v: Vec<Duration>) -> Duration {
    v.sort();
    v[v.len() / 2]
}

#[allow(non_snake_case)]
fn bench(c: &mut Criterion) {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let dir = LearnedModels::dir_from_env();
    if !dir.join("segmenter.toml").exists() {
        eprintln!("no models in {}: nothing to benchmark", dir.display());
        return;
    }
    let models = LearnedModels::in_dir(&dir).unwrap_or_else(|e| panic!("{e}"));
    let catalog =
        Catalog::load(&root.join("../scenarios/parts/usbc.toml")).unwrap_or_else(|e| panic!("{e}"));
    let runtime = Runtime::get().unwrap_or_else(|e| panic!("{e}"));
    // The learned scenario's reprojection gate (12 px), so the poses the cell would use are timed.
    let config = PipelineConfig {
        estimator: EstimatorConfig::with_gate(12.0),
        ..PipelineConfig::default()
    };
    let mut pipeline = LearnedPipeline::with_config(&models, &catalog, &runtime, config)
        .unwrap_or_else(|e| panic!("{e}"));
    let data = root.join("tests/data/learned");
    let spec: FrameSpec = toml::from_str(
        &std::fs::read_to_string(data.join("feeder.toml")).unwrap_or_else(|e| panic!("{e}")),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let pixels = image::open(data.join("feeder.png")).unwrap_or_else(|e| panic!("{e}"));
    let image = FrameImage {
        pixels,
        origin: spec.origin,
    };
    let [x, y, z] = spec.camera_T_table_translation;
    let [qi, qj, qk, qw] = spec.camera_T_table_quaternion_xyzw;
    let camera_T_table = Isometry3::from_parts(
        Translation3::new(x, y, z),
        UnitQuaternion::from_quaternion(Quaternion::new(qw, qi, qj, qk)),
    );
    let camera = Camera::basler_seed();
    let mut times: Vec<StageTimes> = Vec::new();
    let mut found = 0;
    for _ in 0..30 {
        let r = pipeline
            .detect(&image, &camera, &camera_T_table, None)
            .unwrap_or_else(|e| panic!("{e}"));
        found = r.detections.len();
        times.push(r.times);
    }
    let posed = pipeline
        .detect(&image, &camera, &camera_T_table, None)
        .unwrap()
        .detections
        .iter()
        .filter(|d| d.pose.is_ok())
        .count();
    eprintln!(
        "feeder frame {} × {}: {found} instances, {posed} poses; median of 30 frames:",
        image.width(),
        image.height()
    );
    type Stage = (&'static str, fn(&StageTimes) -> Duration);
    let stages: [Stage; 8] = [
        ("preprocess", |t| t.preprocess),
        ("segment", |t| t.segment),
        ("instances", |t| t.instances),
        ("crops", |t| t.crops),
        ("keypoint_net", |t| t.keypoint_net),
        ("voting", |t| t.voting),
        ("pose", |t| t.pose),
        ("total", |t| t.total),
    ];
    for (name, f) in stages {
        let m = median(times.iter().map(f).collect());
        eprintln!("  {name:>12}: {:8.2} ms", m.as_secs_f64() * 1e3);
    }
    c.bench_function("learned_feeder_frame_12_parts", |b| {
        b.iter(|| {
            black_box(
                pipeline
                    .detect(&image, &camera, &camera_T_table, None)
                    .unwrap(),
            )
        })
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = bench
}
criterion_main!(benches);
