//! The simulator's stand-ins for a cell being commissioned: a world whose camera and table sit
//! where nobody typed them (the scenario's poses are only the integrator's first guess), a
//! camera that renders the board from the true camera pose, and an operator who jogs the
//! pointer onto the true marks.
//!
//! Only these stand-ins know the truth. The procedure ([`super::procedure`]) sees their pixels
//! and the robot's readings, nothing else; [`SimWorld::truth`] is for judging the result.

#![allow(non_snake_case)]

use nalgebra::{Isometry3, Point3, Translation3, Vector3, Vector6};
use perception::calibration::Board;
use perception::calibration::covariance::perturb;
use perception::calibration::touch_marks::TouchMark;
use perception::{Camera, FrameImage};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use robots::motion::LinearMotion;
use robots::robot::Robot;
use sim::scene::Randomisation;
use sim::scene::{board_render_settings, sample_board_view};

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
}

impl Default for MountError {
    fn default() -> Self {
        Self {
            camera_translation: 2e-3,
            camera_rotation: 2e-3,
            table_translation: 1e-3,
            table_yaw: 3e-3,
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
        let mut world = scenario.clone();
        world.spec.cell.camera.base_T_camera = pose_spec(&base_T_camera);
        world.spec.cell.base_T_table = pose_spec(&base_T_table);
        Self {
            scenario: world,
            truth: Truth {
                base_T_camera,
                base_T_table,
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
