//! Stable poses from physics drops: a cube has six equally likely faces, a thin plate rests on its
//! two large faces, and physics rest heights agree with the mesh geometry.

use nalgebra::Point3;
use perception::part::TriMesh;
use sim::cad::solid::{Rect, Solid};
use sim::stable_poses::{DropSettings, stable_poses};

fn block(x: f64, y: f64, z: f64) -> TriMesh {
    let mut s = Solid::new();
    s.cuboid(Rect::centred(x, y), 0.0, z);
    s.into_part_mesh()
}

#[test]
fn a_cube_rests_on_each_face_one_time_in_six() {
    let cube = block(10.0, 10.0, 10.0);
    let settings = DropSettings {
        drops: 5000,
        seed: 11,
        ..DropSettings::default()
    };
    let report = stable_poses(&cube, 2700.0, &settings, None);
    assert!(
        report.unsettled < 25,
        "{} drops did not settle",
        report.unsettled
    );
    assert_eq!(report.classes.len(), 6, "{:#?}", report.classes);
    for class in &report.classes {
        let p = class.pose.probability;
        assert!(
            (p - 1.0 / 6.0).abs() < 0.02,
            "face {} has probability {p}",
            class.pose.name
        );
        assert!((class.pose.rest_height - 0.005).abs() < 1e-9);
        assert!(
            class.max_height_error < 1e-5,
            "physics rest height differs from geometry by {} m",
            class.max_height_error
        );
    }
    let mut names: Vec<_> = report.classes.iter().map(|c| c.pose.name.clone()).collect();
    names.sort();
    assert_eq!(names, ["+x", "+y", "+z", "-x", "-y", "-z"]);
}

#[test]
fn a_thin_plate_rests_on_its_two_large_faces() {
    let plate = block(20.0, 20.0, 0.5);
    let settings = DropSettings {
        drops: 2000,
        seed: 5,
        ..DropSettings::default()
    };
    let report = stable_poses(&plate, 2700.0, &settings, None);
    let flat: f64 = report
        .classes
        .iter()
        .filter(|c| c.pose.name == "+z" || c.pose.name == "-z")
        .map(|c| c.pose.probability)
        .sum();
    assert!(
        flat > 0.95,
        "large faces take only {flat}: {:#?}",
        report.classes
    );
    for class in &report.classes {
        assert!(
            class.max_height_error < 1e-5,
            "{}: {}",
            class.pose.name,
            class.max_height_error
        );
    }
    let up = report.classes.iter().find(|c| c.pose.name == "+z").unwrap();
    assert!((up.pose.rest_height - 0.00025).abs() < 1e-9);
}

#[test]
fn drops_are_deterministic_for_a_seed() {
    let part = block(9.0, 6.0, 3.0);
    let settings = DropSettings {
        drops: 256,
        seed: 3,
        ..DropSettings::default()
    };
    let a = stable_poses(&part, 2700.0, &settings, None);
    let b = stable_poses(&part, 2700.0, &settings, None);
    let probs = |r: &sim::stable_poses::StablePoseReport| {
        r.classes
            .iter()
            .map(|c| (c.pose.name.clone(), c.count))
            .collect::<Vec<_>>()
    };
    assert_eq!(probs(&a), probs(&b));
    assert_eq!(a.center_of_mass, b.center_of_mass);
    assert!((a.center_of_mass - Point3::origin()).norm() < 1e-12);
    assert!((a.mass - 2700.0 * 9e-3 * 6e-3 * 3e-3).abs() < 1e-12);
}
