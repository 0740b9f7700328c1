//! The wrist's force/torque sensor in the simulated cell: what the UR's flange sensor reads, in
//! the tool (TCP) frame about the TCP, force (N) then moment (N·m).
//!
//! - **Gravity.** The gripper and the part it holds hang on the sensor: their weight `m·g`
//!   (g = [`robots::virtual_ur::dynamics::GRAVITY`], URScript's) at their centres of mass. The
//!   part's mass is the catalog's ([`super::geometry::PartGeometry::mass`]) at its frame origin
//!   (the bounding-box centre); the gripper's is [`Load::gripper`] (the scenario's gripper has no
//!   inertial of its own; see there).
//! - **Contact.** During an insertion the compliant wrist's springs carry the part
//!   ([`super::insertion::Wrist::spring_wrench`], recorded by both contact engines every 2 ms):
//!   their load on the wrist is the contact wrench the sensor sees, moved from the compliance
//!   centre to the TCP.
//! - **The sensor.** Bias and white noise of the UR5e's datasheet precision (±4 N, ±0.3 N·m),
//!   seeded ([`robots::virtual_ur::force::FtNoise`]), and zeroing (`zero_ftsensor`) as on the
//!   arm: the reading less the true wrench and bias at the moment it was zeroed.
//!
//! Sign convention: the wrench is what the world (gravity, the parts) applies to the tool, so a
//! part held under a tool pointing down reads `+m·g` along the tool's z, and a part pushed into a
//! jam reads the push force against the insertion direction.

use nalgebra::{Isometry3, Point3, Vector3};
use robots::virtual_ur::dynamics::GRAVITY;
use robots::virtual_ur::force::FtNoise;

use super::insertion::contact::WristWrench;

/// A wrench as six numbers: force (N), then moment (N·m).
pub type Wrench = [f64; 6];

/// A mass hanging on the sensor: its mass and centre of mass in the tool (TCP) frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Load {
    /// Mass, kg.
    pub mass: f64,
    /// Centre of mass in the tool frame, metres.
    pub com: Point3<f64>,
}

/// The modelled gripper's mass, kg: a small electric parallel gripper (Robotiq's Hand-E, for one,
/// is 1.0 kg). A modelled value: the scenario's gripper carries no mass.
pub const GRIPPER_MASS: f64 = 1.0;

/// Where the modelled gripper's centre of mass lies between the flange (0) and the fingertip TCP
/// (1): the body sits near the flange, the fingers are light. A modelled value.
pub const GRIPPER_COM_FRACTION: f64 = 0.4;

/// Axial stiffness of a held part pressed onto what stops it (fingers, part and receiver in
/// series), N/m: a guarded move at 10 N stops 0.05 mm past first contact. A modelled value.
pub const HELD_CONTACT_STIFFNESS: f64 = 2e5;

/// Axial force at which a held part slips up the fingers, N (grip force times friction on both
/// fingers): a position-controlled push never loads the wrist beyond it. A modelled value.
pub const GRIP_SLIP_FORCE: f64 = 30.0;

impl Load {
    /// The gripper of a tool whose TCP is at `flange_T_tcp`: [`GRIPPER_MASS`] at
    /// [`GRIPPER_COM_FRACTION`] of the way from the flange to the TCP.
    #[allow(non_snake_case)]
    pub fn gripper(flange_T_tcp: &Isometry3<f64>) -> Load {
        let com_flange = Point3::from(flange_T_tcp.translation.vector * GRIPPER_COM_FRACTION);
        Load {
            mass: GRIPPER_MASS,
            com: flange_T_tcp.inverse_transform_point(&com_flange),
        }
    }

    /// A held part of `mass` kg whose frame (its centre) is at `tcp_T_part`.
    #[allow(non_snake_case)]
    pub fn part(mass: f64, tcp_T_part: &Isometry3<f64>) -> Load {
        Load {
            mass,
            com: Point3::from(tcp_T_part.translation.vector),
        }
    }
}

/// The weight of `loads` on the tool at `base_T_tcp` (base z up), in the tool frame about the TCP.
#[allow(non_snake_case)]
pub fn gravity_wrench(base_T_tcp: &Isometry3<f64>, loads: &[Load]) -> Wrench {
    let down = base_T_tcp.rotation.inverse() * Vector3::new(0.0, 0.0, -GRAVITY);
    let (mut f, mut m) = (Vector3::zeros(), Vector3::zeros());
    for l in loads {
        let weight = down * l.mass;
        f += weight;
        m += l.com.coords.cross(&weight);
    }
    [f.x, f.y, f.z, m.x, m.y, m.z]
}

/// A wrist load recorded in the insertion frame (`w`, about the compliance centre `centre`, a
/// point of the wrist frame) as the tool-frame wrench about the TCP, with the wrist at `ins_T_wrist`
/// and the TCP at `wrist_T_tcp` from it (the commanded part pose and the held part's
/// `tcp_T_part` inverted).
#[allow(non_snake_case)]
pub fn contact_wrench(
    w: &WristWrench,
    ins_T_wrist: &Isometry3<f64>,
    wrist_T_tcp: &Isometry3<f64>,
    centre: &Point3<f64>,
) -> Wrench {
    let ins_T_tcp = ins_T_wrist * wrist_T_tcp;
    let arm = ins_T_wrist * centre - ins_T_tcp.translation.vector;
    let moment = w.moment + arm.coords.cross(&w.force);
    let to_tool = ins_T_tcp.rotation.inverse();
    let (f, m) = (to_tool * w.force, to_tool * moment);
    [f.x, f.y, f.z, m.x, m.y, m.z]
}

/// The flange sensor: its reading error and its zero.
#[derive(Debug, Clone)]
pub struct WristSensor {
    noise: FtNoise,
    zero: Wrench,
}

impl WristSensor {
    /// A UR5e's sensor, seeded (the same seed reads the same numbers).
    pub fn ur5e(seed: u64) -> WristSensor {
        WristSensor::new(FtNoise::ur5e(seed))
    }

    /// A sensor with this reading error.
    pub fn new(noise: FtNoise) -> WristSensor {
        WristSensor {
            noise,
            zero: [0.0; 6],
        }
    }

    /// The sensor's bias (before zeroing).
    pub fn bias(&self) -> Wrench {
        self.noise.bias
    }

    /// The standard deviation of one reading's noise, per axis.
    pub fn sigma(&self) -> Wrench {
        self.noise.sigma
    }

    /// One reading of the true wrench `truth`.
    pub fn read(&mut self, truth: &Wrench) -> Wrench {
        let e = self.noise.sample();
        std::array::from_fn(|i| truth[i] + e[i] - self.zero[i])
    }

    /// `zero_ftsensor()` while the true wrench is `truth`: later readings are relative to it (and
    /// the bias is gone).
    pub fn zero(&mut self, truth: &Wrench) {
        self.zero = std::array::from_fn(|i| truth[i] + self.noise.bias[i]);
    }
}

/// One sensor reading of an insertion: simulated time and the wrench (tool frame, about the TCP).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WrenchSample {
    /// Seconds since the insertion's simulation started.
    pub t: f64,
    /// The reading.
    pub wrench: Wrench,
}

/// The wrist's sensor on the simulated arm: the gripper's load and the sensor.
#[derive(Debug, Clone)]
pub struct WristWrenchModel {
    /// The gripper hanging on the sensor.
    pub gripper: Load,
    /// The sensor.
    pub sensor: WristSensor,
}

impl WristWrenchModel {
    /// The model of a cell whose gripper's TCP is at `flange_T_tcp`, its sensor seeded by `seed`.
    #[allow(non_snake_case)]
    pub fn new(flange_T_tcp: &Isometry3<f64>, seed: u64) -> WristWrenchModel {
        WristWrenchModel {
            gripper: Load::gripper(flange_T_tcp),
            sensor: WristSensor::ur5e(seed),
        }
    }

    /// The true wrench with the tool at `base_T_tcp`, holding `held` (if anything), pressed by
    /// `contact` (tool frame, about the TCP).
    #[allow(non_snake_case)]
    pub fn truth(
        &self,
        base_T_tcp: &Isometry3<f64>,
        held: Option<Load>,
        contact: &Wrench,
    ) -> Wrench {
        let mut loads = vec![self.gripper];
        loads.extend(held);
        let g = gravity_wrench(base_T_tcp, &loads);
        std::array::from_fn(|i| g[i] + contact[i])
    }

    /// One reading with the tool at `base_T_tcp` holding `held`, touching nothing.
    #[allow(non_snake_case)]
    pub fn read_at_rest(&mut self, base_T_tcp: &Isometry3<f64>, held: Option<Load>) -> Wrench {
        let truth = self.truth(base_T_tcp, held, &[0.0; 6]);
        self.sensor.read(&truth)
    }

    /// The readings through an insertion that one of the contact engines simulated: `trace` its
    /// recorded wrist loads, `base_T_ins` the insertion frame, `start_pose` the wrist's start
    /// (the part's start pose in the insertion frame, [`super::insertion::Wrist::start_pose`]),
    /// `wrist` the wrist it descended with, `tcp_T_part` the grasp, `held` the part's load,
    /// `centre` the compliance centre in the part frame (`Mating::lead_point`).
    #[allow(non_snake_case, clippy::too_many_arguments)]
    pub fn insertion_readings(
        &mut self,
        trace: &[WristWrench],
        base_T_ins: &Isometry3<f64>,
        start_pose: &Isometry3<f64>,
        wrist: &super::insertion::Wrist,
        tcp_T_part: &Isometry3<f64>,
        held: Load,
        centre: &Point3<f64>,
    ) -> Vec<WrenchSample> {
        let wrist_T_tcp = tcp_T_part.inverse();
        trace
            .iter()
            .map(|w| {
                let ins_T_wrist = wrist.pose_at(start_pose, w.t);
                let contact = contact_wrench(w, &ins_T_wrist, &wrist_T_tcp, centre);
                let base_T_tcp = base_T_ins * ins_T_wrist * wrist_T_tcp;
                let truth = self.truth(&base_T_tcp, Some(held), &contact);
                WrenchSample {
                    t: w.t,
                    wrench: self.sensor.read(&truth),
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::UnitQuaternion;
    use std::f64::consts::PI;

    /// The tool pointing straight down (tool z = base −z) at 0.4 m out, 0.2 m up.
    fn down() -> Isometry3<f64> {
        Isometry3::from_parts(
            nalgebra::Translation3::new(0.4, 0.0, 0.2),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), PI),
        )
    }

    #[test]
    fn a_part_held_still_reads_its_weight_along_the_tool_axis_within_the_sensor_precision() {
        let flange_T_tcp = Isometry3::translation(0.0, 0.0, 0.15);
        let mut model = WristWrenchModel::new(&flange_T_tcp, 11);
        let part = Load::part(0.25, &Isometry3::translation(0.0, 0.0, 0.01));
        let n = 2_000;
        let mut mean = [0.0; 6];
        for _ in 0..n {
            let r = model.read_at_rest(&down(), Some(part));
            for i in 0..6 {
                mean[i] += r[i] / n as f64;
            }
            // Every reading within the datasheet precision of the truth (bias + 4.5σ).
            let weight = (GRIPPER_MASS + 0.25) * GRAVITY;
            assert!(
                (r[2] - weight).abs() < 4.0 * 1.25,
                "Fz {} against {weight}",
                r[2]
            );
        }
        let weight = (GRIPPER_MASS + 0.25) * GRAVITY;
        let bias = model.sensor.bias();
        // Averaged, the noise goes and the bias stays: m·g plus the bias within 4σ/√n.
        let tol = 4.0 * model.sensor.sigma()[2] / (n as f64).sqrt();
        assert!((mean[2] - (weight + bias[2])).abs() < tol, "{mean:?}");
        assert!((mean[0] - bias[0]).abs() < tol && (mean[1] - bias[1]).abs() < tol);
        // Centred loads under a vertical tool: no moment beyond the bias.
        let tol_m = 4.0 * model.sensor.sigma()[3] / (n as f64).sqrt();
        for i in 3..6 {
            assert!((mean[i] - bias[i]).abs() < tol_m, "moment {i}: {}", mean[i]);
        }
    }

    #[test]
    fn a_tool_held_sideways_reads_the_moment_of_its_load() {
        // Tool z horizontal (along base x): the weight acts across the tool axis, so its moment
        // about the TCP is the load's offset along the axis times its weight.
        let side = Isometry3::from_parts(
            nalgebra::Translation3::new(0.4, 0.0, 0.3),
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), PI / 2.0),
        );
        let flange_T_tcp = Isometry3::translation(0.0, 0.0, 0.15);
        let gripper = Load::gripper(&flange_T_tcp);
        assert!((gripper.com.z + 0.15 * (1.0 - GRIPPER_COM_FRACTION)).abs() < 1e-12);
        let w = gravity_wrench(&side, &[gripper]);
        let weight = GRIPPER_MASS * GRAVITY;
        let f = Vector3::new(w[0], w[1], w[2]);
        assert!((f.norm() - weight).abs() < 1e-9);
        let m = Vector3::new(w[3], w[4], w[5]);
        assert!(
            (m.norm() - weight * gripper.com.z.abs()).abs() < 1e-9,
            "{w:?}"
        );
    }

    #[test]
    fn zeroing_removes_the_load_and_the_bias() {
        let flange_T_tcp = Isometry3::translation(0.0, 0.0, 0.15);
        let mut model = WristWrenchModel::new(&flange_T_tcp, 3);
        let part = Load::part(0.1, &Isometry3::identity());
        let truth = model.truth(&down(), Some(part), &[0.0; 6]);
        model.sensor.zero(&truth);
        let n = 2_000;
        let mean_z: f64 = (0..n)
            .map(|_| model.read_at_rest(&down(), Some(part))[2])
            .sum::<f64>()
            / n as f64;
        assert!(mean_z.abs() < 4.0 * model.sensor.sigma()[2] / (n as f64).sqrt());
    }

    #[test]
    fn a_wrist_pushing_up_reads_up_in_the_tool_frame_about_the_tcp() {
        // Insertion frame = base, wrist = part frame at the origin, tool 5 cm above it pointing
        // down; the compliance centre 1 cm below the part origin; the wrist pushed up by 5 N.
        let w = WristWrench {
            t: 0.0,
            force: Vector3::new(0.0, 0.0, 5.0),
            moment: Vector3::zeros(),
        };
        let wrist_T_tcp = Isometry3::from_parts(
            nalgebra::Translation3::new(0.0, 0.0, 0.05),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), PI),
        );
        let c = contact_wrench(
            &w,
            &Isometry3::identity(),
            &wrist_T_tcp,
            &Point3::new(0.0, 0.0, -0.01),
        );
        // Up is tool −z; the force passes through the TCP: no moment.
        assert!((c[2] + 5.0).abs() < 1e-12, "{c:?}");
        assert!(c[3..].iter().all(|m| m.abs() < 1e-12), "{c:?}");
        // A lateral 2 N at the centre 6 cm below the TCP has a 0.12 N·m moment about it.
        let side = WristWrench {
            force: Vector3::new(2.0, 0.0, 0.0),
            ..w
        };
        let c = contact_wrench(
            &side,
            &Isometry3::identity(),
            &wrist_T_tcp,
            &Point3::new(0.0, 0.0, -0.01),
        );
        let m = Vector3::new(c[3], c[4], c[5]).norm();
        assert!((m - 0.12).abs() < 1e-12, "{c:?}");
    }
}
