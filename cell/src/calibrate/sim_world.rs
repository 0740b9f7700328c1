//! The simulator's stand-ins for a cell being commissioned: a world whose camera and table sit
//! where nobody typed them (the scenario's poses are only the integrator's first guess), a
//! camera that renders the board from the true camera pose, an operator who jogs the
//! pointer onto the true marks, and for hand-eye an arm carrying a flange board mounted off its
//! design ([`SimHoldingArm`]) with a camera that renders it beside the table board
//! ([`SimHandEyeCamera`]).
//!
//! Only these stand-ins know the truth. The procedure ([`super::procedure`]) sees their pixels
//! and the robot's readings, nothing else; [`SimWorld::truth`] is for judging the result.

#![allow(non_snake_case)]

use std::sync::{Arc, Mutex};

use image::{DynamicImage, GrayImage, Luma};
use nalgebra::{Isometry3, Point3, Translation3, Vector3, Vector6};
use perception::calibration::Board;
use perception::calibration::covariance::perturb;
use perception::calibration::touch_marks::TouchMark;
use perception::{Camera, FrameImage};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use robots::motion::LinearMotion;
use robots::observed::{Command, Observed, Observer};
use robots::robot::{ContactOutcome, Robot, RobotFuture};
use sim::render::{RenderOutput, RenderSettings, TagBoard, Window, render, window_covering};
use sim::scene::{BoardView, Randomisation};
use sim::scene::{board_render_settings, sample_board_view};

use super::hand_eye::nominal_tcp_T_flange_board;
use super::preflight::PROBES;
use super::procedure::{BoardImages, CalibrateError, Operator, StepFuture};
use crate::scenario::Scenario;

/// How far the world's true poses lie from the scenario's typed ones (one sigma per axis):
/// a camera mount and a table placed by hand and tape measure.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MountError {
    /// Camera position, metres.
    pub camera_translation: f64,
    /// Camera orientation, radians.
    pub camera_rotation: f64,
    /// Table position in the plane, metres.
    pub table_translation: f64,
    /// Table yaw, radians.
    pub table_yaw: f64,
    /// Position of a hand-eye board on the tool, against its nominal mounting, metres.
    pub flange_board_translation: f64,
    /// Orientation of a hand-eye board on the tool, against its nominal mounting, radians.
    pub flange_board_rotation: f64,
}

impl Default for MountError {
    fn default() -> Self {
        Self {
            camera_translation: 2e-3,
            camera_rotation: 2e-3,
            table_translation: 1e-3,
            table_yaw: 3e-3,
            flange_board_translation: 1e-3,
            flange_board_rotation: 1e-2,
        }
    }
}

/// The true poses of a simulated cell being commissioned.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Truth {
    /// The camera in the base.
    pub base_T_camera: Isometry3<f64>,
    /// The table (board top face) in the base.
    pub base_T_table: Isometry3<f64>,
    /// A hand-eye board on the tool: its true mounting in the TCP frame.
    pub tcp_T_flange_board: Isometry3<f64>,
}

/// A simulated cell being commissioned: the scenario with its camera and table moved by a
/// seeded [`MountError`].
pub struct SimWorld {
    /// The scenario with the true poses: what the simulated cell (arm, camera) is built from.
    pub scenario: Scenario,
    truth: Truth,
}

impl SimWorld {
    /// The world for `scenario`, its mount error drawn from `seed`.
    pub fn new(scenario: &Scenario, error: MountError, seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut g = |s: f64| -> f64 {
            let z: f64 = StandardNormal.sample(&mut rng);
            s * z
        };
        let cell = &scenario.spec.cell;
        let (ct, cr) = (error.camera_translation, error.camera_rotation);
        let base_T_camera = perturb(
            &cell.camera.base_T_camera.isometry(),
            &Vector6::new(g(ct), g(ct), g(ct), g(cr), g(cr), g(cr)),
        );
        let tt = error.table_translation;
        let base_T_table = perturb(
            &cell.base_T_table.isometry(),
            &Vector6::new(g(tt), g(tt), 0.0, 0.0, 0.0, g(error.table_yaw)),
        );
        // Drawn after the camera and the table, so their draws are those of a world without it.
        let (bt, br) = (error.flange_board_translation, error.flange_board_rotation);
        let tcp_T_flange_board = perturb(
            &nominal_tcp_T_flange_board(),
            &Vector6::new(g(bt), g(bt), g(bt), g(br), g(br), g(br)),
        );
        let mut world = scenario.clone();
        world.spec.cell.camera.base_T_camera = pose_spec(&base_T_camera);
        world.spec.cell.base_T_table = pose_spec(&base_T_table);
        Self {
            scenario: world,
            truth: Truth {
                base_T_camera,
                base_T_table,
                tcp_T_flange_board,
            },
        }
    }

    /// The true poses, to judge a calibration by (never to make one).
    pub fn truth(&self) -> Truth {
        self.truth
    }
}

impl Truth {
    /// How far off a calibration places a part the camera sees on the board: the largest
    /// distance, over the board's probes ([`PROBES`]), between a true board point in the base
    /// and where the calibrated camera's ray through its pixel meets the calibrated table.
    pub fn placement_error(
        &self,
        base_T_camera: &Isometry3<f64>,
        base_T_table: &Isometry3<f64>,
        board: &Board,
    ) -> (f64, &'static str) {
        let [px, py] = board.spec().plate;
        let normal = base_T_table.rotation * Vector3::z();
        PROBES
            .iter()
            .filter_map(|&(name, sx, sy)| {
                let truth = self.base_T_table * Point3::new(sx * px / 2.0, sy * py / 2.0, 0.0);
                let seen = self.base_T_camera.inverse() * truth;
                let origin = base_T_camera.translation.vector;
                let direction = base_T_camera.rotation * seen.coords;
                let along = direction.dot(&normal);
                (along.abs() > 1e-12).then(|| {
                    let t = (base_T_table.translation.vector - origin).dot(&normal) / along;
                    ((origin + t * direction - truth.coords).norm(), name)
                })
            })
            .fold((0.0, "centre"), |a, b| if b.0 > a.0 { b } else { a })
    }
}

impl SimWorld {
    /// The camera: renders the board from the true camera pose, lights, print wear and sensor
    /// drawn from the scenario's randomisation with `seed`.
    pub fn camera(&self, board: &Board, seed: u64) -> SimBoardCamera {
        SimBoardCamera {
            board: board.clone(),
            camera: self.scenario.spec.cell.camera.intrinsics,
            table_T_camera: self.truth.base_T_table.inverse() * self.truth.base_T_camera,
            randomisation: Randomisation::default(),
            rng: ChaCha8Rng::seed_from_u64(seed),
        }
    }

    /// The operator: jogs `robot`'s pointer (its tip at `tip` in the TCP frame) onto the true
    /// marks; where the tip truly is then differs from the TCP reading by the scenario's
    /// `noise.robot_repeatability`, drawn from `seed`.
    pub fn operator<R: Robot>(&self, robot: R, tip: Vector3<f64>, seed: u64) -> SimOperator<R> {
        let limits = &self.scenario.spec.cell.limits;
        SimOperator {
            robot,
            repeatability: self.scenario.spec.noise.robot_repeatability,
            rng: ChaCha8Rng::seed_from_u64(seed ^ OPERATOR_STREAM),
            base_T_table: self.truth.base_T_table,
            tip,
            motion: LinearMotion {
                speed: 0.25 * limits.max_tcp_speed,
                acceleration: 0.5 * limits.max_tcp_acceleration,
            },
        }
    }
}

/// A scenario pose from an isometry.
fn pose_spec(p: &Isometry3<f64>) -> sim::config::PoseSpec {
    sim::config::PoseSpec {
        translation: p.translation.vector.into(),
        rotation: p.rotation.scaled_axis().into(),
    }
}

/// The simulated camera of a commissioning: the window of the sensor that shows the board.
pub struct SimBoardCamera {
    board: Board,
    camera: Camera,
    table_T_camera: Isometry3<f64>,
    randomisation: Randomisation,
    rng: ChaCha8Rng,
}

impl BoardImages for SimBoardCamera {
    fn capture(&mut self) -> Result<FrameImage, CalibrateError> {
        let fail = |message: String| CalibrateError::Camera {
            camera: "simulated camera".into(),
            message,
        };
        let mut view = sample_board_view(
            &self.board,
            &self.camera,
            &self.randomisation,
            &mut self.rng,
        )
        .map_err(|e| fail(e.to_string()))?;
        view.scene.table_T_camera = self.table_T_camera;
        let window = view
            .window()
            .ok_or_else(|| fail("the board is out of the camera's view".into()))?;
        let shot = view
            .render(window, &board_render_settings(), &mut self.rng)
            .map_err(|e| fail(e.to_string()))?;
        Ok(shot.image)
    }

    fn describe(&self) -> String {
        "simulated camera".into()
    }

    fn full_sensor(&self) -> bool {
        false
    }
}

/// The simulator's operator: moves the pointer 20 mm above a mark, then down onto it, at a
/// quarter of the scenario's TCP speed. A reading at a touch differs from where the tip truly
/// is by the arm's repeatability (the encoders do not see it): the simulated arm reports the
/// pose it was sent to, so the operator aims off the mark by that error instead.
pub struct SimOperator<R> {
    robot: R,
    repeatability: f64,
    rng: ChaCha8Rng,
    base_T_table: Isometry3<f64>,
    tip: Vector3<f64>,
    motion: LinearMotion,
}

/// Seed stream of the operator's touch errors (apart from the mount error's and the camera's).
const OPERATOR_STREAM: u64 = 0x6f70_6572_6174_6f72;

/// Height above a mark from which the pointer descends onto it, metres.
const APPROACH: f64 = 0.02;

impl<R: Robot> Operator for SimOperator<R> {
    fn touch<'a>(
        &'a mut self,
        mark: &'a TouchMark,
        _index: usize,
        _count: usize,
    ) -> StepFuture<'a, Isometry3<f64>> {
        Box::pin(async move {
            let robot = &mut self.robot;
            let base_T_tcp = robot.tcp_pose().await?;
            let rotation = base_T_tcp.rotation;
            let r = self.repeatability;
            let mut g = || -> f64 {
                let z: f64 = StandardNormal.sample(&mut self.rng);
                r * z
            };
            let target = self.base_T_table * mark.point + Vector3::new(g(), g(), g());
            let tcp_at = |p: Point3<f64>| {
                Isometry3::from_parts(Translation3::from(p.coords - rotation * self.tip), rotation)
            };
            let above = target + Vector3::z() * APPROACH;
            // Off the previous mark first, straight up, never dragging the tip over the print.
            let tip_now = base_T_tcp * Point3::from(self.tip);
            if tip_now.z < above.z {
                robot
                    .move_l(
                        tcp_at(Point3::new(tip_now.x, tip_now.y, above.z)),
                        self.motion,
                    )
                    .await?;
            }
            robot.move_l(tcp_at(above), self.motion).await?;
            robot.move_l(tcp_at(target), self.motion).await?;
            Ok(robot.tcp_pose().await?)
        })
    }
}

/// The true TCP pose of a hand-eye rig's arm, which its camera renders the held board at
/// (`None` until the arm first moves).
type HeldPose = Arc<Mutex<Option<Isometry3<f64>>>>;

/// Seed stream of the hand-eye arm's pose errors.
const ARM_STREAM: u64 = 0x6861_6e64_2d65_7965;

/// The reach over which the arm's position repeatability becomes an orientation error, metres
/// (a UR5e's, as [`perception::calibration::hand_eye::HandEyeSettings`] assumes).
const ARM_REACH: f64 = 0.85;

impl SimWorld {
    /// The hand-eye rig: `robot` carrying `flange_board` at the world's true mounting
    /// ([`Truth::tcp_T_flange_board`]), and the camera that sees it beside `table_board`. The
    /// arm reports the pose it was sent to; where its TCP truly is differs by the scenario's
    /// `noise.robot_repeatability` per axis (and that over a UR5e's reach in orientation), drawn
    /// from `seed`, and the camera renders the board there.
    pub fn hand_eye_rig<R: Robot>(
        &self,
        robot: R,
        table_board: &Board,
        flange_board: &Board,
        seed: u64,
    ) -> (SimHoldingArm<R>, SimHandEyeCamera) {
        let held: HeldPose = Arc::new(Mutex::new(None));
        let arm = Observed::new(
            robot,
            HeldBoard {
                held: held.clone(),
                repeatability: self.scenario.spec.noise.robot_repeatability,
                rng: ChaCha8Rng::seed_from_u64(seed ^ ARM_STREAM),
            },
        );
        let camera = SimHandEyeCamera {
            // The same draw of lights, print wear and sensor as the touch method's camera for
            // this seed, so the two methods are compared on the same world.
            table: self.camera(table_board, seed),
            flange_board: flange_board.clone(),
            tcp_T_board: self.truth.tcp_T_flange_board,
            base_T_table: self.truth.base_T_table,
            held,
            table_render: None,
        };
        (arm, camera)
    }
}

/// The simulated arm of a hand-eye calibration: the robot, and where the board it carries truly
/// is after each move (the commanded pose off by the arm's repeatability, which the robot's
/// reading does not show), kept by its [`HeldBoard`] observer.
pub type SimHoldingArm<R> = Observed<R, HeldBoard>;

/// Where the board a hand-eye calibration's arm carries truly is: after each arm motion, the
/// pose the arm settled at off by its repeatability.
pub struct HeldBoard {
    held: HeldPose,
    repeatability: f64,
    rng: ChaCha8Rng,
}

impl HeldBoard {
    /// Where the TCP truly is when the arm reports `reading`.
    fn settle(&mut self, reading: Isometry3<f64>) {
        let r = self.repeatability;
        let mut g = |s: f64| -> f64 {
            let z: f64 = StandardNormal.sample(&mut self.rng);
            s * z
        };
        let error = Vector6::new(
            g(r),
            g(r),
            g(r),
            g(r / ARM_REACH),
            g(r / ARM_REACH),
            g(r / ARM_REACH),
        );
        *self.held.lock().unwrap_or_else(|p| p.into_inner()) = Some(perturb(&reading, &error));
    }
}

impl<R: Robot> Observer<R> for HeldBoard {
    /// The arm settles after each motion: at the commanded pose after a linear move, where it
    /// stopped after a guarded move, and where it reads after a joint move or a blended path
    /// (the held target's reading is taken from where the arm rests).
    #[allow(non_snake_case)]
    fn after<'a>(
        &'a mut self,
        robot: &'a mut R,
        command: &'a Command<'a>,
        contact: Option<&'a ContactOutcome>,
    ) -> RobotFuture<'a, ()> {
        Box::pin(async move {
            let reading = match (command, contact) {
                (Command::MoveJ { .. } | Command::MovePath { .. }, _) => robot.tcp_pose().await?,
                (Command::MoveL { base_T_tcp, .. }, _) => *base_T_tcp,
                (Command::MoveUntilContact { .. }, Some(outcome)) => outcome.stopped_at,
                _ => return Ok(()),
            };
            self.settle(reading);
            Ok(())
        })
    }
}

/// The simulated camera of a hand-eye calibration: the table board and the board the arm holds,
/// each rendered in the window that shows it (the table board's radiance once, as nothing on it
/// moves; fresh sensor noise every capture), pasted into one window of the sensor that covers
/// both, the rest the grey of an unlit table with sensor noise.
pub struct SimHandEyeCamera {
    table: SimBoardCamera,
    flange_board: Board,
    tcp_T_board: Isometry3<f64>,
    base_T_table: Isometry3<f64>,
    held: HeldPose,
    table_render: Option<(BoardView, Window, RenderOutput)>,
}

/// Settings for renders of the held board: [`board_render_settings`] with 4 × 4 samples at
/// edges instead of 8 × 8. A tilted board has the renderer supersample nearly every pixel of
/// it, and 16 samples are 4 times faster than 64; on world seed 1 the calibration's camera and
/// placement errors moved by a few µm between the two (see `cell calibrate --method hand-eye`).
fn held_board_render_settings() -> RenderSettings {
    RenderSettings {
        supersampling: 4,
        ..board_render_settings()
    }
}

/// Grey level and noise amplitude of the sensor between the boards' windows.
const GAP_FILL: (u8, u8) = (24, 3);

impl SimHandEyeCamera {
    /// Renders the table board's radiance on first use.
    fn render_table(&mut self) -> Result<(), String> {
        if self.table_render.is_none() {
            let t = &mut self.table;
            let mut view = sample_board_view(&t.board, &t.camera, &t.randomisation, &mut t.rng)
                .map_err(|e| e.to_string())?;
            view.scene.table_T_camera = t.table_T_camera;
            let window = view
                .window()
                .ok_or("the table board is out of the camera's view")?;
            let out = render(
                &view.scene.render,
                &view.camera,
                &view.scene.table_T_camera,
                window,
                &board_render_settings(),
            );
            self.table_render = Some((view, window, out));
        }
        Ok(())
    }

    /// The held board's window image, or `None` when it is not in view (or not yet on the arm).
    fn held_board(&mut self, view: &BoardView) -> Result<Option<FrameImage>, String> {
        let Some(base_T_tcp) = *self.held.lock().unwrap_or_else(|p| p.into_inner()) else {
            return Ok(None);
        };
        let table_T_board = self.base_T_table.inverse() * base_T_tcp * self.tcp_T_board;
        let mut v = view.clone();
        let mut held = TagBoard::new(self.flange_board.clone()).with_pose(table_T_board);
        if let Some(b) = &v.scene.render.board {
            (held.white, held.black) = (b.white, b.black);
            (held.grain, held.dust, held.scratches) = (b.grain, b.dust, b.scratches);
        }
        v.scene.render.board = Some(held);
        let [px, py] = self.flange_board.spec().plate;
        let mut lo = Point3::from(Vector3::repeat(f64::INFINITY));
        let mut hi = Point3::from(Vector3::repeat(f64::NEG_INFINITY));
        for sx in [-0.6, 0.6] {
            for sy in [-0.6, 0.6] {
                let p = table_T_board * Point3::new(sx * px, sy * py, 0.0);
                lo = lo.inf(&p);
                hi = hi.sup(&p);
            }
        }
        let Some(window) = window_covering(&v.camera, &v.scene.table_T_camera, &lo, &hi) else {
            return Ok(None);
        };
        let shot = v
            .render(window, &held_board_render_settings(), &mut self.table.rng)
            .map_err(|e| e.to_string())?;
        Ok(Some(shot.image))
    }
}

impl BoardImages for SimHandEyeCamera {
    fn capture(&mut self) -> Result<FrameImage, CalibrateError> {
        let fail = |message: String| CalibrateError::Camera {
            camera: "simulated camera".into(),
            message,
        };
        self.render_table().map_err(fail)?;
        let Some((view, window, out)) = self.table_render.as_ref() else {
            return Err(fail("the table board was not rendered".into()));
        };
        let rgb = view
            .metered_sensor(out)
            .capture(out, &mut self.table.rng)
            .map_err(|e| fail(e.to_string()))?;
        let (view, window) = (view.clone(), *window);
        let table = FrameImage {
            pixels: DynamicImage::ImageLuma8(DynamicImage::ImageRgb8(rgb).into_luma8()),
            origin: [window.x0, window.y0],
        };
        let mut parts = vec![table];
        parts.extend(self.held_board(&view).map_err(fail)?);
        Ok(paste(&parts))
    }

    fn describe(&self) -> String {
        "simulated camera".into()
    }

    fn full_sensor(&self) -> bool {
        false
    }
}

/// One window of the sensor covering `parts` (windows of it), each pasted where it lies (later
/// ones over earlier ones), the rest [`GAP_FILL`] with deterministic sensor-like noise.
fn paste(parts: &[FrameImage]) -> FrameImage {
    let x0 = parts.iter().map(|p| p.origin[0]).min().unwrap_or(0);
    let y0 = parts.iter().map(|p| p.origin[1]).min().unwrap_or(0);
    let x1 = parts
        .iter()
        .map(|p| p.origin[0] + p.width())
        .max()
        .unwrap_or(0);
    let y1 = parts
        .iter()
        .map(|p| p.origin[1] + p.height())
        .max()
        .unwrap_or(0);
    let (fill, noise) = GAP_FILL;
    let span = 2 * u32::from(noise) + 1;
    let mut state = 0x9e37_79b9_u32;
    let mut frame = GrayImage::from_fn(x1 - x0, y1 - y0, |_, _| {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        Luma([(u32::from(fill) + state % span).saturating_sub(u32::from(noise)) as u8])
    });
    for part in parts {
        let grey = part.pixels.to_luma8();
        image::imageops::replace(
            &mut frame,
            &grey,
            i64::from(part.origin[0] - x0),
            i64::from(part.origin[1] - y0),
        );
    }
    FrameImage {
        pixels: DynamicImage::ImageLuma8(frame),
        origin: [x0, y0],
    }
}
