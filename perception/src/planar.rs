//! Planar refinement: a part lying on the calibrated table can only be in one of its stable poses,
//! so a PnP estimate (good in x, y and in-plane rotation, poor in depth and tilt) is snapped onto
//! that manifold.
//!
//! For each stable-pose class the estimate's tilt away from the class is scored (with the class's
//! prior probability); the best class is taken, the yaw about the table normal solved in closed
//! form (continuous, not the seed's 1° grid), the height set to the class's rest height, and x, y
//! re-derived where the viewing ray of the part origin meets the plane at that height: the depth
//! error of PnP slides the part along that ray, so the intersection removes it.
//!
//! [`PlanarRefiner::refine_with_keypoints`] goes one step further: with the class and height fixed
//! it fits x, y and yaw to the keypoints' reprojection error (3 degrees of freedom instead of 6).

use nalgebra::{
    Isometry3, Matrix2, Matrix3, Point2, Point3, Translation3, UnitQuaternion, Vector2, Vector3,
};

use crate::part::StablePose;
use crate::pnp::PnpError;
use crate::{Camera, CameraError};

/// Why planar refinement failed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanarError {
    /// The part has no stable poses (the catalog has not been prepared).
    #[error("the part has no stable poses; run `cell parts prepare` on its catalog")]
    NoStablePoses,
    /// A stable pose is malformed (non-unit or non-finite up vector, negative probability).
    #[error("stable pose {0} is malformed: {1}")]
    BadStablePose(usize, &'static str),
    /// The pose or plane contains NaN or infinite values.
    #[error("non-finite value in {0}")]
    NonFinite(&'static str),
    /// The viewing ray of the part is parallel to the table or meets it behind the camera.
    #[error("the viewing ray of the part does not meet the table plane in front of the camera")]
    RayMissesPlane,
    /// Keypoint refinement failed.
    #[error(transparent)]
    Pnp(#[from] PnpError),
    /// A pixel could not be turned into a ray.
    #[error(transparent)]
    Camera(#[from] CameraError),
    /// Every stable pose was ruled out before the keypoints were weighed.
    #[error("no stable pose is admitted")]
    NoAdmittedClass,
}

/// The stable-pose classes an estimate may be snapped onto: evidence other than the keypoints
/// (a mask larger than a class's footprint) can rule classes out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ClassSet(u64);

impl ClassSet {
    /// Every class.
    pub const ALL: Self = Self(u64::MAX);

    /// The classes among `0..n` for which `admit` holds (classes from 64 on are always kept).
    pub fn filter(n: usize, mut admit: impl FnMut(usize) -> bool) -> Self {
        let mut bits = u64::MAX;
        for class in 0..n.min(64) {
            if !admit(class) {
                bits &= !(1 << class);
            }
        }
        Self(bits)
    }

    /// Whether it holds `class`.
    pub fn contains(self, class: usize) -> bool {
        class >= 64 || self.0 & (1 << class) != 0
    }

    /// Whether it holds none of the classes `0..n`.
    pub fn is_empty_below(self, n: usize) -> bool {
        !(0..n).any(|c| self.contains(c))
    }
}

/// Tuning of the class decision.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlanarConfig {
    /// Standard deviation of PnP's tilt error, radians: how far an estimate may lean away from a
    /// class and still belong to it.
    pub tilt_sigma: f64,
    /// Weigh classes by their probability from the physics drops.
    pub use_prior: bool,
}

impl Default for PlanarConfig {
    fn default() -> Self {
        Self {
            tilt_sigma: 6f64.to_radians(),
            use_prior: true,
        }
    }
}

/// A pose snapped onto the table.
#[derive(Debug, Clone, PartialEq)]
#[allow(non_snake_case)]
pub struct PlanarPose {
    /// The refined pose of the part in the camera frame.
    pub camera_T_part: Isometry3<f64>,
    /// The same in the table frame: `stable_poses[class].table_T_part(x, y, yaw)` (up to the
    /// symmetry representative).
    pub table_T_part: Isometry3<f64>,
    /// Index of the chosen stable-pose class.
    pub class: usize,
    /// Yaw about the table normal, radians.
    pub yaw: f64,
    /// How far the input estimate leaned away from the chosen class, radians.
    pub tilt: f64,
    /// Posterior probability of the chosen class among the admitted ones (softmax of the scores).
    pub confidence: f64,
    /// Score margin (log-likelihood units) to the runner-up; infinite without one.
    pub margin: f64,
    /// The class ranked next below the chosen one, if any and if not ruled out.
    pub runner_up: Option<usize>,
    /// The part symmetry `g` chosen for the canonical representative: the reported pose is the
    /// estimate's `table_T_part · g` (identity when the part has no exact symmetry).
    pub symmetry: UnitQuaternion<f64>,
}

/// Tilt from its nearest stable pose below which a part rests in it, radians (1°).
pub const RESTING_TILT: f64 = std::f64::consts::PI / 180.0;
/// Height off its nearest stable pose's below which a part rests in it, metres (0.2 mm).
pub const RESTING_LIFT: f64 = 2e-4;

impl PlanarPose {
    /// The refined pose in the frame the keypoints were observed in: `camera_T_part · g⁻¹`, with
    /// `g` the [`PlanarPose::symmetry`] of the canonical representative. The same part in the
    /// same place as `camera_T_part`, but keypoint `i` of the model lands where keypoint `i` was
    /// seen, so reprojection errors are measured with this pose (the canonical one carries the
    /// keypoints of a symmetric twin).
    #[allow(non_snake_case)]
    pub fn camera_T_observed(&self) -> Isometry3<f64> {
        self.camera_T_part * self.symmetry.inverse()
    }

    /// Whether `table_T_part`, the pose this one was snapped from, rests on the table in it:
    /// tilted less than [`RESTING_TILT`] and within [`RESTING_LIFT`] of its height. A part
    /// leaning on or lying on another one does not, and no planar estimate of it can be right.
    #[allow(non_snake_case)]
    pub fn rests(&self, table_T_part: &Isometry3<f64>) -> bool {
        let lift = table_T_part.translation.z - self.table_T_part.translation.z;
        self.tilt < RESTING_TILT && lift.abs() < RESTING_LIFT
    }
}

/// Snaps pose estimates of one part onto the stable poses on a calibrated table.
#[derive(Debug, Clone)]
#[allow(non_snake_case)]
pub struct PlanarRefiner {
    camera_T_table: Isometry3<f64>,
    stable_poses: Vec<StablePose>,
    ups: Vec<Vector3<f64>>,
    log_priors: Vec<f64>,
    group: Vec<UnitQuaternion<f64>>,
    /// Per class, the classes that are the same resting state under the symmetry group (itself
    /// included): a round peg standing on either end, or on any of its sides.
    twins: Vec<Vec<usize>>,
    /// Classes reported in preference to a twin that explains the estimate equally well.
    preferred: Vec<bool>,
    config: PlanarConfig,
}

/// Scores (log-likelihood units) closer than this tie: symmetric twins score alike up to
/// rounding.
const SCORE_TIE: f64 = 1e-6;

/// Per class, the classes that a symmetry of `group` makes the same resting state
/// ([`crate::symmetry::stable_pose_twins`]; each class is its own twin).
fn twin_classes(stable_poses: &[StablePose], group: &[UnitQuaternion<f64>]) -> Vec<Vec<usize>> {
    (0..stable_poses.len())
        .map(|c| {
            (0..stable_poses.len())
                .filter(|&d| {
                    c == d
                        || crate::symmetry::stable_pose_twins(
                            &stable_poses[c],
                            &stable_poses[d],
                            group,
                        )
                })
                .collect()
        })
        .collect()
}

impl PlanarRefiner {
    /// A refiner for a part with these stable poses and symmetry group (from
    /// [`crate::symmetry::symmetry_group`]; `&[]` or the identity alone for none), on the table
    /// whose pose in the camera frame came from extrinsic calibration.
    #[allow(non_snake_case)]
    pub fn new(
        camera_T_table: Isometry3<f64>,
        stable_poses: &[StablePose],
        group: &[UnitQuaternion<f64>],
        config: PlanarConfig,
    ) -> Result<Self, PlanarError> {
        if stable_poses.is_empty() {
            return Err(PlanarError::NoStablePoses);
        }
        if !isometry_finite(&camera_T_table) {
            return Err(PlanarError::NonFinite("camera_T_table"));
        }
        let mut ups = Vec::with_capacity(stable_poses.len());
        let mut log_priors = Vec::with_capacity(stable_poses.len());
        for (i, s) in stable_poses.iter().enumerate() {
            let up = Vector3::from(s.up_in_part);
            if !up.iter().all(|v| v.is_finite()) || (up.norm() - 1.0).abs() > 1e-6 {
                return Err(PlanarError::BadStablePose(
                    i,
                    "up_in_part is not a unit vector",
                ));
            }
            if !(s.probability.is_finite() && s.probability >= 0.0) {
                return Err(PlanarError::BadStablePose(i, "probability must be ≥ 0"));
            }
            if !(s.rest_height.is_finite() && s.rotation.iter().all(|v| v.is_finite())) {
                return Err(PlanarError::BadStablePose(i, "non-finite rest pose"));
            }
            ups.push(up);
        }
        let mut group = group.to_vec();
        if group.is_empty() {
            group.push(UnitQuaternion::identity());
        }
        let twins = twin_classes(stable_poses, &group);
        // A class's prior is its resting state's: the drops' share of it and of its twins (so
        // twins score alike and the preferred one can be reported).
        for twin in &twins {
            let probability: f64 = twin.iter().map(|&d| stable_poses[d].probability).sum();
            log_priors.push(if config.use_prior {
                probability.max(1e-6).ln()
            } else {
                0.0
            });
        }
        if !(config.tilt_sigma.is_finite() && config.tilt_sigma > 0.0) {
            return Err(PlanarError::NonFinite("tilt_sigma"));
        }
        Ok(Self {
            camera_T_table,
            stable_poses: stable_poses.to_vec(),
            ups,
            log_priors,
            group,
            twins,
            preferred: vec![false; stable_poses.len()],
            config,
        })
    }

    /// The same refiner, reporting one of `preferred` where a symmetric twin class explains the
    /// estimate as well (a peg standing on either end is reported on the end it is grasped in).
    pub fn with_preferred(mut self, preferred: impl Fn(usize) -> bool) -> Self {
        self.preferred = (0..self.stable_poses.len()).map(preferred).collect();
        self
    }

    /// The classes that are the same resting state as `class` under the part's symmetries,
    /// `class` included.
    pub fn twins(&self, class: usize) -> &[usize] {
        self.twins.get(class).map_or(&[], Vec::as_slice)
    }

    /// The table's pose in the camera frame.
    #[allow(non_snake_case)]
    pub fn camera_T_table(&self) -> &Isometry3<f64> {
        &self.camera_T_table
    }

    /// The stable poses, in the order class indices refer to.
    pub fn stable_poses(&self) -> &[StablePose] {
        &self.stable_poses
    }

    /// Class scores (log prior − tilt² / 2σ²) of a table-frame rotation, and the tilts.
    fn scores(&self, table_r_part: &UnitQuaternion<f64>) -> Vec<(f64, f64)> {
        let up_est = table_r_part.inverse() * Vector3::z();
        let s2 = 2.0 * self.config.tilt_sigma * self.config.tilt_sigma;
        self.ups
            .iter()
            .zip(&self.log_priors)
            .map(|(up, lp)| {
                let tilt = up.dot(&up_est).clamp(-1.0, 1.0).acos();
                (lp - tilt * tilt / s2, tilt)
            })
            .collect()
    }

    /// Snaps a camera-frame pose estimate (from PnP) onto the table.
    #[allow(non_snake_case)]
    pub fn refine(&self, camera_T_part: &Isometry3<f64>) -> Result<PlanarPose, PlanarError> {
        self.refine_in(camera_T_part, ClassSet::ALL)
    }

    /// [`PlanarRefiner::refine`] onto the best of `classes` only; the confidence is the
    /// posterior among them.
    #[allow(non_snake_case)]
    pub fn refine_in(
        &self,
        camera_T_part: &Isometry3<f64>,
        classes: ClassSet,
    ) -> Result<PlanarPose, PlanarError> {
        if !isometry_finite(camera_T_part) {
            return Err(PlanarError::NonFinite("camera_T_part"));
        }
        if classes.is_empty_below(self.stable_poses.len()) {
            return Err(PlanarError::NoAdmittedClass);
        }
        let table_T_est = self.camera_T_table.inverse() * camera_T_part;
        // Class and symmetry representative: best score, then a preferred class, then the
        // smallest |yaw|.
        let mut best: Option<(f64, f64, usize, f64, UnitQuaternion<f64>)> = None;
        let mut scores_of_best = Vec::new();
        for g in &self.group {
            let r = table_T_est.rotation * g;
            let scores = self.scores(&r);
            let (class, &(score, tilt)) = scores
                .iter()
                .enumerate()
                .filter(|(c, _)| classes.contains(*c))
                .max_by(|a, b| a.1.0.total_cmp(&b.1.0))
                .expect("at least one class");
            let yaw = best_yaw(&r, &self.stable_poses[class].rest_rotation());
            let better = match &best {
                None => true,
                Some((s, y, c, ..)) => {
                    let (p, q) = (self.preferred[class], self.preferred[*c]);
                    score > s + SCORE_TIE
                        || ((score - s).abs() <= SCORE_TIE
                            && ((p && !q) || (p == q && yaw.abs() < y.abs() - 1e-9)))
                }
            };
            if better {
                best = Some((score, yaw, class, tilt, *g));
                scores_of_best = scores;
            }
        }
        let (best_score, yaw, class, tilt, symmetry) = best.expect("the group has the identity");
        let (confidence, margin, runner_up) =
            class_confidence(&scores_of_best, &self.twins[class], best_score, classes);
        let pose = &self.stable_poses[class];
        // The origin's viewing ray meets the plane z = rest_height (table frame).
        let ray = camera_T_part.translation.vector;
        let (x, y) = ray_on_table(&self.camera_T_table, &ray, pose.rest_height)?;
        let table_T_part = pose.table_T_part(x, y, yaw);
        Ok(PlanarPose {
            camera_T_part: self.camera_T_table * table_T_part,
            table_T_part,
            class,
            yaw,
            tilt,
            confidence,
            margin,
            runner_up,
            symmetry,
        })
    }

    /// Table-frame (x, y) of the point at `height` above the table that `camera` sees at
    /// `pixel` (distorted, as observed).
    pub fn table_point(
        &self,
        camera: &Camera,
        pixel: Point2<f64>,
        height: f64,
    ) -> Result<(f64, f64), PlanarError> {
        ray_on_table(
            &self.camera_T_table,
            &camera.pixel_ray(pixel)?.into_inner(),
            height,
        )
    }

    /// [`PlanarRefiner::refine_in`] `classes`, then x, y and yaw fitted to the keypoints by
    /// Gauss–Newton on the (covariance-weighted) reprojection error with the class and height
    /// held fixed.
    ///
    /// `pixels` are observed (distorted) pixels of `model` keypoints in `camera`.
    #[allow(non_snake_case)]
    pub fn refine_with_keypoints(
        &self,
        camera_T_part: &Isometry3<f64>,
        camera: &Camera,
        model: &[Point3<f64>],
        pixels: &[Point2<f64>],
        covariances: Option<&[Matrix2<f64>]>,
        classes: ClassSet,
    ) -> Result<PlanarPose, PlanarError> {
        let mut planar = self.refine_in(camera_T_part, classes)?;
        if model.len() != pixels.len() {
            return Err(PnpError::LengthMismatch {
                what: "image points",
                expected: model.len(),
                got: pixels.len(),
            }
            .into());
        }
        if model.len() < 2 {
            return Err(PnpError::TooFewPoints(model.len()).into());
        }
        let normalized = pixels
            .iter()
            .map(|p| camera.unproject(*p))
            .collect::<Result<Vec<_>, _>>()?;
        let whiten: Vec<Matrix2<f64>> = match covariances {
            None => vec![Matrix2::identity(); model.len()],
            Some(c) if c.len() != model.len() => {
                return Err(PnpError::LengthMismatch {
                    what: "covariances",
                    expected: model.len(),
                    got: c.len(),
                }
                .into());
            }
            Some(c) => c
                .iter()
                .enumerate()
                .map(|(i, m)| {
                    m.cholesky()
                        .and_then(|ch| ch.l().try_inverse())
                        .filter(|w| w.iter().all(|v| v.is_finite()))
                        .ok_or(PnpError::BadCovariance(i))
                })
                .collect::<Result<_, _>>()?,
        };
        let pose = &self.stable_poses[planar.class];
        // Fit in the estimate's own frame (keypoint correspondences hold there), i.e. with the
        // symmetry undone, and report the canonical representative again afterwards.
        let rest_canonical = pose.rest_rotation();
        let rest = rest_canonical * planar.symmetry.inverse();
        let mut params = Vector3::new(
            planar.table_T_part.translation.x,
            planar.table_T_part.translation.y,
            planar.yaw,
        );
        let (fx, fy) = (camera.fx, camera.fy);
        let cost = |p: &Vector3<f64>| -> f64 {
            let t = self.camera_T_table * table_pose(p, &rest, pose.rest_height);
            residual_norm2(&t, model, &normalized, &whiten, fx, fy)
        };
        let mut current = cost(&params);
        let mut lambda = 1e-3;
        for _ in 0..30 {
            let (jtj, jtr) = normal_equations(
                &params,
                &rest,
                pose.rest_height,
                &self.camera_T_table,
                model,
                &normalized,
                &whiten,
                fx,
                fy,
            );
            let mut improved = false;
            for _ in 0..10 {
                let mut a = jtj;
                for i in 0..3 {
                    a[(i, i)] *= 1.0 + lambda;
                }
                let Some(step) = a.cholesky().map(|c| c.solve(&(-jtr))) else {
                    lambda *= 10.0;
                    continue;
                };
                let candidate = params + step;
                let c = cost(&candidate);
                if c < current {
                    let done = step.norm() < 1e-12 || (current - c) <= 1e-15 * current;
                    params = candidate;
                    current = c;
                    lambda = (lambda * 0.1).max(1e-12);
                    improved = !done;
                    break;
                }
                lambda *= 10.0;
            }
            if !improved {
                break;
            }
        }
        let table_T_part = table_pose(&params, &rest_canonical, pose.rest_height);
        planar.table_T_part = table_T_part;
        planar.camera_T_part = self.camera_T_table * table_T_part;
        planar.yaw = wrap_angle(params.z);
        Ok(planar)
    }
}

/// The yaw ψ minimising ‖R − Rz(ψ)·R_rest‖_F: ψ = atan2(M₀₁ − M₁₀, M₀₀ + M₁₁), M = R_rest·Rᵀ.
pub fn best_yaw(table_r_part: &UnitQuaternion<f64>, rest: &UnitQuaternion<f64>) -> f64 {
    let m: Matrix3<f64> = (rest * table_r_part.inverse())
        .to_rotation_matrix()
        .into_inner();
    (m[(0, 1)] - m[(1, 0)]).atan2(m[(0, 0)] + m[(1, 1)])
}

fn wrap_angle(a: f64) -> f64 {
    let w = (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
    if w <= -std::f64::consts::PI {
        w + std::f64::consts::TAU
    } else {
        w
    }
}

fn table_pose(p: &Vector3<f64>, rest: &UnitQuaternion<f64>, height: f64) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(p.x, p.y, height),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), p.z) * rest,
    )
}

fn residual_norm2(
    camera_t_part: &Isometry3<f64>,
    model: &[Point3<f64>],
    normalized: &[Vector2<f64>],
    whiten: &[Matrix2<f64>],
    fx: f64,
    fy: f64,
) -> f64 {
    model
        .iter()
        .zip(normalized)
        .zip(whiten)
        .map(|((p, o), w)| {
            let c = camera_t_part * p;
            if c.z <= 1e-9 {
                return f64::INFINITY;
            }
            (w * Vector2::new(fx * (c.x / c.z - o.x), fy * (c.y / c.z - o.y))).norm_squared()
        })
        .sum()
}

/// JᵀJ and Jᵀr of the whitened pixel residuals with respect to (x, y, yaw).
#[allow(clippy::too_many_arguments)]
fn normal_equations(
    params: &Vector3<f64>,
    rest: &UnitQuaternion<f64>,
    height: f64,
    camera_t_table: &Isometry3<f64>,
    model: &[Point3<f64>],
    normalized: &[Vector2<f64>],
    whiten: &[Matrix2<f64>],
    fx: f64,
    fy: f64,
) -> (Matrix3<f64>, Vector3<f64>) {
    let table_t_part = table_pose(params, rest, height);
    let r_ct = camera_t_table.rotation;
    let mut jtj = Matrix3::zeros();
    let mut jtr = Vector3::zeros();
    for ((p, o), w) in model.iter().zip(normalized).zip(whiten) {
        let q = table_t_part * p; // table frame
        let c = camera_t_table * q;
        if c.z <= 1e-9 {
            continue;
        }
        let iz = 1.0 / c.z;
        let dproj = nalgebra::Matrix2x3::new(
            fx * iz,
            0.0,
            -fx * c.x * iz * iz,
            0.0,
            fy * iz,
            -fy * c.y * iz * iz,
        );
        // d q / d(x, y, yaw) in the table frame: unit x, unit y, and z × (q − t).
        let arm = q.coords - table_t_part.translation.vector;
        let dq = Matrix3::new(1.0, 0.0, -arm.y, 0.0, 1.0, arm.x, 0.0, 0.0, 0.0);
        let j = w * dproj * (r_ct.to_rotation_matrix().into_inner() * dq);
        let r = w * Vector2::new(fx * (c.x * iz - o.x), fy * (c.y * iz - o.y));
        jtj += j.transpose() * j;
        jtr += j.transpose() * r;
    }
    (jtj, jtr)
}

/// Softmax posterior of the chosen class's resting state (the class and its symmetric `twins`)
/// among the admitted `classes`, the margin to the runner-up, and the
/// runner-up: the class ranked next below the chosen one that is not a twin of it, unless it is
/// ruled out (then there is none: the keypoints' next choice is no alternative).
fn class_confidence(
    scores: &[(f64, f64)],
    twins: &[usize],
    best: f64,
    classes: ClassSet,
) -> (f64, f64, Option<usize>) {
    let weight = |c: usize| {
        if classes.contains(c) {
            (scores[c].0 - best).exp()
        } else {
            0.0
        }
    };
    let total: f64 = (0..scores.len()).map(weight).sum();
    let chosen: f64 = twins.iter().map(|&c| weight(c)).sum();
    let runner_up = scores
        .iter()
        .enumerate()
        .filter(|(c, (s, _))| !twins.contains(c) && *s <= best)
        .max_by(|a, b| a.1.0.total_cmp(&b.1.0))
        .map(|(c, _)| c)
        .filter(|c| classes.contains(*c));
    let margin = runner_up.map_or(f64::INFINITY, |c| best - scores[c].0);
    (chosen / total, margin, runner_up)
}

fn isometry_finite(t: &Isometry3<f64>) -> bool {
    t.translation.vector.iter().all(|v| v.is_finite())
        && t.rotation.coords.iter().all(|v| v.is_finite())
}

/// Table-frame (x, y) where the camera-frame ray direction `ray` meets the plane `height` above
/// the table at `camera_T_table`; an error when the ray runs parallel to it or away from it.
#[allow(non_snake_case)]
pub fn ray_on_table(
    camera_T_table: &Isometry3<f64>,
    ray: &Vector3<f64>,
    height: f64,
) -> Result<(f64, f64), PlanarError> {
    let table_t_camera = camera_T_table.inverse();
    let origin = table_t_camera.translation.vector;
    let dir = table_t_camera.rotation * ray;
    if dir.z.abs() < 1e-12 {
        return Err(PlanarError::RayMissesPlane);
    }
    let s = (height - origin.z) / dir.z;
    if !(s.is_finite() && s > 0.0) {
        return Err(PlanarError::RayMissesPlane);
    }
    let p = origin + dir * s;
    Ok((p.x, p.y))
}
