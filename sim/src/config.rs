//! The simulated and real cell as scenario files describe it: geometry, feeder, gripper, limits,
//! assembly steps and error sources. The `cell` crate's scenario files embed these tables.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};

use nalgebra::{Isometry3, Matrix6, Translation3, UnitQuaternion, Vector3};
use perception::calibration::{Board, BoardError};
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
    /// The calibration board on the table (a board file, relative to the scenario file); the
    /// seed's board ([`Board::seed`]) when absent. The simulated cell renders this board.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub board: Option<PathBuf>,
    /// What `cell calibrate` measured (`[cell.calibration]`); when present, the simulated cell
    /// draws its camera calibration error from the measured covariance instead of
    /// `noise.calibration_translation` / `calibration_rotation`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration: Option<CalibrationSpec>,
    /// The board `board` names, once [`CellSpec::load_board`] read it.
    #[serde(skip)]
    board_layout: BoardCache,
}

/// The board a [`CellSpec`] read from its file: a cache of what `board` names, so it takes no
/// part in comparing specs.
#[derive(Debug, Clone, Default)]
struct BoardCache(OnceLock<Arc<Board>>);

impl PartialEq for BoardCache {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl CellSpec {
    /// Reads the board `board` names (relative to `dir`, the scenario's folder), or the seed's
    /// board when none is named, and keeps it for [`CellSpec::board_layout`]. Scenario
    /// validation calls this once; a board that cannot be read is a located scenario problem.
    pub fn load_board(&self, dir: &Path) -> Result<Arc<Board>, BoardError> {
        if let Some(b) = self.board_layout.0.get() {
            return Ok(b.clone());
        }
        let board = Arc::new(match &self.board {
            Some(path) => Board::load(&dir.join(path))?,
            None => Board::seed(),
        });
        Ok(self.board_layout.0.get_or_init(|| board).clone())
    }

    /// The board on the table: the one [`CellSpec::load_board`] read, or the seed's board when
    /// the scenario names none. `None` when a board is named but was never loaded (a spec that
    /// did not go through scenario validation).
    pub fn board_layout(&self) -> Option<Arc<Board>> {
        match (self.board_layout.0.get(), &self.board) {
            (Some(b), _) => Some(b.clone()),
            (None, None) => Some(Arc::new(Board::seed())),
            (None, Some(_)) => None,
        }
    }
}

/// How `cell calibrate` located the board (and so the camera) in the robot base.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CalibrationMethod {
    /// The operator touched marked board points with a pointer tool (rigid fit).
    Touch,
    /// The robot moved a board through planned poses (AX = XB).
    HandEye,
}

/// A calibration result as `cell calibrate` writes it into `[cell.calibration]`: how it was
/// measured, when, with which board, and how uncertain `base_T_camera` and `base_T_table` are.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrationSpec {
    /// How the board was located in the robot base.
    pub method: CalibrationMethod,
    /// When it was measured: an RFC 3339 UTC time (`2026-11-28T03:30:00Z`).
    #[serde(deserialize_with = "rfc3339")]
    pub date: String,
    /// Covariance of `cell.camera.base_T_camera` (see [`PoseCovariance`]).
    pub camera_covariance: PoseCovariance,
    /// Covariance of `cell.base_T_table` (see [`PoseCovariance`]).
    pub table_covariance: PoseCovariance,
    /// Root-mean-square reprojection error of the board's tag corners, pixels.
    #[serde(deserialize_with = "non_negative")]
    pub reprojection_rms_px: f64,
    /// Tags the board pose was estimated from.
    pub tags: u32,
    /// The board file used, relative to the scenario file; absent: the seed's built-in board.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub board: Option<PathBuf>,
}

/// Deserializes an RFC 3339 UTC time, kept as written.
fn rfc3339<'de, D: serde::Deserializer<'de>>(d: D) -> Result<String, D::Error> {
    let text = String::deserialize(d)?;
    humantime::parse_rfc3339(&text).map_err(|e| {
        serde::de::Error::custom(format!(
            "date {text:?} is not an RFC 3339 UTC time like 2026-11-28T03:30:00Z ({e})"
        ))
    })?;
    Ok(text)
}

/// Deserializes a finite, non-negative number.
fn non_negative<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    let v = f64::deserialize(d)?;
    if v.is_finite() && v >= 0.0 {
        Ok(v)
    } else {
        Err(serde::de::Error::custom(format!(
            "must be a finite number of at least 0, got {v}"
        )))
    }
}

/// The covariance of a pose's error `[δt (m); δω (rad)]` in perception's PnP convention
/// ([`perception::pnp::PnpSolution::covariance`]) applied to a pose `a_T_b`: the true pose is
/// `(exp(δω) · R̂, t̂ + δt)`, so δt and δω are along frame a's axes and the rotation turns frame
/// b about its own origin (for `base_T_camera`: base axes, about the camera's centre).
/// Symmetric and positive definite by construction; in a scenario file, 36 numbers row by row
/// or 6 arrays of 6.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseCovariance {
    matrix: Matrix6<f64>,
    /// Lower Cholesky factor L with L Lᵀ = `matrix`.
    factor: Matrix6<f64>,
}

/// Why a 6×6 matrix is not a pose covariance.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CovarianceError {
    /// An entry is NaN or infinite.
    #[error("entry ({row}, {column}) is {value}: a covariance must be finite")]
    NonFinite {
        /// 0-based row.
        row: usize,
        /// 0-based column.
        column: usize,
        /// The entry.
        value: f64,
    },
    /// It differs from its transpose beyond rounding.
    #[error(
        "entries ({row}, {column}) = {a:e} and ({column}, {row}) = {b:e} differ: a covariance is \
         symmetric"
    )]
    Asymmetric {
        /// 0-based row.
        row: usize,
        /// 0-based column.
        column: usize,
        /// Entry (row, column).
        a: f64,
        /// Entry (column, row).
        b: f64,
    },
    /// Its Cholesky factorisation failed.
    #[error(
        "it is not positive definite (Cholesky factorisation fails): some combination of the \
         six errors would have zero or negative variance; write the covariance the calibration \
         measured"
    )]
    NotPositiveDefinite,
}

impl PoseCovariance {
    /// Checks a 6×6 covariance: finite, symmetric to 1e-9 of its largest entry, positive definite.
    pub fn new(matrix: Matrix6<f64>) -> Result<Self, CovarianceError> {
        for (k, v) in matrix.iter().enumerate() {
            if !v.is_finite() {
                return Err(CovarianceError::NonFinite {
                    row: k % 6,
                    column: k / 6,
                    value: *v,
                });
            }
        }
        let scale = matrix.amax();
        for row in 0..6 {
            for column in row + 1..6 {
                let (a, b) = (matrix[(row, column)], matrix[(column, row)]);
                if (a - b).abs() > 1e-9 * scale {
                    return Err(CovarianceError::Asymmetric { row, column, a, b });
                }
            }
        }
        let symmetric = (matrix + matrix.transpose()) / 2.0;
        let factor = symmetric
            .cholesky()
            .ok_or(CovarianceError::NotPositiveDefinite)?
            .l();
        Ok(Self {
            matrix: symmetric,
            factor,
        })
    }

    /// The covariance matrix (exactly symmetric).
    pub fn matrix(&self) -> &Matrix6<f64> {
        &self.matrix
    }

    /// The lower Cholesky factor L (L Lᵀ = the covariance): `L z` with z standard normal draws
    /// an error with this covariance.
    pub fn factor(&self) -> &Matrix6<f64> {
        &self.factor
    }

    /// One-sigma of each error: `[tx, ty, tz]` in metres, `[rx, ry, rz]` in radians.
    pub fn sigmas(&self) -> [f64; 6] {
        std::array::from_fn(|i| self.matrix[(i, i)].sqrt())
    }
}

impl Serialize for PoseCovariance {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let rows: [[f64; 6]; 6] =
            std::array::from_fn(|r| std::array::from_fn(|c| self.matrix[(r, c)]));
        rows.serialize(s)
    }
}

/// One element of a covariance as written: a number (36 in a row) or a row of 6.
#[derive(Deserialize)]
#[serde(untagged)]
enum CovarianceEntry {
    Number(f64),
    Row(Vec<f64>),
}

impl<'de> Deserialize<'de> for PoseCovariance {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        use serde::de::Error;
        let entries = Vec::<CovarianceEntry>::deserialize(d).map_err(|_| {
            D::Error::custom(
                "a covariance is 36 numbers row by row, or 6 arrays of 6 numbers".to_string(),
            )
        })?;
        let shape = |what: String| {
            D::Error::custom(format!(
                "a covariance is 36 numbers row by row, or 6 arrays of 6 numbers; {what}"
            ))
        };
        let mut values = Vec::with_capacity(36);
        let rows = entries
            .iter()
            .filter(|e| matches!(e, CovarianceEntry::Row(_)))
            .count();
        match rows {
            0 => values.extend(entries.iter().map(|e| match e {
                CovarianceEntry::Number(v) => *v,
                CovarianceEntry::Row(_) => unreachable!("counted no rows"),
            })),
            n if n == entries.len() => {
                for (i, e) in entries.iter().enumerate() {
                    if let CovarianceEntry::Row(r) = e {
                        if r.len() != 6 {
                            return Err(shape(format!("row {} has {} numbers", i + 1, r.len())));
                        }
                        values.extend(r);
                    }
                }
            }
            _ => return Err(shape("this one mixes numbers and arrays".into())),
        }
        if values.len() != 36 {
            return Err(shape(match rows {
                0 => format!("this one has {} numbers", values.len()),
                _ => format!("this one has {rows} rows"),
            }));
        }
        PoseCovariance::new(Matrix6::from_row_slice(&values)).map_err(D::Error::custom)
    }
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
    /// Seconds the fingers take to travel the full stroke, open to closed (default
    /// [`DEFAULT_GRIPPER_ACTUATION_TIME`]): a shorter travel takes less
    /// ([`GripperSpec::travel_time`]) on the simulated clock; our controller program sleeps the
    /// full time after setting the gripper output. Finite, from 0 to
    /// [`robots::ur_robot::MAX_GRIPPER_ACTUATION_S`].
    #[serde(default = "actuation_time")]
    pub actuation_time: f64,
    /// Room left between each finger and the part when the fingers open for a grasp, metres:
    /// they open to the part's width across the jaws plus twice this, so neighbours that close
    /// leave room. Absent: the fingers always open the full stroke.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub opening_margin: Option<f64>,
    /// The controller's standard analog output (0 or 1) that sets where the fingers open to, as
    /// a ratio of the stroke, for a gripper with a position input; its digital output still
    /// closes them on the part. Absent: on a controller the fingers open the full stroke, and a
    /// controller run sets `opening_margin` aside.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub width_output: Option<u8>,
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

    /// The gripper as our controller program drives it: the actuation time our program sleeps,
    /// and the analog output that sets the opening, if the gripper has one.
    pub fn configure_ur(&self, config: &mut robots::ur_robot::UrRobotConfig) {
        config.gripper_actuation_s = self.actuation_time;
        config.gripper_width =
            self.width_output
                .map(|output| robots::ur_robot::GripperWidthOutput {
                    output,
                    stroke: self.stroke,
                });
    }

    /// How far apart the fingers open to grasp a part `width` across the jaws: the width plus
    /// both margins, at most the stroke; the full stroke without an `opening_margin`.
    pub fn opening_for(&self, width: f64) -> f64 {
        match self.opening_margin {
            Some(m) => (width + 2.0 * m).min(self.stroke),
            None => self.stroke,
        }
    }

    /// Seconds the fingers take to travel `travel` metres: [`GRIPPER_SETTLE_TIME`] (capped by
    /// `actuation_time`) to start and to settle, plus the rest of `actuation_time` in proportion
    /// to the stroke travelled (an electric gripper's fingers move at a set speed).
    pub fn travel_time(&self, travel: f64) -> f64 {
        let settle = GRIPPER_SETTLE_TIME.min(self.actuation_time);
        let fraction = if self.stroke > 0.0 {
            (travel.abs() / self.stroke).min(1.0)
        } else {
            1.0
        };
        settle + (self.actuation_time - settle) * fraction
    }
}

/// Seconds an electric gripper takes to start and to settle on a move however short, s.
pub const GRIPPER_SETTLE_TIME: f64 = 0.05;

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

#[cfg(test)]
mod tests {
    use super::*;

    fn gripper(margin: Option<f64>) -> GripperSpec {
        GripperSpec {
            stroke: 0.014,
            finger_width: 0.004,
            finger_thickness: 0.002,
            finger_length: 0.02,
            friction: 0.3,
            tcp_offset: 0.15,
            actuation_time: 0.25,
            opening_margin: margin,
            width_output: None,
        }
    }

    #[test]
    fn fingers_open_to_the_part_plus_the_margins_and_travel_in_proportion() {
        let g = gripper(Some(0.001));
        assert!((g.opening_for(0.009) - 0.011).abs() < 1e-15);
        // Never wider than the stroke.
        assert_eq!(g.opening_for(0.0135), 0.014);
        assert_eq!(gripper(None).opening_for(0.009), 0.014);
        // The full stroke takes the full time, none only the settle time, half a stroke half
        // of the rest; the direction does not matter.
        assert!((g.travel_time(0.014) - 0.25).abs() < 1e-15);
        assert!((g.travel_time(0.0) - GRIPPER_SETTLE_TIME).abs() < 1e-15);
        let half = GRIPPER_SETTLE_TIME + 0.5 * (0.25 - GRIPPER_SETTLE_TIME);
        assert!((g.travel_time(-0.007) - half).abs() < 1e-15);
        // A gripper faster than the settle time takes its own time.
        let quick = GripperSpec {
            actuation_time: 0.02,
            ..g
        };
        assert!((quick.travel_time(0.001) - 0.02).abs() < 1e-15);
    }

    /// A `[cell.calibration]` body with these two covariances written in.
    fn calibration(camera: &str, table: &str, date: &str) -> String {
        format!(
            "method = \"hand-eye\"\ndate = \"{date}\"\ncamera_covariance = {camera}\n\
             table_covariance = {table}\nreprojection_rms_px = 0.04\ntags = 16\n\
             board = \"boards/seed.toml\"\n"
        )
    }

    fn diagonal_flat(v: [f64; 6]) -> String {
        let m = Matrix6::from_diagonal(&v.into());
        let numbers: Vec<String> = m.transpose().iter().map(|x| format!("{x:e}")).collect();
        format!("[{}]", numbers.join(", "))
    }

    fn diagonal_rows(v: [f64; 6]) -> String {
        let rows: Vec<String> = (0..6)
            .map(|r| {
                let row: Vec<String> = (0..6)
                    .map(|c| format!("{:e}", if r == c { v[r] } else { 0.0 }))
                    .collect();
                format!("[{}]", row.join(", "))
            })
            .collect();
        format!("[\n  {},\n]", rows.join(",\n  "))
    }

    /// 1-based (line, column) of a toml error.
    fn located(text: &str, e: &toml::de::Error) -> (usize, usize) {
        let at = e.span().expect("located").start;
        let before = &text[..at];
        let line = before.matches('\n').count() + 1;
        let column = at - before.rfind('\n').map_or(0, |i| i + 1) + 1;
        (line, column)
    }

    #[test]
    fn covariances_read_as_36_numbers_or_6_rows() {
        let v = [1e-10, 2e-10, 9e-10, 4e-10, 3e-10, 1e-10];
        let text = calibration(&diagonal_flat(v), &diagonal_rows(v), "2026-11-28T03:30:00Z");
        let c: CalibrationSpec = toml::from_str(&text).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(c.method, CalibrationMethod::HandEye);
        assert_eq!(c.camera_covariance, c.table_covariance);
        assert_eq!(c.camera_covariance.matrix()[(2, 2)], 9e-10);
        let sigmas = c.camera_covariance.sigmas();
        assert!((sigmas[2] - 3e-5).abs() < 1e-18);
        // The Cholesky factor reproduces the matrix.
        let l = c.camera_covariance.factor();
        assert!((l * l.transpose() - c.camera_covariance.matrix()).amax() < 1e-25);
        // It writes back as 6 rows that read as the same covariance.
        let back: CalibrationSpec = toml::from_str(&toml::to_string(&c).unwrap()).unwrap();
        assert_eq!(back, c);
    }

    #[test]
    fn bad_covariances_and_dates_are_refused_where_they_are_written() {
        let good = diagonal_flat([1e-10; 6]);
        let not_pd = diagonal_flat([1e-10, 1e-10, -1e-10, 1e-10, 1e-10, 1e-10]);
        let text = calibration(&good, &not_pd, "2026-11-28T03:30:00Z");
        let e = toml::from_str::<CalibrationSpec>(&text).unwrap_err();
        assert_eq!(located(&text, &e), (4, 20), "{e}");
        assert!(e.message().contains("not positive definite"), "{e}");

        let mut asymmetric = Matrix6::<f64>::identity() * 1e-10;
        asymmetric[(0, 4)] = 5e-11;
        let numbers: Vec<String> = asymmetric
            .transpose()
            .iter()
            .map(|x| format!("{x:e}"))
            .collect();
        let text = calibration(
            &format!("[{}]", numbers.join(", ")),
            &good,
            "2026-11-28T03:30:00Z",
        );
        let e = toml::from_str::<CalibrationSpec>(&text).unwrap_err();
        assert_eq!(located(&text, &e), (3, 21), "{e}");
        assert!(e.message().contains("entries (0, 4)"), "{e}");

        let text = calibration("[1e-10, 0.0]", &good, "2026-11-28T03:30:00Z");
        let e = toml::from_str::<CalibrationSpec>(&text).unwrap_err();
        assert!(e.message().contains("this one has 2 numbers"), "{e}");
        let text = calibration("[[1e-10, 0.0], [0.0]]", &good, "2026-11-28T03:30:00Z");
        let e = toml::from_str::<CalibrationSpec>(&text).unwrap_err();
        assert!(e.message().contains("row 1 has 2 numbers"), "{e}");

        let text = calibration(&good, &good, "28/11/2026");
        let e = toml::from_str::<CalibrationSpec>(&text).unwrap_err();
        assert_eq!(located(&text, &e), (2, 8), "{e}");
        assert!(e.message().contains("RFC 3339"), "{e}");
    }

    #[test]
    fn the_board_is_the_seed_unless_named_and_loaded() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios");
        let spec = CellSpec {
            board: None,
            ..nominal_cell()
        };
        assert_eq!(spec.board_layout().as_deref(), Some(&Board::seed()));
        let named = CellSpec {
            board: Some("boards/seed.toml".into()),
            ..nominal_cell()
        };
        assert!(named.board_layout().is_none(), "named but not loaded");
        assert_eq!(*named.load_board(&dir).unwrap(), Board::seed());
        assert_eq!(named.board_layout().as_deref(), Some(&Board::seed()));
        let missing = CellSpec {
            board: Some("boards/missing.toml".into()),
            ..nominal_cell()
        };
        let e = missing.load_board(&dir).unwrap_err().to_string();
        assert!(e.contains("missing.toml"), "{e}");
    }

    /// The nominal scenario's `[cell]`.
    fn nominal_cell() -> CellSpec {
        #[derive(Deserialize)]
        struct Scenario {
            cell: CellSpec,
        }
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/usbc_nominal.toml");
        let text = std::fs::read_to_string(path).unwrap();
        let value: toml::Table = toml::from_str(&text).unwrap();
        let cell = toml::to_string(&toml::Table::from_iter([(
            "cell".to_string(),
            value["cell"].clone(),
        )]))
        .unwrap();
        toml::from_str::<Scenario>(&cell).unwrap().cell
    }
}
