//! Renderer throughput on the real parts: 128 × 128 keypoint crops at full resolution with
//! shadows, 1000 × 700 overview frames of the board at the default overview scale, the feeder
//! window of the full 20 MP camera with 12 parts (whole, with shared centre rays, and rendered
//! again after a pick), and the physics drop.
//!
//! The machine is shared, so every case is measured twice: `render/…` in wall-clock time and
//! `render_cpu/…` in CPU time of the whole process (all threads, from /proc), which does not
//! depend on how busy the other cores are. Throughput on k idle cores ≈ k / CPU time per item
//! for work that runs one item per core (datasets do).

use std::path::Path;
use std::time::{Duration, Instant};

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use perception::camera::Camera;
use perception::part::Catalog;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sim::render::{
    CentreRays, IncrementalRenderer, RenderSettings, SensorModel, Window, capture, render,
    render_with_rays, window_covering,
};
use sim::scene::{
    PartModel, Randomisation, SampledScene, SceneRequest, drop_parts, nominal_scene, sample_scene,
};

fn models() -> Vec<PartModel> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/parts/usbc.toml");
    let catalog = Catalog::load(&path).expect("catalog");
    let names: Vec<String> = ["main_shell", "insert_mold", "top_shell"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    PartModel::from_catalog(&catalog, &names).expect("models")
}

fn nominal_pose() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(0.0, 0.0, 1.51),
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
    )
}

fn scene(models: &[PartModel], counts: Vec<usize>) -> SampledScene {
    let request = SceneRequest {
        counts,
        drop_centre: (0.0, 0.0),
        drop_half: 0.05,
        aim_at_part: None,
        nominal_table_T_camera: nominal_pose(),
    };
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    sample_scene(models, &request, &Randomisation::default(), &mut rng).expect("scene")
}

/// CPU time of this process so far (every thread), from /proc/self/task/*/schedstat.
fn cpu_time() -> Duration {
    let mut ns = 0u64;
    if let Ok(tasks) = std::fs::read_dir("/proc/self/task") {
        for t in tasks.flatten() {
            if let Ok(text) = std::fs::read_to_string(t.path().join("schedstat")) {
                ns += text
                    .split_whitespace()
                    .next()
                    .and_then(|v| v.parse::<u64>().ok())
                    .unwrap_or(0);
            }
        }
    }
    Duration::from_nanos(ns)
}

/// Benchmarks `f` in wall time (group `render`) and in process CPU time (group `render_cpu`).
fn both(c: &mut Criterion, name: &str, samples: usize, mut f: impl FnMut()) {
    let mut g = c.benchmark_group("render");
    g.throughput(Throughput::Elements(1));
    g.sample_size(samples);
    g.bench_function(name, |b| b.iter(&mut f));
    g.finish();
    let mut g = c.benchmark_group("render_cpu");
    g.throughput(Throughput::Elements(1));
    g.sample_size(samples);
    g.bench_function(name, |b| {
        b.iter_custom(|iters| {
            let (t0, w0) = (cpu_time(), Instant::now());
            for _ in 0..iters {
                f();
            }
            // Guard against a /proc without schedstat: fall back to wall time.
            let cpu = cpu_time().saturating_sub(t0);
            if cpu.is_zero() { w0.elapsed() } else { cpu }
        })
    });
    g.finish();
}

#[allow(non_snake_case)]
fn bench(c: &mut Criterion) {
    let models = models();
    let camera = Camera::basler_seed();
    let settings = RenderSettings::default();
    let s = scene(&models, vec![2, 2, 2]);
    let camera_T_table = s.table_T_camera.inverse();
    let centre = camera
        .project(&(camera_T_table * Point3::from(s.parts[0].table_T_part.translation.vector)))
        .expect("in view");
    let window = Window::centred(centre.x, centre.y, 128, camera.width, camera.height);
    both(c, "crop_128_ss2_shadows_masks", 50, || {
        render(&s.render, &camera, &s.table_T_camera, window, &settings);
    });

    let overview = camera.scaled(0.4).expect("scale");
    let centre = overview
        .project(&(camera_T_table * Point3::origin()))
        .expect("board in view");
    let window = Window::centred(centre.x, centre.y, 1000, overview.width, overview.height);
    let window = Window {
        height: 700,
        y0: (centre.y - 350.0).max(0.0) as u32,
        ..window
    };
    both(c, "overview_1000x700_ss2_shadows_masks", 10, || {
        render(&s.render, &overview, &s.table_T_camera, window, &settings);
    });

    // The nominal feeder (80 × 60 mm at (0, 0.05) on the board) with four of each part, seen by
    // the full-resolution camera at its nominal pose; no full masks (a run needs the image).
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let parts = drop_parts(&models, &[4, 4, 4], (0.0, 0.05), 0.03, &mut rng).expect("drop");
    let feeder = nominal_scene(&models, &parts);
    let pose = nominal_pose();
    let window = window_covering(
        &camera,
        &pose,
        &Point3::new(-0.04, 0.02, 0.0),
        &Point3::new(0.04, 0.08, 0.005),
    )
    .expect("feeder in view");
    let run_settings = RenderSettings {
        full_masks: false,
        ..settings
    };
    let sensor = SensorModel {
        read_noise: 0.004,
        shot_noise: 0.001,
        ..SensorModel::default()
    };
    for ss in [2, 1] {
        let settings = RenderSettings {
            supersampling: ss,
            ..run_settings
        };
        both(
            c,
            &format!("feeder_{}x{}_12_parts_ss{ss}", window.width, window.height),
            20,
            || {
                let mut rng = ChaCha8Rng::seed_from_u64(9);
                capture(
                    &feeder, &camera, &pose, window, &settings, &sensor, &mut rng,
                )
                .expect("capture");
            },
        );
    }

    // The cell's captures: the episode shares the window's centre rays with every other
    // episode, and after a pick renders again only what the picked part changed.
    let rays = CentreRays::new(&camera, window);
    let name = format!("feeder_{}x{}_12_parts_ss2", window.width, window.height);
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    both(c, &format!("{name}_shared_centre_rays"), 20, || {
        let output = render_with_rays(&feeder, &camera, &pose, window, &run_settings, Some(&rays));
        sensor.capture(&output, &mut rng).expect("capture");
    });
    let mut primed = IncrementalRenderer::new();
    primed.render(&feeder, &camera, &pose, window, &run_settings, Some(&rays));
    let picked = nominal_scene(&models, &parts[1..]);
    both(c, &format!("{name}_after_a_pick"), 20, || {
        let mut renderer = primed.clone();
        let output = renderer.render(&picked, &camera, &pose, window, &run_settings, Some(&rays));
        sensor.capture(output, &mut rng).expect("capture");
    });

    both(c, "drop_6_parts", 10, || {
        scene(&models, vec![2, 2, 2]);
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
