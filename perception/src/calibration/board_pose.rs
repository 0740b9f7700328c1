//! The board's pose in the camera from one image: PnP over every tag corner, with covariance.
//!
//! Every decoded corner goes to the project's PnP ([`crate::pnp::solve_pnp`]: SQPnP, then
//! Levenberg–Marquardt through the lens distortion with a covariance). The pose's 1σ uncertainty
//! is reported in the board frame, at the board's centre, in millimetres and degrees, and beside
//! it the Cramér–Rao bound that a given corner noise allows.

use nalgebra::{Isometry3, Matrix3, Matrix6, Point2, Point3, Vector3, Vector6};

use super::{Board, BoardSighting, CalibrationError};
use crate::Camera;
use crate::pnp::solve_pnp;

/// Fewest decoded tags a board pose is computed from: 16 corners, spread over the board.
pub const MIN_TAGS: usize = 4;

/// Largest angle between the board's normal and the line of sight to its centre, degrees: beyond
/// it the tags' foreshortened edges lose the accuracy the pose needs.
pub const MAX_VIEW_ANGLE_DEG: f64 = 60.0;

/// Largest share of saturated pixels around the tag borders, percent: a blurred edge whose light
/// side clips moves by a good part of the blur's width.
pub const MAX_CLIPPED_PERCENT: f64 = 1.0;

/// The board's pose in the camera with its statistics.
#[derive(Debug, Clone, PartialEq)]
#[allow(non_snake_case)]
pub struct BoardPose {
    /// Pose of the board frame in the camera frame.
    pub camera_T_board: Isometry3<f64>,
    /// Covariance of `[δt; δω]` in the camera frame, as [`crate::pnp::PnpSolution::covariance`]
    /// (the residuals set the noise level).
    pub covariance: Matrix6<f64>,
    /// Reprojection RMS over all corners, pixels (per corner, both axes).
    pub rms_px: f64,
    /// Each used tag's id and the RMS reprojection residual of its four corners, pixels.
    pub tag_residuals_px: Vec<(u32, f64)>,
    /// Angle between the board's normal and the line of sight to its centre, radians.
    pub view_angle: f64,
}

/// 1σ uncertainty of a board pose at the table, in the board frame: translation of the board's
/// centre along board x, y, z (z is the height) and rotation about board x, y, z.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct TableSigma {
    /// Translation along board x, y, z, millimetres.
    pub translation_mm: [f64; 3],
    /// Rotation about board x, y, z, degrees.
    pub rotation_deg: [f64; 3],
}

impl BoardPose {
    /// The ids of the tags the pose was computed from.
    pub fn tags_used(&self) -> Vec<u32> {
        self.tag_residuals_px.iter().map(|(id, _)| *id).collect()
    }

    /// The pose covariance as `[δt; δθ]` of the board frame: the true board is the estimate
    /// moved by δt and turned by δθ, both along board axes, about the board's centre.
    pub fn board_covariance(&self) -> Matrix6<f64> {
        to_board_frame(&self.camera_T_board, &self.covariance)
    }

    /// 1σ uncertainty of the pose at the table in mm and degrees.
    pub fn sigma_at_table(&self) -> TableSigma {
        table_sigma(&self.board_covariance())
    }
}

/// Computes the board's pose in `camera` from the decoded corners of `sighting`.
///
/// Refuses an image that does not fit the camera's sensor (`Resolution`), fewer than
/// [`MIN_TAGS`] tags (`TooFewTags`), borders clipped at full scale beyond
/// [`MAX_CLIPPED_PERCENT`] (`Overexposed`) and a board seen more than [`MAX_VIEW_ANGLE_DEG`] off
/// its normal (`TooOblique`).
pub fn board_pose(
    camera: &Camera,
    board: &Board,
    sighting: &BoardSighting,
) -> Result<BoardPose, CalibrationError> {
    check_window(camera, sighting.origin, sighting.size)?;
    let tags: Vec<_> = sighting
        .tags
        .iter()
        .filter_map(|t| board.corners(t.id).map(|c| (t, c)))
        .collect();
    if tags.len() < MIN_TAGS {
        return Err(CalibrationError::TooFewTags {
            found: tags.len(),
            need: MIN_TAGS,
            total: board.tags().len(),
        });
    }
    let clipped = 100.0 * tags.iter().map(|(t, _)| t.clipped).sum::<f64>() / tags.len() as f64;
    if clipped > MAX_CLIPPED_PERCENT {
        return Err(CalibrationError::Overexposed {
            percent: clipped,
            max_percent: MAX_CLIPPED_PERCENT,
        });
    }
    let model: Vec<Point3<f64>> = tags.iter().flat_map(|(_, c)| *c).collect();
    let pixels: Vec<Point2<f64>> = tags.iter().flat_map(|(t, _)| t.corners).collect();
    let solution = solve_pnp(camera, &model, &pixels, None)?;
    let pose = solution.camera_T_part;
    let centre = pose.translation.vector;
    let normal = pose.rotation * Vector3::z();
    let view_angle = normal.dot(&-centre.normalize()).clamp(-1.0, 1.0).acos();
    if view_angle.to_degrees() > MAX_VIEW_ANGLE_DEG {
        return Err(CalibrationError::TooOblique {
            angle_deg: view_angle.to_degrees(),
            max_deg: MAX_VIEW_ANGLE_DEG,
        });
    }
    let tag_residuals_px = tags
        .iter()
        .map(|(t, corners)| {
            let sum: f64 = corners
                .iter()
                .zip(&t.corners)
                .map(|(p, px)| {
                    camera
                        .project(&(pose * p))
                        .map_or(f64::INFINITY, |q| (q - px).norm_squared())
                })
                .sum();
            (t.id, (sum / 4.0).sqrt())
        })
        .collect();
    Ok(BoardPose {
        camera_T_board: pose,
        covariance: solution.covariance,
        rms_px: solution.rms_px,
        tag_residuals_px,
        view_angle,
    })
}

/// Refuses an image (top-left sensor pixel `origin`, `size` pixels) that does not lie on the
/// camera's sensor: another camera, binning or region of interest than the calibration's.
pub fn check_window(
    camera: &Camera,
    origin: [u32; 2],
    size: [u32; 2],
) -> Result<(), CalibrationError> {
    let fits = u64::from(origin[0]) + u64::from(size[0]) <= u64::from(camera.width)
        && u64::from(origin[1]) + u64::from(size[1]) <= u64::from(camera.height);
    if fits && size[0] > 0 && size[1] > 0 {
        Ok(())
    } else {
        Err(CalibrationError::Resolution {
            got_w: size[0],
            got_h: size[1],
            want_w: camera.width,
            want_h: camera.height,
        })
    }
}

/// Refuses a full frame whose size is not the camera's sensor.
pub fn check_full_frame(camera: &Camera, size: [u32; 2]) -> Result<(), CalibrationError> {
    if size == [camera.width, camera.height] {
        Ok(())
    } else {
        Err(CalibrationError::Resolution {
            got_w: size[0],
            got_h: size[1],
            want_w: camera.width,
            want_h: camera.height,
        })
    }
}

/// The Cramér–Rao bound on `[δt; δω]` (camera frame, as [`BoardPose::covariance`]) of a pose
/// `camera_T_board` from the corners of the tags `ids`, each corner's pixel coordinates carrying
/// independent noise of `sigma_px`: σ²·(JᵀJ)⁻¹ with J the pixels' derivative in the pose.
#[allow(non_snake_case)]
pub fn cramer_rao(
    camera: &Camera,
    board: &Board,
    ids: &[u32],
    camera_T_board: &Isometry3<f64>,
    sigma_px: f64,
) -> Matrix6<f64> {
    let mut jtj = Matrix6::zeros();
    for p in ids.iter().filter_map(|id| board.corners(*id)).flatten() {
        let c = camera_T_board * p;
        let Ok((_, d)) = camera.project_with_jacobian(&c) else {
            continue;
        };
        // The true pose is (exp(δω)·R, t + δt): the point moves by δt + δω × (R p).
        let rp = c.coords - camera_T_board.translation.vector;
        let mut j = nalgebra::Matrix2x6::zeros();
        j.fixed_view_mut::<2, 3>(0, 0).copy_from(&d);
        j.fixed_view_mut::<2, 3>(0, 3)
            .copy_from(&(d * -rp.cross_matrix()));
        jtj += j.transpose() * j;
    }
    jtj.try_inverse()
        .map_or(Matrix6::from_diagonal_element(f64::INFINITY), |inv| {
            inv * sigma_px * sigma_px
        })
}

/// A camera-frame `[δt; δω]` covariance of `camera_T_board` as the board-frame `[δt; δθ]` at
/// the board's centre: both rotate by the board's orientation.
#[allow(non_snake_case)]
pub fn to_board_frame(camera_T_board: &Isometry3<f64>, covariance: &Matrix6<f64>) -> Matrix6<f64> {
    let rt: Matrix3<f64> = camera_T_board
        .rotation
        .to_rotation_matrix()
        .matrix()
        .transpose();
    let mut a = Matrix6::zeros();
    a.fixed_view_mut::<3, 3>(0, 0).copy_from(&rt);
    a.fixed_view_mut::<3, 3>(3, 3).copy_from(&rt);
    a * covariance * a.transpose()
}

/// 1σ of a board-frame `[δt; δθ]` covariance in mm and degrees.
pub fn table_sigma(board_covariance: &Matrix6<f64>) -> TableSigma {
    let s = |i: usize| board_covariance[(i, i)].max(0.0).sqrt();
    TableSigma {
        translation_mm: [s(0) * 1e3, s(1) * 1e3, s(2) * 1e3],
        rotation_deg: [s(3).to_degrees(), s(4).to_degrees(), s(5).to_degrees()],
    }
}

/// The error of an estimated board pose against the truth, in the board frame: `[δt; δθ]` with
/// the true board at the estimate moved by δt (metres) and turned by δθ (radians), along and about
/// board axes at the board's centre.
#[allow(non_snake_case)]
pub fn board_error(
    estimate_camera_T_board: &Isometry3<f64>,
    true_camera_T_board: &Isometry3<f64>,
) -> Vector6<f64> {
    let d = estimate_camera_T_board.inverse() * true_camera_T_board;
    let t = d.translation.vector;
    let w = d.rotation.scaled_axis();
    Vector6::new(t.x, t.y, t.z, w.x, w.y, w.z)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibration::TagSighting;
    use crate::calibration::detect::DetectionTimings;
    use nalgebra::{Translation3, UnitQuaternion};
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    #[allow(non_snake_case)]
    fn sighting(camera: &Camera, board: &Board, camera_T_board: &Isometry3<f64>) -> BoardSighting {
        let tags = board
            .tags()
            .iter()
            .map(|t| {
                let c = board
                    .corners(t.id)
                    .unwrap()
                    .map(|p| camera.project(&(camera_T_board * p)).unwrap());
                TagSighting {
                    id: t.id,
                    corners: c,
                    raw_corners: c,
                    margin: 100.0,
                    hamming: 0,
                    clipped: 0.0,
                }
            })
            .collect();
        BoardSighting {
            tags,
            foreign: Vec::new(),
            origin: [0, 0],
            size: [camera.width, camera.height],
            timings: DetectionTimings::default(),
        }
    }

    #[allow(non_snake_case)]
    fn looking_down(tilt: f64) -> Isometry3<f64> {
        // Camera 1.5 m above, its optical axis along −z of the board, tilted about board x.
        let r = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI + tilt);
        let table_T_camera =
            Isometry3::from_parts(Translation3::from(r * Vector3::new(0.0, 0.0, -1.5)), r);
        table_T_camera.inverse()
    }

    #[test]
    fn noisy_corners_give_the_pose_within_the_bound_that_their_noise_allows() {
        let camera = Camera::basler_seed();
        let board = Board::seed();
        let truth = looking_down(0.1);
        let sigma = 0.05;
        let noise = Normal::new(0.0, sigma).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let ids: Vec<u32> = board.tags().iter().map(|t| t.id).collect();
        let bound = table_sigma(&to_board_frame(
            &truth,
            &cramer_rao(&camera, &board, &ids, &truth, sigma),
        ));
        let trials = 300;
        let mut sq = Vector6::zeros();
        for _ in 0..trials {
            let mut s = sighting(&camera, &board, &truth);
            for t in &mut s.tags {
                for c in &mut t.corners {
                    c.x += noise.sample(&mut rng);
                    c.y += noise.sample(&mut rng);
                }
            }
            let pose = board_pose(&camera, &board, &s).unwrap();
            let e = board_error(&pose.camera_T_board, &truth);
            sq += e.component_mul(&e);
            // Per corner, both axes: √2 σ (less the six fitted degrees of freedom).
            assert!(
                (pose.rms_px / (2f64.sqrt() * sigma) - 1.0).abs() < 0.2,
                "{}",
                pose.rms_px
            );
        }
        let rms = (sq / trials as f64).map(f64::sqrt);
        // LM on unbiased Gaussian corners is efficient: the spread over trials meets the bound
        // (to the sampling error of 300 trials, about ±8 %).
        for i in 0..3 {
            let b = bound.translation_mm[i] / 1e3;
            assert!((rms[i] / b - 1.0).abs() < 0.15, "t{i}: {} vs {b}", rms[i]);
            let b = bound.rotation_deg[i].to_radians();
            assert!(
                (rms[i + 3] / b - 1.0).abs() < 0.15,
                "r{i}: {} vs {b}",
                rms[i + 3]
            );
        }
        // The height is the weakest: a 21 cm board seen from 1.5 m.
        assert!(bound.translation_mm[2] > 5.0 * bound.translation_mm[0]);
    }

    #[test]
    fn refusals_name_the_cause() {
        let camera = Camera::basler_seed();
        let board = Board::seed();
        let truth = looking_down(0.05);
        let mut s = sighting(&camera, &board, &truth);
        s.tags.truncate(3);
        let e = board_pose(&camera, &board, &s).unwrap_err();
        assert!(
            matches!(
                e,
                CalibrationError::TooFewTags {
                    found: 3,
                    need: 4,
                    total: 16
                }
            ),
            "{e}"
        );
        let s = sighting(&camera, &board, &looking_down(65f64.to_radians()));
        let e = board_pose(&camera, &board, &s).unwrap_err();
        match e {
            CalibrationError::TooOblique { angle_deg, .. } => {
                assert!((angle_deg - 65.0).abs() < 0.5, "{angle_deg}")
            }
            other => panic!("{other}"),
        }
        let mut s = sighting(&camera, &board, &truth);
        s.size = [6000, 4000];
        let e = board_pose(&camera, &board, &s).unwrap_err().to_string();
        assert!(
            e.contains("6000 × 4000") && e.contains("5472 × 3648"),
            "{e}"
        );
        assert!(check_full_frame(&camera, [2736, 1824]).is_err());
        assert!(check_full_frame(&camera, [5472, 3648]).is_ok());
    }
}
