//! A board placed at a pose (held by the robot for hand-eye calibration) renders its print where
//! the pose puts it, and exactly as the unposed board seen from the correspondingly moved camera.
#![allow(non_snake_case)]

use nalgebra::{Isometry3, Point2, Point3, Translation3, UnitQuaternion, Vector3};
use perception::calibration::{Board, BoardSpec};
use perception::camera::Camera;
use perception::part::Material;
use sim::render::{
    Appearance, PointLight, RenderOutput, RenderScene, RenderSettings, Table, TagBoard, Window,
    render, window_covering,
};

/// The 2 × 2 board of 3 cm tags on an 8 cm plate that a flange carries.
fn flange_board() -> Board {
    Board::new(BoardSpec {
        grid: [2, 2],
        removed: None,
        plate: [0.08, 0.08],
        ..BoardSpec::seed()
    })
    .unwrap()
}

/// The camera 1.5 m above the table origin, looking down.
fn overhead() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(0.0, 0.0, 1.5),
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
    )
}

/// The held board: 30 cm above the table, off-centre, tilted about 20° and turned.
fn held_pose() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(0.04, -0.03, 0.3),
        UnitQuaternion::from_euler_angles(0.3, -0.18, 0.7),
    )
}

fn lights() -> Vec<PointLight> {
    vec![
        PointLight {
            position: Point3::new(0.3, 0.2, 1.2),
            intensity: [2.0; 3],
            radius: 0.02,
        },
        PointLight {
            position: Point3::new(-0.4, 0.1, 1.0),
            intensity: [1.0; 3],
            radius: 0.0,
        },
    ]
}

/// A worn print (grain, dust, scratches), so the texture must follow the pose too.
fn worn(board: Board) -> TagBoard {
    let mut b = TagBoard::new(board);
    b.grain = 0.05;
    b.dust = 1.0;
    b.scratches = 2.0;
    b.texture_seed = 5;
    b
}

/// The window showing the plate at `table_T_board`, with a margin.
fn plate_window(camera: &Camera, table_T_board: &Isometry3<f64>, board: &Board) -> Window {
    let [px, py] = board.spec().plate;
    let mut lo = Point3::from(Vector3::repeat(f64::INFINITY));
    let mut hi = Point3::from(Vector3::repeat(f64::NEG_INFINITY));
    for sx in [-0.6, 0.6] {
        for sy in [-0.6, 0.6] {
            let p = table_T_board * Point3::new(sx * px, sy * py, 0.0);
            lo = lo.inf(&p);
            hi = hi.sup(&p);
        }
    }
    window_covering(camera, &overhead(), &lo, &hi).unwrap()
}

fn luminance(out: &RenderOutput, pixel: Point2<f64>) -> f32 {
    let i = out
        .index(pixel.x.round() as u32, pixel.y.round() as u32)
        .expect("inside the window");
    let [r, g, b] = out.radiance[i];
    0.2126 * r + 0.7152 * g + 0.0722 * b
}

#[test]
fn a_held_board_shows_its_print_where_its_pose_puts_it() {
    let camera = Camera::basler_seed();
    let board = flange_board();
    let pose = held_pose();
    let scene = RenderScene::new(
        Vec::new(),
        Some(TagBoard::new(board.clone()).with_pose(pose)),
        Some(Table {
            height: -0.003,
            appearance: Appearance::for_material(Material::DarkPlastic),
        }),
        lights(),
        [0.1; 3],
    );
    let window = plate_window(&camera, &pose, &board);
    let out = render(
        &scene,
        &camera,
        &overhead(),
        window,
        &RenderSettings::default(),
    );
    let camera_T_board = overhead().inverse() * pose;
    let project = |p: Point3<f64>| camera.project(&(camera_T_board * p)).unwrap();

    // Every cell of every tag, at its centre: black where the family prints black.
    let cell = board.spec().tag_size / board.family().width_at_border as f64;
    let (mut black, mut white) = (Vec::new(), Vec::new());
    for tag in board.tags() {
        let w = board.family().total_width as i32;
        for cy in 0..w {
            for cx in 0..w {
                let x = tag.center.x + (cx as f64 + 0.5 - w as f64 / 2.0) * cell;
                let y = tag.center.y - (cy as f64 + 0.5 - w as f64 / 2.0) * cell;
                let l = luminance(&out, project(Point3::new(x, y, 0.0)));
                if board.is_black(x, y) {
                    black.push(l);
                } else {
                    white.push(l);
                }
            }
        }
    }
    let darkest_white = white.iter().copied().fold(f32::INFINITY, f32::min);
    let brightest_black = black.iter().copied().fold(0.0, f32::max);
    assert_eq!(black.len() + white.len(), 4 * 100);
    assert!(black.len() > 150 && white.len() > 150);
    assert!(
        brightest_black < 0.2 * darkest_white,
        "black up to {brightest_black}, white from {darkest_white}"
    );

    // The depth at the board's centre is the posed top face's.
    let centre = camera_T_board * Point3::origin();
    let pixel = project(Point3::origin());
    let i = out
        .index(pixel.x.round() as u32, pixel.y.round() as u32)
        .unwrap();
    // The pixel centre is within half a pixel of the projected centre: the depth within the
    // board's tilt over half a pixel's footprint (0.1 mm × tan 25°).
    assert!(
        (out.depth[i] - centre.z).abs() < 5e-5,
        "{} vs {}",
        out.depth[i],
        centre.z
    );

    // Just beyond the plate is the table, far below and darker than the print's white.
    let [px, _] = board.spec().plate;
    let beyond = luminance(&out, project(Point3::new(0.55 * px, 0.0, 0.0)));
    let j = out
        .index(
            project(Point3::new(0.55 * px, 0.0, 0.0)).x.round() as u32,
            project(Point3::new(0.55 * px, 0.0, 0.0)).y.round() as u32,
        )
        .unwrap();
    assert!(out.depth[j] > 1.49, "{}", out.depth[j]);
    assert!(beyond < 0.5 * darkest_white, "{beyond}");
}

#[test]
fn a_posed_board_renders_as_the_unposed_board_from_the_moved_camera() {
    // Scene A: the board at a pose, camera overhead. Scene B: the board unposed, the camera
    // and the lights moved by the inverse pose. Same geometry, so the same image up to rounding.
    let camera = Camera::basler_seed();
    let board = flange_board();
    let pose = held_pose();
    let a = RenderScene::new(
        Vec::new(),
        Some(worn(board.clone()).with_pose(pose)),
        None,
        lights(),
        [0.1; 3],
    );
    let moved: Vec<PointLight> = lights()
        .into_iter()
        .map(|l| PointLight {
            position: pose.inverse() * l.position,
            ..l
        })
        .collect();
    let b = RenderScene::new(Vec::new(), Some(worn(board.clone())), None, moved, [0.1; 3]);
    let window = plate_window(&camera, &pose, &board);
    let settings = RenderSettings::default();
    let out_a = render(&a, &camera, &overhead(), window, &settings);
    let out_b = render(
        &b,
        &camera,
        &(pose.inverse() * overhead()),
        window,
        &settings,
    );
    let mut on_board = 0;
    let mut worst: f32 = 0.0;
    for (pa, pb) in out_a.radiance.iter().zip(&out_b.radiance) {
        if pa[1] > 0.0 || pb[1] > 0.0 {
            on_board += 1;
        }
        for c in 0..3 {
            worst = worst.max((pa[c] - pb[c]).abs() / pa[c].abs().max(pb[c].abs()).max(1e-3));
        }
    }
    let depth_err = out_a
        .depth
        .iter()
        .zip(&out_b.depth)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max);
    eprintln!(
        "{on_board} board pixels; radiance differs by at most {worst:.2e} (relative), depth by \
         {depth_err:.2e} m"
    );
    assert!(on_board > 480_000, "{on_board}");
    // The same image up to floating-point rounding, print edges, dust and scratches included.
    assert!(worst < 1e-5, "{worst}");
    assert!(depth_err < 1e-12, "{depth_err}");
}
