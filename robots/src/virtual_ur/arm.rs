//! The simulated arm behind the virtual controller: a trait so a physics simulator can plug in,
//! and a kinematic joint-space model with velocity and acceleration limits stepped at 500 Hz.

use super::dynamics::ArmDynamics;
use super::path_move::PathMove;
use crate::kinematics::{Joints, UrKinematics, from_ur_pose, to_ur_pose};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3, Vector6};
use thiserror::Error;

/// Joint and TCP state of the arm (SI units; poses as UR pose vectors in the base frame).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ArmState {
    /// Measured joint positions (rad).
    pub q: Joints,
    /// Measured joint velocities (rad/s).
    pub qd: Joints,
    /// Commanded joint positions.
    pub target_q: Joints,
    /// Commanded joint velocities.
    pub target_qd: Joints,
    /// Commanded joint accelerations.
    pub target_qdd: Joints,
    /// Measured TCP pose (x, y, z, rx, ry, rz).
    pub tcp_pose: [f64; 6],
    /// Commanded TCP pose.
    pub target_tcp_pose: [f64; 6],
    /// Measured TCP speed (linear m/s, angular rad/s).
    pub tcp_speed: [f64; 6],
}

/// A motion request to the arm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ArmCommand {
    /// Joint-space move, synchronised joints; `speed`/`accel` of the leading joint (rad/s, rad/s²).
    MoveJ {
        /// Target joints.
        q: Joints,
        /// Leading-joint speed.
        speed: f64,
        /// Leading-joint acceleration.
        accel: f64,
    },
    /// Straight-line TCP move to a pose (m/s, m/s²).
    MoveL {
        /// Target TCP pose (UR pose vector).
        pose: [f64; 6],
        /// Tool speed.
        speed: f64,
        /// Tool acceleration.
        accel: f64,
    },
    /// Joint velocity control, reached with `accel`.
    SpeedJ {
        /// Target joint velocities.
        qd: Joints,
        /// Acceleration.
        accel: f64,
    },
    /// Servo towards `q`, arriving in `time` seconds (within the limits).
    ServoJ {
        /// Servo target.
        q: Joints,
        /// Time to reach it.
        time: f64,
    },
    /// Tool-space velocity control (`speedl`): the TCP moves with twist `xd` (linear m/s, then
    /// angular rad/s, base frame), reached with `accel` (m/s² and rad/s²). The joint speeds are
    /// recomputed from the Jacobian every cycle, so the TCP holds its line.
    SpeedL {
        /// Target twist.
        xd: [f64; 6],
        /// Acceleration (m/s², and rad/s² for the rotation).
        accel: f64,
    },
    /// Decelerate to rest at `decel` (rad/s² of the fastest joint).
    Stop {
        /// Deceleration.
        decel: f64,
    },
    /// Decelerate to rest in tool space (`stopl`): the TCP keeps its direction and slows at
    /// `decel` (m/s², and rad/s² for the rotation).
    StopL {
        /// Deceleration.
        decel: f64,
    },
    /// Safety stop: halt at once.
    Halt,
}

/// Why the arm refused or aborted a motion.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ArmError {
    /// A target or parameter is not finite or not positive.
    #[error("invalid motion parameter: {0}")]
    InvalidParameter(&'static str),
    /// No inverse kinematics solution for a Cartesian target.
    #[error("target pose unreachable: {0}")]
    Unreachable(String),
    /// The arm met something (a collision, a safety plane): the controller makes a protective
    /// stop, as a real controller does.
    #[error("protective stop: {0}")]
    ProtectiveStop(String),
    /// A joint target lies outside the joint position limits (a UR refuses it).
    #[error(
        "joint {joint} target {value:.4} rad is outside its limits [{lower:.4}, {upper:.4}] rad"
    )]
    JointLimit {
        /// Joint index (0 = base).
        joint: usize,
        /// The refused value.
        value: f64,
        /// Lower limit.
        lower: f64,
        /// Upper limit.
        upper: f64,
    },
    /// The model cannot do this exactly, so it refuses.
    #[error("not simulated by this arm model: {0}")]
    Unsupported(&'static str),
    /// A straight-line move would need joint speeds over the limit (singularity).
    #[error("straight-line move passes a singularity (joint {joint} would need {speed:.2} rad/s)")]
    Singularity {
        /// Joint index.
        joint: usize,
        /// Needed speed.
        speed: f64,
    },
}

/// An arm the virtual controller can drive. Implementations step at the control period.
pub trait ArmModel: Send + 'static {
    /// Starts a motion (replacing the current one).
    fn command(&mut self, cmd: ArmCommand) -> Result<(), ArmError>;
    /// Advances by `dt` seconds; `speed_fraction` (0–1) scales the motion's time like the speed
    /// slider. Returns an error when the running motion had to be aborted.
    fn step(&mut self, dt: f64, speed_fraction: f64) -> Result<(), ArmError>;
    /// Current state.
    fn state(&self) -> ArmState;
    /// Whether a motion is in progress.
    fn is_moving(&self) -> bool;
    /// Forward kinematics to the TCP as a UR pose vector.
    fn forward(&self, q: &Joints) -> [f64; 6];
    /// Inverse kinematics nearest `near`.
    fn inverse(&self, pose: &[f64; 6], near: &Joints) -> Result<Joints, ArmError>;
    /// The kinematic model (its `flange_T_tcp` is the active TCP, its joint limits the
    /// controller's): forward and inverse kinematics with other TCPs, Jacobians, limit checks.
    fn kinematics(&self) -> &UrKinematics;
    /// Sets the active TCP (`set_tcp`). Models that cannot change their tool refuse.
    #[allow(non_snake_case)]
    fn set_tcp(&mut self, _flange_T_tcp: Isometry3<f64>) -> Result<(), ArmError> {
        Err(ArmError::Unsupported("set_tcp"))
    }
    /// A digital output changed: standard 0–7, configurable 8–15, tool 16–17 (as
    /// `actual_digital_output_bits`). The controller calls it from every path that sets one.
    fn digital_output(&mut self, _pin: u32, _level: bool) {}
    /// Standard analog output `index` (0 or 1) changed to `ratio` of its range (0–1): a
    /// gripper's opening set-point, say. The controller calls it from every path that sets one.
    fn analog_output(&mut self, _index: u32, _ratio: f64) {}
    /// Starts a blended path (replacing the current motion): each segment runs from the previous
    /// via-point (the arm's pose for the first) with its own speed and acceleration, and within
    /// a segment's blend radius of its via-point the next segment starts, so the arm rounds the
    /// corner instead of stopping. Blend radii must already be settled
    /// (the path module's `settle_blends`). Models that cannot blend refuse.
    fn command_path(&mut self, _path: &[PathMove]) -> Result<(), ArmError> {
        Err(ArmError::Unsupported(
            "blended paths (moveJ/moveL with a path, movePath)",
        ))
    }
    /// While a path runs: the index of the newest segment started (URScript returns from a
    /// blended move's statement when its blend begins, and from an unblended one at its end).
    fn path_progress(&self) -> Option<usize> {
        None
    }
    /// The arm's gravity model (link inertials and torque constants), for the joint torques and
    /// motor currents the controller reports. By default the built-in model of the arm the
    /// kinematics describe ([`ArmDynamics::for_dh`]: the UR5e), or none.
    fn dynamics(&self) -> Option<ArmDynamics> {
        ArmDynamics::for_dh(&self.kinematics().dh)
    }
    /// The external wrench on the tool (base frame, at the TCP: force N, moment N·m) when the
    /// model simulates its own contacts (a simulated cell's parts); `None` lets the controller's
    /// contact environment decide (the table plane, or nothing).
    fn external_wrench(&self) -> Option<[f64; 6]> {
        None
    }
    /// Seconds the device on output `pin` needs to act after a change (a gripper's stroke).
    /// Programs do not wait for it (a real one cannot know it): ours sleeps the wait its client
    /// sends, and the controller warns when that is shorter than this.
    fn actuation_time(&self, _pin: u32) -> f64 {
        0.0
    }
}

/// Trapezoidal (or triangular) velocity profile over a path of length `length`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Trapezoid {
    length: f64,
    accel: f64,
    v_peak: f64,
    t_accel: f64,
    t_cruise: f64,
}

impl Trapezoid {
    fn new(length: f64, speed: f64, accel: f64) -> Trapezoid {
        let t_full = speed / accel;
        let d_accel = 0.5 * accel * t_full * t_full;
        if 2.0 * d_accel >= length {
            let t_accel = (length / accel).sqrt();
            Trapezoid {
                length,
                accel,
                v_peak: accel * t_accel,
                t_accel,
                t_cruise: 0.0,
            }
        } else {
            Trapezoid {
                length,
                accel,
                v_peak: speed,
                t_accel: t_full,
                t_cruise: (length - 2.0 * d_accel) / speed,
            }
        }
    }

    fn duration(&self) -> f64 {
        2.0 * self.t_accel + self.t_cruise
    }

    /// Distance, speed and acceleration along the path at time `t`.
    fn at(&self, t: f64) -> (f64, f64, f64) {
        let (a, ta, tc) = (self.accel, self.t_accel, self.t_cruise);
        if t <= 0.0 {
            (0.0, 0.0, 0.0)
        } else if t < ta {
            (0.5 * a * t * t, a * t, a)
        } else if t < ta + tc {
            let d = 0.5 * a * ta * ta;
            (d + self.v_peak * (t - ta), self.v_peak, 0.0)
        } else if t < self.duration() {
            let rem = self.duration() - t;
            (self.length - 0.5 * a * rem * rem, a * rem, -a)
        } else {
            (self.length, 0.0, 0.0)
        }
    }
}

#[derive(Debug, Clone)]
enum Motion {
    Idle,
    Joint {
        start: Joints,
        end: Joints,
        delta: Joints,
        profile: Trapezoid,
        t: f64,
    },
    Linear {
        start: Isometry3<f64>,
        end: Isometry3<f64>,
        profile: Trapezoid,
        t: f64,
    },
    Speed {
        qd: Joints,
        accel: f64,
    },
    Servo {
        target: Joints,
        time: f64,
    },
    Stopping {
        decel: f64,
    },
    /// A blended path: segments `first..started` run (two while blending), the rest wait.
    Path {
        segments: Vec<PathSegment>,
        first: usize,
        started: usize,
    },
    /// Resolved-rate tool-space motion (speedl, stopl): `reference` is the integrated TCP pose
    /// the arm tracks, `twist` the current TCP twist, ramped towards `target` at `accel`.
    Cartesian {
        reference: Isometry3<f64>,
        twist: Vector6<f64>,
        target: Vector6<f64>,
        accel: f64,
    },
}

/// One planned segment of a blended path, from the previous via-point to its own.
#[derive(Debug, Clone)]
struct PathSegment {
    shape: SegmentShape,
    /// Joints at the via-point.
    end_q: Joints,
    /// TCP position at the via-point.
    end_point: Vector3<f64>,
    profile: Trapezoid,
    /// Blend radius (m) around the via-point.
    blend: f64,
    /// Time since the segment started.
    t: f64,
}

#[derive(Debug, Clone)]
enum SegmentShape {
    /// Joint-space interpolation.
    Joint { start: Joints, delta: Joints },
    /// Straight tool line (position and orientation interpolated together).
    Linear {
        start: Isometry3<f64>,
        end: Isometry3<f64>,
    },
}

impl PathSegment {
    /// Fraction of the segment done at its time `t`.
    fn fraction(&self) -> f64 {
        if self.profile.length <= 0.0 {
            1.0
        } else {
            self.profile.at(self.t).0 / self.profile.length
        }
    }

    fn done(&self) -> bool {
        self.t >= self.profile.duration()
    }
}

/// Moves `v` towards `target` by at most `step` (vector norm).
fn approach(v: &Vector3<f64>, target: &Vector3<f64>, step: f64) -> Vector3<f64> {
    let d = target - v;
    let n = d.norm();
    if n <= step {
        *target
    } else {
        v + d * (step / n)
    }
}

/// The pose error from `current` to `reference`: translation, then rotation vector (base frame).
fn pose_error(reference: &Isometry3<f64>, current: &Isometry3<f64>) -> Vector6<f64> {
    let dp = reference.translation.vector - current.translation.vector;
    let dr = (reference.rotation * current.rotation.inverse()).scaled_axis();
    Vector6::new(dp.x, dp.y, dp.z, dr.x, dr.y, dr.z)
}

/// Kinematic UR arm: perfect tracking of joint-space and straight-line trajectories, joint speeds
/// capped at `max_joint_speed` and accelerations at `max_joint_accel`. Poses (TCP state, `movel`
/// targets, forward and inverse kinematics) are of the TCP set by the kinematics'
/// `flange_T_tcp`, as the TCP configured in a real controller's installation.
#[derive(Debug, Clone)]
pub struct KinematicArm {
    kinematics: UrKinematics,
    q: Joints,
    qd: Joints,
    qdd: Joints,
    motion: Motion,
    /// Joint speed limit (rad/s).
    pub max_joint_speed: f64,
    /// Joint acceleration limit (rad/s²).
    pub max_joint_accel: f64,
    /// Tool speed limit (m/s).
    pub max_tool_speed: f64,
    /// Tool acceleration limit (m/s²).
    pub max_tool_accel: f64,
}

impl KinematicArm {
    /// A UR5e at joints `q`, TCP at the flange.
    pub fn ur5e(q: Joints) -> KinematicArm {
        KinematicArm::new(UrKinematics::ur5e(), q)
    }

    /// An arm with `kinematics` (its `flange_T_tcp` is the TCP) at joints `q`, with a UR5e's
    /// joint and tool limits.
    pub fn new(kinematics: UrKinematics, q: Joints) -> KinematicArm {
        KinematicArm {
            kinematics,
            q,
            qd: [0.0; 6],
            qdd: [0.0; 6],
            motion: Motion::Idle,
            max_joint_speed: std::f64::consts::PI,
            max_joint_accel: 40.0,
            max_tool_speed: 3.0,
            max_tool_accel: 15.0,
        }
    }

    /// The kinematics (with the TCP).
    pub fn kinematics(&self) -> &UrKinematics {
        &self.kinematics
    }

    /// While a blended path runs: whether every segment moving now is a straight tool line (the
    /// TCP speed limit of linear moves applies then); `None` when no path runs.
    pub fn path_on_tool_lines(&self) -> Option<bool> {
        match &self.motion {
            Motion::Path {
                segments,
                first,
                started,
            } => Some(
                segments[*first..*started]
                    .iter()
                    .all(|s| matches!(s.shape, SegmentShape::Linear { .. })),
            ),
            _ => None,
        }
    }

    /// Refuses joints outside the kinematics' joint limits.
    fn check_limits(&self, q: &Joints) -> Result<(), ArmError> {
        let limits = &self.kinematics.joint_limits;
        match limits.first_violation(q) {
            Some((joint, value)) => Err(ArmError::JointLimit {
                joint,
                value,
                lower: limits.lower[joint],
                upper: limits.upper[joint],
            }),
            None => Ok(()),
        }
    }

    /// Moves to `q` unless that leaves the joint limits: then the arm halts and reports a
    /// protective stop, as a UR does when a joint reaches its position limit.
    fn advance(&mut self, q: Joints, dt: f64) -> Result<(), ArmError> {
        if let Err(e) = self.check_limits(&q) {
            self.halt();
            return Err(ArmError::ProtectiveStop(format!(
                "position limit reached: {e}"
            )));
        }
        self.set_q(q, dt);
        Ok(())
    }

    fn halt(&mut self) {
        self.motion = Motion::Idle;
        self.qd = [0.0; 6];
        self.qdd = [0.0; 6];
    }

    /// The TCP twist (linear, angular; base frame) of the current joint speeds.
    fn twist(&self) -> Vector6<f64> {
        self.kinematics.jacobian(&self.q) * Vector6::from_column_slice(&self.qd)
    }

    /// The reference pose and twist a tool-space motion starts from: the running one's, or the
    /// arm's present pose and twist.
    fn cartesian_start(&self) -> (Isometry3<f64>, Vector6<f64>) {
        match &self.motion {
            Motion::Cartesian {
                reference, twist, ..
            } => (*reference, *twist),
            // Along a straight-line move: the path's pose and velocity at this instant.
            Motion::Linear {
                start,
                end,
                profile,
                t,
            } => {
                let (s, v, _) = profile.at(*t);
                let reference = start.lerp_slerp(end, s / profile.length);
                let linear =
                    (end.translation.vector - start.translation.vector) * (v / profile.length);
                let angular =
                    (end.rotation * start.rotation.inverse()).scaled_axis() * (v / profile.length);
                let twist = Vector6::new(
                    linear.x, linear.y, linear.z, angular.x, angular.y, angular.z,
                );
                (reference, twist)
            }
            _ => (self.kinematics.forward_tcp(&self.q), self.twist()),
        }
    }

    /// One resolved-rate cycle: ramp the twist, advance the reference pose, and move the joints
    /// by the Jacobian's solution for the twist that reaches the reference in this cycle.
    fn cartesian_step(
        &mut self,
        (mut reference, twist, target, accel): (Isometry3<f64>, Vector6<f64>, Vector6<f64>, f64),
        dt: f64,
        scaled: f64,
    ) -> Result<(), ArmError> {
        let step = accel * scaled;
        let lin = approach(
            &twist.fixed_rows::<3>(0).into_owned(),
            &target.fixed_rows::<3>(0).into_owned(),
            step,
        );
        let ang = approach(
            &twist.fixed_rows::<3>(3).into_owned(),
            &target.fixed_rows::<3>(3).into_owned(),
            step,
        );
        reference.translation = Translation3::from(reference.translation.vector + lin * scaled);
        reference.rotation = UnitQuaternion::from_scaled_axis(ang * scaled) * reference.rotation;
        let current = self.kinematics.forward_tcp(&self.q);
        let wanted = pose_error(&reference, &current) / dt;
        let qd = match self.kinematics.joint_speeds_for_twist(&self.q, &wanted) {
            Ok(qd) => qd,
            Err(e) => {
                self.halt();
                return Err(ArmError::Unreachable(e.to_string()));
            }
        };
        if let Some((joint, speed)) = qd
            .iter()
            .map(|v| v.abs())
            .enumerate()
            .find(|(_, v)| *v > self.max_joint_speed * 1.5)
        {
            self.halt();
            return Err(ArmError::Singularity { joint, speed });
        }
        let q = std::array::from_fn(|i| self.q[i] + qd[i] * dt);
        self.advance(q, dt)?;
        let twist = Vector6::new(lin.x, lin.y, lin.z, ang.x, ang.y, ang.z);
        self.motion = if twist.norm() == 0.0 && target.norm() == 0.0 {
            self.qd = [0.0; 6];
            Motion::Idle
        } else {
            Motion::Cartesian {
                reference,
                twist,
                target,
                accel,
            }
        };
        Ok(())
    }

    /// Plans a blended path from the arm's present joints.
    fn plan_path(&self, path: &[PathMove]) -> Result<Vec<PathSegment>, ArmError> {
        let mut q_prev = self.q;
        let mut pose_prev = self.kinematics.forward_tcp(&self.q);
        let mut segments = Vec::with_capacity(path.len());
        for m in path {
            let (shape, end_q, end_pose, length, speed, accel, blend) = match *m {
                PathMove::Joint {
                    q,
                    speed,
                    accel,
                    blend,
                } => {
                    if !finite(&q) {
                        return Err(ArmError::InvalidParameter("path joint target"));
                    }
                    self.check_limits(&q)?;
                    let speed = positive(speed, "speed")?.min(self.max_joint_speed);
                    let accel = positive(accel, "acceleration")?.min(self.max_joint_accel);
                    let delta: Joints = std::array::from_fn(|i| q[i] - q_prev[i]);
                    let length = delta.iter().fold(0.0f64, |m, d| m.max(d.abs()));
                    let shape = SegmentShape::Joint {
                        start: q_prev,
                        delta,
                    };
                    let end_pose = self.kinematics.forward_tcp(&q);
                    (shape, q, end_pose, length, speed, accel, blend)
                }
                PathMove::Linear {
                    pose,
                    speed,
                    accel,
                    blend,
                } => {
                    if !finite(&pose) {
                        return Err(ArmError::InvalidParameter("path pose target"));
                    }
                    let speed = positive(speed, "speed")?.min(self.max_tool_speed);
                    let accel = positive(accel, "acceleration")?.min(self.max_tool_accel);
                    let end = from_ur_pose(&pose);
                    let end_q = self
                        .kinematics
                        .inverse_nearest(&end, &q_prev)
                        .map_err(|e| ArmError::Unreachable(e.to_string()))?
                        .joints;
                    let distance = (end.translation.vector - pose_prev.translation.vector).norm();
                    let angle = pose_prev.rotation.angle_to(&end.rotation);
                    let shape = SegmentShape::Linear {
                        start: pose_prev,
                        end,
                    };
                    let length = distance.max(angle * 0.1);
                    (shape, end_q, end, length, speed, accel, blend)
                }
            };
            let blend = if blend.is_finite() {
                blend.max(0.0)
            } else {
                0.0
            };
            segments.push(PathSegment {
                shape,
                end_q,
                end_point: end_pose.translation.vector,
                profile: Trapezoid::new(length.max(0.0), speed, accel),
                blend,
                t: 0.0,
            });
            q_prev = end_q;
            pose_prev = end_pose;
        }
        Ok(segments)
    }

    /// Where one path segment puts the joints at its time (IK near `near` for tool lines).
    fn segment_joints(&self, seg: &PathSegment, near: &Joints) -> Result<Joints, ArmError> {
        let f = seg.fraction();
        match &seg.shape {
            SegmentShape::Joint { start, delta } => {
                Ok(std::array::from_fn(|i| start[i] + delta[i] * f))
            }
            SegmentShape::Linear { start, end } => {
                self.tool_joints(&start.lerp_slerp(end, f), near)
            }
        }
    }

    fn tool_joints(&self, pose: &Isometry3<f64>, near: &Joints) -> Result<Joints, ArmError> {
        self.kinematics
            .inverse_nearest(pose, near)
            .map(|s| s.joints)
            .map_err(|e| ArmError::Unreachable(e.to_string()))
    }

    /// The joints of the running segments: one alone, or two superposed while blending (the
    /// tail of the first and the start of the next, less the via-point they share: in tool
    /// space when both are tool lines, else in joint space). Velocities add, so the arm keeps
    /// moving through the corner and leaves it on the next segment.
    fn path_joints(&self, active: &[PathSegment]) -> Result<Joints, ArmError> {
        match active {
            [seg] => self.segment_joints(seg, &self.q),
            [a, b] => {
                if let (
                    SegmentShape::Linear { start: sa, end: ea },
                    SegmentShape::Linear { start: sb, end: eb },
                ) = (&a.shape, &b.shape)
                {
                    let pa = sa.lerp_slerp(ea, a.fraction());
                    let pb = sb.lerp_slerp(eb, b.fraction());
                    let translation =
                        pa.translation.vector + pb.translation.vector - ea.translation.vector;
                    let rotation = pb.rotation * ea.rotation.inverse() * pa.rotation;
                    let pose = Isometry3::from_parts(Translation3::from(translation), rotation);
                    self.tool_joints(&pose, &self.q)
                } else {
                    let qa = self.segment_joints(a, &self.q)?;
                    let qb = self.segment_joints(b, &self.q)?;
                    Ok(std::array::from_fn(|i| qa[i] + qb[i] - a.end_q[i]))
                }
            }
            _ => Ok(self.q),
        }
    }

    /// One control cycle of a blended path.
    fn path_step(
        &mut self,
        (mut segments, mut first, mut started): (Vec<PathSegment>, usize, usize),
        dt: f64,
        scaled: f64,
    ) -> Result<(), ArmError> {
        for seg in &mut segments[first..started] {
            seg.t += scaled;
        }
        // A segment that ends without having blended hands over at its via-point.
        if started < segments.len() && segments[started - 1].done() {
            started += 1;
        }
        while first + 1 < started && segments[first].done() {
            first += 1;
        }
        let finished = first + 1 == started && started == segments.len() && segments[first].done();
        let q = if finished {
            let last = &segments[first];
            match &last.shape {
                SegmentShape::Joint { .. } => last.end_q,
                SegmentShape::Linear { end, .. } => self.tool_joints(end, &self.q)?,
            }
        } else {
            match self.path_joints(&segments[first..started]) {
                Ok(q) => q,
                Err(e) => {
                    self.halt();
                    return Err(e);
                }
            }
        };
        if let Some((joint, speed)) = q
            .iter()
            .zip(&self.q)
            .map(|(a, b)| (a - b).abs() / dt)
            .enumerate()
            .find(|(_, v)| *v > self.max_joint_speed * 1.5)
        {
            self.halt();
            return Err(ArmError::Singularity { joint, speed });
        }
        self.advance(q, dt)?;
        if finished {
            self.halt();
            return Ok(());
        }
        // Within the blend radius of its via-point, the next segment starts.
        if first + 1 == started && started < segments.len() {
            let seg = &segments[first];
            let tcp = self.kinematics.forward_tcp(&self.q).translation.vector;
            if seg.blend > 0.0 && (tcp - seg.end_point).norm() <= seg.blend {
                started += 1;
            }
        }
        self.motion = Motion::Path {
            segments,
            first,
            started,
        };
        Ok(())
    }

    fn set_q(&mut self, q: Joints, dt: f64) {
        let qd: Joints = std::array::from_fn(|i| (q[i] - self.q[i]) / dt);
        self.qdd = std::array::from_fn(|i| (qd[i] - self.qd[i]) / dt);
        self.qd = qd;
        self.q = q;
    }
}

fn finite(values: &[f64]) -> bool {
    values.iter().all(|v| v.is_finite())
}

fn positive(v: f64, what: &'static str) -> Result<f64, ArmError> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(ArmError::InvalidParameter(what))
    }
}

impl ArmModel for KinematicArm {
    fn command(&mut self, cmd: ArmCommand) -> Result<(), ArmError> {
        self.motion = match cmd {
            ArmCommand::MoveJ { q, speed, accel } => {
                if !finite(&q) {
                    return Err(ArmError::InvalidParameter("joint target"));
                }
                self.check_limits(&q)?;
                let speed = positive(speed, "speed")?.min(self.max_joint_speed);
                let accel = positive(accel, "acceleration")?.min(self.max_joint_accel);
                let delta: Joints = std::array::from_fn(|i| q[i] - self.q[i]);
                let length = delta.iter().fold(0.0f64, |m, d| m.max(d.abs()));
                if length < 1e-12 {
                    Motion::Idle
                } else {
                    Motion::Joint {
                        start: self.q,
                        end: q,
                        delta,
                        profile: Trapezoid::new(length, speed, accel),
                        t: 0.0,
                    }
                }
            }
            ArmCommand::MoveL { pose, speed, accel } => {
                if !finite(&pose) {
                    return Err(ArmError::InvalidParameter("pose target"));
                }
                let speed = positive(speed, "speed")?.min(self.max_tool_speed);
                let accel = positive(accel, "acceleration")?.min(self.max_tool_accel);
                let end = from_ur_pose(&pose);
                self.inverse(&pose, &self.q)?;
                let start = self.kinematics.forward_tcp(&self.q);
                let distance = (end.translation.vector - start.translation.vector).norm();
                let angle = start.rotation.angle_to(&end.rotation);
                // Translation leads; a pure reorientation uses the speed as rad/s.
                let length = distance.max(angle * 0.1);
                if length < 1e-9 {
                    Motion::Idle
                } else {
                    Motion::Linear {
                        start,
                        end,
                        profile: Trapezoid::new(length, speed, accel),
                        t: 0.0,
                    }
                }
            }
            ArmCommand::SpeedJ { qd, accel } => {
                if !finite(&qd) {
                    return Err(ArmError::InvalidParameter("joint speed"));
                }
                let accel = positive(accel, "acceleration")?.min(self.max_joint_accel);
                let qd = qd.map(|v| v.clamp(-self.max_joint_speed, self.max_joint_speed));
                Motion::Speed { qd, accel }
            }
            ArmCommand::ServoJ { q, time } => {
                if !finite(&q) {
                    return Err(ArmError::InvalidParameter("servo target"));
                }
                self.check_limits(&q)?;
                let time = positive(time, "servo time")?;
                Motion::Servo { target: q, time }
            }
            ArmCommand::SpeedL { xd, accel } => {
                if !finite(&xd) {
                    return Err(ArmError::InvalidParameter("tool speed"));
                }
                let accel = positive(accel, "acceleration")?.min(self.max_tool_accel);
                let mut target = Vector6::from_column_slice(&xd);
                let linear = target.fixed_rows::<3>(0).norm();
                if linear > self.max_tool_speed {
                    let k = self.max_tool_speed / linear;
                    target.fixed_rows_mut::<3>(0).scale_mut(k);
                }
                let (reference, twist) = self.cartesian_start();
                Motion::Cartesian {
                    reference,
                    twist,
                    target,
                    accel,
                }
            }
            ArmCommand::Stop { decel } => Motion::Stopping {
                decel: positive(decel, "deceleration")?.min(self.max_joint_accel * 2.0),
            },
            ArmCommand::StopL { decel } => {
                let accel = positive(decel, "deceleration")?;
                if matches!(self.motion, Motion::Idle) {
                    Motion::Idle
                } else {
                    let (reference, twist) = self.cartesian_start();
                    Motion::Cartesian {
                        reference,
                        twist,
                        target: Vector6::zeros(),
                        accel,
                    }
                }
            }
            ArmCommand::Halt => {
                self.qd = [0.0; 6];
                self.qdd = [0.0; 6];
                Motion::Idle
            }
        };
        Ok(())
    }

    fn step(&mut self, dt: f64, speed_fraction: f64) -> Result<(), ArmError> {
        let scaled = dt * speed_fraction.clamp(0.0, 1.0);
        if matches!(self.motion, Motion::Path { .. }) {
            let Motion::Path {
                segments,
                first,
                started,
            } = std::mem::replace(&mut self.motion, Motion::Idle)
            else {
                unreachable!("matched a path")
            };
            return self.path_step((segments, first, started), dt, scaled);
        }
        if let Motion::Cartesian {
            reference,
            twist,
            target,
            accel,
        } = self.motion
        {
            return self.cartesian_step((reference, twist, target, accel), dt, scaled);
        }
        match &mut self.motion {
            Motion::Idle => {
                self.qd = [0.0; 6];
                self.qdd = [0.0; 6];
            }
            Motion::Joint {
                start,
                end,
                delta,
                profile,
                t,
            } => {
                *t += scaled;
                let done = *t >= profile.duration();
                let q = if done {
                    // Exactly the commanded joints (start + delta may differ in the last bit).
                    *end
                } else {
                    let (s, _, _) = profile.at(*t);
                    let f = s / profile.length;
                    std::array::from_fn(|i| start[i] + delta[i] * f)
                };
                self.set_q(q, dt);
                if done {
                    self.motion = Motion::Idle;
                    self.qd = [0.0; 6];
                }
            }
            Motion::Linear {
                start,
                end,
                profile,
                t,
            } => {
                *t += scaled;
                let (s, _, _) = profile.at(*t);
                let f = s / profile.length;
                let pose = start.lerp_slerp(end, f);
                let done = *t >= profile.duration();
                let q = match self.kinematics.inverse_nearest(&pose, &self.q) {
                    Ok(sol) => sol.joints,
                    Err(e) => {
                        self.motion = Motion::Idle;
                        self.qd = [0.0; 6];
                        return Err(ArmError::Unreachable(e.to_string()));
                    }
                };
                for (i, (a, b)) in q.iter().zip(&self.q).enumerate() {
                    let speed = (a - b).abs() / dt;
                    if speed > self.max_joint_speed * 1.5 {
                        self.motion = Motion::Idle;
                        self.qd = [0.0; 6];
                        return Err(ArmError::Singularity { joint: i, speed });
                    }
                }
                self.set_q(q, dt);
                if done {
                    self.motion = Motion::Idle;
                    self.qd = [0.0; 6];
                }
            }
            Motion::Speed { qd, accel } => {
                let (qd, accel) = (*qd, *accel);
                let next: Joints = std::array::from_fn(|i| {
                    let dv = (qd[i] * speed_fraction - self.qd[i]).clamp(-accel * dt, accel * dt);
                    self.qd[i] + dv
                });
                let q = std::array::from_fn(|i| self.q[i] + next[i] * dt);
                self.advance(q, dt)?;
            }
            Motion::Servo { target, time } => {
                // Reach the target in `time` where the limits allow; never pass it.
                let (target, time) = (*target, time.max(dt));
                let a = self.max_joint_accel * dt;
                let next: Joints = std::array::from_fn(|i| {
                    let want = ((target[i] - self.q[i]) / time)
                        .clamp(-self.max_joint_speed, self.max_joint_speed);
                    let v = self.qd[i] + (want - self.qd[i]).clamp(-a, a);
                    let step = v * dt;
                    let remaining = target[i] - self.q[i];
                    if step.abs() >= remaining.abs() {
                        remaining / dt
                    } else {
                        v
                    }
                });
                let q = std::array::from_fn(|i| self.q[i] + next[i] * dt);
                self.advance(q, dt)?;
            }
            Motion::Cartesian { .. } | Motion::Path { .. } => {}
            Motion::Stopping { decel } => {
                let peak = self.qd.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                if peak <= *decel * dt {
                    self.motion = Motion::Idle;
                    self.qd = [0.0; 6];
                } else {
                    let k = (peak - *decel * dt) / peak;
                    let next: Joints = self.qd.map(|v| v * k);
                    let q = std::array::from_fn(|i| self.q[i] + next[i] * dt);
                    self.advance(q, dt)?;
                }
            }
        }
        Ok(())
    }

    fn state(&self) -> ArmState {
        let pose = self.forward(&self.q);
        let ahead: Joints = std::array::from_fn(|i| self.q[i] + self.qd[i] * 1e-3);
        let pose_ahead = self.forward(&ahead);
        let tcp_speed = std::array::from_fn(|i| {
            if i < 3 {
                (pose_ahead[i] - pose[i]) / 1e-3
            } else {
                let a = from_ur_pose(&pose).rotation;
                let b = from_ur_pose(&pose_ahead).rotation;
                (b * a.inverse()).scaled_axis()[i - 3] / 1e-3
            }
        });
        ArmState {
            q: self.q,
            qd: self.qd,
            target_q: self.q,
            target_qd: self.qd,
            target_qdd: self.qdd,
            tcp_pose: pose,
            target_tcp_pose: pose,
            tcp_speed,
        }
    }

    fn is_moving(&self) -> bool {
        match self.motion {
            Motion::Idle => false,
            Motion::Speed { .. } => true,
            _ => true,
        }
    }

    fn forward(&self, q: &Joints) -> [f64; 6] {
        to_ur_pose(&self.kinematics.forward_tcp(q))
    }

    fn inverse(&self, pose: &[f64; 6], near: &Joints) -> Result<Joints, ArmError> {
        self.kinematics
            .inverse_nearest(&from_ur_pose(pose), near)
            .map(|s| s.joints)
            .map_err(|e| ArmError::Unreachable(e.to_string()))
    }

    fn kinematics(&self) -> &UrKinematics {
        &self.kinematics
    }

    fn command_path(&mut self, path: &[PathMove]) -> Result<(), ArmError> {
        let segments = self.plan_path(path)?;
        self.motion = if segments.is_empty() {
            Motion::Idle
        } else {
            Motion::Path {
                segments,
                first: 0,
                started: 1,
            }
        };
        Ok(())
    }

    fn path_progress(&self) -> Option<usize> {
        match &self.motion {
            Motion::Path { started, .. } => Some(started - 1),
            _ => None,
        }
    }

    #[allow(non_snake_case)]
    fn set_tcp(&mut self, flange_T_tcp: Isometry3<f64>) -> Result<(), ArmError> {
        if self.is_moving() {
            return Err(ArmError::InvalidParameter("set_tcp while the arm moves"));
        }
        self.kinematics.flange_T_tcp = flange_T_tcp;
        Ok(())
    }
}
