//! Closed-form inverse kinematics of UR arms: every solution, singularities flagged.
//!
//! With `p` the flange position and `X, Y, Z` the flange axes in the base frame:
//! 1. The wrist centre `p05 = p − d6·Z` must satisfy `p05 · n = d4` with `n = (sin q1, −cos q1, 0)`
//!    the direction of the parallel joint axes 2–4; that fixes q1 up to two shoulder branches.
//! 2. The flange z axis gives `cos q5 = Z · n` (two wrist branches `±q5`).
//! 3. The flange x and y axes give `q6 = atan2(−Y·n / sin q5, X·n / sin q5)`.
//! 4. Removing joints 1, 5 and 6 leaves the planar 3R problem in frame 1: two elbow branches for
//!    q3, then q2 and q4 from the position and orientation of frame 4.

use nalgebra::{Isometry3, Vector3};
use std::f64::consts::FRAC_PI_2;
use std::ops::Deref;
use thiserror::Error;

use super::angles::{Joints, normalize_angle};
use super::dh::UrDh;
use super::singularity::{Singularities, SingularityThresholds};

/// The most solutions a UR arm has for one pose: 2 shoulder × 2 wrist × 2 elbow.
pub const MAX_IK_SOLUTIONS: usize = 8;

/// Below this |sin q5| the two wrist branches coincide and q6 is free. sin q5 comes from a
/// cross product of unit vectors, accurate to rounding.
const DEGENERATE: f64 = 1e-12;
/// Below this |sin q3|, or this in-plane distance (m) of the wrist centre from joint 1, the
/// elbow or shoulder branch pair coincides. Both come from `sqrt(a² − b²)`, whose rounding error
/// is about √ε ≈ 1e-8; snapping them to zero moves the pose by only O(value²).
const DEGENERATE_SQRT: f64 = 1e-7;
/// How far beyond the planar reach (in cos q3) still counts as the boundary of the workspace.
const REACH_SLACK: f64 = 1e-10;

/// One joint solution of the inverse kinematics with the singularities it is at.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct IkSolution {
    /// The joint angles (rad).
    pub joints: Joints,
    /// Singularities this configuration is at or near (per the thresholds used).
    pub singularities: Singularities,
}

/// All solutions for one pose (up to [`MAX_IK_SOLUTIONS`]), without allocating.
#[derive(Clone, Copy, Debug, Default)]
pub struct IkSolutions {
    items: [IkSolution; MAX_IK_SOLUTIONS],
    len: usize,
}

impl IkSolutions {
    fn push(&mut self, solution: IkSolution) {
        if self.len < MAX_IK_SOLUTIONS {
            self.items[self.len] = solution;
            self.len += 1;
        }
    }
}

impl Deref for IkSolutions {
    type Target = [IkSolution];
    fn deref(&self) -> &[IkSolution] {
        &self.items[..self.len]
    }
}

/// Why inverse kinematics found no usable joint solution.
#[derive(Clone, Debug, PartialEq, Error)]
pub enum IkError {
    /// The target pose contains NaN or infinite values.
    #[error("target pose is not finite")]
    NonFinitePose,
    /// The reference joints (for nearest-solution selection) contain NaN or infinite values.
    #[error("reference joints are not finite: {0:?}")]
    NonFiniteJoints(Joints),
    /// The DH parameters are not a valid UR arm.
    #[error("invalid UR DH parameters: {0:?}")]
    InvalidParameters(UrDh),
    /// The wrist centre is closer to the base z axis than the shoulder offset d4.
    #[error(
        "unreachable: wrist centre is {distance:.4} m from the base z axis, inside the shoulder \
         offset d4 = {offset:.4} m"
    )]
    WristCentreInsideShoulderOffset {
        /// Horizontal distance of the wrist centre from the base z axis (m).
        distance: f64,
        /// The shoulder offset d4 (m).
        offset: f64,
    },
    /// The wrist is too far from (or too near) the shoulder for the upper arm and forearm.
    #[error(
        "unreachable: wrist is {distance:.4} m from the shoulder in the arm plane, outside the \
         reach [{min:.4}, {max:.4}] m"
    )]
    OutOfReach {
        /// Distance from the joint 2 axis to frame 4 in the arm plane (m), nearest branch.
        distance: f64,
        /// Smallest reachable distance ||a2| − |a3|| (m).
        min: f64,
        /// Largest reachable distance |a2| + |a3| (m).
        max: f64,
    },
    /// Solutions exist but none fits the joint limits.
    #[error("all {solutions} IK solutions violate the joint limits")]
    OutsideJointLimits {
        /// How many solutions were found before the limits were applied.
        solutions: usize,
    },
    /// Every solution within the joint limits is singular and the policy rejects singular ones.
    #[error("every IK solution within the joint limits is singular ({singularities})")]
    Singular {
        /// The union of the singularities of the rejected solutions.
        singularities: Singularities,
    },
}

/// Every joint solution placing the flange at `base_T_flange`, angles in (−π, π].
///
/// At an exact wrist singularity q6 is free; it is set to `q6_hint` (pass the current q6 so the
/// wrist does not spin). Exactly coincident branches are returned once.
#[allow(non_snake_case)]
pub fn solve(
    dh: &UrDh,
    base_T_flange: &Isometry3<f64>,
    q6_hint: f64,
    thresholds: &SingularityThresholds,
) -> Result<IkSolutions, IkError> {
    if !dh.is_valid() {
        return Err(IkError::InvalidParameters(*dh));
    }
    let p = base_T_flange.translation.vector;
    let rotation = base_T_flange.rotation;
    if !(p.iter().all(|v| v.is_finite()) && rotation.coords.iter().all(|v| v.is_finite())) {
        return Err(IkError::NonFinitePose);
    }
    let x_axis = rotation * Vector3::x();
    let y_axis = rotation * Vector3::y();
    let z_axis = rotation * Vector3::z();
    let rows = dh.rows();

    // q1: the wrist centre lies d4 off the plane of the arm.
    let p05 = p - dh.d6 * z_axis;
    let radius = p05.x.hypot(p05.y);
    let offset = dh.d4.abs();
    if radius < offset - DEGENERATE {
        return Err(IkError::WristCentreInsideShoulderOffset {
            distance: radius,
            offset,
        });
    }
    let mut in_plane = (radius * radius - offset * offset).max(0.0).sqrt();
    if in_plane < DEGENERATE_SQRT {
        in_plane = 0.0;
    }
    let psi = p05.y.atan2(p05.x);
    let phi = in_plane.atan2(dh.d4);
    let shoulder = in_plane < thresholds.shoulder_distance;
    let q1_branches: &[f64] = if in_plane == 0.0 {
        &[psi + FRAC_PI_2]
    } else {
        &[psi + FRAC_PI_2 + phi, psi + FRAC_PI_2 - phi]
    };

    let mut out = IkSolutions::default();
    let planar_max = dh.planar_reach();
    let planar_min = (dh.a2.abs() - dh.a3.abs()).abs();
    let mut nearest_miss: Option<(f64, f64)> = None;

    for &q1_raw in q1_branches {
        let q1 = normalize_angle(q1_raw);
        let (s1, c1) = q1.sin_cos();
        let n = Vector3::new(s1, -c1, 0.0);
        let c5 = z_axis.dot(&n);
        let s5_abs = z_axis.cross(&n).norm();
        let q1_inv = rows[0].transform(q1).inverse();

        let wrist_branches: &[f64] = if s5_abs < DEGENERATE {
            &[1.0]
        } else {
            &[1.0, -1.0]
        };
        for &sign5 in wrist_branches {
            let s5 = sign5 * s5_abs;
            let q5 = s5.atan2(c5);
            let q6 = if s5_abs < DEGENERATE {
                normalize_angle(q6_hint)
            } else {
                let (xn, yn) = (x_axis.dot(&n), y_axis.dot(&n));
                (-yn * sign5).atan2(xn * sign5)
            };
            let wrist = s5_abs < thresholds.wrist_sin_q5;

            // Frame 4 seen from frame 1: the planar 3R arm.
            let t14 = q1_inv
                * base_T_flange
                * rows[5].transform(q6).inverse()
                * rows[4].transform(q5).inverse();
            let (x, y) = (t14.translation.x, t14.translation.y);
            let dist_sq = x * x + y * y;
            let mut c3 = (dist_sq - dh.a2 * dh.a2 - dh.a3 * dh.a3) / (2.0 * dh.a2 * dh.a3);
            if c3.abs() > 1.0 {
                if c3.abs() > 1.0 + REACH_SLACK {
                    let d = dist_sq.sqrt();
                    let miss = (d - planar_max).max(planar_min - d);
                    if nearest_miss.is_none_or(|(best, _)| miss < best) {
                        nearest_miss = Some((miss, d));
                    }
                    continue;
                }
                c3 = c3.signum();
            }
            let mut s3_abs = (1.0 - c3 * c3).max(0.0).sqrt();
            if s3_abs < DEGENERATE_SQRT {
                s3_abs = 0.0;
                c3 = c3.signum();
            }
            let elbow = s3_abs < thresholds.elbow_sin_q3;
            let x4 = t14.rotation * Vector3::x();
            let q234 = x4.y.atan2(x4.x);
            let elbow_branches: &[f64] = if s3_abs == 0.0 { &[1.0] } else { &[1.0, -1.0] };
            for &sign3 in elbow_branches {
                let s3 = sign3 * s3_abs;
                let q3 = s3.atan2(c3);
                let q2 = normalize_angle(y.atan2(x) - (dh.a3 * s3).atan2(dh.a2 + dh.a3 * c3));
                let q4 = normalize_angle(q234 - q2 - q3);
                out.push(IkSolution {
                    joints: [q1, q2, q3, q4, q5, q6],
                    singularities: Singularities {
                        wrist,
                        elbow,
                        shoulder,
                    },
                });
            }
        }
    }

    if out.is_empty() {
        return Err(IkError::OutOfReach {
            distance: nearest_miss.map_or(f64::NAN, |(_, d)| d),
            min: planar_min,
            max: planar_max,
        });
    }
    Ok(out)
}
