//! The simulated and real cell as scenario files describe it: geometry, feeder, gripper, limits,
//! assembly steps and error sources. The `cell` crate's scenario files embed these tables.

use std::collections::BTreeMap;
use std::path::PathBuf;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use perception::camera::Camera;
use robots::limits::Limits;
use serde::{Deserialize, Serialize};

/// A pose in a scenario file: `{ translation = [x, y, z], rotation = [rx, ry, rz] }`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PoseSpec {
    /// Translation in metres.
    pub translation: [f64; 3],
    /// Rotation vector (axis × angle) in radians.
    #[serde(default)]
    pub rotation: [f64; 3],
}

impl PoseSpec {
    /// The pose as an isometry.
    pub fn isometry(&self) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::from(Vector3::from(self.translation)),
            UnitQuaternion::from_scaled_axis(Vector3::from(self.rotation)),
        )
    }

    /// Whether every number is finite.
    pub fn is_finite(&self) -> bool {
        self.translation
            .iter()
            .chain(&self.rotation)
            .all(|v| v.is_finite())
    }
}

/// The cell: robot, table, camera, feeder, fixture, gripper and limits.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(non_snake_case)]
pub struct CellSpec {
    /// Robot description (URDF), relative to the scenario file.
    pub robot: PathBuf,
    /// Pose of the table frame (tag board plane, z up) in the robot base frame.
    pub base_T_table: PoseSpec,
    /// The overhead camera.
    pub camera: CameraSpec,
    /// The flexible feeder region where parts lie.
    pub feeder: FeederSpec,
    /// The fixture nest that receives the main part.
    pub fixture: FixtureSpec,
    /// The parallel gripper.
    pub gripper: GripperSpec,
    /// Motion limits; production refuses to start without them.
    pub limits: Limits,
}

/// Camera intrinsics, distortion and mounting.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(non_snake_case)]
pub struct CameraSpec {
    /// Intrinsics and distortion.
    pub intrinsics: Camera,
    /// Pose of the camera (OpenCV frame: x right, y down, z forward) in the robot base frame.
    pub base_T_camera: PoseSpec,
}

/// How parts are placed in the feeder.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Placement {
    /// Orientation class drawn by the stable-pose probabilities, yaw uniform, no overlap (fast).
    Sampled,
    /// Dropped with physics.
    Dropped,
}

/// The feeder: a rectangle on the table and how many parts of each kind lie in it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FeederSpec {
    /// Centre of the region in the table frame, metres.
    pub center: [f64; 2],
    /// Size of the region along table x and y, metres.
    pub size: [f64; 2],
    /// Parts per catalog part name.
    pub parts: BTreeMap<String, u32>,
    /// How parts are placed.
    #[serde(default = "sampled")]
    pub placement: Placement,
    /// Shakes allowed per step before a run gives up on finding a usable part.
    #[serde(default = "three")]
    pub max_shakes: u32,
    /// Seconds one shake takes until the parts are at rest again (vibration plus settling).
    #[serde(default = "shake_time")]
    pub shake_time: f64,
}

fn shake_time() -> f64 {
    1.5
}

fn sampled() -> Placement {
    Placement::Sampled
}

fn three() -> u32 {
    3
}

/// The fixture nest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(non_snake_case)]
pub struct FixtureSpec {
    /// Catalog part that is the nest's mesh.
    pub part: String,
    /// Pose of the nest frame in the table frame.
    pub table_T_fixture: PoseSpec,
}

/// The parallel gripper.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GripperSpec {
    /// Largest opening between the fingers, metres.
    pub stroke: f64,
    /// Finger size across the closing direction, metres.
    pub finger_width: f64,
    /// Finger thickness along the closing direction, metres.
    pub finger_thickness: f64,
    /// Finger length below the TCP, metres.
    pub finger_length: f64,
    /// Coulomb friction between fingers and parts.
    #[serde(default = "friction")]
    pub friction: f64,
    /// Distance from the robot flange to the fingertip centre (the TCP) along the tool axis,
    /// metres; the simulated cell's `flange_T_tcp` (default 0.15 m, a small parallel gripper).
    #[serde(default = "tcp_offset")]
    pub tcp_offset: f64,
    /// Seconds the fingers take to open or to close (default
    /// [`DEFAULT_GRIPPER_ACTUATION_TIME`]): added to the simulated clock per actuation, and the
    /// wait our controller program sleeps after setting the gripper output. Finite, from 0 to
    /// [`robots::ur_robot::MAX_GRIPPER_ACTUATION_S`].
    #[serde(default = "actuation_time")]
    pub actuation_time: f64,
}

/// Default gripper actuation time, s (a small electric parallel gripper).
pub const DEFAULT_GRIPPER_ACTUATION_TIME: f64 = 0.25;

impl GripperSpec {
    /// Why `actuation_time` is unusable (not finite, negative, or longer than a real controller's
    /// program may wait), or `None` when it is fine.
    pub fn actuation_time_problem(&self) -> Option<String> {
        let t = self.actuation_time;
        let max = robots::ur_robot::MAX_GRIPPER_ACTUATION_S;
        (!(t.is_finite() && (0.0..=max).contains(&t)))
            .then(|| format!("actuation_time must be a finite time from 0 to {max} s, got {t}"))
    }
}

fn tcp_offset() -> f64 {
    0.15
}

fn actuation_time() -> f64 {
    DEFAULT_GRIPPER_ACTUATION_TIME
}

fn friction() -> f64 {
    0.3
}

/// What a part goes into.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Destination {
    /// The fixture nest.
    Fixture,
    /// A part placed by an earlier step, by catalog name.
    Part(String),
}

/// Success tolerances of one insertion.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Tolerances {
    /// Largest lateral offset from the target when seated, metres.
    pub lateral: f64,
    /// Largest distance above fully seated, metres.
    pub depth: f64,
    /// Largest tilt from the target orientation, radians.
    pub tilt: f64,
}

/// One assembly step: put a part into the fixture or onto an earlier part.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
#[allow(non_snake_case)]
pub struct AssemblyStep {
    /// Catalog part placed by this step.
    pub part: String,
    /// `"fixture"` or `{ part = "main_shell" }`.
    pub into: Destination,
    /// Seated pose of the part in the frame of what it goes into.
    pub target: PoseSpec,
    /// Direction of insertion in that frame (unit vector, usually straight down).
    pub insertion_axis: [f64; 3],
    /// Total clearance across the mating features, metres.
    pub clearance: f64,
    /// Lead-in chamfer size, metres.
    pub lead_in: f64,
    /// What counts as seated.
    pub tolerances: Tolerances,
}

/// Error sources, each named so a report can attribute failures to it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseSpec {
    /// Robot pose repeatability (one sigma per axis), metres; UR5e: ±0.03 mm (ISO 9283).
    pub robot_repeatability: f64,
    /// Camera extrinsic calibration error, translation (one sigma per axis), metres.
    pub calibration_translation: f64,
    /// Camera extrinsic calibration error, rotation (one sigma per axis), radians.
    pub calibration_rotation: f64,
    /// Residual lateral offset of a part in the fingers after closing (one sigma), metres.
    pub grasp_offset: f64,
    /// Residual rotation of a part in the fingers after closing (one sigma), radians.
    pub grasp_rotation: f64,
}

impl Default for NoiseSpec {
    fn default() -> Self {
        Self {
            robot_repeatability: 3e-5,
            calibration_translation: 5e-5,
            calibration_rotation: 2e-4,
            grasp_offset: 5e-5,
            grasp_rotation: 2e-3,
        }
    }
}
