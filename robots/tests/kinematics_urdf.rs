//! The shipped UR URDFs against the DH kinematics derived from them, and the loader's errors.

#![allow(non_snake_case)]

use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use robots::description::{DescriptionError, RobotDescription};
use robots::kinematics::{Joints, UrKinematics};
use robots::ur_arm::UrArm;
use std::f64::consts::{PI, TAU};
use std::path::PathBuf;

fn ur5e_urdf() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenarios/robots/ur5e.urdf")
}

fn close(a: &Isometry3<f64>, b: &Isometry3<f64>, tol: f64) -> bool {
    (a.translation.vector - b.translation.vector).norm() < tol
        && a.rotation.angle_to(&b.rotation) < tol
}

#[test]
fn urdf_chain_equals_dh_forward_kinematics() {
    let description = RobotDescription::from_file(ur5e_urdf()).unwrap();
    assert_eq!(description.name(), "ur5e");
    let chain = description.chain("base", "tool0").unwrap();
    assert_eq!(chain.dof(), 6);
    assert_eq!(
        chain.joint_names(),
        [
            "shoulder_pan_joint",
            "shoulder_lift_joint",
            "elbow_joint",
            "wrist_1_joint",
            "wrist_2_joint",
            "wrist_3_joint"
        ]
    );
    let kin = UrKinematics::ur5e();
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    for _ in 0..5000 {
        let q: Joints = std::array::from_fn(|_| rng.random_range(-TAU..TAU));
        let urdf = chain.forward(&q).unwrap();
        let dh = kin.forward_flange(&q);
        assert!(close(&urdf, &dh, 1e-9), "{q:?}: {urdf} vs {dh}");
        // The link frames are the DH frames too: wrist_3_link sits at DH frame 5 turned by q6.
        let links = chain.link_poses(&q).unwrap();
        let frames = kin.dh.frames(&q);
        assert_eq!(links[5].0, "wrist_3_link");
        let wrist3 = frames[4]
            * Isometry3::from_parts(
                Default::default(),
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), q[5]),
            );
        assert!(close(&links[5].1, &wrist3, 1e-9));
    }
}

#[test]
fn ros_frames_follow_ur_conventions() {
    let description = RobotDescription::from_file(ur5e_urdf()).unwrap();
    let kin = UrKinematics::ur5e();
    let q = [0.3, -1.1, 1.2, -0.4, 0.9, 2.0];
    // ROS base_link is the controller base turned by π about z.
    let base_link_T_tool0 = description.chain("base_link", "tool0").unwrap();
    let turn = Isometry3::rotation(Vector3::z() * PI);
    assert!(close(
        &base_link_T_tool0.forward(&q).unwrap(),
        &(turn * kin.forward_flange(&q)),
        1e-9
    ));
    // ROS-I flange: x along the tool axis (tool0's z), y along tool0's x... i.e. flange_T_tool0
    // has rpy (π/2, 0, π/2).
    let flange = description
        .chain("base", "flange")
        .unwrap()
        .forward(&q)
        .unwrap();
    let tool0 = kin.forward_flange(&q);
    assert!(((flange.rotation * Vector3::x()) - (tool0.rotation * Vector3::z())).norm() < 1e-12);
    assert!((flange.translation.vector - tool0.translation.vector).norm() < 1e-12);
    // A fixed-only chain has no joints.
    let fixed = description.chain("base", "base_link").unwrap();
    assert_eq!(fixed.dof(), 0);
    assert!(close(&fixed.forward(&[]).unwrap(), &turn.inverse(), 1e-12));
}

#[test]
fn limits_and_collision_geometry_are_present() {
    let description = RobotDescription::from_file(ur5e_urdf()).unwrap();
    let chain = description.chain("base", "tool0").unwrap();
    let limits = chain.joint_limits6().unwrap();
    assert_eq!(limits, robots::kinematics::JointLimits::symmetric(TAU));
    for limit in chain.limits() {
        assert!((limit.velocity - PI).abs() < 1e-12);
        assert!(limit.effort >= 28.0);
    }
    for name in [
        "base_link_inertia",
        "shoulder_link",
        "upper_arm_link",
        "forearm_link",
        "wrist_1_link",
        "wrist_2_link",
        "wrist_3_link",
    ] {
        let link = description.link(name).unwrap();
        assert!(
            !link.collision.is_empty(),
            "{name} has no collision geometry"
        );
        assert!(link.inertial.mass.value > 0.3, "{name}");
    }
    let total: f64 = description
        .urdf()
        .links
        .iter()
        .map(|l| l.inertial.mass.value)
        .sum();
    // The UR5e weighs 20.6 kg: UR's six link masses plus the base.
    assert!((total - 20.6).abs() < 0.01, "total mass {total}");
}

const MINI: &str = r#"<robot name="mini">
  <link name="a"/><link name="b"/><link name="c"/><link name="island"/>
  <joint name="j1" type="revolute">
    <parent link="a"/><child link="b"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
  <joint name="j2" type="prismatic">
    <parent link="b"/><child link="c"/><origin xyz="1 0 0" rpy="0 0 0"/><axis xyz="1 0 0"/>
    <limit lower="0" upper="0.5" effort="1" velocity="1"/>
  </joint>
</robot>"#;

#[test]
fn generic_chain_handles_revolute_and_prismatic_joints() {
    let description = RobotDescription::from_urdf_str(MINI, "mini.urdf").unwrap();
    let chain = description.chain("a", "c").unwrap();
    let pose = chain.forward(&[PI / 2.0, 0.25]).unwrap();
    assert!((pose.translation.vector - Vector3::new(0.0, 1.25, 0.0)).norm() < 1e-12);
    match chain.forward(&[0.0]) {
        Err(DescriptionError::JointCount {
            expected: 2,
            got: 1,
            ..
        }) => {}
        other => panic!("{other:?}"),
    }
}

#[test]
fn loader_errors_name_the_file_and_what_is_missing() {
    let err = RobotDescription::from_file("/nonexistent/robot.urdf").unwrap_err();
    assert!(matches!(err, DescriptionError::Read { .. }));
    assert!(err.to_string().contains("/nonexistent/robot.urdf"), "{err}");

    let err = RobotDescription::from_urdf_str("<robot name=", "broken.urdf").unwrap_err();
    assert!(matches!(err, DescriptionError::Parse { .. }));
    assert!(err.to_string().starts_with("broken.urdf"), "{err}");

    let description = RobotDescription::from_urdf_str(MINI, "mini.urdf").unwrap();
    let err = description.chain("a", "tool0").unwrap_err();
    assert!(matches!(err, DescriptionError::UnknownLink { .. }));
    assert!(
        err.to_string().contains("mini.urdf") && err.to_string().contains("tool0"),
        "{err}"
    );
    let err = description.chain("a", "island").unwrap_err();
    assert!(matches!(err, DescriptionError::NoChain { .. }), "{err}");
    assert!(
        err.to_string().contains("no chain from `a` to `island`"),
        "{err}"
    );
    let err = description.chain("c", "a").unwrap_err();
    assert!(
        matches!(err, DescriptionError::MovableJointAboveRoot { .. }),
        "{err}"
    );

    let duplicate = MINI.replace(r#"<link name="c"/>"#, r#"<link name="b"/>"#);
    assert!(matches!(
        RobotDescription::from_urdf_str(&duplicate, "dup.urdf"),
        Err(DescriptionError::DuplicateLink { .. })
    ));
    let missing = MINI.replace(r#"<child link="c"/>"#, r#"<child link="d"/>"#);
    assert!(matches!(
        RobotDescription::from_urdf_str(&missing, "missing.urdf"),
        Err(DescriptionError::MissingJointLink { .. })
    ));
    let two_parents = MINI.replace(r#"<child link="c"/>"#, r#"<child link="b"/>"#);
    assert!(matches!(
        RobotDescription::from_urdf_str(&two_parents, "two.urdf"),
        Err(DescriptionError::MultipleParents { .. })
    ));
    let cycle = MINI.replace(
        r#"<parent link="a"/><child link="b"/>"#,
        r#"<parent link="c"/><child link="b"/>"#,
    );
    assert!(matches!(
        RobotDescription::from_urdf_str(&cycle, "cycle.urdf"),
        Err(DescriptionError::Cycle { .. })
    ));
    let no_limit = MINI.replace(
        r#"<limit lower="-1" upper="1" effort="1" velocity="1"/>"#,
        "",
    );
    let err = RobotDescription::from_urdf_str(&no_limit, "nolimit.urdf").unwrap_err();
    assert!(
        matches!(err, DescriptionError::InvalidJoint { .. }),
        "{err}"
    );
    let zero_axis = MINI.replace(r#"<axis xyz="0 0 1"/>"#, r#"<axis xyz="0 0 0"/>"#);
    assert!(matches!(
        RobotDescription::from_urdf_str(&zero_axis, "axis.urdf"),
        Err(DescriptionError::InvalidJoint { .. })
    ));
    let floating = MINI.replace(r#"type="prismatic""#, r#"type="floating""#);
    assert!(matches!(
        RobotDescription::from_urdf_str(&floating, "float.urdf"),
        Err(DescriptionError::UnsupportedJoint { .. })
    ));
}

/// The shipped arms with UR's published DH lengths (d1, a2, a3, d4, d5, d6) and their datasheet
/// joint speeds (deg/s, base first).
const ARMS: [(&str, [f64; 6], [f64; 6]); 5] = [
    (
        "ur3e",
        [0.15185, -0.24355, -0.2132, 0.13105, 0.08535, 0.0921],
        [180.0, 180.0, 180.0, 360.0, 360.0, 360.0],
    ),
    (
        "ur5e",
        [0.1625, -0.425, -0.3922, 0.1333, 0.0997, 0.0996],
        [180.0; 6],
    ),
    (
        "ur10e",
        [0.1807, -0.6127, -0.57155, 0.17415, 0.11985, 0.11655],
        [120.0, 120.0, 180.0, 180.0, 180.0, 180.0],
    ),
    (
        "ur16e",
        [0.1807, -0.4784, -0.36, 0.17415, 0.11985, 0.11655],
        [120.0, 120.0, 180.0, 180.0, 180.0, 180.0],
    ),
    (
        "ur20",
        [0.2363, -0.862, -0.7287, 0.201, 0.1593, 0.1543],
        [120.0, 120.0, 150.0, 210.0, 210.0, 210.0],
    ),
];

fn arm_urdf(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(format!("../scenarios/robots/{name}.urdf"))
}

#[test]
fn every_shipped_arm_yields_the_published_ur_parameters_and_its_urdf_kinematics() {
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    for (name, published, speeds_deg) in ARMS {
        let arm = UrArm::from_file(arm_urdf(name)).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(arm.name, name);
        let dh = arm.kinematics.dh;
        let derived = [dh.d1, dh.a2, dh.a3, dh.d4, dh.d5, dh.d6];
        for (d, p) in derived.iter().zip(published) {
            assert!(
                *d == p,
                "{name}: derived {derived:?}, published {published:?}"
            );
        }
        for (speed, deg) in arm.max_joint_speeds.iter().zip(speeds_deg) {
            assert!(
                (speed - deg.to_radians()).abs() < 1e-12,
                "{name}: {:?}",
                arm.max_joint_speeds
            );
        }
        // ±360° on every joint; the UR3e's wrist 3 turns without limit.
        let limits = arm.kinematics.joint_limits;
        for i in 0..6 {
            let unlimited = name == "ur3e" && i == 5;
            let expected = if unlimited { f64::INFINITY } else { TAU };
            assert_eq!(
                (limits.lower[i], limits.upper[i]),
                (-expected, expected),
                "{name} {i}"
            );
        }
        // FK through the URDF joint chain and through the derived parameters agree.
        let chain = RobotDescription::from_file(arm_urdf(name))
            .unwrap()
            .chain("base", "tool0")
            .unwrap();
        for _ in 0..500 {
            let q: Joints = std::array::from_fn(|_| rng.random_range(-TAU..TAU));
            let urdf = chain.forward(&q).unwrap();
            let derived = arm.kinematics.forward_flange(&q);
            assert!(
                close(&urdf, &derived, 1e-9),
                "{name} {q:?}: {urdf} vs {derived}"
            );
        }
    }
    // The UR5e derived from its URDF is exactly the built-in nominal UR5e.
    assert_eq!(
        UrArm::from_file(ur5e_urdf()).unwrap().kinematics,
        UrKinematics::ur5e()
    );
}

fn ur5e_text() -> String {
    std::fs::read_to_string(ur5e_urdf()).unwrap()
}

fn not_ur(text: &str, origin: &str) -> String {
    let err = UrArm::from_description(&RobotDescription::from_urdf_str(text, origin).unwrap())
        .unwrap_err();
    let message = err.to_string();
    assert!(message.starts_with(origin), "{message}");
    message
}

#[test]
fn a_urdf_that_is_not_a_six_joint_ur_chain_is_refused_with_the_reason() {
    // Not a UR chain at all: no `base` link (the file and the known links are named).
    let err = UrArm::from_description(&RobotDescription::from_urdf_str(MINI, "mini.urdf").unwrap())
        .unwrap_err();
    assert!(matches!(err, DescriptionError::UnknownLink { .. }), "{err}");
    assert!(err.to_string().starts_with("mini.urdf"), "{err}");

    // Five movable joints: wrist 3 welded.
    let text = ur5e_text().replace(
        r#"<joint name="wrist_3_joint" type="revolute">"#,
        r#"<joint name="wrist_3_joint" type="fixed">"#,
    );
    let message = not_ur(&text, "five.urdf");
    assert!(message.contains("has 5 movable joints"), "{message}");

    // A sliding joint.
    let text = ur5e_text().replace(
        r#"<joint name="elbow_joint" type="revolute">"#,
        r#"<joint name="elbow_joint" type="prismatic">"#,
    );
    let message = not_ur(&text, "slide.urdf");
    assert!(message.contains("joint `elbow_joint` slides"), "{message}");

    // A joint turning the other way round.
    let text = ur5e_text().replace(
        "<origin xyz=\"0 0 0.1625\" rpy=\"1.570796326794897 0 0\"/>\n    <axis xyz=\"0 0 1\"/>",
        "<origin xyz=\"0 0 0.1625\" rpy=\"1.570796326794897 0 0\"/>\n    <axis xyz=\"0 0 -1\"/>",
    );
    assert_ne!(text, ur5e_text());
    let message = not_ur(&text, "flipped.urdf");
    assert!(
        message.contains("joint 2 `shoulder_lift_joint` turns about"),
        "{message}"
    );

    // The forearm offset sideways: parallel axes, but no longer the UR structure the analytic
    // IK solves (the FK check finds it).
    let text = ur5e_text().replace(
        r#"<origin xyz="-0.3922 0 0" rpy="0 0 0"/>"#,
        r#"<origin xyz="-0.3922 0.01 0" rpy="0 0 0"/>"#,
    );
    let message = not_ur(&text, "offset.urdf");
    assert!(
        message.contains("not a six-joint UR arm")
            && message.contains("forward kinematics only to"),
        "{message}"
    );

    // Missing file: named.
    let err = UrArm::from_file("/nonexistent/ur.urdf").unwrap_err();
    assert!(err.to_string().contains("/nonexistent/ur.urdf"), "{err}");
}
