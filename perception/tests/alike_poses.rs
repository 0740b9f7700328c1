//! Stable poses a camera cannot tell apart (perception::part::alike_stable_poses): boxes whose
//! resting shapes match, or do not, under a turn.

use nalgebra::{Point3, Vector3};
use perception::part::{ALIKE_WITHIN_REL, StablePose, Symmetry, TriMesh, alike_stable_poses};

/// A resting class with `up` (part frame) up; only its up matters to the check.
fn pose(name: &str, up: [f64; 3]) -> StablePose {
    StablePose {
        name: name.into(),
        probability: 0.2,
        up_in_part: up,
        rotation: [0.0; 3],
        rest_height: 0.0,
    }
}

fn block(x_mm: f64, y_mm: f64, z_mm: f64) -> TriMesh {
    TriMesh::cuboid(Vector3::new(x_mm, y_mm, z_mm) * 1e-3)
}

fn tolerance(mesh: &TriMesh) -> f64 {
    ALIKE_WITHIN_REL * mesh.extents().max()
}

#[test]
fn a_near_cube_standing_and_lying_is_found_alike_by_its_length_less_its_width() {
    // The 12 mm square peg at 12 mm long: 11.9285 mm square, 12 mm long.
    let mesh = block(11.9285, 11.9285, 12.0);
    let poses = [pose("+z", [0.0, 0.0, 1.0]), pose("+x", [1.0, 0.0, 0.0])];
    let found = alike_stable_poses(&mesh, Point3::origin(), &poses, &[], tolerance(&mesh));
    assert_eq!(found.len(), 1, "{found:?}");
    let a = &found[0];
    assert_eq!((a.first, a.second), (0, 1));
    // Turned, its 12 mm length lies where an 11.9285 mm width was: half the difference each end.
    assert!((a.deviation - 0.03575e-3).abs() < 2e-6, "{}", a.deviation);
    assert!((a.turn * Vector3::z() - Vector3::x()).norm() < 1e-9);
}

#[test]
fn the_same_peg_two_millimetres_longer_rests_unlike_itself() {
    let mesh = block(11.9285, 11.9285, 14.0);
    let poses = [pose("+z", [0.0, 0.0, 1.0]), pose("+x", [1.0, 0.0, 0.0])];
    let found = alike_stable_poses(&mesh, Point3::origin(), &poses, &[], tolerance(&mesh));
    assert!(found.is_empty(), "{found:?}");
}

#[test]
fn the_match_is_refused_just_under_its_deviation_and_found_just_over() {
    let mesh = block(11.9, 11.9, 12.0);
    let poses = [pose("+z", [0.0, 0.0, 1.0]), pose("-y", [0.0, -1.0, 0.0])];
    // Half of the 0.1 mm difference each end.
    assert!(alike_stable_poses(&mesh, Point3::origin(), &poses, &[], 0.045e-3).is_empty());
    let found = alike_stable_poses(&mesh, Point3::origin(), &poses, &[], 0.055e-3);
    assert_eq!(found.len(), 1);
    assert!((found[0].deviation - 0.05e-3).abs() < 2e-6);
}

#[test]
fn two_sides_of_a_square_bar_are_found_alike_under_a_quarter_turn_about_its_axis() {
    // Without its declared symmetry a square bar's sides are distinct classes that look alike;
    // the turn between them is found by the search about the vertical, whatever its yaw.
    let mesh = block(8.0, 8.0, 20.0);
    let poses = [
        pose("+x", [1.0, 0.0, 0.0]),
        pose("+y", [0.0, 1.0, 0.0]),
        pose("+z", [0.0, 0.0, 1.0]),
    ];
    let found = alike_stable_poses(&mesh, Point3::origin(), &poses, &[], tolerance(&mesh));
    assert_eq!(found.len(), 1, "{found:?}");
    let a = &found[0];
    assert_eq!((a.first, a.second), (0, 1));
    assert!(a.deviation < 1e-6, "{}", a.deviation);
    assert!((a.turn * Vector3::x() - Vector3::y()).norm() < 1e-6);
}

#[test]
fn an_off_centre_pin_breaks_the_likeness_of_a_cube() {
    // A 10 mm cube with a 2 mm pin on its top face, off centre: standing on its bottom and
    // lying on a side it shows a pin in both, but not the same shape.
    let mut mesh = block(10.0, 10.0, 10.0);
    let com = Point3::origin();
    let poses = [pose("+z", [0.0, 0.0, 1.0]), pose("+x", [1.0, 0.0, 0.0])];
    assert_eq!(
        alike_stable_poses(&mesh, com, &poses, &[], tolerance(&mesh)).len(),
        1
    );
    let pin =
        block(2.0, 2.0, 2.0).transformed(&nalgebra::Isometry3::translation(0.002, 0.0, 0.006));
    mesh.append(&pin);
    assert!(alike_stable_poses(&mesh, com, &poses, &[], tolerance(&mesh)).is_empty());
}

#[test]
fn a_pair_that_a_declared_symmetry_relates_is_left_out() {
    // The square bar's quarter turn about its axis, declared (exact or near): its sides are the
    // catalog's own business, not an unnamed ambiguity.
    let mesh = block(8.0, 8.0, 20.0);
    let poses = [pose("+x", [1.0, 0.0, 0.0]), pose("+y", [0.0, 1.0, 0.0])];
    for exact in [true, false] {
        let declared = [Symmetry {
            axis: [0.0, 0.0, 1.0],
            order: 4,
            exact,
        }];
        assert!(alike_stable_poses(&mesh, Point3::origin(), &poses, &declared, 1e-4).is_empty());
    }
    assert_eq!(
        alike_stable_poses(&mesh, Point3::origin(), &poses, &[], 1e-4).len(),
        1
    );
}

#[test]
fn a_near_cube_of_two_touching_bodies_is_found_alike_too() {
    // The near-cube of the first test, exported as two touching halves (each closed): their
    // shared wall lies inside the part.
    let half = TriMesh::cuboid(Vector3::new(11.9285, 11.9285, 6.0) * 1e-3);
    let mut mesh = half.transformed(&nalgebra::Isometry3::translation(0.0, 0.0, -0.003));
    mesh.append(&half.transformed(&nalgebra::Isometry3::translation(0.0, 0.0, 0.003)));
    let poses = [pose("+z", [0.0, 0.0, 1.0]), pose("+x", [1.0, 0.0, 0.0])];
    let found = alike_stable_poses(&mesh, Point3::origin(), &poses, &[], tolerance(&mesh));
    assert_eq!(found.len(), 1, "{found:?}");
}
