//! The wrist's force/torque sensor and what the virtual arm touches: the sensor's noise and bias
//! (UR5e datasheet precision, seeded and deterministic), the contact surface the arm meets when no
//! richer contact model is plugged in (the table plane), force mode's admittance law, and the
//! joint torques a contact wrench loads the joints with (`τ = −Jᵀ·F`).
//!
//! Conventions, stated once:
//! - An **external wrench** is what the environment applies to the tool, at the TCP, in the base
//!   frame: force (N) then moment about the TCP (N·m). `actual_TCP_force` reports it (payload
//!   compensated, as a UR does): pressing the tool down on the table reads `+Fz`.
//! - A **force-mode wrench** is what the robot applies to the environment, in the task frame
//!   (URScript's `force_mode`): `[0, 0, -10, 0, 0, 0]` in the base frame pushes down with 10 N,
//!   so at rest on the table `actual_TCP_force` reads `+10 N` in z.
//!
//! Model limits, stated: the surface is a linear spring (no friction along it, no damping); the
//! force controller regulates on the noise-free wrench (a real controller filters its sensor);
//! the arm is kinematic, so compliance is a commanded tool speed (an admittance), not a torque.

use crate::kinematics::{Joints, from_ur_pose};
use nalgebra::{Isometry3, Matrix6, Rotation3, Unit, UnitQuaternion, Vector3, Vector6};

/// UR5e datasheet: force/torque sensor force precision, N (±).
pub const UR5E_FORCE_PRECISION: f64 = 4.0;

/// UR5e datasheet: force/torque sensor torque precision, N·m (±).
pub const UR5E_TORQUE_PRECISION: f64 = 0.3;

/// Stiffness of the contact between the tool and the table, N/m: a gripper's fingers on a steel
/// table (10 N sinks 0.2 mm). A modelled value.
pub const TABLE_STIFFNESS: f64 = 5e4;

/// Contact force (N) along the motion above which `tool_contact` reports a contact: above the
/// sensor's noise (3σ = 2 N, see [`FtNoise::ur5e`]) so free motion never trips it. A modelled
/// value.
pub const CONTACT_DETECTION_FORCE: f64 = 5.0;

/// Force-mode admittance at gain scaling 1: tool speed per newton of force error, m/(s·N). With
/// the table's stiffness and the 2 ms period the loop gain `K·k·dt` stays under 1 up to the
/// largest gain scaling (2), so force mode never oscillates against it. A modelled value.
pub const FORCE_GAIN: f64 = 0.004;

/// Force-mode admittance about the axes at gain scaling 1, rad/(s·N·m). A modelled value.
pub const TORQUE_GAIN: f64 = 0.2;

/// Largest gain scaling `force_mode_set_gain_scaling` accepts (URScript: 0 to 2).
pub const MAX_GAIN_SCALING: f64 = 2.0;

/// A small deterministic generator (SplitMix64) for the sensor noise: the same seed gives the same
/// readings on every platform.
#[derive(Debug, Clone)]
struct SplitMix(u64);

impl SplitMix {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Standard normal (Box–Muller).
    fn normal(&mut self) -> f64 {
        let u = 1.0 - self.uniform();
        let v = self.uniform();
        (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
    }
}

/// A force/torque sensor's reading error: a bias drawn once per sensor and white noise drawn per
/// reading, seeded.
#[derive(Debug, Clone)]
pub struct FtNoise {
    rng: SplitMix,
    /// Bias of each axis (N, then N·m), fixed for the sensor's life until zeroed.
    pub bias: [f64; 6],
    /// Standard deviation of each axis' white noise (N, then N·m).
    pub sigma: [f64; 6],
}

impl FtNoise {
    /// A sensor whose reading error stays within `±force_precision` N and
    /// `±torque_precision` N·m: bias uniform within half the precision, white noise with σ a sixth
    /// of it, so bias plus 3σ is the precision.
    pub fn new(seed: u64, force_precision: f64, torque_precision: f64) -> FtNoise {
        let mut rng = SplitMix(seed);
        let precision = |i: usize| {
            if i < 3 {
                force_precision
            } else {
                torque_precision
            }
        };
        let bias = std::array::from_fn(|i| (rng.uniform() - 0.5) * precision(i));
        let sigma = std::array::from_fn(|i| precision(i) / 6.0);
        FtNoise { rng, bias, sigma }
    }

    /// The UR5e's sensor ([`UR5E_FORCE_PRECISION`], [`UR5E_TORQUE_PRECISION`]).
    pub fn ur5e(seed: u64) -> FtNoise {
        FtNoise::new(seed, UR5E_FORCE_PRECISION, UR5E_TORQUE_PRECISION)
    }

    /// A noiseless, unbiased sensor.
    pub fn ideal() -> FtNoise {
        FtNoise::new(0, 0.0, 0.0)
    }

    /// One reading's error: bias plus a fresh noise draw.
    pub fn sample(&mut self) -> [f64; 6] {
        std::array::from_fn(|i| self.bias[i] + self.sigma[i] * self.rng.normal())
    }
}

/// A flat surface the tool can press on: the plane z = 0 of `base_T_plane`, its normal +z, a
/// linear spring of `stiffness` under it.
#[derive(Debug, Clone, Copy, PartialEq)]
#[allow(non_snake_case)]
pub struct ContactPlane {
    /// The plane's frame in the robot base frame (z up out of the surface).
    pub base_T_plane: Isometry3<f64>,
    /// Contact stiffness, N/m.
    pub stiffness: f64,
}

impl ContactPlane {
    /// The table the robot stands on: the base frame's xy plane, [`TABLE_STIFFNESS`].
    pub fn table() -> ContactPlane {
        ContactPlane {
            base_T_plane: Isometry3::identity(),
            stiffness: TABLE_STIFFNESS,
        }
    }

    /// How far the TCP at `base_T_tcp` is below the surface (m; 0 when above it).
    #[allow(non_snake_case)]
    pub fn penetration(&self, base_T_tcp: &Isometry3<f64>) -> f64 {
        let local = self.base_T_plane.inverse() * base_T_tcp;
        (-local.translation.z).max(0.0)
    }

    /// The external wrench on the tool at `base_T_tcp` (base frame, at the TCP): the surface's
    /// spring pushing the TCP back out along its normal.
    #[allow(non_snake_case)]
    pub fn wrench_at(&self, base_T_tcp: &Isometry3<f64>) -> [f64; 6] {
        let f = self.base_T_plane.rotation
            * Vector3::z()
            * (self.stiffness * self.penetration(base_T_tcp));
        [f.x, f.y, f.z, 0.0, 0.0, 0.0]
    }
}

/// What the arm touches when no arm model reports a wrench of its own.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum ContactEnvironment {
    /// Nothing: the tool never touches anything.
    #[default]
    Nothing,
    /// A plane (the table).
    Plane(ContactPlane),
}

impl ContactEnvironment {
    /// The external wrench on the tool at `base_T_tcp` (base frame, at the TCP).
    #[allow(non_snake_case)]
    pub fn wrench_at(&self, base_T_tcp: &Isometry3<f64>) -> [f64; 6] {
        match self {
            ContactEnvironment::Nothing => [0.0; 6],
            ContactEnvironment::Plane(p) => p.wrench_at(base_T_tcp),
        }
    }
}

/// The joint torques (N·m) the contact wrench `external` (base frame, at the TCP) loads the
/// joints with beyond gravity, with `jacobian` the geometric Jacobian at the TCP: the motors hold
/// `−Jᵀ·F` (the sign of `M q̈ + C q̇ + g(q) = τ + Jᵀ F`).
pub fn contact_torques(jacobian: &Matrix6<f64>, external: &[f64; 6]) -> Joints {
    let t = -(jacobian.transpose() * Vector6::from_column_slice(external));
    std::array::from_fn(|i| t[i])
}

/// The wrench `w` (base frame, at the TCP) expressed in a frame rotated by `rotation` (same
/// point): both vectors rotated into it.
pub fn rotate_wrench(rotation: &UnitQuaternion<f64>, w: &[f64; 6]) -> [f64; 6] {
    let f = rotation * Vector3::new(w[0], w[1], w[2]);
    let m = rotation * Vector3::new(w[3], w[4], w[5]);
    [f.x, f.y, f.z, m.x, m.y, m.z]
}

/// URScript `force_mode`'s task-frame types.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ForceModeType {
    /// 1: the frame's y axis points from the TCP towards the task frame's origin.
    Point,
    /// 2: the task frame as given.
    Frame,
    /// 3: the frame's x axis is the TCP's direction of motion projected onto the task frame's
    /// xy plane.
    Motion,
}

/// A running `force_mode(task_frame, selection_vector, wrench, type, limits)`.
#[derive(Debug, Clone, PartialEq)]
pub struct ForceMode {
    /// The task frame in the base frame.
    pub task_frame: Isometry3<f64>,
    /// Compliant axes (task frame: x, y, z, rx, ry, rz).
    pub selection: [bool; 6],
    /// The wrench the robot applies to the environment along the compliant axes (N, N·m).
    pub wrench: [f64; 6],
    /// How the task frame is interpreted.
    pub kind: ForceModeType,
    /// Compliant axes: largest tool speed (m/s, rad/s); other axes: largest deviation from the
    /// program's path (m, rad; the model holds them on it).
    pub limits: [f64; 6],
    /// The last task-frame rotation of a motion-type frame (kept while the TCP stands still).
    last_rotation: Option<UnitQuaternion<f64>>,
}

impl ForceMode {
    /// Checks and builds a force mode from the control script's registers: `task_frame` as a UR
    /// pose, `selection` 0/1 per axis, `kind` 1–3, `limits` positive.
    pub fn new(
        task_frame: &[f64; 6],
        selection: &[i32; 6],
        wrench: &[f64; 6],
        kind: i32,
        limits: &[f64; 6],
    ) -> Result<ForceMode, String> {
        let kind = match kind {
            1 => ForceModeType::Point,
            2 => ForceModeType::Frame,
            3 => ForceModeType::Motion,
            other => return Err(format!("force_mode: type {other} is not 1, 2 or 3")),
        };
        if let Some(s) = selection.iter().find(|s| !matches!(s, 0 | 1)) {
            return Err(format!(
                "force_mode: selection vector entry {s} is not 0 or 1"
            ));
        }
        let finite = |v: &[f64; 6]| v.iter().all(|x| x.is_finite());
        if !(finite(task_frame) && finite(wrench)) {
            return Err("force_mode: task frame or wrench not finite".into());
        }
        if let Some((i, l)) = limits
            .iter()
            .enumerate()
            .find(|(_, l)| !(l.is_finite() && **l > 0.0))
        {
            return Err(format!(
                "force_mode: limit {i} is {l}, not a positive number"
            ));
        }
        Ok(ForceMode {
            task_frame: from_ur_pose(task_frame),
            selection: selection.map(|s| s == 1),
            wrench: *wrench,
            kind,
            limits: *limits,
            last_rotation: None,
        })
    }

    /// Whether `other` is the same `force_mode` call (the script re-sends it every cycle).
    pub fn same_command(&self, other: &ForceMode) -> bool {
        self.task_frame == other.task_frame
            && self.selection == other.selection
            && self.wrench == other.wrench
            && self.kind == other.kind
            && self.limits == other.limits
    }

    /// The task frame's rotation now, for the TCP at `base_T_tcp` moving at `tcp_velocity`
    /// (base frame, m/s).
    #[allow(non_snake_case)]
    pub fn frame_rotation(
        &mut self,
        base_T_tcp: &Isometry3<f64>,
        tcp_velocity: &Vector3<f64>,
    ) -> UnitQuaternion<f64> {
        let given = self.task_frame.rotation;
        let z = given * Vector3::z();
        let from_axes = |x: Vector3<f64>, y: Vector3<f64>, z: Vector3<f64>| {
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_basis_unchecked(&[x, y, z]))
        };
        match self.kind {
            ForceModeType::Frame => given,
            ForceModeType::Point => {
                let to_origin = self.task_frame.translation.vector - base_T_tcp.translation.vector;
                let z_perp =
                    z - to_origin * (z.dot(&to_origin) / to_origin.norm_squared().max(1e-300));
                match (Unit::try_new(to_origin, 1e-9), Unit::try_new(z_perp, 1e-9)) {
                    (Some(y), Some(z)) => from_axes(y.cross(&z), *y, *z),
                    _ => given,
                }
            }
            ForceModeType::Motion => {
                let planar = tcp_velocity - z * z.dot(tcp_velocity);
                if let Some(x) = Unit::try_new(planar, 1e-6) {
                    let r = from_axes(*x, z.cross(&x), z);
                    self.last_rotation = Some(r);
                    r
                } else {
                    self.last_rotation.unwrap_or(given)
                }
            }
        }
    }

    /// The tool twist (base frame: m/s, then rad/s) force mode commands this cycle: along each
    /// compliant axis of the task frame (rotated by `rotation`), the force error — the wrench to
    /// apply less the one applied (`−external`) — times the admittance scaled by
    /// `gain_scaling`, within the axis' speed limit; zero along the other axes.
    pub fn twist(
        &self,
        rotation: &UnitQuaternion<f64>,
        external: &[f64; 6],
        gain_scaling: f64,
    ) -> [f64; 6] {
        let local = rotate_wrench(&rotation.inverse(), external);
        let v: [f64; 6] = std::array::from_fn(|i| {
            if !self.selection[i] {
                return 0.0;
            }
            let gain = if i < 3 { FORCE_GAIN } else { TORQUE_GAIN } * gain_scaling;
            let error = self.wrench[i] + local[i];
            (gain * error).clamp(-self.limits[i], self.limits[i])
        });
        rotate_wrench(rotation, &v)
    }
}

/// Force mode's tuning (`force_mode_set_damping`, `force_mode_set_gain_scaling`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForceTuning {
    /// Damping, 0 (none: the tool keeps its speed) to 1 (full: it takes the commanded speed at
    /// once).
    pub damping: f64,
    /// Gain scaling, 0 to [`MAX_GAIN_SCALING`].
    pub gain_scaling: f64,
}

impl Default for ForceTuning {
    /// URScript's defaults (damping 0.005, gain scaling 1); ur_rtde's script sets 0.025 and 0.5.
    fn default() -> Self {
        ForceTuning {
            damping: 0.005,
            gain_scaling: 1.0,
        }
    }
}

impl ForceTuning {
    /// The share of the way from the present tool speed to force mode's commanded speed taken in
    /// one control cycle: 0.1 with no damping to 1 with full damping. (The floor keeps the loop
    /// against a stiff surface well damped: a modelled choice.)
    pub fn blend(&self) -> f64 {
        0.1 + 0.9 * self.damping.clamp(0.0, 1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_is_seeded_and_within_the_datasheet_precision() {
        let mut a = FtNoise::ur5e(7);
        let mut b = FtNoise::ur5e(7);
        let n = 20_000;
        let mut mean = [0.0; 6];
        for _ in 0..n {
            let x = a.sample();
            assert_eq!(x, b.sample());
            for i in 0..6 {
                let limit = if i < 3 {
                    UR5E_FORCE_PRECISION
                } else {
                    UR5E_TORQUE_PRECISION
                };
                // Bias + 4.5σ: a draw beyond is a 1-in-150 000 event per axis.
                assert!(x[i].abs() <= limit * 1.25, "axis {i}: {}", x[i]);
                mean[i] += x[i] / n as f64;
            }
        }
        for (i, m) in mean.iter().enumerate() {
            let se = 4.0 * a.sigma[i] / (n as f64).sqrt();
            assert!(
                (m - a.bias[i]).abs() < se,
                "axis {i}: mean {m} bias {}",
                a.bias[i]
            );
        }
        assert_ne!(FtNoise::ur5e(8).bias, a.bias);
    }

    #[test]
    fn the_table_pushes_up_in_proportion_to_the_depth() {
        let t = ContactPlane::table();
        let above = Isometry3::translation(0.3, 0.1, 0.002);
        assert_eq!(t.wrench_at(&above), [0.0; 6]);
        let below = Isometry3::translation(0.3, 0.1, -2e-4);
        let w = t.wrench_at(&below);
        assert!((w[2] - 10.0).abs() < 1e-9, "{w:?}");
        assert!(w[0].abs() < 1e-12 && w[1].abs() < 1e-12);
    }

    #[test]
    fn force_mode_pushes_down_in_free_space_and_stops_at_the_commanded_force() {
        let fm = ForceMode::new(
            &[0.0; 6],
            &[0, 0, 1, 0, 0, 0],
            &[0.0, 0.0, -10.0, 0.0, 0.0, 0.0],
            2,
            &[0.1, 0.1, 0.05, 1.0, 1.0, 1.0],
        )
        .expect("valid");
        let r = UnitQuaternion::identity();
        // Free space: down at the speed limit.
        let free = fm.twist(&r, &[0.0; 6], 1.0);
        assert!((free[2] + 0.04).abs() < 1e-12, "{free:?}");
        assert_eq!(&free[..2], &[0.0, 0.0]);
        // Pressing with 10 N: the error vanishes.
        let held = fm.twist(&r, &[0.0, 0.0, 10.0, 0.0, 0.0, 0.0], 1.0);
        assert!(held.iter().all(|v| v.abs() < 1e-12), "{held:?}");
        // A lateral push on a non-compliant axis moves nothing.
        let side = fm.twist(&r, &[5.0, 0.0, 10.0, 0.0, 0.0, 0.0], 1.0);
        assert!(side.iter().all(|v| v.abs() < 1e-12), "{side:?}");
        assert!(ForceMode::new(&[0.0; 6], &[0, 0, 2, 0, 0, 0], &[0.0; 6], 2, &[1.0; 6]).is_err());
        assert!(ForceMode::new(&[0.0; 6], &[0; 6], &[0.0; 6], 4, &[1.0; 6]).is_err());
        assert!(ForceMode::new(&[0.0; 6], &[0; 6], &[0.0; 6], 2, &[0.0; 6]).is_err());
    }

    #[test]
    fn point_and_motion_task_frames_follow_the_tcp() {
        let tcp = Isometry3::translation(0.4, 0.0, 0.3);
        // Type 1: y from the TCP towards the frame's origin, z kept as near the frame's as it can.
        let mut point = ForceMode::new(
            &[0.4, 0.2, 0.3, 0.0, 0.0, 0.0],
            &[0, 1, 0, 0, 0, 0],
            &[0.0, 5.0, 0.0, 0.0, 0.0, 0.0],
            1,
            &[0.1; 6],
        )
        .expect("valid");
        let r = point.frame_rotation(&tcp, &Vector3::zeros());
        assert!((r * Vector3::y() - Vector3::y()).norm() < 1e-12);
        assert!((r * Vector3::z() - Vector3::z()).norm() < 1e-12);
        let mut far = point.clone();
        far.task_frame = Isometry3::translation(0.4, -0.2, 0.3);
        let r = far.frame_rotation(&tcp, &Vector3::zeros());
        assert!((r * Vector3::y() + Vector3::y()).norm() < 1e-12);
        // In free space the tool moves towards the point (y of that frame): −y of the base.
        let v = far.twist(&r, &[0.0; 6], 1.0);
        assert!(v[1] < 0.0 && v[0].abs() < 1e-12, "{v:?}");
        // Type 3: x along the motion projected onto the frame's xy plane; kept when still.
        let mut motion =
            ForceMode::new(&[0.0; 6], &[0, 0, 1, 0, 0, 0], &[0.0; 6], 3, &[0.1; 6]).expect("valid");
        let r = motion.frame_rotation(&tcp, &Vector3::new(0.0, 0.05, 0.01));
        assert!((r * Vector3::x() - Vector3::y()).norm() < 1e-12);
        let still = motion.frame_rotation(&tcp, &Vector3::zeros());
        assert!(still.angle_to(&r) < 1e-12);
    }

    #[test]
    fn the_admittance_loop_settles_on_the_table_without_oscillating_at_every_gain() {
        let plane = ContactPlane::table();
        for gain in [0.1, 0.5, 1.0, 2.0] {
            for damping in [0.0, 0.025, 1.0] {
                let tuning = ForceTuning {
                    damping,
                    gain_scaling: gain,
                };
                let fm = ForceMode::new(
                    &[0.0; 6],
                    &[0, 0, 1, 0, 0, 0],
                    &[0.0, 0.0, -10.0, 0.0, 0.0, 0.0],
                    2,
                    &[0.1, 0.1, 0.05, 1.0, 1.0, 1.0],
                )
                .expect("valid");
                let (dt, mut z, mut v) = (0.002, 0.003, 0.0);
                for _ in 0..3000 {
                    let tcp = Isometry3::translation(0.4, 0.0, z);
                    let target =
                        fm.twist(&UnitQuaternion::identity(), &plane.wrench_at(&tcp), gain);
                    v += tuning.blend() * (target[2] - v);
                    z += v * dt;
                }
                let f = plane.wrench_at(&Isometry3::translation(0.4, 0.0, z))[2];
                assert!(
                    (f - 10.0).abs() < 0.05,
                    "gain {gain} damping {damping}: {f} N"
                );
            }
        }
    }

    #[test]
    fn contact_torques_are_the_jacobian_transpose() {
        let k = crate::kinematics::UrKinematics::ur5e();
        let q = [0.3, -1.4, 1.5, -1.7, -std::f64::consts::FRAC_PI_2, 0.2];
        let j = k.jacobian(&q);
        let t = contact_torques(&j, &[0.0, 0.0, 10.0, 0.0, 0.0, 0.0]);
        // Joint 1's axis is vertical: a vertical force has no moment about it.
        assert!(t[0].abs() < 1e-9, "{t:?}");
        // Virtual work: τ·q̇ = −F·v for any joint speed.
        let qd = Vector6::new(0.1, -0.2, 0.3, 0.05, -0.1, 0.2);
        let v = j * qd;
        let work: f64 = (0..6).map(|i| t[i] * qd[i]).sum();
        assert!((work + 10.0 * v[2]).abs() < 1e-9);
    }
}

/// Contact force (N) beyond which the arm protective-stops: UR's default safety force limit.
pub const PROTECTIVE_STOP_FORCE: f64 = 150.0;

/// The controller's view of the wrist sensor, updated every control cycle.
#[derive(Debug, Clone)]
pub struct FtSensorState {
    /// The sensor's reading error.
    pub noise: FtNoise,
    /// What `zero_ftsensor` subtracts from `actual_TCP_force` (the true wrench and the bias when
    /// it was zeroed).
    pub zero: [f64; 6],
    /// The true external wrench on the tool (base frame, at the TCP).
    pub external: [f64; 6],
    /// Consecutive control cycles (this one included) in which the tool has been touching
    /// something; 0 when free.
    pub contact_cycles: u32,
    /// The joint torques the contact loads the joints with ([`contact_torques`]).
    pub joint_torques: Joints,
    /// `actual_TCP_force`: the external wrench as the sensor reads it, payload compensated.
    pub tcp_force: [f64; 6],
    /// `ft_raw_wrench`: the sensor's raw reading in the flange frame about the flange, the
    /// payload's weight included.
    pub raw: [f64; 6],
}

impl FtSensorState {
    /// A sensor with this reading error, touching nothing.
    pub fn new(noise: FtNoise) -> FtSensorState {
        FtSensorState {
            noise,
            zero: [0.0; 6],
            external: [0.0; 6],
            contact_cycles: 0,
            joint_torques: [0.0; 6],
            tcp_force: [0.0; 6],
            raw: [0.0; 6],
        }
    }

    /// `zero_ftsensor()`: later `actual_TCP_force` readings are relative to the present wrench,
    /// and the bias is gone.
    pub fn zero(&mut self) {
        self.zero = std::array::from_fn(|i| self.external[i] + self.noise.bias[i]);
    }

    /// One control cycle: the tool at `base_T_tcp` (flange at `base_T_flange`) meets
    /// `external`, the Jacobian at the TCP is `jacobian`, the payload's weight `payload_weight`
    /// (N, base frame: its mass times gravity) acts at `payload_cog` (flange frame).
    #[allow(non_snake_case)]
    pub fn update(
        &mut self,
        external: [f64; 6],
        base_T_tcp: &Isometry3<f64>,
        base_T_flange: &Isometry3<f64>,
        jacobian: &Matrix6<f64>,
        payload_weight: &[f64; 3],
        payload_cog: &[f64; 3],
    ) {
        let touching = external.iter().any(|v| *v != 0.0);
        self.contact_cycles = if touching {
            self.contact_cycles.saturating_add(1)
        } else {
            0
        };
        self.external = external;
        self.joint_torques = contact_torques(jacobian, &external);
        let e = self.noise.sample();
        self.tcp_force = std::array::from_fn(|i| external[i] + e[i] - self.zero[i]);
        // Raw: the contact moved to the flange, plus the payload's weight, in the flange frame.
        let f = Vector3::new(external[0], external[1], external[2]);
        let arm = base_T_tcp.translation.vector - base_T_flange.translation.vector;
        let m = Vector3::new(external[3], external[4], external[5]) + arm.cross(&f);
        let to_flange = base_T_flange.rotation.inverse();
        let weight = to_flange * Vector3::from(*payload_weight);
        let cog = Vector3::new(payload_cog[0], payload_cog[1], payload_cog[2]);
        let (f, m) = (to_flange * f + weight, to_flange * m + cog.cross(&weight));
        self.raw = [
            f.x + e[0],
            f.y + e[1],
            f.z + e[2],
            m.x + e[3],
            m.y + e[4],
            m.z + e[5],
        ];
    }

    /// Whether the tool touches something against `direction` (a TCP direction of motion, base
    /// frame; all zeros: any direction) with more than [`CONTACT_DETECTION_FORCE`].
    pub fn touches(&self, direction: &[f64; 3]) -> bool {
        let f = Vector3::new(self.external[0], self.external[1], self.external[2]);
        let d = Vector3::new(direction[0], direction[1], direction[2]);
        match Unit::try_new(d, 1e-12) {
            Some(d) => -f.dot(&d) > CONTACT_DETECTION_FORCE,
            None => f.norm() > CONTACT_DETECTION_FORCE,
        }
    }
}
