//! The joint torques and motor currents the virtual arm reports: the torque each joint needs to
//! hold its links and the payload against gravity, from the robot description's link inertials,
//! and the current a motor draws for it through a per-joint torque constant.
//!
//! The rigid-body model behind PolyScope 5.23's dynamics functions (`get_mass_matrix`,
//! `get_coriolis_and_centrifugal_torques`, `get_jacobian`, `get_jacobian_time_derivative`):
//! recursive Newton–Euler over the links' masses, centres of mass and inertias, and the
//! geometric Jacobian of the TCP.
//!
//! Model limits, stated: the reported joint torques and currents are gravity only (no inertial,
//! Coriolis or friction torques: the kinematic arm tracks its trajectory perfectly, so at rest,
//! where these figures are read, they are zero anyway); rigid links without motor rotor inertia
//! or friction; the torque constants are modelled values, not Universal Robots data (see
//! [`MODEL_PEAK_CURRENT`]).

use super::registers::Payload;
use crate::description::{DescriptionError, RobotDescription};
use crate::kinematics::{Joints, UrDh};
use crate::ur_arm::{BASE_LINK, FLANGE_LINK};
use nalgebra::{Isometry3, Matrix3, Matrix6, Point3, UnitQuaternion, Vector3};

/// Gravity (m/s²) along −z of the base frame: URScript's default gravity vector
/// (`set_gravity([0, 0, 9.82])`).
pub const GRAVITY: f64 = 9.82;

/// URScript's default `set_gravity([0, 0, 9.82])`: the vector opposite to gravity in the base
/// frame (m/s²).
pub const UP: [f64; 3] = [0.0, 0.0, GRAVITY];

/// The modelled motor current (A) at which a joint delivers its rated torque (the URDF joint's
/// `effort`): the torque constants are `effort / MODEL_PEAK_CURRENT`, 10 N·m/A for a UR5e's
/// 150 N·m joints and 1.87 N·m/A for its 28 N·m wrists. A modelled value, not UR data.
pub const MODEL_PEAK_CURRENT: f64 = 15.0;

/// One link's mass and centre of mass.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkInertial {
    /// Mass (kg).
    pub mass: f64,
    /// Centre of mass in the link's joint frame: DH frame i−1 turned by q_i about its z axis
    /// (for link i, the child of joint i; frame 0 is the base). For UR descriptions this is the
    /// URDF link frame itself.
    pub com: Vector3<f64>,
    /// Inertia tensor (kg m²) about the centre of mass, in the link's joint frame.
    pub inertia: Matrix3<f64>,
}

/// Gravity model of a UR arm: the six moving links' inertials and the joints' torque constants.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmDynamics {
    /// Links 1–6 (shoulder to wrist 3), the child of each joint.
    pub links: [LinkInertial; 6],
    /// Joint torque per motor ampere (N·m/A), joint 1 first.
    pub torque_constants: Joints,
}

impl ArmDynamics {
    /// The UR5e of `scenarios/robots/ur5e.urdf`: masses from UR's published table, centres of
    /// mass and inertias of its link geometry, torque constants from its joint efforts (150, 150, 150, 28, 28,
    /// 28 N·m) and [`MODEL_PEAK_CURRENT`]. `robots/tests/virtual_ur_dynamics.rs` checks this table
    /// against the URDF.
    pub fn ur5e() -> ArmDynamics {
        let link = |mass, x, y, z, [ixx, iyy, izz]: [f64; 3]| LinkInertial {
            mass,
            com: Vector3::new(x, y, z),
            inertia: Matrix3::from_diagonal(&Vector3::new(ixx, iyy, izz)),
        };
        let big = 150.0 / MODEL_PEAK_CURRENT;
        let small = 28.0 / MODEL_PEAK_CURRENT;
        ArmDynamics {
            links: [
                link(3.761, 0.0, 0.0, 0.12, [0.0095279, 0.0095279, 0.0067698]),
                link(8.058, -0.2125, 0.0, 0.138, [0.011749, 0.12716, 0.12716]),
                link(2.846, -0.1961, 0.0, 0.01, [0.0022768, 0.03762, 0.03762]),
                link(1.37, 0.0, 0.0, 0.1233, [0.0023376, 0.0013871, 0.0023376]),
                link(1.3, 0.0, 0.0, 0.0897, [0.0022181, 0.0013162, 0.0022181]),
                link(
                    0.365,
                    0.0,
                    0.0,
                    0.0746,
                    [0.00026082, 0.00026082, 0.00036956],
                ),
            ],
            torque_constants: [big, big, big, small, small, small],
        }
    }

    /// The built-in model for an arm with these DH lengths: the UR5e's, or none.
    pub fn for_dh(dh: &UrDh) -> Option<ArmDynamics> {
        (*dh == UrDh::ur5e()).then(ArmDynamics::ur5e)
    }

    /// Reads the model from a UR robot description (chain `base` → `tool0`, as
    /// [`crate::ur_arm::UrArm`]): each moving link's `<inertial>` mass and origin, and each
    /// joint's `effort` over [`MODEL_PEAK_CURRENT`]. `dh` must be the arm's derived DH lengths
    /// (`UrArm::from_description(..).kinematics.dh`). `None` when a link carries no inertial or a
    /// joint no positive effort.
    pub fn from_description(
        description: &RobotDescription,
        dh: &UrDh,
    ) -> Result<Option<ArmDynamics>, DescriptionError> {
        let chain = description.chain(BASE_LINK, FLANGE_LINK)?;
        let zero = [0.0; 6];
        let poses = chain.link_poses(&zero)?;
        if poses.len() != 6 || chain.limits().len() != 6 {
            return Ok(None);
        }
        let joint_frames = joint_frames(dh, &zero);
        let mut links = [LinkInertial {
            mass: 0.0,
            com: Vector3::zeros(),
            inertia: Matrix3::zeros(),
        }; 6];
        let mut torque_constants = [0.0; 6];
        for (i, (name, pose)) in poses.iter().enumerate() {
            let Some(link) = description.link(name) else {
                return Ok(None);
            };
            let inertial = &link.inertial;
            let mass = inertial.mass.value;
            if !(mass.is_finite() && mass > 0.0) {
                return Ok(None);
            }
            let [x, y, z] = inertial.origin.xyz.0;
            let com_base = pose * Point3::new(x, y, z);
            let com = joint_frames[i].inverse_transform_point(&com_base).coords;
            let [roll, pitch, yaw] = inertial.origin.rpy.0;
            let inertial_frame = UnitQuaternion::from_euler_angles(roll, pitch, yaw);
            let to_joint = (joint_frames[i].rotation.inverse() * pose.rotation * inertial_frame)
                .to_rotation_matrix()
                .into_inner();
            let t = &inertial.inertia;
            let tensor = Matrix3::new(
                t.ixx, t.ixy, t.ixz, t.ixy, t.iyy, t.iyz, t.ixz, t.iyz, t.izz,
            );
            let inertia = to_joint * tensor * to_joint.transpose();
            links[i] = LinkInertial { mass, com, inertia };
            let effort = chain.limits()[i].effort;
            if !(effort.is_finite() && effort > 0.0) {
                return Ok(None);
            }
            torque_constants[i] = effort / MODEL_PEAK_CURRENT;
        }
        Ok(Some(ArmDynamics {
            links,
            torque_constants,
        }))
    }

    /// The torque (N·m) each joint applies to hold the arm and `payload` still at `q` against
    /// gravity: `τ = ∂V/∂q` with `V = Σ m g z`, positive about the joint's axis (the sign of
    /// `M(q) q̈ + C(q, q̇) q̇ + g(q) = τ`).
    pub fn gravity_torques(&self, dh: &UrDh, q: &Joints, payload: &Payload) -> Joints {
        let frames = joint_frames(dh, q);
        let flange = dh.forward(q);
        // Every mass point in the base frame, with the first joint that moves it.
        let mut masses: Vec<(usize, f64, Vector3<f64>)> = self
            .links
            .iter()
            .enumerate()
            .map(|(i, l)| (i, l.mass, (frames[i] * Point3::from(l.com)).coords))
            .collect();
        if payload.mass > 0.0 {
            let cog = Point3::from(Vector3::from(payload.cog));
            masses.push((5, payload.mass, (flange * cog).coords));
        }
        std::array::from_fn(|j| {
            let axis = frames[j].rotation * Vector3::z();
            let origin = frames[j].translation.vector;
            masses
                .iter()
                .filter(|(link, _, _)| *link >= j)
                .map(|(_, m, c)| m * GRAVITY * axis.cross(&(c - origin)).z)
                .sum()
        })
    }

    /// The torques (N·m) that hold the arm and `payload` still at `q` when `up` is the vector
    /// URScript's `set_gravity(up)` set (m/s², pointing away from the earth; [`UP`] by default):
    /// [`ArmDynamics::gravity_torques`] for the default, Newton–Euler for any other.
    pub fn holding_torques(
        &self,
        dh: &UrDh,
        q: &Joints,
        payload: &Payload,
        up: &[f64; 3],
    ) -> Joints {
        if *up == UP {
            return self.gravity_torques(dh, q, payload);
        }
        let zero = [0.0; 6];
        self.inverse_dynamics(dh, q, &zero, &zero, payload, &-Vector3::from(*up))
    }

    /// The motor current (A) for each joint torque: `τ / k`.
    pub fn currents(&self, torques: &Joints) -> Joints {
        std::array::from_fn(|i| torques[i] / self.torque_constants[i])
    }

    /// The joint torques (N·m) of `τ = M(q) q̈ + C(q, q̇) q̇ + g(q)` by recursive Newton–Euler,
    /// with the payload on the flange and `gravity` the acceleration of gravity in the base
    /// frame (m/s², `[0, 0, −9.82]` by default).
    pub fn inverse_dynamics(
        &self,
        dh: &UrDh,
        q: &Joints,
        qd: &Joints,
        qdd: &Joints,
        payload: &Payload,
        gravity: &Vector3<f64>,
    ) -> Joints {
        let frames = joint_frames(dh, q);
        // Each link's bodies in the base frame: (mass, centre of mass, inertia about it).
        let mut bodies: [Vec<Body>; 6] = Default::default();
        for (i, l) in self.links.iter().enumerate() {
            let r = frames[i].rotation.to_rotation_matrix().into_inner();
            let c = (frames[i] * Point3::from(l.com)).coords;
            bodies[i].push((l.mass, c, r * l.inertia * r.transpose()));
        }
        if payload.mass > 0.0 {
            let flange = dh.forward(q);
            let r = flange.rotation.to_rotation_matrix().into_inner();
            let c = (flange * Point3::from(Vector3::from(payload.cog))).coords;
            let [ixx, iyy, izz, ixy, ixz, iyz] = payload.inertia;
            let tensor = Matrix3::new(ixx, ixy, ixz, ixy, iyy, iyz, ixz, iyz, izz);
            bodies[5].push((payload.mass, c, r * tensor * r.transpose()));
        }
        // Forward: each joint origin's acceleration (gravity as an upward acceleration of the
        // base), each link's angular velocity and acceleration, and the force and moment (about
        // its joint origin) that its bodies' motion takes.
        let (mut w, mut alpha, mut accel) = (Vector3::zeros(), Vector3::zeros(), -gravity);
        let mut origin = Vector3::zeros();
        let mut origins = [Vector3::zeros(); 6];
        let mut axes = [Vector3::zeros(); 6];
        let mut forces = [Vector3::zeros(); 6];
        let mut moments = [Vector3::zeros(); 6];
        for i in 0..6 {
            let p = frames[i].translation.vector;
            let z = frames[i].rotation * Vector3::z();
            let d = p - origin;
            accel += alpha.cross(&d) + w.cross(&w.cross(&d));
            alpha += z * qdd[i] + w.cross(&(z * qd[i]));
            w += z * qd[i];
            for (m, c, inertia) in &bodies[i] {
                let r = c - p;
                let a_c = accel + alpha.cross(&r) + w.cross(&w.cross(&r));
                let f = a_c * *m;
                forces[i] += f;
                moments[i] += inertia * alpha + w.cross(&(inertia * w)) + r.cross(&f);
            }
            origin = p;
            origins[i] = p;
            axes[i] = z;
        }
        // Backward: what each joint transmits to the links it carries.
        let mut torques = [0.0; 6];
        let (mut f_child, mut n_child) = (Vector3::zeros(), Vector3::zeros());
        for i in (0..6).rev() {
            let lever = if i < 5 {
                origins[i + 1] - origins[i]
            } else {
                Vector3::zeros()
            };
            let n = moments[i] + n_child + lever.cross(&f_child);
            let f = forces[i] + f_child;
            torques[i] = axes[i].dot(&n);
            (f_child, n_child) = (f, n);
        }
        torques
    }

    /// The joint-space mass matrix `M(q)` (kg m²) of the arm with `payload`, symmetric and
    /// positive definite.
    pub fn mass_matrix(&self, dh: &UrDh, q: &Joints, payload: &Payload) -> Matrix6<f64> {
        let zero = [0.0; 6];
        let mut m = Matrix6::zeros();
        for j in 0..6 {
            let mut unit = [0.0; 6];
            unit[j] = 1.0;
            let column = self.inverse_dynamics(dh, q, &zero, &unit, payload, &Vector3::zeros());
            for (i, v) in column.iter().enumerate() {
                m[(i, j)] = *v;
            }
        }
        m
    }

    /// The Coriolis and centrifugal torques `C(q, q̇) q̇` (N·m).
    pub fn coriolis_and_centrifugal(
        &self,
        dh: &UrDh,
        q: &Joints,
        qd: &Joints,
        payload: &Payload,
    ) -> Joints {
        self.inverse_dynamics(dh, q, qd, &[0.0; 6], payload, &Vector3::zeros())
    }
}

/// The geometric Jacobian of the TCP (`tcp`: its pose in the flange frame) at `q`, in the base frame:
/// rows 0–2 map joint speeds to the TCP's linear velocity (m/s), rows 3–5 to its angular
/// velocity (rad/s), as URScript's `get_jacobian()`.
pub fn jacobian(dh: &UrDh, q: &Joints, tcp: &Isometry3<f64>) -> Matrix6<f64> {
    let frames = joint_frames(dh, q);
    let tcp = (dh.forward(q) * tcp).translation.vector;
    let mut j = Matrix6::zeros();
    for (i, f) in frames.iter().enumerate() {
        let z = f.rotation * Vector3::z();
        let v = z.cross(&(tcp - f.translation.vector));
        j.fixed_view_mut::<3, 1>(0, i).copy_from(&v);
        j.fixed_view_mut::<3, 1>(3, i).copy_from(&z);
    }
    j
}

/// The time derivative `J̇(q, q̇)` of [`jacobian`] while the joints move at `qd`
/// (`get_jacobian_time_derivative()`).
pub fn jacobian_time_derivative(
    dh: &UrDh,
    q: &Joints,
    qd: &Joints,
    tcp: &Isometry3<f64>,
) -> Matrix6<f64> {
    let frames = joint_frames(dh, q);
    let tcp = (dh.forward(q) * tcp).translation.vector;
    let axes: [Vector3<f64>; 6] = std::array::from_fn(|i| frames[i].rotation * Vector3::z());
    let origins: [Vector3<f64>; 6] = std::array::from_fn(|i| frames[i].translation.vector);
    // The velocity of a point `p` fixed on link `i` (moved by joints 0..=i).
    let velocity = |p: &Vector3<f64>, upto: usize| -> Vector3<f64> {
        (0..upto)
            .map(|k| axes[k].cross(&(p - origins[k])) * qd[k])
            .sum()
    };
    let tcp_velocity = velocity(&tcp, 6);
    let mut w = Vector3::zeros();
    let mut out = Matrix6::zeros();
    for i in 0..6 {
        // Joint i's axis and origin move with link i−1.
        let z_dot = w.cross(&axes[i]);
        let p_dot = velocity(&origins[i], i);
        let v = z_dot.cross(&(tcp - origins[i])) + axes[i].cross(&(tcp_velocity - p_dot));
        out.fixed_view_mut::<3, 1>(0, i).copy_from(&v);
        out.fixed_view_mut::<3, 1>(3, i).copy_from(&z_dot);
        w += axes[i] * qd[i];
    }
    out
}

/// A rigid body in the base frame: mass (kg), centre of mass (m), inertia about it (kg m²).
type Body = (f64, Vector3<f64>, Matrix3<f64>);

/// Each joint's frame at `q`: DH frame i−1 (the base for joint 1) turned by q_i about its z.
fn joint_frames(dh: &UrDh, q: &Joints) -> [Isometry3<f64>; 6] {
    let dh_frames = dh.frames(q);
    std::array::from_fn(|i| {
        let before = if i == 0 {
            Isometry3::identity()
        } else {
            dh_frames[i - 1]
        };
        before * Isometry3::rotation(Vector3::z() * q[i])
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector6;
    use std::f64::consts::FRAC_PI_2;

    #[test]
    fn a_vertical_arm_needs_no_shoulder_torque_and_a_horizontal_one_does() {
        let d = ArmDynamics::ur5e();
        let dh = UrDh::ur5e();
        // Straight up: q2 = −π/2, q3 = 0 (the upper arm and forearm along +z).
        let up = [0.0, -FRAC_PI_2, 0.0, -FRAC_PI_2, 0.0, 0.0];
        let t = d.gravity_torques(&dh, &up, &Payload::default());
        assert!(t[0].abs() < 1e-12, "{t:?}");
        assert!(t[1].abs() < 0.5, "shoulder nearly unloaded upright: {t:?}");
        // Stretched out horizontally: the shoulder carries every link's moment.
        let flat = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let t = d.gravity_torques(&dh, &flat, &Payload::default());
        assert!(t[1].abs() > 40.0, "{t:?}");
        // A payload at the flange adds m g times its horizontal reach to the shoulder.
        let kg = Payload {
            mass: 1.0,
            ..Payload::default()
        };
        let with = d.gravity_torques(&dh, &flat, &kg);
        let reach = dh.forward(&flat).translation.vector.x.abs();
        assert!(((with[1] - t[1]).abs() - GRAVITY * reach).abs() < 1e-9);
        // Joint 1 (vertical axis) never holds gravity.
        assert!(with[0].abs() < 1e-12);
    }

    const POSES: [Joints; 3] = [
        [0.3, -1.4, 1.5, -1.7, -1.4, 0.2],
        [-0.7, -0.9, 2.1, 0.4, 1.1, -2.3],
        [1.9, -2.2, -1.3, -0.6, 0.35, 0.8],
    ];
    const SPEEDS: Joints = [0.4, -0.7, 0.9, 1.3, -1.1, 0.6];

    fn loaded() -> Payload {
        Payload {
            mass: 1.2,
            cog: [0.01, -0.02, 0.06],
            inertia: [0.003, 0.004, 0.002, 0.0004, -0.0002, 0.0003],
        }
    }

    fn tcp() -> Isometry3<f64> {
        Isometry3::new(Vector3::new(0.01, 0.02, 0.15), Vector3::new(0.1, -0.2, 0.3))
    }

    /// `q + t v`.
    fn along(q: &Joints, v: &Joints, t: f64) -> Joints {
        std::array::from_fn(|i| q[i] + t * v[i])
    }

    #[test]
    fn newton_euler_at_rest_is_the_gravity_model_in_any_direction() {
        let (d, dh) = (ArmDynamics::ur5e(), UrDh::ur5e());
        let down = Vector3::new(0.0, 0.0, -GRAVITY);
        for q in &POSES {
            for payload in [Payload::default(), loaded()] {
                let zero = [0.0; 6];
                let rnea = d.inverse_dynamics(&dh, q, &zero, &zero, &payload, &down);
                let g = d.gravity_torques(&dh, q, &payload);
                for i in 0..6 {
                    assert!((rnea[i] - g[i]).abs() < 1e-9, "{rnea:?} vs {g:?}");
                }
            }
        }
        // Gravity along +x: the potential m g·c differentiated by finite differences.
        let sideways = Vector3::new(GRAVITY, 0.0, 0.0);
        let q = POSES[1];
        let zero = [0.0; 6];
        let rnea = d.inverse_dynamics(&dh, &q, &zero, &zero, &loaded(), &sideways);
        let potential = |q: &Joints| -> f64 {
            let frames = joint_frames(&dh, q);
            let links: f64 = (0..6)
                .map(|i| {
                    let c = frames[i] * Point3::from(d.links[i].com);
                    -d.links[i].mass * sideways.dot(&c.coords)
                })
                .sum();
            let p = dh.forward(q) * Point3::from(Vector3::from(loaded().cog));
            links - loaded().mass * sideways.dot(&p.coords)
        };
        for j in 0..6 {
            let mut e = [0.0; 6];
            e[j] = 1.0;
            let h = 1e-6;
            let fd = (potential(&along(&q, &e, h)) - potential(&along(&q, &e, -h))) / (2.0 * h);
            assert!(
                (rnea[j] - fd).abs() < 1e-6,
                "joint {j}: {} vs {fd}",
                rnea[j]
            );
        }
    }

    /// Kinetic energy by brute force: each body's centre-of-mass velocity and angular velocity
    /// from finite differences of its pose along `qd`.
    fn kinetic_energy(d: &ArmDynamics, dh: &UrDh, q: &Joints, qd: &Joints, p: &Payload) -> f64 {
        let h = 1e-6;
        let poses = |q: &Joints| -> Vec<Isometry3<f64>> {
            let mut v: Vec<Isometry3<f64>> = joint_frames(dh, q).to_vec();
            v.push(dh.forward(q));
            v
        };
        let (a, b) = (poses(&along(q, qd, -h)), poses(&along(q, qd, h)));
        let mut bodies: Vec<(usize, f64, Vector3<f64>, Matrix3<f64>)> = (0..6)
            .map(|i| (i, d.links[i].mass, d.links[i].com, d.links[i].inertia))
            .collect();
        let [ixx, iyy, izz, ixy, ixz, iyz] = p.inertia;
        bodies.push((
            6,
            p.mass,
            Vector3::from(p.cog),
            Matrix3::new(ixx, ixy, ixz, ixy, iyy, iyz, ixz, iyz, izz),
        ));
        bodies
            .iter()
            .map(|(k, m, com, inertia)| {
                let v = ((b[*k] * Point3::from(*com)) - (a[*k] * Point3::from(*com))) / (2.0 * h);
                // Angular velocity in the body frame.
                let w = (a[*k].rotation.inverse() * b[*k].rotation).scaled_axis() / (2.0 * h);
                0.5 * m * v.norm_squared() + 0.5 * w.dot(&(inertia * w))
            })
            .sum()
    }

    #[test]
    fn the_mass_matrix_is_the_kinetic_energy_and_coriolis_follows_from_it() {
        let (d, dh) = (ArmDynamics::ur5e(), UrDh::ur5e());
        for q in &POSES {
            for payload in [Payload::default(), loaded()] {
                let m = d.mass_matrix(&dh, q, &payload);
                assert!((m - m.transpose()).abs().max() < 1e-12, "{m}");
                let eigen = m.symmetric_eigenvalues();
                assert!(eigen.min() > 0.0, "not positive definite: {eigen}");
                let qd = Vector6::from(SPEEDS);
                let t = 0.5 * qd.dot(&(m * qd));
                let brute = kinetic_energy(&d, &dh, q, &SPEEDS, &payload);
                assert!((t - brute).abs() < 1e-6 * brute.max(1.0), "{t} vs {brute}");
                // c_i = Σ_jk (∂M_ij/∂q_k − ½ ∂M_jk/∂q_i) q̇_j q̇_k, ∂M by central differences.
                let h = 1e-6;
                let dm: Vec<Matrix6<f64>> = (0..6)
                    .map(|k| {
                        let mut e = [0.0; 6];
                        e[k] = 1.0;
                        (d.mass_matrix(&dh, &along(q, &e, h), &payload)
                            - d.mass_matrix(&dh, &along(q, &e, -h), &payload))
                            / (2.0 * h)
                    })
                    .collect();
                let c = d.coriolis_and_centrifugal(&dh, q, &SPEEDS, &payload);
                for i in 0..6 {
                    let mut want = 0.0;
                    for j in 0..6 {
                        for k in 0..6 {
                            want += (dm[k][(i, j)] - 0.5 * dm[i][(j, k)]) * qd[j] * qd[k];
                        }
                    }
                    assert!((c[i] - want).abs() < 1e-6, "joint {i}: {} vs {want}", c[i]);
                }
            }
        }
    }

    #[test]
    fn the_jacobian_and_its_derivative_match_finite_differences() {
        let dh = UrDh::ur5e();
        let tcp = tcp();
        let h = 1e-6;
        for q in &POSES {
            let j = jacobian(&dh, q, &tcp);
            let pose = |q: &Joints| dh.forward(q) * tcp;
            for k in 0..6 {
                let mut e = [0.0; 6];
                e[k] = 1.0;
                let (a, b) = (pose(&along(q, &e, -h)), pose(&along(q, &e, h)));
                let v = (b.translation.vector - a.translation.vector) / (2.0 * h);
                let w = (b.rotation * a.rotation.inverse()).scaled_axis() / (2.0 * h);
                for r in 0..3 {
                    assert!((j[(r, k)] - v[r]).abs() < 1e-7, "{j} column {k}: {v}");
                    assert!((j[(r + 3, k)] - w[r]).abs() < 1e-7, "{j} column {k}: {w}");
                }
            }
            let jd = jacobian_time_derivative(&dh, q, &SPEEDS, &tcp);
            let fd = (jacobian(&dh, &along(q, &SPEEDS, h), &tcp)
                - jacobian(&dh, &along(q, &SPEEDS, -h), &tcp))
                / (2.0 * h);
            assert!((jd - fd).abs().max() < 1e-6, "{jd} vs {fd}");
        }
    }

    #[test]
    fn inverse_dynamics_is_mass_matrix_coriolis_and_gravity() {
        let (d, dh) = (ArmDynamics::ur5e(), UrDh::ur5e());
        let down = Vector3::new(0.0, 0.0, -GRAVITY);
        let qdd = [1.0, -0.5, 0.3, 2.0, -1.5, 0.7];
        for q in &POSES {
            let p = loaded();
            let tau = d.inverse_dynamics(&dh, q, &SPEEDS, &qdd, &p, &down);
            let m = d.mass_matrix(&dh, q, &p) * Vector6::from(qdd);
            let c = d.coriolis_and_centrifugal(&dh, q, &SPEEDS, &p);
            let g = d.gravity_torques(&dh, q, &p);
            for i in 0..6 {
                assert!((tau[i] - (m[i] + c[i] + g[i])).abs() < 1e-9);
            }
        }
    }
}
