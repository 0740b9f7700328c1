//! Renderer acceptance: exact depth on a plane, mask area against the projected mesh area, crops
//! equal to the same window of a full frame, keypoints reprojecting onto the rendered part.
#![allow(non_snake_case)]

use std::sync::Arc;

use nalgebra::{Isometry3, Point2, Point3, Translation3, UnitQuaternion, Vector3};
use perception::calibration::{Board, BoardSpec};
use perception::camera::{Camera, Distortion};
use perception::part::{Material, TriMesh};
use sim::render::{
    Appearance, Instance, PointLight, RenderMesh, RenderScene, RenderSettings, TagBoard, Window,
    render,
};

/// A closed box mesh with outward triangles, centred on the origin.
fn cuboid(sx: f64, sy: f64, sz: f64) -> TriMesh {
    TriMesh::cuboid(nalgebra::Vector3::new(sx, sy, sz))
}

/// Camera `h` metres above the table origin looking straight down (x along table x).
fn overhead(h: f64) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(0.0, 0.0, h),
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
    )
}

fn lights() -> Vec<PointLight> {
    vec![
        PointLight {
            position: Point3::new(0.3, 0.2, 1.0),
            intensity: [2.0; 3],
            radius: 0.0,
        },
        PointLight {
            position: Point3::new(-0.4, 0.1, 0.8),
            intensity: [1.0; 3],
            radius: 0.0,
        },
    ]
}

fn part_scene(mesh: &TriMesh, pose: Isometry3<f64>, board: bool) -> RenderScene {
    let inst = Instance::new(
        Arc::new(RenderMesh::new(mesh).unwrap()),
        pose,
        Appearance::for_material(Material::Metal),
    );
    RenderScene::new(
        vec![inst],
        board.then(TagBoard::default),
        None,
        lights(),
        [0.1; 3],
    )
}

#[test]
fn depth_on_a_plane_is_exact_through_a_distorted_lens() {
    let camera = Camera::basler_seed().scaled(0.05).unwrap();
    let board = TagBoard::new(
        Board::new(BoardSpec {
            plate: [4.0, 4.0],
            ..BoardSpec::seed()
        })
        .unwrap(),
    );
    let scene = RenderScene::new(vec![], Some(board), None, lights(), [0.1; 3]);
    let h = 1.234;
    let out = render(
        &scene,
        &camera,
        &overhead(h),
        Window::full(camera.width, camera.height),
        &RenderSettings::default(),
    );
    for d in &out.depth {
        assert!((d - h).abs() < 1e-12, "depth {d} at a plane {h} m away");
    }
    // Tilted camera: depth is the camera-frame z of the plane point, checked pixel by pixel.
    let tilted = overhead(h) * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 0.2);
    let out = render(
        &scene,
        &camera,
        &tilted,
        Window::full(camera.width, camera.height),
        &RenderSettings::default(),
    );
    let camera_T_table = tilted.inverse();
    let normal_c = camera_T_table.rotation * Vector3::z();
    let point_c = camera_T_table * Point3::origin();
    for (i, d) in out.depth.iter().enumerate() {
        let (u, v) = (
            (i % camera.width as usize) as f64,
            (i / camera.width as usize) as f64,
        );
        let ray = camera.pixel_ray(Point2::new(u, v)).unwrap();
        let t = normal_c.dot(&point_c.coords) / normal_c.dot(&ray);
        let z = t * ray.z;
        assert!(
            (d - z).abs() < 1e-9,
            "pixel ({u}, {v}): depth {d}, plane {z}"
        );
    }
}

/// Area of the convex hull of 2-D points (monotone chain + shoelace).
fn hull_area(mut p: Vec<Point2<f64>>) -> f64 {
    p.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    let cross = |o: &Point2<f64>, a: &Point2<f64>, b: &Point2<f64>| {
        (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x)
    };
    let mut hull: Vec<Point2<f64>> = Vec::new();
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &Point2<f64>>> = if pass == 0 {
            Box::new(p.iter())
        } else {
            Box::new(p.iter().rev())
        };
        for q in iter {
            while hull.len() >= start + 2
                && cross(&hull[hull.len() - 2], &hull[hull.len() - 1], q) <= 0.0
            {
                hull.pop();
            }
            hull.push(*q);
        }
        hull.pop();
    }
    let n = hull.len();
    (0..n)
        .map(|i| {
            let (a, b) = (hull[i], hull[(i + 1) % n]);
            a.x * b.y - b.x * a.y
        })
        .sum::<f64>()
        .abs()
        / 2.0
}

#[test]
fn mask_area_matches_the_projected_mesh_area() {
    let camera = Camera::new(1800.0, 1800.0, 319.5, 239.5, 640, 480, Distortion::NONE).unwrap();
    let mesh = cuboid(0.04, 0.03, 0.02);
    for (k, axis) in [Vector3::new(0.3, 1.0, 0.2), Vector3::new(-1.0, 0.4, 0.7)]
        .iter()
        .enumerate()
    {
        let pose = Isometry3::from_parts(
            Translation3::new(0.01 * k as f64, -0.005, 0.04),
            UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(*axis), 0.7 + k as f64),
        );
        let scene = part_scene(&mesh, pose, true);
        let cam_pose = overhead(0.35);
        let settings = RenderSettings {
            supersampling: 1,
            shadows: false,
            full_masks: true,
        };
        let out = render(
            &scene,
            &camera,
            &cam_pose,
            Window::full(640, 480),
            &settings,
        );
        let camera_T_part = cam_pose.inverse() * pose;
        let projected: Vec<_> = mesh
            .vertices
            .iter()
            .map(|v| camera.project(&(camera_T_part * v)).unwrap())
            .collect();
        let expected = hull_area(projected);
        let full = out.full_masks[0].count() as f64;
        let visible = out.visible_count(0) as f64;
        assert!(expected > 10_000.0, "test part too small: {expected} px²");
        assert!(
            (full - expected).abs() / expected < 0.01,
            "full mask {full} px vs projected {expected} px²"
        );
        // Nothing occludes the part: the visible mask is the full mask.
        assert_eq!(full, visible);
    }
}

#[test]
fn a_crop_rendered_directly_equals_the_same_window_of_the_full_frame() {
    let camera = Camera::basler_seed().scaled(0.12).unwrap();
    let mesh = cuboid(0.009, 0.009, 0.003);
    let pose = Isometry3::from_parts(
        Translation3::new(0.02, -0.01, 0.0015),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.4),
    );
    let scene = part_scene(&mesh, pose, true);
    let cam_pose = overhead(0.3);
    let settings = RenderSettings::default();
    let full = render(
        &scene,
        &camera,
        &cam_pose,
        Window::full(camera.width, camera.height),
        &settings,
    );
    let centre = camera
        .project(&(cam_pose.inverse() * Point3::new(0.02, -0.01, 0.0)))
        .unwrap();
    let window = Window::centred(centre.x, centre.y, 128, camera.width, camera.height);
    let crop = render(&scene, &camera, &cam_pose, window, &settings);
    assert!(crop.visible_count(0) > 500, "the part is in the crop");
    for y in 0..window.height {
        for x in 0..window.width {
            let i = (y * window.width + x) as usize;
            let j = full.index(window.x0 + x, window.y0 + y).unwrap();
            assert_eq!(crop.radiance[i], full.radiance[j]);
            assert_eq!(crop.depth[i], full.depth[j]);
            assert_eq!(crop.visible[i], full.visible[j]);
            assert_eq!(
                crop.full_masks[0].contains(window.x0 + x, window.y0 + y),
                full.full_masks[0].contains(window.x0 + x, window.y0 + y)
            );
        }
    }
    // Through the crop camera (shifted principal point) the same pixels come out, up to the
    // rounding of the shifted principal point.
    let crop_camera = camera.crop(window.x0 as f64, window.y0 as f64, 128, 128);
    let direct = render(
        &scene,
        &crop_camera,
        &cam_pose,
        Window::full(128, 128),
        &settings,
    );
    let same = direct
        .visible
        .iter()
        .zip(&crop.visible)
        .filter(|(a, b)| a == b)
        .count();
    assert!(
        same >= 128 * 128 - 2,
        "{same} of {} mask pixels agree",
        128 * 128
    );
    let worst = direct
        .depth
        .iter()
        .zip(&crop.depth)
        .filter(|(a, b)| (**a > 0.0) == (**b > 0.0))
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(worst < 1e-6, "depth differs by {worst} m");
}

#[test]
fn shadows_darken_the_board_under_a_part() {
    let camera = Camera::new(1500.0, 1500.0, 99.5, 99.5, 200, 200, Distortion::NONE).unwrap();
    let mesh = cuboid(0.02, 0.02, 0.02);
    let pose = Isometry3::translation(0.0, 0.0, 0.03);
    let mut scene = part_scene(&mesh, pose, true);
    scene.lights = vec![PointLight {
        position: Point3::new(0.0, 0.0, 1.0),
        intensity: [2.0; 3],
        radius: 0.0,
    }];
    // Look from the side so the shadow under the floating cube is visible next to it.
    let cam_pose = super_look(Point3::new(0.25, 0.0, 0.3), Point3::origin());
    let lit = RenderSettings {
        shadows: false,
        ..RenderSettings::default()
    };
    let shadowed = RenderSettings::default();
    let a = render(&scene, &camera, &cam_pose, Window::full(200, 200), &lit);
    let b = render(
        &scene,
        &camera,
        &cam_pose,
        Window::full(200, 200),
        &shadowed,
    );
    let p = camera
        .project(&(cam_pose.inverse() * Point3::new(0.0, 0.0, 0.0)))
        .unwrap();
    let i = b.index(p.x.round() as u32, p.y.round() as u32).unwrap();
    assert_eq!(b.visible[i], 0, "the board point under the cube is visible");
    assert!(
        b.radiance[i][0] < 0.3 * a.radiance[i][0],
        "shadowed {:?} vs lit {:?}",
        b.radiance[i],
        a.radiance[i]
    );
}

fn super_look(eye: Point3<f64>, target: Point3<f64>) -> Isometry3<f64> {
    sim::scene::look_at(&eye, &target, &Vector3::y(), 0.0)
}
