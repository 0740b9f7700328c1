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

/// The window showing the plate at `table_T_board` from the overhead camera, with a margin.
fn plate_window(camera: &Camera, table_T_board: &Isometry3<f64>, board: &Board) -> Window {
    plate_window_from(camera, &overhead(), table_T_board, board)
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

/// Hand-eye from rendered pixels alone: a 2 × 2 flange board held at eight planned poses
/// 20 cm above the table, each view rendered under the renderer's randomisation (print wear,
/// lights, blur, noise), detected and posed by the calibration's own detector and PnP, and the
/// robot's readings with its repeatability. Nothing but those poses and pixels reaches the solver.
#[test]
fn hand_eye_from_rendered_views_recovers_the_camera() {
    use perception::calibration::board_pose::board_pose;
    use perception::calibration::hand_eye::{HandEyeSettings, HandEyeView, plan_hand_eye_poses};
    use perception::calibration::{DetectorSettings, detect_board};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};
    use sim::scene::{Randomisation, board_render_settings, sample_board_view};

    let mut rng = ChaCha8Rng::seed_from_u64(2026);
    let camera = Camera::basler_seed();
    let board = flange_board();
    let base_T_table = Isometry3::from_parts(
        Translation3::new(0.42, -0.15, -0.02),
        UnitQuaternion::from_euler_angles(0.001, -0.002, 0.25),
    );
    let flange_T_board = Isometry3::from_parts(
        Translation3::new(0.002, -0.003, 0.04),
        UnitQuaternion::from_euler_angles(0.0, 0.0, 0.3),
    );
    let table_T_board_centre = Isometry3::translation(0.01, -0.02, 0.2);
    let centre = base_T_table * table_T_board_centre * flange_T_board.inverse();
    let poses = plan_hand_eye_poses(&centre, 8, 0.35, 0.6);
    let settings = HandEyeSettings::default();
    let noise = Normal::new(0.0, settings.robot_translation_sigma).unwrap();
    let turn = Normal::new(0.0, settings.robot_rotation_sigma).unwrap();
    let view = sample_board_view(&board, &camera, &Randomisation::default(), &mut rng).unwrap();
    let base_T_camera = base_T_table * view.scene.table_T_camera;
    let mut views = Vec::new();
    for base_T_flange in &poses {
        let table_T_board = base_T_table.inverse() * base_T_flange * flange_T_board;
        let mut v = view.clone();
        let mut held = TagBoard::new(board.clone()).with_pose(table_T_board);
        if let Some(b) = &v.scene.render.board {
            (held.white, held.black) = (b.white, b.black);
            (held.grain, held.dust, held.scratches) = (b.grain, b.dust, b.scratches);
        }
        v.scene.render.board = Some(held);
        let window = plate_window_from(&camera, &v.scene.table_T_camera, &table_T_board, &board);
        let image = v
            .render(window, &board_render_settings(), &mut rng)
            .unwrap()
            .image;
        let sighting = detect_board(&image, &board, &DetectorSettings::default()).unwrap();
        assert_eq!(sighting.tags.len(), 4);
        let pose = board_pose(&camera, &board, &sighting).unwrap();
        let read = Isometry3::from_parts(
            Translation3::from(
                base_T_flange.translation.vector + Vector3::from_fn(|_, _| noise.sample(&mut rng)),
            ),
            UnitQuaternion::from_scaled_axis(Vector3::from_fn(|_, _| turn.sample(&mut rng)))
                * base_T_flange.rotation,
        );
        views.push(HandEyeView {
            base_T_flange: read,
            camera_T_board: pose.camera_T_board,
            covariance: pose.covariance,
        });
    }
    let solution = perception::calibration::hand_eye::solve_hand_eye(&views, &settings).unwrap();
    // The error where it matters, and what the solution's covariance predicts for it: table
    // points of the feeder (±10 cm) seen by the camera, mapped into the base.
    let (mut sum, mut predicted) = (0.0, 0.0);
    for i in -2..=2 {
        for j in -2..=2 {
            let p = base_T_table * Point3::new(i as f64 * 0.05, j as f64 * 0.05, 0.0);
            let seen = base_T_camera.inverse() * p;
            sum += (solution.base_T_camera * seen - p).norm_squared();
            let lever = p.coords - solution.base_T_camera.translation.vector;
            let mut jac = nalgebra::Matrix3x6::zeros();
            jac.fixed_view_mut::<3, 3>(0, 0)
                .copy_from(&nalgebra::Matrix3::identity());
            jac.fixed_view_mut::<3, 3>(0, 3)
                .copy_from(&(-lever.cross_matrix()));
            predicted += (jac * solution.covariance * jac.transpose()).trace();
        }
    }
    let (feeder, predicted) = ((sum / 25.0).sqrt(), (predicted / 25.0).sqrt());
    let mut delta = nalgebra::Vector6::zeros();
    delta
        .fixed_rows_mut::<3>(0)
        .copy_from(&(base_T_camera.translation.vector - solution.base_T_camera.translation.vector));
    delta.fixed_rows_mut::<3>(3).copy_from(
        &(base_T_camera.rotation * solution.base_T_camera.rotation.inverse()).scaled_axis(),
    );
    let mahalanobis =
        (delta.transpose() * solution.covariance.try_inverse().unwrap() * delta)[(0, 0)].sqrt();
    let chi2: f64 = solution
        .residuals
        .iter()
        .map(|r| r.mahalanobis.powi(2))
        .sum();
    let dof = 6 * views.len() - 12;
    eprintln!(
        "feeder error {:.1} µm (predicted 1σ {:.1} µm), camera rotation error {:.1} µrad, \
         Mahalanobis {mahalanobis:.2} (6 dof), residual χ² {chi2:.1} for {dof} dof",
        feeder * 1e6,
        predicted * 1e6,
        (solution.base_T_camera.inverse() * base_T_camera)
            .rotation
            .angle()
            * 1e6,
    );
    // The error is what the covariance says it should be: within the 98.6 % region of χ²(6),
    // the residuals within the central 98 % of χ²(36), and the feeder within 3σ.
    assert!(mahalanobis < 4.0, "{mahalanobis}");
    assert!((19.2..58.6).contains(&chi2), "{chi2}");
    assert!(feeder < 3.0 * predicted, "{feeder} vs {predicted}");
}

/// The window showing the plate at `table_T_board` from a camera at `table_T_camera`.
fn plate_window_from(
    camera: &Camera,
    table_T_camera: &Isometry3<f64>,
    table_T_board: &Isometry3<f64>,
    board: &Board,
) -> Window {
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
    window_covering(camera, table_T_camera, &lo, &hi).unwrap()
}
