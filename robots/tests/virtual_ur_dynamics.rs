//! The virtual controller's gravity model against the robot descriptions it comes from: the
//! built-in UR5e table equals `scenarios/robots/ur5e.urdf`, and its joint torques equal a
//! direct computation over the URDF chain (link poses, joint axes, `<inertial>` masses and
//! origins) for random joints and payloads, for every shipped UR description.

use nalgebra::{Point3, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use robots::description::RobotDescription;
use robots::kinematics::Joints;
use robots::ur_arm::UrArm;
use robots::virtual_ur::dynamics::{ArmDynamics, GRAVITY, MODEL_PEAK_CURRENT};
use robots::virtual_ur::registers::Payload;
use std::path::PathBuf;

fn urdf(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(format!("../scenarios/robots/{name}.urdf"))
}

/// Gravity torques straight from the URDF chain `base` → `tool0`: each joint holds
/// `Σ m g (axis × (c − p))_z` of the links (and payload) it carries.
fn urdf_gravity(description: &RobotDescription, q: &Joints, payload: &Payload) -> Joints {
    let chain = description.chain("base", "tool0").unwrap();
    let axes = chain.joint_axes(q).unwrap();
    let mut masses: Vec<(usize, f64, Vector3<f64>)> = chain
        .link_poses(q)
        .unwrap()
        .iter()
        .enumerate()
        .map(|(i, (name, pose))| {
            let inertial = &description.link(name).unwrap().inertial;
            let [x, y, z] = inertial.origin.xyz.0;
            (i, inertial.mass.value, (pose * Point3::new(x, y, z)).coords)
        })
        .collect();
    let flange = chain.forward(q).unwrap();
    let [x, y, z] = payload.cog;
    masses.push((5, payload.mass, (flange * Point3::new(x, y, z)).coords));
    std::array::from_fn(|j| {
        let (p, axis) = axes[j];
        masses
            .iter()
            .filter(|(link, _, _)| *link >= j)
            .map(|(_, m, c)| m * GRAVITY * axis.cross(&(c - p.coords)).z)
            .sum()
    })
}

#[test]
fn the_built_in_ur5e_table_is_the_ur5e_urdf() {
    let description = RobotDescription::from_file(urdf("ur5e")).unwrap();
    let arm = UrArm::from_description(&description).unwrap();
    let read = ArmDynamics::from_description(&description, &arm.kinematics.dh)
        .unwrap()
        .expect("the UR5e URDF carries inertials and efforts");
    let table = ArmDynamics::ur5e();
    for (a, b) in read.links.iter().zip(&table.links) {
        assert!((a.mass - b.mass).abs() < 1e-12, "{a:?} vs {b:?}");
        assert!((a.com - b.com).norm() < 1e-9, "{a:?} vs {b:?}");
        assert!((a.inertia - b.inertia).abs().max() < 1e-9, "{a:?} vs {b:?}");
    }
    for (a, b) in read.torque_constants.iter().zip(&table.torque_constants) {
        assert!((a - b).abs() < 1e-12);
    }
    assert_eq!(table.torque_constants[1], 150.0 / MODEL_PEAK_CURRENT);
    assert_eq!(
        ArmDynamics::for_dh(&arm.kinematics.dh),
        Some(table),
        "the UR5e's DH lengths select the table"
    );
}

#[test]
fn gravity_torques_equal_the_urdf_chain_for_every_shipped_arm() {
    let mut rng = ChaCha8Rng::seed_from_u64(43);
    for name in ["ur3e", "ur5e", "ur10e", "ur16e", "ur20"] {
        let description = RobotDescription::from_file(urdf(name)).unwrap();
        let arm = UrArm::from_description(&description).unwrap();
        let dh = arm.kinematics.dh;
        let dynamics = ArmDynamics::from_description(&description, &dh)
            .unwrap()
            .unwrap_or_else(|| panic!("{name} carries inertials"));
        for _ in 0..50 {
            let q: Joints = std::array::from_fn(|_| rng.random_range(-3.0..3.0));
            let payload = Payload {
                mass: rng.random_range(0.0..5.0),
                cog: std::array::from_fn(|_| rng.random_range(-0.1..0.1)),
                ..Payload::default()
            };
            let got = dynamics.gravity_torques(&dh, &q, &payload);
            let want = urdf_gravity(&description, &q, &payload);
            for (g, w) in got.iter().zip(&want) {
                assert!((g - w).abs() < 1e-9, "{name} at {q:?}: {got:?} vs {want:?}");
            }
            let currents = dynamics.currents(&got);
            for i in 0..6 {
                assert!((currents[i] * dynamics.torque_constants[i] - got[i]).abs() < 1e-9);
            }
        }
    }
}
