//! The commissioning procedure by hand-eye, automatic: the arm carries a small board (the flange
//! board) through poses planned around a point beside the table board in the camera's view;
//! at each the robot's TCP reading and the board's pose in the camera give one view of
//! AX = XB, solved for the camera in the base. One image of the table board gives the table in
//! the camera, hence in the base, with the covariances composed.
//!
//! Like [`super::procedure`], this reads pixels ([`BoardImages`]) and the robot's readings
//! ([`Robot::tcp_pose`]) only. The scenario's typed poses are used to plan (where to put the
//! board so the camera sees it), never as a result.

#![allow(non_snake_case)]

use std::f64::consts::PI;

use nalgebra::{
    Isometry3, Matrix6, Point2, Point3, Translation3, UnitQuaternion, Vector2, Vector3,
};
use perception::Camera;
use perception::calibration::board_pose::{board_pose, check_full_frame};
use perception::calibration::covariance::compose_covariance;
use perception::calibration::detect::{
    BoardDetector, BoardSighting, DetectorSettings, TagSighting,
};
use perception::calibration::hand_eye::{
    HandEyeSettings, HandEyeView, plan_hand_eye_poses, solve_hand_eye,
};
use perception::calibration::{Board, CalibrationError};
use robots::motion::LinearMotion;
use robots::robot::{Robot, RobotError};

use super::evidence::{BaseEvidence, Calibration, HandEyeEvidence, LeftOut};
use super::procedure::{BoardImages, CalibrateError};

/// The fewest views [`solve_hand_eye`] accepts (rotations about two axes need three poses).
pub const MIN_HAND_EYE_VIEWS: usize = 3;

/// Pixels a planned board's plate must keep from the sensor's edge to count as in view.
const VIEW_MARGIN_PX: f64 = 40.0;

/// The flange board's nominal mounting in the TCP frame: on a bracket beside the tool, its
/// centre 6 cm along the tool's x axis and 2 cm back toward the flange, its print facing away
/// from the tool (up, toward the camera, when the tool points down).
pub fn nominal_tcp_T_flange_board() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(0.06, 0.0, -0.02),
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), PI),
    )
}

/// How the hand-eye poses are planned and judged.
#[derive(Debug, Clone, PartialEq)]
pub struct HandEyeOptions {
    /// Poses planned ([`plan_hand_eye_poses`]).
    pub poses: usize,
    /// Largest tilt of the board about an axis in its plane, radians.
    pub tilt: f64,
    /// Largest turn of the board about its normal, radians.
    pub spin: f64,
    /// The board's centre at the planned poses' centre, in the typed table frame, metres:
    /// beside the table board (so neither hides the other) and above it.
    pub board_at: Vector3<f64>,
    /// The board's mounting in the TCP frame, as designed (the solution measures the real one).
    pub tcp_T_board: Isometry3<f64>,
    /// The arm's noise and the rotation spread required.
    pub arm: HandEyeSettings,
    /// The board detector's settings.
    pub detector: DetectorSettings,
}

impl Default for HandEyeOptions {
    /// Twelve poses tilted up to 20° and turned up to ±34° around a point 22 cm beside the
    /// table board's centre and 25 cm above it (in view of a camera 1.5 m up with a ±15° field).
    fn default() -> Self {
        Self {
            poses: 12,
            tilt: 0.35,
            spin: 0.6,
            board_at: Vector3::new(0.22, 0.0, 0.25),
            tcp_T_board: nominal_tcp_T_flange_board(),
            arm: HandEyeSettings::default(),
            detector: DetectorSettings::default(),
        }
    }
}

/// The scenario's typed poses: where the integrator believes the camera and the table are,
/// used to plan poses in view, never as a result.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Guess {
    /// The typed camera in the base.
    pub base_T_camera: Isometry3<f64>,
    /// The typed table in the base.
    pub base_T_table: Isometry3<f64>,
}

/// The table board's and the flange board's tags in one image, each board's tags apart.
struct Detectors {
    table: BoardDetector,
    flange: BoardDetector,
    table_board: Board,
    flange_board: Board,
}

impl Detectors {
    /// The `board`'s sighting in `image`, any decoded id of `other` expected (both boards are
    /// in view), any other id refused.
    fn sight(
        detector: &mut BoardDetector,
        board: &Board,
        other: &Board,
        image: &perception::FrameImage,
    ) -> Result<BoardSighting, CalibrationError> {
        let mut sighting = detector.sight(image)?;
        let unknown: Vec<u32> = sighting
            .foreign
            .iter()
            .copied()
            .filter(|&id| other.tag(id).is_none())
            .collect();
        let tags = board.tags();
        let (first, last) = (tags[0].id, tags[tags.len() - 1].id);
        if !unknown.is_empty() {
            return Err(CalibrationError::ForeignTag {
                ids: unknown,
                first,
                last,
            });
        }
        sighting.foreign.clear();
        if sighting.tags.is_empty() {
            return Err(CalibrationError::NoBoard {
                family: board.family().name.clone(),
                first,
                last,
            });
        }
        Ok(sighting)
    }
}

/// Whether a board-pose refusal means this view is unusable rather than the run wrong.
fn view_unusable(e: &CalibrationError) -> bool {
    matches!(
        e,
        CalibrationError::NoBoard { .. }
            | CalibrationError::TooFewTags { .. }
            | CalibrationError::TooOblique { .. }
            | CalibrationError::Overexposed { .. }
    )
}

/// Whether the board at `base_T_board` lies in the camera's view by the typed camera pose.
fn in_view(camera: &Camera, guess: &Guess, board: &Board, base_T_board: &Isometry3<f64>) -> bool {
    let [px, py] = board.spec().plate;
    let camera_T_board = guess.base_T_camera.inverse() * base_T_board;
    [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
        .iter()
        .all(|&(sx, sy)| {
            let p = camera_T_board * Point3::new(sx * px / 2.0, sy * py / 2.0, 0.0);
            p.z > 0.0
                && camera.project(&p).is_ok_and(|q| {
                    let m = VIEW_MARGIN_PX;
                    (m..f64::from(camera.width) - m).contains(&q.x)
                        && (m..f64::from(camera.height) - m).contains(&q.y)
                })
        })
}

/// The whole procedure by hand-eye: the flange board moved through the planned poses and seen
/// at each, the camera solved from AX = XB, the table board seen in one of the images, composed.
pub async fn calibrate_by_hand_eye<R: Robot>(
    camera: &Camera,
    table_board: &Board,
    flange_board: &Board,
    guess: &Guess,
    images: &mut dyn BoardImages,
    robot: &mut R,
    options: &HandEyeOptions,
) -> Result<Calibration, CalibrateError> {
    let shared: Vec<u32> = flange_board
        .tags()
        .iter()
        .map(|t| t.id)
        .filter(|&id| table_board.tag(id).is_some())
        .collect();
    if !shared.is_empty() {
        return Err(CalibrateError::SharedIds { ids: shared });
    }
    let mut detectors = Detectors {
        table: BoardDetector::new(table_board, &options.detector)?,
        flange: BoardDetector::new(flange_board, &options.detector)?,
        table_board: table_board.clone(),
        flange_board: flange_board.clone(),
    };
    let table_T_centre = Isometry3::from_parts(
        Translation3::from(options.board_at),
        UnitQuaternion::identity(),
    );
    let centre = guess.base_T_table * table_T_centre * options.tcp_T_board.inverse();
    let poses = plan_hand_eye_poses(&centre, options.poses, options.tilt, options.spin);
    let limits = robot.limits();
    let motion = LinearMotion {
        speed: 0.25 * limits.max_tcp_speed,
        acceleration: 0.5 * limits.max_tcp_acceleration,
    };
    let mut left = LeftOut::default();
    let mut used = Vec::new();
    let mut views = Vec::new();
    let mut table_sightings: Vec<BoardSighting> = Vec::new();
    for (k, pose) in poses.iter().enumerate() {
        let number = k + 1;
        if !in_view(camera, guess, flange_board, &(pose * options.tcp_T_board)) {
            left.out_of_view.push(number);
            continue;
        }
        match robot.move_l(*pose, motion).await {
            Ok(()) => {}
            Err(e @ (RobotError::LimitViolation(_) | RobotError::Unreachable(_))) => {
                left.refused.push((number, e.to_string()));
                continue;
            }
            Err(e) => return Err(e.into()),
        }
        let reading = robot.tcp_pose().await?;
        let image = images.capture()?;
        if images.full_sensor() {
            check_full_frame(camera, [image.width(), image.height()])?;
        }
        let seen = Detectors::sight(
            &mut detectors.flange,
            &detectors.flange_board,
            &detectors.table_board,
            &image,
        )
        .and_then(|s| board_pose(camera, flange_board, &s));
        match seen {
            Ok(p) => {
                used.push((number, p.rms_px));
                views.push(HandEyeView {
                    base_T_flange: reading,
                    camera_T_board: p.camera_T_board,
                    covariance: p.covariance,
                });
            }
            Err(e) if view_unusable(&e) => {
                left.unseen.push((number, e.to_string()));
                continue;
            }
            Err(e) => return Err(e.into()),
        }
        // The table board in the same image: every image is another look at it (fresh sensor
        // noise), averaged below; an image where it is not found is left out of the average.
        match Detectors::sight(
            &mut detectors.table,
            &detectors.table_board,
            &detectors.flange_board,
            &image,
        ) {
            Ok(s) => table_sightings.push(s),
            Err(e @ CalibrationError::ForeignTag { .. }) => return Err(e.into()),
            Err(_) => {}
        }
    }
    if views.len() < MIN_HAND_EYE_VIEWS {
        return Err(CalibrateError::TooFewPoses {
            reached: views.len(),
            planned: poses.len(),
            needed: MIN_HAND_EYE_VIEWS,
            why: left.describe(),
        });
    }
    let sighting = mean_sighting(&table_sightings).ok_or(CalibrateError::Calibration(
        CalibrationError::NoBoard {
            family: table_board.family().name.clone(),
            first: table_board.tags()[0].id,
            last: table_board.tags()[table_board.tags().len() - 1].id,
        },
    ))?;
    let table_pose = board_pose(camera, table_board, &sighting)?;
    let solution = solve_hand_eye(&views, &options.arm)?;
    let base_T_camera = solution.base_T_camera;
    let camera_T_table = table_pose.camera_T_board;
    // base_T_table = base_T_camera · camera_T_table = a · b⁻¹ with b = table_T_camera, whose
    // covariance is that of the inverse (the identity composed with camera_T_table⁻¹).
    let inverse_covariance = compose_covariance(
        &Isometry3::identity(),
        &Matrix6::zeros(),
        &camera_T_table,
        &table_pose.covariance,
    );
    let table_covariance = compose_covariance(
        &base_T_camera,
        &solution.covariance,
        &camera_T_table.inverse(),
        &inverse_covariance,
    );
    let camera_covariance = solution.covariance;
    let evidence = HandEyeEvidence {
        solution,
        planned: poses.len(),
        left_out: left,
        views: used,
    };
    Ok(Calibration {
        base_T_camera,
        base_T_table: base_T_camera * camera_T_table,
        camera_covariance,
        table_covariance,
        sighting,
        board_pose: table_pose,
        base: BaseEvidence::HandEye(Box::new(evidence)),
    })
}

/// The table board's tags seen in every one of `sightings`, each corner the mean of its
/// sightings (the board does not move, so the mean of k images has the corner noise of one over
/// √k); `None` without sightings.
fn mean_sighting(sightings: &[BoardSighting]) -> Option<BoardSighting> {
    let first = sightings.first()?;
    let mut mean = first.clone();
    mean.tags.retain(|t| {
        sightings
            .iter()
            .all(|s| s.tags.iter().any(|u| u.id == t.id))
    });
    let k = sightings.len() as f64;
    for tag in &mut mean.tags {
        let seen: Vec<&TagSighting> = sightings
            .iter()
            .filter_map(|s| s.tags.iter().find(|u| u.id == tag.id))
            .collect();
        for c in 0..4 {
            let sum = |pick: fn(&TagSighting) -> [Point2<f64>; 4]| {
                seen.iter()
                    .fold(Vector2::zeros(), |a, t| a + pick(t)[c].coords)
                    / k
            };
            tag.corners[c] = Point2::from(sum(|t| t.corners));
            tag.raw_corners[c] = Point2::from(sum(|t| t.raw_corners));
        }
    }
    Some(mean)
}

impl LeftOut {
    /// The poses left out and why, in words.
    pub fn describe(&self) -> String {
        let mut parts = Vec::new();
        if !self.out_of_view.is_empty() {
            parts.push(format!(
                "{} out of the camera's view by the scenario's poses",
                self.out_of_view.len()
            ));
        }
        if let Some((n, why)) = self.refused.first() {
            parts.push(format!(
                "{} refused by the robot (pose {n}: {why})",
                self.refused.len()
            ));
        }
        if let Some((n, why)) = self.unseen.first() {
            parts.push(format!(
                "{} where the board could not be posed (pose {n}: {why})",
                self.unseen.len()
            ));
        }
        if parts.is_empty() {
            "none".into()
        } else {
            parts.join("; ")
        }
    }
}
