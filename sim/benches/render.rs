//! Renderer throughput on the real parts: 128 × 128 keypoint crops at full resolution with
//! shadows, and 1000 × 700 overview frames of the board at reduced resolution.

use std::path::Path;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use perception::camera::Camera;
use perception::part::Catalog;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sim::render::{RenderSettings, Window, render};
use sim::scene::{PartModel, Randomisation, SampledScene, SceneRequest, sample_scene};

fn scene(counts: Vec<usize>) -> (Vec<PartModel>, SampledScene) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/parts/usbc.toml");
    let catalog = Catalog::load(&path).expect("catalog");
    let names: Vec<String> = ["main_shell", "insert_mold", "top_shell"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    let models = PartModel::from_catalog(&catalog, &names).expect("models");
    let request = SceneRequest {
        counts,
        drop_centre: (0.0, 0.0),
        drop_half: 0.05,
        aim_at_part: None,
        nominal_table_T_camera: Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 1.51),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
        ),
    };
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let s = sample_scene(&models, &request, &Randomisation::default(), &mut rng).expect("scene");
    (models, s)
}

#[allow(non_snake_case)]
fn bench(c: &mut Criterion) {
    let camera = Camera::basler_seed();
    let settings = RenderSettings::default();
    let (_, s) = scene(vec![2, 2, 2]);
    let camera_T_table = s.table_T_camera.inverse();
    let centre = camera
        .project(&(camera_T_table * Point3::from(s.parts[0].table_T_part.translation.vector)))
        .expect("in view");
    let window = Window::centred(centre.x, centre.y, 128, camera.width, camera.height);
    let mut g = c.benchmark_group("render");
    g.throughput(Throughput::Elements(1));
    g.bench_function("crop_128_ss2_shadows_masks", |b| {
        b.iter(|| render(&s.render, &camera, &s.table_T_camera, window, &settings))
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
    g.sample_size(10);
    for ss in [1, 2] {
        let settings = RenderSettings {
            supersampling: ss,
            ..settings
        };
        g.bench_function(format!("overview_1000x700_ss{ss}_shadows_masks"), |b| {
            b.iter(|| render(&s.render, &overview, &s.table_T_camera, window, &settings))
        });
    }
    g.bench_function("drop_6_parts", |b| b.iter(|| scene(vec![2, 2, 2])));
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
