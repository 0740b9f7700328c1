//! Labels against renders of the real parts: the 9 keypoints reproject onto the rendered part,
//! and dropped parts come to rest on the board (not still falling, not sunk into it).

#![allow(non_snake_case)] // poses are named a_T_b, the workspace convention

use std::path::Path;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use perception::camera::Camera;
use perception::part::Catalog;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sim::render::{RenderSettings, Window, render};
use sim::scene::{PartModel, Randomisation, SceneRequest, label_instances, sample_scene};

fn usbc_models() -> Vec<PartModel> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/parts/usbc.toml");
    let catalog = Catalog::load(&path).unwrap();
    let names: Vec<String> = ["main_shell", "insert_mold", "top_shell"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    PartModel::from_catalog(&catalog, &names).unwrap()
}

#[test]
fn keypoints_reproject_onto_the_rendered_parts_and_parts_rest_on_the_board() {
    let models = usbc_models();
    let camera = Camera::basler_seed();
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let request = SceneRequest {
        counts: vec![2, 2, 2],
        drop_centre: (0.0, 0.0),
        drop_half: 0.03,
        aim_at_part: None,
        nominal_table_T_camera: Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 1.51),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
        ),
    };
    let scene = sample_scene(&models, &request, &Randomisation::default(), &mut rng).unwrap();
    assert_eq!(scene.parts.len(), 6);
    for p in &scene.parts {
        let lowest = models[p.model]
            .mesh
            .vertices
            .iter()
            .map(|v| (p.table_T_part * v).z)
            .fold(f64::INFINITY, f64::min);
        assert!(
            lowest < 6e-3,
            "{} rests {lowest} m above the board",
            models[p.model].name
        );
        // The table contact is stiff: nothing sinks into the board (rapier's soft default let
        // an upside-down shell sink 1.1 mm).
        assert!(
            lowest > -2e-5,
            "{} sank {:.1} µm into the board",
            models[p.model].name,
            -lowest * 1e6
        );
    }
    let settings = RenderSettings {
        supersampling: 1,
        shadows: true,
        full_masks: true,
    };
    let camera_T_table = scene.table_T_camera.inverse();
    let mut checked = 0;
    for (i, p) in scene.parts.iter().enumerate() {
        let c = camera
            .project(&(camera_T_table * nalgebra::Point3::from(p.table_T_part.translation.vector)))
            .unwrap();
        let window = Window::centred(c.x, c.y, 128, camera.width, camera.height);
        let out = render(
            &scene.render,
            &camera,
            &scene.table_T_camera,
            window,
            &settings,
        );
        let labels = label_instances(&scene.parts, &models, &camera, &scene.table_T_camera, &out);
        let label = &labels[i];
        assert!(
            label.px_count_all > 500,
            "part {i} covers {} px",
            label.px_count_all
        );
        if label.visib_fract < 0.999 {
            continue;
        }
        checked += 1;
        let mask = &out.full_masks[i];
        let mut visible = 0;
        for (k, kp) in label.keypoints.iter().enumerate() {
            let (u, v) = (kp.x.round() as i64, kp.y.round() as i64);
            let near = (-1..=1).any(|dy| {
                (-1..=1).any(|dx| {
                    let (x, y) = (u + dx + window.x0 as i64, v + dy + window.y0 as i64);
                    x >= 0 && y >= 0 && mask.contains(x as u32, y as u32)
                })
            });
            assert!(
                near,
                "part {i} keypoint {k} at ({u}, {v}) is off the rendered silhouette"
            );
            if k < 8 {
                let z = (label.camera_T_part * models[p.model].keypoints[k]).z;
                let d = out.depth[(v * window.width as i64 + u) as usize];
                if (d - z).abs() < 3e-4 {
                    visible += 1;
                }
            }
        }
        assert!(
            visible >= 1,
            "part {i}: only {visible} surface keypoints meet the rendered depth"
        );
    }
    assert!(checked >= 3, "only {checked} unoccluded parts");
}
