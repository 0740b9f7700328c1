//! One commissioning run against the robot `--robot` names: the simulated cell in process, the
//! simulated cell behind a virtual UR over loopback RTDE, or a real controller with its camera
//! source and a person at the pendant (touch points) or the arm moving on its own behind its
//! limits (hand-eye, with `--allow-motion`).

use std::time::Duration;

use nalgebra::Vector3;
use perception::calibration::detect::DetectorSettings;
use perception::calibration::rigid_fit::{DEFAULT_TOUCH_BOUND, UR_REPEATABILITY_SIGMA};
use robots::virtual_ur::VirtualUrConfig;

use perception::calibration::{Board, BoardSpec};
use robots::ur_robot::{UrRobot, UrRobotConfig};
use sim::config::CalibrationMethod;

use super::evidence::Calibration;
use super::hand_eye::{Guess, HandEyeOptions, calibrate_by_hand_eye};
use super::procedure::{CalibrateError, TouchSettings, calibrate_by_touch};
use super::production::{CameraImages, PendantOperator};
use super::sim_world::{MountError, SimWorld, Truth};
use crate::camera::{CameraSpec, Sensor};
use crate::harness::{HarnessError, SimSetup, connect_sim_over_rtde};
use crate::orchestrator::CellKnowledge;
use crate::run::RobotTarget;
use crate::scenario::Scenario;

/// How a commissioning run is made.
#[derive(Debug, Clone, PartialEq)]
pub struct CommissionOptions {
    /// The pointer's tip in the TCP frame, metres.
    pub tip: Vector3<f64>,
    /// The farthest a touch may lie from where the others put it, metres.
    pub bound: f64,
    /// The per-axis 1σ of one touch, metres.
    pub touch_sigma: f64,
    /// The board detector's settings.
    pub detector: DetectorSettings,
    /// Seed of the simulated world (its mount error, lights and sensor); simulation only.
    pub world_seed: u64,
    /// How long a real camera's capture may wait.
    pub capture_timeout: Duration,
    /// How the board is found in the robot base.
    pub method: Method,
    /// The hand-eye poses and settings (`--method hand-eye`).
    pub hand_eye: HandEyeOptions,
    /// The board the arm carries for hand-eye (default `scenarios/boards/flange.toml`'s).
    pub flange_board: Option<Board>,
    /// The explicit opt-in that a real arm will move (hand-eye on `ur://`).
    pub allow_motion: bool,
}

/// How `cell calibrate` finds the table board in the robot base.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Method {
    /// A person (or the simulator's stand-in) touches the board's marks with a pointer; the
    /// arm is only read.
    #[default]
    Touch,
    /// The arm carries a flange board through planned poses (it moves on its own).
    HandEye,
}

impl Method {
    /// The method as the scenario's `[cell.calibration] method` records it.
    pub fn recorded(self) -> CalibrationMethod {
        match self {
            Method::Touch => CalibrationMethod::Touch,
            Method::HandEye => CalibrationMethod::HandEye,
        }
    }
}

/// The flange board of `scenarios/boards/flange.toml`: 2 × 2 tag36h11 tags from id 16 on an
/// 8 cm plate.
pub fn default_flange_board() -> Board {
    Board::new(BoardSpec {
        grid: [2, 2],
        removed: None,
        first_id: 16,
        plate: [0.08, 0.08],
        ..BoardSpec::seed()
    })
    .expect("the default flange board is valid")
}

impl Default for CommissionOptions {
    fn default() -> Self {
        Self {
            tip: Vector3::new(0.0, 0.0, 0.05),
            bound: DEFAULT_TOUCH_BOUND,
            touch_sigma: UR_REPEATABILITY_SIGMA,
            detector: DetectorSettings::default(),
            world_seed: 0,
            capture_timeout: Duration::from_secs(5),
            method: Method::Touch,
            hand_eye: HandEyeOptions::default(),
            flange_board: None,
            allow_motion: false,
        }
    }
}

impl CommissionOptions {
    fn touch(&self) -> TouchSettings {
        TouchSettings {
            tip: self.tip,
            bound: self.bound,
            touch_sigma: self.touch_sigma,
            detector: self.detector,
        }
    }
}

/// Why a commissioning run could not be made.
#[derive(Debug, thiserror::Error)]
pub enum CommissionError {
    /// The procedure stopped.
    #[error(transparent)]
    Calibrate(#[from] CalibrateError),
    /// The simulated cell could not be built.
    #[error(transparent)]
    Harness(#[from] HarnessError),
    /// The virtual controller could not be started or reached.
    #[error(transparent)]
    OverRtde(#[from] crate::harness::OverRtdeError),
    /// The scenario's board was not loaded.
    #[error("the scenario's board file was not read (validate the scenario first)")]
    NoBoard,
    /// A real controller needs a camera source.
    #[error(
        "commissioning a real cell needs --camera SPEC (the camera that sees the board: \
         folder:/path, cmd:'grab --out {{path}}', files:/path or aravis:[DEVICE])"
    )]
    NoCamera,
    /// The camera source could not be opened.
    #[error("camera: {0}")]
    Camera(#[from] crate::camera::CameraError),
    /// The simulated cell refused its limits.
    #[error("limits: {0}")]
    Limits(String),
    /// The scenario's cell cannot be modelled for planning.
    #[error(transparent)]
    Knowledge(#[from] crate::orchestrator::KnowledgeError),
    /// Hand-eye on a real controller moves the arm: it needs the explicit opt-in.
    #[error(
        "hand-eye calibration moves the arm through {poses} poses on its own: pass \
         --allow-motion (and keep the workspace clear), or use --method touch"
    )]
    NotAllowed {
        /// Poses it would move through.
        poses: usize,
    },
}

/// A finished commissioning run; in simulation with the world's truth beside it, to judge it.
pub struct Commissioned {
    /// The calibration.
    pub calibration: Calibration,
    /// The simulated world's true poses (simulation only).
    pub truth: Option<Truth>,
}

/// Commissions `scenario`'s cell on `target` by `options.method`.
pub async fn commission(
    scenario: &Scenario,
    target: &RobotTarget,
    camera: Option<&CameraSpec>,
    options: &CommissionOptions,
) -> Result<Commissioned, CommissionError> {
    match options.method {
        Method::Touch => commission_by_touch(scenario, target, camera, options).await,
        Method::HandEye => commission_by_hand_eye(scenario, target, camera, options).await,
    }
}

/// Commissions by touch points.
async fn commission_by_touch(
    scenario: &Scenario,
    target: &RobotTarget,
    camera: Option<&CameraSpec>,
    options: &CommissionOptions,
) -> Result<Commissioned, CommissionError> {
    let cell = &scenario.spec.cell;
    let board = cell.board_layout().ok_or(CommissionError::NoBoard)?;
    let intrinsics = cell.camera.intrinsics;
    let settings = options.touch();
    match target {
        RobotTarget::Ur { host, port } => {
            let spec = camera.ok_or(CommissionError::NoCamera)?;
            let mut images = CameraImages {
                source: crate::camera::open(spec, Sensor::of(&intrinsics))?,
                timeout: options.capture_timeout,
            };
            let mut operator = PendantOperator::connect(format!("{host}:{port}")).await?;
            let calibration =
                calibrate_by_touch(&intrinsics, &board, &mut images, &mut operator, &settings)
                    .await?;
            Ok(Commissioned {
                calibration,
                truth: None,
            })
        }
        sim_target => {
            let world = SimWorld::new(scenario, MountError::default(), options.world_seed);
            let setup = SimSetup::new(world.scenario.clone())?;
            let mut images = world.camera(&board, options.world_seed);
            let calibration = if matches!(sim_target, RobotTarget::VirtualUr) {
                let over =
                    connect_sim_over_rtde(&setup, 0, VirtualUrConfig::default().unlock_delay)
                        .await?;
                let mut operator = world.operator(over.robot, options.tip, options.world_seed);
                let result =
                    calibrate_by_touch(&intrinsics, &board, &mut images, &mut operator, &settings)
                        .await;
                drop(operator);
                drop(over.controller);
                result?
            } else {
                let robot = setup
                    .model
                    .limited(setup.sim_cell(0)?)
                    .map_err(|e| CommissionError::Limits(e.to_string()))?;
                let mut operator = world.operator(robot, options.tip, options.world_seed);
                calibrate_by_touch(&intrinsics, &board, &mut images, &mut operator, &settings)
                    .await?
            };
            Ok(Commissioned {
                calibration,
                truth: Some(world.truth()),
            })
        }
    }
}

/// Commissions by hand-eye: on a real controller only with `--allow-motion` and `--camera`,
/// both checked before anything connects.
async fn commission_by_hand_eye(
    scenario: &Scenario,
    target: &RobotTarget,
    camera: Option<&CameraSpec>,
    options: &CommissionOptions,
) -> Result<Commissioned, CommissionError> {
    let cell = &scenario.spec.cell;
    let board = cell.board_layout().ok_or(CommissionError::NoBoard)?;
    let flange = options
        .flange_board
        .clone()
        .unwrap_or_else(default_flange_board);
    let intrinsics = cell.camera.intrinsics;
    let guess = Guess {
        base_T_camera: cell.camera.base_T_camera.isometry(),
        base_T_table: cell.base_T_table.isometry(),
    };
    let he = &options.hand_eye;
    match target {
        RobotTarget::Ur { host, port } => {
            if !options.allow_motion {
                return Err(CommissionError::NotAllowed { poses: he.poses });
            }
            let spec = camera.ok_or(CommissionError::NoCamera)?;
            let mut images = CameraImages {
                source: crate::camera::open(spec, Sensor::of(&intrinsics))?,
                timeout: options.capture_timeout,
            };
            // The engine's model of the arm (kinematics with the gripper's TCP), as a production
            // run builds it: no simulated cell exists for a real controller.
            let knowledge = CellKnowledge::new(scenario)?;
            let mut config = UrRobotConfig::new(host.clone(), knowledge.kinematics.clone());
            config.rtde_port = *port;
            config.limits = cell.limits.clone();
            cell.gripper.configure_ur(&mut config);
            // Connected behind `Limited`: every planned pose is checked against the limits.
            let mut robot = UrRobot::connect(config)
                .await
                .map_err(|e| CommissionError::Calibrate(e.into()))?;
            let calibration = calibrate_by_hand_eye(
                &intrinsics,
                &board,
                &flange,
                &guess,
                &mut images,
                &mut robot,
                he,
            )
            .await?;
            Ok(Commissioned {
                calibration,
                truth: None,
            })
        }
        sim_target => {
            let world = SimWorld::new(scenario, MountError::default(), options.world_seed);
            let setup = SimSetup::new(world.scenario.clone())?;
            let calibration = if matches!(sim_target, RobotTarget::VirtualUr) {
                let over =
                    connect_sim_over_rtde(&setup, 0, VirtualUrConfig::default().unlock_delay)
                        .await?;
                // `over.robot` is connected behind `Limited` already.
                let (mut arm, mut images) =
                    world.hand_eye_rig(over.robot, &board, &flange, options.world_seed);
                let result = calibrate_by_hand_eye(
                    &intrinsics,
                    &board,
                    &flange,
                    &guess,
                    &mut images,
                    &mut arm,
                    he,
                )
                .await;
                drop(arm);
                drop(over.controller);
                result?
            } else {
                let robot = setup
                    .model
                    .limited(setup.sim_cell(0)?)
                    .map_err(|e| CommissionError::Limits(e.to_string()))?;
                let (mut arm, mut images) =
                    world.hand_eye_rig(robot, &board, &flange, options.world_seed);
                calibrate_by_hand_eye(
                    &intrinsics,
                    &board,
                    &flange,
                    &guess,
                    &mut images,
                    &mut arm,
                    he,
                )
                .await?
            };
            Ok(Commissioned {
                calibration,
                truth: Some(world.truth()),
            })
        }
    }
}
