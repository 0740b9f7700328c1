//! The shipped UR5e URDF against the DH kinematics, and the loader's errors.

#![allow(non_snake_case)]

use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use robots::description::{DescriptionError, RobotDescription};
use robots::kinematics::{Joints, UrKinematics};
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
