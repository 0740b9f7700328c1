//! The production pre-flight's camera check: the board re-detected in the run's first capture
//! must sit where the calibration put it. A bumped camera moves the board in the image, and
//! every part it sees would be placed off by about as much; the run refuses to move and says
//! by how much.

#![allow(non_snake_case)]

use std::sync::Arc;

use nalgebra::{Isometry3, Point3};
use perception::calibration::board_pose::board_pose;
use perception::calibration::detect::{DetectorSettings, detect_board};
use perception::calibration::{Board, CalibrationError};
use perception::{Camera, FrameImage};

/// How far a table point may appear moved before a run refuses, metres (the insert mold's
/// capture band is ±0.145 mm; a bump of this size already eats most of it).
pub const DEFAULT_TOLERANCE: f64 = 1e-4;

/// Why the camera check refused a run.
#[derive(Debug, thiserror::Error)]
pub enum CameraCheckError {
    /// The board moved in the image beyond the tolerance.
    #[error(
        "the camera appears moved: a part at the board's {at} would be placed {shift_mm:.3} mm \
         off (tolerance {tolerance_mm:.3} mm); re-run `cell calibrate` before production"
    )]
    Moved {
        /// The apparent shift, mm.
        shift_mm: f64,
        /// Where on the board it is largest.
        at: &'static str,
        /// The tolerance, mm.
        tolerance_mm: f64,
    },
    /// The board could not be found or measured.
    #[error("could not check the camera against the board: {0}")]
    Board(#[from] CalibrationError),
}

/// The check, set up from the scenario's calibration.
#[derive(Debug, Clone)]
pub struct CameraCheck {
    board: Arc<Board>,
    camera: Camera,
    /// Where the calibration says the camera is, in the table (board) frame.
    expected_table_T_camera: Isometry3<f64>,
    tolerance: f64,
    detector: DetectorSettings,
}

/// The board points shifts are measured at: its centre and plate corners, as fractions of the
/// plate's half size.
pub const PROBES: [(&str, f64, f64); 5] = [
    ("centre", 0.0, 0.0),
    ("top-left corner", -1.0, 1.0),
    ("top-right corner", 1.0, 1.0),
    ("bottom-right corner", 1.0, -1.0),
    ("bottom-left corner", -1.0, -1.0),
];

impl CameraCheck {
    /// A check of `camera` against `board` as the calibration placed them.
    pub fn new(
        board: Arc<Board>,
        camera: Camera,
        base_T_camera: &Isometry3<f64>,
        base_T_table: &Isometry3<f64>,
        tolerance: f64,
    ) -> Self {
        Self {
            board,
            camera,
            expected_table_T_camera: base_T_table.inverse() * base_T_camera,
            tolerance,
            detector: DetectorSettings::default(),
        }
    }

    /// Detects the board in `image` and measures how far the camera appears moved.
    pub fn check(&self, image: &FrameImage) -> Result<f64, CameraCheckError> {
        let sighting = detect_board(image, &self.board, &self.detector)?;
        let measured = board_pose(&self.camera, &self.board, &sighting)?.camera_T_board;
        let (shift, at) = self.shift(&measured.inverse());
        if shift > self.tolerance {
            return Err(CameraCheckError::Moved {
                shift_mm: shift * 1e3,
                at,
                tolerance_mm: self.tolerance * 1e3,
            });
        }
        Ok(shift)
    }

    /// The largest displacement, over the board's probes, of where a point of the table would
    /// be placed: seen by the camera where it truly is (`measured`), located through the pose
    /// the calibration gave (`expected`), intersected with the table plane.
    pub fn shift(&self, measured_table_T_camera: &Isometry3<f64>) -> (f64, &'static str) {
        let [px, py] = self.board.spec().plate;
        let expected = &self.expected_table_T_camera;
        PROBES
            .iter()
            .filter_map(|&(name, sx, sy)| {
                let q = Point3::new(sx * px / 2.0, sy * py / 2.0, 0.0);
                // The ray on which the camera sees q, carried to the expected camera pose.
                let ray = measured_table_T_camera.inverse() * q;
                let origin = expected.translation.vector;
                let direction = expected.rotation * ray.coords;
                (direction.z.abs() > 1e-12).then(|| {
                    let t = -origin.z / direction.z;
                    let placed = origin + t * direction;
                    ((placed.xy() - q.coords.xy()).norm(), name)
                })
            })
            .fold((0.0, "centre"), |a, b| if b.0 > a.0 { b } else { a })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    fn check() -> CameraCheck {
        let base_T_table = Isometry3::translation(0.0, -0.45, 0.0);
        let base_T_camera = Isometry3::from_parts(
            Translation3::new(0.0, -0.45, 1.51),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
        );
        CameraCheck::new(
            Arc::new(Board::seed()),
            Camera::basler_seed(),
            &base_T_camera,
            &base_T_table,
            DEFAULT_TOLERANCE,
        )
    }

    #[test]
    fn an_unmoved_camera_shows_no_shift() {
        let c = check();
        let (shift, _) = c.shift(&c.expected_table_T_camera.clone());
        assert!(shift < 1e-12, "{shift}");
    }

    /// A camera turned by 0.1 mrad about its optical axis moves table points by up to
    /// 0.1 mrad × the plate's half-diagonal (0.148 m): 15 µm at the corners, none at the centre;
    /// tilted by 0.1 mrad it moves all of them by about 0.1 mrad × 1.51 m = 0.15 mm.
    #[test]
    fn the_shift_is_the_displacement_of_table_points() {
        let c = check();
        let e = c.expected_table_T_camera;
        let spun = Isometry3::from_parts(
            e.translation,
            e.rotation * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 1e-4),
        );
        let (s, at) = c.shift(&spun);
        assert!((s - 1e-4 * 0.105 * 2f64.sqrt()).abs() < 1e-7, "{s} at {at}");
        assert_ne!(at, "centre");
        let tilted = Isometry3::from_parts(
            e.translation,
            e.rotation * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 1e-4),
        );
        let (s, _) = c.shift(&tilted);
        assert!((s - 1.51e-4).abs() < 0.03e-4, "{s}");
    }
}
