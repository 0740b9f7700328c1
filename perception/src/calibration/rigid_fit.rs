//! Touch points: the board in the robot base from TCP readings at marked board points.
//!
//! A least-squares rigid transform (Kabsch/Umeyama without scale, nalgebra's SVD, reflections
//! guarded) maps the marks' board coordinates onto the touched base coordinates. A point touched
//! in the wrong place is found by leaving each point out in turn: the culprit is the one whose
//! removal leaves the others fitting best, and its distance from where they put it is reported.

use nalgebra::{
    Isometry3, Matrix3, Matrix6, Point3, Rotation3, Translation3, UnitQuaternion, Vector3,
};

use super::CalibrationError;

/// UR e-Series pose repeatability (±0.03 mm, ISO 9283) as a 1σ per axis, metres. ISO 9283's
/// figure is the mean distance from the mean position plus three standard deviations of that
/// distance, ≈ 3.6σ for a 3-D normal of σ per axis, so σ ≈ 0.008 mm; 0.01 mm is a little cautious.
pub const UR_REPEATABILITY_SIGMA: f64 = 1e-5;

/// The largest distance, metres, a touch may lie from where the other touches put it: fifty times
/// the arm's σ per axis and ten times a careful pointer placement on a printed corner (≈ 0.05 mm),
/// yet well under the 3.75 mm cell of a 3 cm tag36h11 tag, so a touch on the wrong corner or a
/// pointer stopped short of the plate is refused while an honest touch never is.
pub const DEFAULT_TOUCH_BOUND: f64 = 0.5e-3;

/// One touched mark: where it is on the board and where the robot read the pointer tip.
#[derive(Debug, Clone, PartialEq)]
pub struct TouchPoint {
    /// The mark's name, for messages ([`super::touch_marks::TouchMark::name`]).
    pub name: String,
    /// The mark in the board frame, metres.
    pub board: Point3<f64>,
    /// The pointer tip in the robot base when touching it, metres.
    pub base: Point3<f64>,
}

/// A rigid fit of touch points.
#[derive(Debug, Clone, PartialEq)]
#[allow(non_snake_case)]
pub struct RigidFit {
    /// The board's pose in the robot base.
    pub base_T_board: Isometry3<f64>,
    /// Per point: touched minus fitted position, base frame, metres.
    pub residuals: Vec<Vector3<f64>>,
    /// Per point: distance from where the other points put it (leave-one-out), metres; with three
    /// points the plain residual norms, as two points cannot place a third.
    pub distances_from_others: Vec<f64>,
    /// Root-mean-square residual norm, metres.
    pub rms: f64,
    /// The per-axis noise the residuals imply, metres (√(Σ|r|² / (3n − 6)); 0 for three points
    /// when they fit exactly).
    pub sigma_from_residuals: f64,
    /// Covariance of the pose error `[δt (m); δω (rad)]` in the base frame, where the true pose is
    /// `(exp(δω) · R̂, t̂ + δt)` (the convention of [`crate::pnp::PnpSolution::covariance`]), from
    /// the given per-axis touch noise: σ² (JᵀJ)⁻¹.
    pub covariance: Matrix6<f64>,
}

impl RigidFit {
    /// 1σ of the fitted position of board point `p` in the base frame, per base axis, metres.
    pub fn position_sigma(&self, p: &Point3<f64>) -> Vector3<f64> {
        let q = self.base_T_board.rotation * p.coords;
        let j = point_jacobian(&q);
        let c = j * self.covariance * j.transpose();
        Vector3::new(c[(0, 0)], c[(1, 1)], c[(2, 2)]).map(f64::sqrt)
    }
}

/// Fits `base_T_board` to touch points by least squares.
///
/// `point_sigma` is the per-axis 1σ of one touch (e.g. [`UR_REPEATABILITY_SIGMA`]) and sets the
/// covariance; `bound` ([`DEFAULT_TOUCH_BOUND`]) is the largest distance a touch may lie from
/// where the others put it. Refuses fewer than three points, points on one line or with a
/// non-finite coordinate, and a set in which a touch lies beyond `bound`, naming the worst.
pub fn fit_rigid(
    points: &[TouchPoint],
    bound: f64,
    point_sigma: f64,
) -> Result<RigidFit, CalibrationError> {
    const NEED: usize = 3;
    if let Some(i) = points
        .iter()
        .position(|p| !(p.board.coords.iter().chain(p.base.coords.iter())).all(|v| v.is_finite()))
    {
        return Err(CalibrationError::NonFiniteTouchPoint {
            index: i + 1,
            name: points[i].name.clone(),
        });
    }
    if points.len() < NEED || collinear(points) {
        return Err(CalibrationError::TooFewTouchPoints {
            got: points.len(),
            need: NEED,
        });
    }
    let pose = kabsch(points);
    let residuals: Vec<Vector3<f64>> = points.iter().map(|p| p.base - pose * p.board).collect();
    let n = points.len();
    let sum_sq: f64 = residuals.iter().map(|r| r.norm_squared()).sum();
    let rms = (sum_sq / n as f64).sqrt();
    let dof = 3 * n - 6;
    let sigma_from_residuals = (sum_sq / dof as f64).sqrt();

    // Leave each point out in turn (with four or more): where the others put it, and how well
    // the others fit without it.
    let (distances_from_others, rest_rms): (Vec<f64>, Vec<f64>) = if n > NEED {
        (0..n)
            .map(|i| {
                let rest: Vec<TouchPoint> = points
                    .iter()
                    .enumerate()
                    .filter(|(k, _)| *k != i)
                    .map(|(_, p)| p.clone())
                    .collect();
                if collinear(&rest) {
                    // The others cannot place it: judge it by its residual in the full fit.
                    return (residuals[i].norm(), f64::INFINITY);
                }
                let t = kabsch(&rest);
                let distance = (points[i].base - t * points[i].board).norm();
                let rms = (rest
                    .iter()
                    .map(|p| (p.base - t * p.board).norm_squared())
                    .sum::<f64>()
                    / rest.len() as f64)
                    .sqrt();
                (distance, rms)
            })
            .unzip()
    } else {
        let d: Vec<f64> = residuals.iter().map(|r| r.norm()).collect();
        let r = vec![0.0; n];
        (d, r)
    };

    if distances_from_others
        .iter()
        .any(|d| d.is_nan() || *d > bound)
    {
        let by = |v: &[f64], best_low: bool| {
            (0..n)
                .min_by(|&a, &b| {
                    if best_low {
                        v[a].total_cmp(&v[b])
                    } else {
                        v[b].total_cmp(&v[a])
                    }
                })
                .unwrap_or(0)
        };
        // The culprit: the point whose removal leaves the best fit, unless that one is within
        // the bound itself (then the farthest point).
        let mut worst = if n > NEED {
            by(&rest_rms, true)
        } else {
            by(&distances_from_others, false)
        };
        if distances_from_others[worst] <= bound {
            worst = by(&distances_from_others, false);
        }
        return Err(CalibrationError::TouchPointsDontFit {
            worst: worst + 1,
            name: points[worst].name.clone(),
            residual_mm: distances_from_others[worst] * 1e3,
            bound_mm: bound * 1e3,
        });
    }

    let mut jtj = Matrix6::zeros();
    for p in points {
        let j = point_jacobian(&(pose.rotation * p.board.coords));
        jtj += j.transpose() * j;
    }
    let covariance = jtj
        .try_inverse()
        .map_or(Matrix6::from_diagonal_element(f64::INFINITY), |inv| {
            inv * point_sigma.powi(2)
        });
    Ok(RigidFit {
        base_T_board: pose,
        residuals,
        distances_from_others,
        rms,
        sigma_from_residuals,
        covariance,
    })
}

/// d(R q + t) / d[δt; δω] for the left perturbation `(exp(δω) R, t + δt)`, with `q_rot = R q`.
fn point_jacobian(q_rot: &Vector3<f64>) -> nalgebra::Matrix3x6<f64> {
    let mut j = nalgebra::Matrix3x6::zeros();
    j.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&Matrix3::identity());
    j.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&(-q_rot.cross_matrix()));
    j
}

/// Whether the board points lie on one line (relative to their spread), so no rotation about
/// that line can be fitted.
fn collinear(points: &[TouchPoint]) -> bool {
    if points.len() < 3 {
        return true;
    }
    let c = centroid(points.iter().map(|p| p.board));
    let mut scatter = Matrix3::zeros();
    for p in points {
        let d = p.board - c;
        scatter += d * d.transpose();
    }
    let mut s = scatter.symmetric_eigenvalues().as_slice().to_vec();
    s.sort_by(|a, b| b.total_cmp(a));
    // The second spread must be at least 1 % of the first (in length; 1e-4 in variance).
    !(s[0] > 0.0 && s[1] > 1e-4 * s[0])
}

/// The mean of points.
fn centroid(points: impl Iterator<Item = Point3<f64>>) -> Point3<f64> {
    let (sum, n) = points.fold((Vector3::zeros(), 0usize), |(s, n), p| {
        (s + p.coords, n + 1)
    });
    Point3::from(sum / n.max(1) as f64)
}

/// The least-squares rotation and translation taking the board points onto the base points
/// (Kabsch), with a determinant guard so the result is never a reflection.
fn kabsch(points: &[TouchPoint]) -> Isometry3<f64> {
    let cb = centroid(points.iter().map(|p| p.board));
    let ca = centroid(points.iter().map(|p| p.base));
    let mut h = Matrix3::zeros();
    for p in points {
        h += (p.board - cb) * (p.base - ca).transpose();
    }
    let svd = h.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Isometry3::identity();
    };
    let v = v_t.transpose();
    let d = (v * u.transpose()).determinant().signum();
    let r = v * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * u.transpose();
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    let t = ca.coords - rotation * cb.coords;
    Isometry3::from_parts(Translation3::from(t), rotation)
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    use super::*;
    use crate::calibration::Board;

    #[allow(non_snake_case)]
    fn truth() -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(0.412, -0.287, 0.0321),
            UnitQuaternion::from_euler_angles(0.004, -0.003, 1.1),
        )
    }

    #[allow(non_snake_case)]
    fn touches(base_T_board: &Isometry3<f64>, sigma: f64, rng: &mut ChaCha8Rng) -> Vec<TouchPoint> {
        let noise = Normal::new(0.0, sigma).unwrap();
        Board::seed()
            .touch_marks()
            .into_iter()
            .map(|m| TouchPoint {
                base: base_T_board * m.point + Vector3::from_fn(|_, _| noise.sample(rng)),
                board: m.point,
                name: m.name,
            })
            .collect()
    }

    #[test]
    fn exact_touches_give_the_exact_pose() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let fit = fit_rigid(&touches(&truth(), 0.0, &mut rng), DEFAULT_TOUCH_BOUND, 1e-5).unwrap();
        let e = fit.base_T_board.inverse() * truth();
        assert!(e.translation.vector.norm() < 1e-14, "{e}");
        assert!(e.rotation.angle() < 1e-14);
        assert!(fit.rms < 1e-14);
        assert!(
            fit.base_T_board
                .rotation
                .to_rotation_matrix()
                .matrix()
                .determinant()
                > 0.0
        );
    }

    /// With the UR's repeatability (σ = 10 µm per axis) on the seed board's eight marks, over
    /// 2000 trials: the worst of the four plate corners of the fitted board is off by 24.4 µm
    /// at the 99th percentile and 31.4 µm at worst; the plate centre by 6.2 µm rms (√3 · 10 µm /
    /// √8, as eight points average), which the fit's own covariance predicts (6.1 µm).
    #[test]
    fn ur_repeatability_places_the_board_well_within_fifty_micrometres() {
        let mut rng = ChaCha8Rng::seed_from_u64(42);
        let t = truth();
        let [px, py] = Board::seed().spec().plate;
        let plate: Vec<Point3<f64>> = [(-1.0, 1.0), (1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)]
            .iter()
            .map(|(sx, sy)| Point3::new(sx * px / 2.0, sy * py / 2.0, 0.0))
            .collect();
        let trials = 2000;
        let mut worst_corner = Vec::with_capacity(trials);
        let mut centre_sq = 0.0;
        let mut centre_var_predicted = 0.0;
        for _ in 0..trials {
            let fit = fit_rigid(
                &touches(&t, UR_REPEATABILITY_SIGMA, &mut rng),
                DEFAULT_TOUCH_BOUND,
                UR_REPEATABILITY_SIGMA,
            )
            .unwrap();
            let w = plate
                .iter()
                .map(|p| (fit.base_T_board * p - t * p).norm())
                .fold(0.0, f64::max);
            worst_corner.push(w);
            centre_sq +=
                (fit.base_T_board.translation.vector - t.translation.vector).norm_squared();
            centre_var_predicted += fit.position_sigma(&Point3::origin()).norm_squared();
        }
        worst_corner.sort_by(f64::total_cmp);
        let p99 = worst_corner[trials * 99 / 100];
        let max = worst_corner[trials - 1];
        let centre = (centre_sq / trials as f64).sqrt();
        let predicted = (centre_var_predicted / trials as f64).sqrt();
        eprintln!(
            "plate corner p99 {:.2} µm, max {:.2} µm; centre rms {:.2} µm (predicted {:.2} µm)",
            p99 * 1e6,
            max * 1e6,
            centre * 1e6,
            predicted * 1e6
        );
        assert!((p99 - 24.4e-6).abs() < 1.5e-6, "p99 {p99}");
        assert!(max < 35e-6, "max {max}");
        assert!((centre - 6.12e-6).abs() < 0.3e-6, "centre {centre}");
        assert!(
            (centre / predicted - 1.0).abs() < 0.05,
            "{centre} vs {predicted}"
        );
    }

    /// A touch 2 mm off, in any direction, on any of the seed board's eight marks is named.
    #[test]
    fn a_point_touched_two_millimetres_off_is_named() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let directions = [
            Vector3::x(),
            Vector3::y(),
            Vector3::z(),
            Vector3::new(1.0, -1.0, 0.5).normalize(),
        ];
        for bad in 0..8 {
            for direction in directions {
                let mut points = touches(&truth(), UR_REPEATABILITY_SIGMA, &mut rng);
                points[bad].base += direction * 2e-3;
                let e =
                    fit_rigid(&points, DEFAULT_TOUCH_BOUND, UR_REPEATABILITY_SIGMA).unwrap_err();
                let CalibrationError::TouchPointsDontFit {
                    worst,
                    name,
                    residual_mm,
                    ..
                } = &e
                else {
                    panic!("{e}");
                };
                assert_eq!(*worst, bad + 1, "{e}");
                assert_eq!(name, &points[bad].name);
                assert!((residual_mm - 2.0).abs() < 0.05, "{e}");
                let text = e.to_string();
                assert!(
                    text.contains(&points[bad].name) && text.contains("touch it again"),
                    "{text}"
                );
            }
        }
    }

    /// With only the four corner marks, a touch off in the board's plane is still named (the
    /// others' distances to it change); one off along the normal is refused but cannot be
    /// told from the opposite corner's (see the module note in `touch_marks`).
    #[test]
    fn four_marks_name_an_in_plane_mistouch_and_refuse_one_along_the_normal() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for bad in 0..4 {
            for direction in [Vector3::x(), Vector3::y(), Vector3::z()] {
                let mut points = touches(&truth(), UR_REPEATABILITY_SIGMA, &mut rng);
                points.truncate(4);
                points[bad].base += truth().rotation * direction * 2e-3;
                let e =
                    fit_rigid(&points, DEFAULT_TOUCH_BOUND, UR_REPEATABILITY_SIGMA).unwrap_err();
                let CalibrationError::TouchPointsDontFit { worst, .. } = e else {
                    panic!("{e}");
                };
                if direction != Vector3::z() {
                    assert_eq!(worst, bad + 1);
                }
            }
        }
    }

    #[test]
    fn three_points_fit_and_a_wrong_one_among_three_is_refused() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut points = touches(&truth(), UR_REPEATABILITY_SIGMA, &mut rng);
        points.truncate(3);
        let fit = fit_rigid(&points, DEFAULT_TOUCH_BOUND, UR_REPEATABILITY_SIGMA).unwrap();
        assert!((fit.base_T_board.translation.vector - truth().translation.vector).norm() < 60e-6);
        // A touch on the neighbouring tag's corner, 10 mm away.
        points[1].base += Vector3::new(0.01, 0.0, 0.0);
        let e = fit_rigid(&points, DEFAULT_TOUCH_BOUND, UR_REPEATABILITY_SIGMA).unwrap_err();
        assert!(
            matches!(e, CalibrationError::TouchPointsDontFit { .. }),
            "{e}"
        );
    }

    #[test]
    fn too_few_collinear_or_non_finite_points_are_refused() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let points = touches(&truth(), 0.0, &mut rng);
        let e = fit_rigid(&points[..2], DEFAULT_TOUCH_BOUND, 1e-5).unwrap_err();
        assert!(
            matches!(e, CalibrationError::TooFewTouchPoints { got: 2, need: 3 }),
            "{e}"
        );
        // Three points along the board's top edge.
        let line: Vec<TouchPoint> = [-0.09, 0.0, 0.09]
            .iter()
            .map(|&x| {
                let board = Point3::new(x, 0.095, 0.0);
                TouchPoint {
                    name: format!("x = {x}"),
                    board,
                    base: truth() * board,
                }
            })
            .collect();
        let e = fit_rigid(&line, DEFAULT_TOUCH_BOUND, 1e-5).unwrap_err();
        assert!(
            matches!(e, CalibrationError::TooFewTouchPoints { got: 3, .. }),
            "{e}"
        );
        assert!(e.to_string().contains("not all on one line"));
        let mut bad = points.clone();
        bad[2].base.y = f64::NAN;
        let e = fit_rigid(&bad, DEFAULT_TOUCH_BOUND, 1e-5).unwrap_err();
        assert!(e.to_string().starts_with("touch point 3 ("), "{e}");
    }
}
