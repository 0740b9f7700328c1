//! A UR arm's kinematic model with its tool, joint limits and singularity handling.

use nalgebra::Isometry3;
use serde::{Deserialize, Serialize};

use super::angles::{Joints, joint_distance};
use super::dh::UrDh;
use super::ik::{self, IkError, IkSolution, IkSolutions};
use super::joint_limits::JointLimits;
use super::singularity::{Singularities, SingularityPolicy, SingularityThresholds};

/// Kinematics of a UR arm: DH parameters, tool offset, joint limits and singularity handling.
#[allow(non_snake_case)]
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct UrKinematics {
    /// The arm's DH lengths.
    pub dh: UrDh,
    /// Pose of the tool centre point in the flange frame.
    pub flange_T_tcp: Isometry3<f64>,
    /// Joint position limits respected by [`UrKinematics::inverse_nearest`].
    pub joint_limits: JointLimits,
    /// How close to a singularity a solution must be to be flagged.
    #[serde(default)]
    pub singularity_thresholds: SingularityThresholds,
    /// Whether [`UrKinematics::inverse_nearest`] may pick a flagged solution.
    #[serde(default)]
    pub singularity_policy: SingularityPolicy,
}

impl UrKinematics {
    /// A nominal UR5e with the TCP at the flange, ±2π limits, singular solutions reported (for
    /// tests and benches; a cell takes its arm from its robot description,
    /// [`crate::ur_arm::UrArm`]).
    pub fn ur5e() -> Self {
        Self {
            dh: UrDh::ur5e(),
            flange_T_tcp: Isometry3::identity(),
            joint_limits: JointLimits::default(),
            singularity_thresholds: SingularityThresholds::default(),
            singularity_policy: SingularityPolicy::Report,
        }
    }

    /// The same arm with another tool offset.
    #[allow(non_snake_case)]
    pub fn with_tcp(mut self, flange_T_tcp: Isometry3<f64>) -> Self {
        self.flange_T_tcp = flange_T_tcp;
        self
    }

    /// Forward kinematics to the flange: `base_T_flange`.
    pub fn forward_flange(&self, q: &Joints) -> Isometry3<f64> {
        self.dh.forward(q)
    }

    /// Forward kinematics to the TCP: `base_T_tcp`.
    pub fn forward_tcp(&self, q: &Joints) -> Isometry3<f64> {
        self.dh.forward(q) * self.flange_T_tcp
    }

    /// Flange pose that puts the TCP at `base_T_tcp`.
    #[allow(non_snake_case)]
    pub fn flange_for_tcp(&self, base_T_tcp: &Isometry3<f64>) -> Isometry3<f64> {
        base_T_tcp * self.flange_T_tcp.inverse()
    }

    /// Geometric Jacobian at the TCP in the base frame (linear rows first, then angular).
    pub fn jacobian(&self, q: &Joints) -> nalgebra::Matrix6<f64> {
        super::jacobian::jacobian(&self.dh, q, &self.flange_T_tcp)
    }

    /// Joint speeds (rad/s) that move the TCP with `twist` (linear m/s, then angular rad/s, base
    /// frame) at `q`; `IkError::Singular` where the Jacobian cannot be inverted.
    pub fn joint_speeds_for_twist(
        &self,
        q: &Joints,
        twist: &nalgebra::Vector6<f64>,
    ) -> Result<Joints, IkError> {
        let singular = || IkError::Singular {
            singularities: self.singularities(q),
        };
        if super::jacobian::manipulability(&self.dh, q) < 1e-12 {
            return Err(singular());
        }
        let speeds = self.jacobian(q).lu().solve(twist).ok_or_else(singular)?;
        Ok(std::array::from_fn(|i| speeds[i]))
    }

    /// Singularities of a joint configuration under this model's thresholds.
    pub fn singularities(&self, q: &Joints) -> Singularities {
        let flange = self.dh.forward(q);
        let wrist_centre =
            flange.translation.vector - self.dh.d6 * (flange.rotation * nalgebra::Vector3::z());
        let radius_sq = wrist_centre.x * wrist_centre.x + wrist_centre.y * wrist_centre.y;
        let in_plane = (radius_sq - self.dh.d4 * self.dh.d4).max(0.0).sqrt();
        let t = &self.singularity_thresholds;
        Singularities {
            wrist: q[4].sin().abs() < t.wrist_sin_q5,
            elbow: q[2].sin().abs() < t.elbow_sin_q3,
            shoulder: in_plane < t.shoulder_distance,
        }
    }

    /// Every solution putting the TCP at `base_T_tcp`, angles in (−π, π]; q6 = `q6_hint` at an
    /// exact wrist singularity. Joint limits are not applied here.
    #[allow(non_snake_case)]
    pub fn inverse_all(
        &self,
        base_T_tcp: &Isometry3<f64>,
        q6_hint: f64,
    ) -> Result<IkSolutions, IkError> {
        ik::solve(
            &self.dh,
            &self.flange_for_tcp(base_T_tcp),
            q6_hint,
            &self.singularity_thresholds,
        )
    }

    /// The solution within the joint limits nearest `current` (Euclidean in joint space), each
    /// joint taken at the 2π-equivalent nearest its current value.
    #[allow(non_snake_case)]
    pub fn inverse_nearest(
        &self,
        base_T_tcp: &Isometry3<f64>,
        current: &Joints,
    ) -> Result<IkSolution, IkError> {
        if !current.iter().all(|v| v.is_finite()) {
            return Err(IkError::NonFiniteJoints(*current));
        }
        let all = self.inverse_all(base_T_tcp, current[5])?;
        let mut best: Option<(f64, IkSolution)> = None;
        let mut within_limits = 0;
        let mut rejected = Singularities::default();
        for solution in all.iter() {
            let Some(joints) = self
                .joint_limits
                .wrap_nearest_all(&solution.joints, current)
            else {
                continue;
            };
            within_limits += 1;
            let s = solution.singularities;
            if self.singularity_policy == SingularityPolicy::Reject && !s.is_empty() {
                rejected.wrist |= s.wrist;
                rejected.elbow |= s.elbow;
                rejected.shoulder |= s.shoulder;
                continue;
            }
            let distance = joint_distance(&joints, current);
            if best.is_none_or(|(d, _)| distance < d) {
                best = Some((
                    distance,
                    IkSolution {
                        joints,
                        singularities: s,
                    },
                ));
            }
        }
        match best {
            Some((_, solution)) => Ok(solution),
            None if within_limits == 0 => Err(IkError::OutsideJointLimits {
                solutions: all.len(),
            }),
            None => Err(IkError::Singular {
                singularities: rejected,
            }),
        }
    }
}
