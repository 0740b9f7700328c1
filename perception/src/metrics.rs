//! Pose error metrics and their summaries.
//!
//! Per-axis translation errors follow the seed's Table 1 (absolute, camera frame, mm); angles are
//! geodesic (θ = arccos((tr(Rᵀ R̂) − 1) / 2)) and symmetry-aware; ADD / ADD-S are Hinterstoisser's;
//! MSSD / MSPD are the BOP challenge's (maximum surface / projection distance, minimised over the
//! symmetry group).

use nalgebra::{Isometry3, Point3, Unit, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::Camera;
use crate::symmetry::symmetric_angle_round;

/// Every error of one estimate against its ground truth. Names carry their units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PoseErrors {
    /// |Δx| in the camera frame, mm.
    pub x_mm: f64,
    /// |Δy| in the camera frame, mm.
    pub y_mm: f64,
    /// |Δz| (depth) in the camera frame, mm.
    pub z_mm: f64,
    /// Geodesic rotation error, degrees.
    pub angle_deg: f64,
    /// Geodesic rotation error to the nearest exact twin (the symmetry group, and any turn about
    /// an axis the part is round about), degrees: the geodesic error for a part without exact
    /// symmetries. Outliers are counted on this angle.
    pub sym_angle_deg: f64,
    /// ADD: mean distance between corresponding model points, mm.
    pub add_mm: f64,
    /// ADD-S: mean distance to the closest transformed model point, mm.
    pub adds_mm: f64,
    /// BOP MSSD: max surface distance, minimised over symmetries, mm.
    pub mssd_mm: f64,
    /// BOP MSPD: max projection distance, minimised over symmetries, px (NaN when a point is
    /// behind the camera).
    pub mspd_px: f64,
}

/// Geodesic angle between two rotations, radians.
pub fn geodesic_angle(a: &UnitQuaternion<f64>, b: &UnitQuaternion<f64>) -> f64 {
    a.angle_to(b)
}

/// ADD: mean ‖T·p − T̂·p‖ over the model points (metres).
#[allow(non_snake_case)]
pub fn add(points: &[Point3<f64>], truth: &Isometry3<f64>, estimate: &Isometry3<f64>) -> f64 {
    if points.is_empty() {
        return 0.0;
    }
    points
        .iter()
        .map(|p| (truth * p - estimate * p).norm())
        .sum::<f64>()
        / points.len() as f64
}

/// ADD-S: mean over p of min over q of ‖T·p − T̂·q‖ (metres). Quadratic in the point count.
pub fn add_s(points: &[Point3<f64>], truth: &Isometry3<f64>, estimate: &Isometry3<f64>) -> f64 {
    if points.is_empty() {
        return 0.0;
    }
    let est: Vec<Point3<f64>> = points.iter().map(|q| estimate * q).collect();
    points
        .iter()
        .map(|p| {
            let tp = truth * p;
            est.iter()
                .map(|q| (tp - q).norm_squared())
                .fold(f64::INFINITY, f64::min)
                .sqrt()
        })
        .sum::<f64>()
        / points.len() as f64
}

/// BOP MSSD: min over symmetries g of max over p of ‖T·g·p − T̂·p‖ (metres).
pub fn mssd(
    points: &[Point3<f64>],
    truth: &Isometry3<f64>,
    estimate: &Isometry3<f64>,
    group: &[UnitQuaternion<f64>],
) -> f64 {
    over_group(group, |g| {
        let t = truth * Isometry3::from_parts(Default::default(), *g);
        points
            .iter()
            .map(|p| (t * p - estimate * p).norm())
            .fold(0.0, f64::max)
    })
}

/// BOP MSPD: min over symmetries g of max over p of the pixel distance between projections.
pub fn mspd(
    camera: &Camera,
    points: &[Point3<f64>],
    truth: &Isometry3<f64>,
    estimate: &Isometry3<f64>,
    group: &[UnitQuaternion<f64>],
) -> f64 {
    over_group(group, |g| {
        let t = truth * Isometry3::from_parts(Default::default(), *g);
        points
            .iter()
            .map(
                |p| match (camera.project(&(t * p)), camera.project(&(estimate * p))) {
                    (Ok(a), Ok(b)) => (a - b).norm(),
                    _ => f64::NAN,
                },
            )
            .fold(
                0.0,
                |a: f64, b| if b.is_nan() { f64::NAN } else { a.max(b) },
            )
    })
}

fn over_group(group: &[UnitQuaternion<f64>], f: impl Fn(&UnitQuaternion<f64>) -> f64) -> f64 {
    let identity = [UnitQuaternion::identity()];
    let group = if group.is_empty() {
        &identity[..]
    } else {
        group
    };
    group.iter().map(f).fold(f64::INFINITY, f64::min)
}

/// All errors of `estimate` against `truth`, both `camera_T_part`.
///
/// `points` are model points (vertices or samples) in metres; `group` the part's symmetry group;
/// `round` the part-frame axes it turns freely about ([`crate::part::round_axes`]).
pub fn pose_errors(
    camera: &Camera,
    points: &[Point3<f64>],
    group: &[UnitQuaternion<f64>],
    round: &[Unit<Vector3<f64>>],
    truth: &Isometry3<f64>,
    estimate: &Isometry3<f64>,
) -> PoseErrors {
    let d = estimate.translation.vector - truth.translation.vector;
    let identity = [UnitQuaternion::identity()];
    let g = if group.is_empty() {
        &identity[..]
    } else {
        group
    };
    PoseErrors {
        x_mm: d.x.abs() * 1e3,
        y_mm: d.y.abs() * 1e3,
        z_mm: d.z.abs() * 1e3,
        angle_deg: geodesic_angle(&truth.rotation, &estimate.rotation).to_degrees(),
        sym_angle_deg: symmetric_angle_round(&estimate.rotation, &truth.rotation, g, round)
            .to_degrees(),
        add_mm: add(points, truth, estimate) * 1e3,
        adds_mm: add_s(points, truth, estimate) * 1e3,
        mssd_mm: mssd(points, truth, estimate, g) * 1e3,
        mspd_px: mspd(camera, points, truth, estimate, g),
    }
}

/// Mean, standard deviation and percentiles of a sample.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// Sample size (finite values only).
    pub count: usize,
    /// Mean.
    pub mean: f64,
    /// Standard deviation (population, as the seed reports).
    pub std: f64,
    /// Median.
    pub p50: f64,
    /// 90th percentile.
    pub p90: f64,
    /// 95th percentile.
    pub p95: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Maximum.
    pub max: f64,
}

impl Summary {
    /// Summarises the finite values of `values` (NaN everywhere when there are none).
    pub fn of(values: impl IntoIterator<Item = f64>) -> Self {
        let mut v: Vec<f64> = values.into_iter().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return Self {
                count: 0,
                mean: f64::NAN,
                std: f64::NAN,
                p50: f64::NAN,
                p90: f64::NAN,
                p95: f64::NAN,
                p99: f64::NAN,
                max: f64::NAN,
            };
        }
        v.sort_by(f64::total_cmp);
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        let std = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt();
        Self {
            count: v.len(),
            mean,
            std,
            p50: percentile(&v, 50.0),
            p90: percentile(&v, 90.0),
            p95: percentile(&v, 95.0),
            p99: percentile(&v, 99.0),
            max: v[v.len() - 1],
        }
    }
}

/// Linear-interpolated percentile of sorted values.
fn percentile(sorted: &[f64], q: f64) -> f64 {
    let pos = (q / 100.0) * (sorted.len() - 1) as f64;
    let lo = pos.floor() as usize;
    let hi = pos.ceil() as usize;
    sorted[lo] + (sorted[hi] - sorted[lo]) * (pos - lo as f64)
}

/// How a set of errors is summarised.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SummaryOptions {
    /// Drop samples with an angle error above `outlier_deg` from every statistic (the seed's
    /// practice); off by default. Outliers are counted either way.
    pub drop_outliers: bool,
    /// Outlier threshold on the angle to the nearest exact twin, degrees (the seed uses 10°; its
    /// parts have no exact symmetries, so this is its geodesic angle).
    pub outlier_deg: f64,
}

impl Default for SummaryOptions {
    fn default() -> Self {
        Self {
            drop_outliers: false,
            outlier_deg: 10.0,
        }
    }
}

/// Summaries of every metric over a set of estimates.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ErrorSummary {
    /// Samples given.
    pub samples: usize,
    /// Samples whose angle to the nearest exact twin is above the threshold (whether dropped or
    /// not).
    pub outliers: usize,
    /// Whether outliers were dropped from the statistics below.
    pub outliers_dropped: bool,
    /// |Δx|, mm.
    pub x_mm: Summary,
    /// |Δy|, mm.
    pub y_mm: Summary,
    /// |Δz|, mm.
    pub z_mm: Summary,
    /// Geodesic angle, degrees.
    pub angle_deg: Summary,
    /// Symmetry-aware angle, degrees.
    pub sym_angle_deg: Summary,
    /// ADD, mm.
    pub add_mm: Summary,
    /// ADD-S, mm.
    pub adds_mm: Summary,
    /// MSSD, mm.
    pub mssd_mm: Summary,
    /// MSPD, px.
    pub mspd_px: Summary,
}

impl ErrorSummary {
    /// Summarises `errors` under `options`.
    pub fn of(errors: &[PoseErrors], options: SummaryOptions) -> Self {
        let is_outlier =
            |e: &PoseErrors| e.sym_angle_deg.is_nan() || e.sym_angle_deg > options.outlier_deg;
        let outliers = errors.iter().filter(|e| is_outlier(e)).count();
        let kept: Vec<&PoseErrors> = errors
            .iter()
            .filter(|e| !(options.drop_outliers && is_outlier(e)))
            .collect();
        let s = |f: fn(&PoseErrors) -> f64| Summary::of(kept.iter().map(|e| f(e)));
        Self {
            samples: errors.len(),
            outliers,
            outliers_dropped: options.drop_outliers,
            x_mm: s(|e| e.x_mm),
            y_mm: s(|e| e.y_mm),
            z_mm: s(|e| e.z_mm),
            angle_deg: s(|e| e.angle_deg),
            sym_angle_deg: s(|e| e.sym_angle_deg),
            add_mm: s(|e| e.add_mm),
            adds_mm: s(|e| e.adds_mm),
            mssd_mm: s(|e| e.mssd_mm),
            mspd_px: s(|e| e.mspd_px),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::part::Symmetry;
    use crate::symmetry::symmetry_group;
    use nalgebra::{Translation3, Vector3};

    fn box_points() -> Vec<Point3<f64>> {
        let mut v = Vec::new();
        for x in [-0.004, 0.004] {
            for y in [-0.003, 0.003] {
                for z in [-0.001, 0.001] {
                    v.push(Point3::new(x, y, z));
                }
            }
        }
        v
    }

    #[test]
    fn translation_errors_are_per_axis_in_mm() {
        let cam = Camera::basler_seed();
        let truth = Isometry3::translation(0.01, 0.02, 1.5);
        let est = Isometry3::translation(0.011, 0.018, 1.56);
        let e = pose_errors(&cam, &box_points(), &[], &[], &truth, &est);
        assert!((e.x_mm - 1.0).abs() < 1e-9);
        assert!((e.y_mm - 2.0).abs() < 1e-9);
        assert!((e.z_mm - 60.0).abs() < 1e-9);
        assert!(e.angle_deg.abs() < 1e-9);
        // A pure translation moves every point the same: ADD = MSSD = |Δt|.
        let d = (1.0f64 + 4.0 + 3600.0).sqrt();
        assert!((e.add_mm - d).abs() < 1e-9 && (e.mssd_mm - d).abs() < 1e-9);
    }

    #[test]
    fn symmetric_flip_is_free_under_symmetry_aware_metrics_only() {
        let cam = Camera::basler_seed();
        let group = symmetry_group(&[Symmetry {
            axis: [0.0, 0.0, 1.0],
            order: 2,
            exact: true,
        }]);
        let truth = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 1.5),
            UnitQuaternion::from_euler_angles(0.2, -0.1, 0.4),
        );
        let flip = Isometry3::from_parts(
            Default::default(),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::PI),
        );
        let est = truth * flip;
        let pts = box_points();
        let e = pose_errors(&cam, &pts, &group, &[], &truth, &est);
        assert!((e.angle_deg - 180.0).abs() < 1e-6);
        assert!(e.sym_angle_deg < 1e-6);
        assert!(e.mssd_mm < 1e-9 && e.mspd_px < 1e-6);
        assert!(e.adds_mm < 1e-9, "the box maps onto itself");
        assert!(e.add_mm > 5.0);
    }

    #[test]
    fn a_turn_about_a_round_axis_is_free_and_no_outlier() {
        let cam = Camera::basler_seed();
        let truth = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 1.5),
            UnitQuaternion::from_euler_angles(0.3, 0.1, -0.2),
        );
        // 100° about the part's z plus 2° of swing off it: only the swing is an error.
        let turn = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 100f64.to_radians())
            * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 2f64.to_radians());
        let est = truth * Isometry3::from_parts(Default::default(), turn);
        let e = pose_errors(&cam, &box_points(), &[], &[Vector3::z_axis()], &truth, &est);
        assert!(e.angle_deg > 99.0);
        assert!((e.sym_angle_deg - 2.0).abs() < 1e-6, "{}", e.sym_angle_deg);
        let summary = ErrorSummary::of(&[e], SummaryOptions::default());
        assert_eq!(summary.outliers, 0);
        // Without the round axis the same estimate is an outlier.
        let e = pose_errors(&cam, &box_points(), &[], &[], &truth, &est);
        assert_eq!(
            ErrorSummary::of(&[e], SummaryOptions::default()).outliers,
            1
        );
    }

    #[test]
    fn summaries_count_and_optionally_drop_outliers() {
        let mk = |a: f64| PoseErrors {
            x_mm: a,
            y_mm: a,
            z_mm: a,
            angle_deg: a,
            sym_angle_deg: a,
            add_mm: a,
            adds_mm: a,
            mssd_mm: a,
            mspd_px: a,
        };
        let errors: Vec<PoseErrors> = [1.0, 2.0, 3.0, 4.0, 50.0].into_iter().map(mk).collect();
        let all = ErrorSummary::of(&errors, SummaryOptions::default());
        assert_eq!((all.samples, all.outliers, all.x_mm.count), (5, 1, 5));
        assert!((all.x_mm.mean - 12.0).abs() < 1e-12);
        assert!((all.x_mm.p50 - 3.0).abs() < 1e-12);
        let dropped = ErrorSummary::of(
            &errors,
            SummaryOptions {
                drop_outliers: true,
                ..Default::default()
            },
        );
        assert_eq!((dropped.outliers, dropped.x_mm.count), (1, 4));
        assert!((dropped.x_mm.mean - 2.5).abs() < 1e-12);
        assert!((dropped.x_mm.std - 1.25f64.sqrt()).abs() < 1e-12);
        assert_eq!(Summary::of([]).count, 0);
    }
}
