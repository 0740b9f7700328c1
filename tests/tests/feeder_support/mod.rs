//! Shared set-up of the perception tests: rendered feeder frames (a dozen parts dropped close
//! together, several touching, at full resolution through the simulated sensor) and the truth
//! behind them.

#![allow(dead_code)]

use cell_tests::repo_root;
use image::DynamicImage;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use perception::part::Catalog;
use perception::planar::{PlanarConfig, PlanarPose, PlanarRefiner};
use perception::{Camera, FrameImage};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sim::render::{RenderSettings, Window, render, window_covering};
use sim::scene::{PartModel, Randomisation, Range, SceneRequest, sample_scene};

pub const PARTS: [&str; 3] = ["main_shell", "insert_mold", "top_shell"];

/// A rendered feeder frame and the truth behind it.
#[allow(non_snake_case)]
pub struct Feeder {
    pub image: FrameImage,
    pub camera: Camera,
    pub table_T_camera: Isometry3<f64>,
    /// (part, table_T_part) of every part dropped.
    pub truth: Vec<(String, Isometry3<f64>)>,
}

pub fn catalog() -> Catalog {
    Catalog::load(&repo_root().join("scenarios/parts/usbc.toml")).unwrap_or_else(|e| panic!("{e}"))
}

/// Renders a feeder frame of four parts of each kind dropped into a 3 × 3 cm square, seen from
/// 1.51 m, like `cell dataset`'s feeder frames.
pub fn render_feeder(catalog: &Catalog, seed: u64) -> Feeder {
    let names: Vec<String> = PARTS.iter().map(|s| s.to_string()).collect();
    let models = PartModel::from_catalog(catalog, &names).unwrap_or_else(|e| panic!("{e}"));
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let request = SceneRequest {
        counts: vec![4; models.len()],
        drop_centre: (0.0, 0.0),
        drop_half: 0.015,
        aim_at_part: Some(0),
        nominal_table_T_camera: Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 1.51),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
        ),
    };
    let rand = Randomisation {
        camera_height: Range::new(1.51, 1.51),
        ..Randomisation::default()
    };
    let scene = sample_scene(&models, &request, &rand, &mut rng).unwrap_or_else(|e| panic!("{e}"));
    let camera = Camera::basler_seed();
    let (lo, hi) = scene.footprint(&models, 0.003);
    let window: Window =
        window_covering(&camera, &scene.table_T_camera, &lo, &hi).expect("the parts are in view");
    let out = render(
        &scene.render,
        &camera,
        &scene.table_T_camera,
        window,
        &RenderSettings::default(),
    );
    let pixels = scene
        .metered_sensor(&out)
        .capture(&out, &mut rng)
        .unwrap_or_else(|e| panic!("{e}"));
    Feeder {
        image: FrameImage {
            pixels: DynamicImage::ImageRgb8(pixels),
            origin: [window.x0, window.y0],
        },
        camera,
        table_T_camera: scene.table_T_camera,
        truth: scene
            .parts
            .iter()
            .map(|p| (models[p.model].name.clone(), p.table_T_part))
            .collect(),
    }
}

/// Where planar refinement puts part `name` lying at `table_T_part` on a table seen through
/// `camera_T_table`: its nearest stable pose, with how far the truth tilts from it.
#[allow(non_snake_case)]
pub fn snapped(
    catalog: &Catalog,
    camera_T_table: &Isometry3<f64>,
    name: &str,
    table_T_part: &Isometry3<f64>,
) -> PlanarPose {
    let spec = catalog.part(name).expect("a catalog part");
    PlanarRefiner::new(
        *camera_T_table,
        &spec.stable_poses,
        &[],
        PlanarConfig::default(),
    )
    .expect("a refiner")
    .refine(&(camera_T_table * table_T_part))
    .expect("the truth snaps onto the table")
}
