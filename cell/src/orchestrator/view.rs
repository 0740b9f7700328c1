//! Whether the arm stands between the camera and the feeder: the arm's pose from its joints
//! through the planning kinematics, as capsules around its links, the gripper and a held part,
//! against the pyramid from the calibrated camera's centre to the feeder rectangle. Only what a
//! production cell knows too (joints, kinematics, calibration), never the simulator's truth, so
//! an overlapped capture is refused the same way in both.

use nalgebra::{Isometry3, Point3};
use robots::kinematics::Joints;

use super::geometry::CellKnowledge;

/// Radius of the capsule around every arm link (the UR5e's joint housings are 0.09 m across;
/// rounded up), metres.
pub const LINK_RADIUS: f64 = 0.06;
/// Radius of the capsule around the gripper, flange to fingertips, metres.
pub const GRIPPER_RADIUS: f64 = 0.04;
/// Margin around the feeder rectangle the camera must see clear (parts overhanging its edge,
/// as the feeder window's), metres.
const FEEDER_MARGIN: f64 = 0.008;
/// Spacing of the points checked along each capsule's axis, metres.
const STEP: f64 = 0.005;

/// Height above the table below which an arm over the feeder is near it: a shake flips parts
/// a few millimetres up, metres.
pub const AWAY_HEIGHT: f64 = 0.05;

/// The arm at joints `q` as spheres along its links' axes (table frame), by link name: the
/// links, the gripper, and a held part as a sphere of radius `held` around the TCP.
#[allow(non_snake_case)]
pub(super) fn spheres(
    k: &CellKnowledge,
    q: &Joints,
    held: Option<f64>,
) -> Vec<(&'static str, Point3<f64>, f64)> {
    let table_T_base = k.geometry.base_T_table.inverse();
    let frames = k.kinematics.dh.frames(q);
    let at = |iso: &Isometry3<f64>| table_T_base * Point3::from(iso.translation.vector);
    let base = at(&Isometry3::identity());
    let tcp = at(&k.kinematics.forward_tcp(q));
    let links: [(&'static str, Point3<f64>, Point3<f64>, f64); 7] = [
        ("base", base, at(&frames[0]), LINK_RADIUS),
        ("upper arm", at(&frames[0]), at(&frames[1]), LINK_RADIUS),
        ("forearm", at(&frames[1]), at(&frames[2]), LINK_RADIUS),
        ("wrist 1", at(&frames[2]), at(&frames[3]), LINK_RADIUS),
        ("wrist 2", at(&frames[3]), at(&frames[4]), LINK_RADIUS),
        ("wrist 3", at(&frames[4]), at(&frames[5]), LINK_RADIUS),
        ("gripper", at(&frames[5]), tcp, GRIPPER_RADIUS),
    ];
    let mut out = Vec::new();
    for (name, a, b, r) in links {
        let n = ((b - a).norm() / STEP).ceil().max(1.0) as usize;
        out.extend((0..=n).map(|i| (name, a + (b - a) * (i as f64 / n as f64), r)));
    }
    if let Some(r) = held {
        out.push(("held part", tcp, r));
    }
    out
}

/// The feeder rectangle's centre and half sizes with the margin (table frame), metres.
fn feeder_rect(k: &CellKnowledge) -> ([f64; 2], [f64; 2]) {
    let f = &k.spec.feeder;
    (
        f.center,
        [
            0.5 * f.size[0] + FEEDER_MARGIN,
            0.5 * f.size[1] + FEEDER_MARGIN,
        ],
    )
}

/// The first part of the arm (or the held part) found in the camera's view of the feeder at
/// joints `q`, by name; `None` when the view is clear. `held` is the radius of a held part's
/// bounding sphere around the TCP, metres.
pub fn arm_in_feeder_view(
    k: &CellKnowledge,
    q: &Joints,
    held: Option<f64>,
) -> Option<&'static str> {
    arm_in_view_of(k, q, held, feeder_rect(k))
}

/// The first part of the arm (or the held part) at joints `q` that shades the table rectangle
/// `(centre, half size)` (table frame, metres) from the calibrated camera, by name; `None` when
/// the camera sees all of it.
#[allow(non_snake_case)]
pub(super) fn arm_in_view_of(
    k: &CellKnowledge,
    q: &Joints,
    held: Option<f64>,
    (center, half): ([f64; 2], [f64; 2]),
) -> Option<&'static str> {
    let table_T_base = k.geometry.base_T_table.inverse();
    let camera = table_T_base * Point3::from(k.geometry.base_T_camera_nominal.translation.vector);
    spheres(k, q, held)
        .into_iter()
        .find(|(_, p, r)| shadow_hits(&camera, p, *r, center, half))
        .map(|(name, _, _)| name)
}

/// The first part of the arm (or the held part) near the feeder at joints `q`: over its
/// rectangle and lower than [`AWAY_HEIGHT`] above the table, where a shake could throw parts
/// against it; `None` when the arm is away from the feeder.
pub fn arm_near_feeder(k: &CellKnowledge, q: &Joints, held: Option<f64>) -> Option<&'static str> {
    let (center, half) = feeder_rect(k);
    spheres(k, q, held)
        .into_iter()
        .find(|(_, p, r)| {
            p.z - r < AWAY_HEIGHT
                && (p.x - center[0]).abs() <= half[0] + r
                && (p.y - center[1]).abs() <= half[1] + r
        })
        .map(|(name, _, _)| name)
}

/// Whether a sphere at `p` (table frame) of radius `r` casts its shadow from `camera` onto
/// the table plane inside the rectangle around `center` with half sizes `half`: the sphere
/// then stands between the camera and that rectangle. The shadow's radius is the sphere's
/// scaled by the distance ratio, over the cosine of the ray's tilt (an ellipse's long axis).
pub(super) fn shadow_hits(
    camera: &Point3<f64>,
    p: &Point3<f64>,
    r: f64,
    center: [f64; 2],
    half: [f64; 2],
) -> bool {
    // Only what is between the camera (above the table) and the table plane hides the feeder.
    if camera.z <= 0.0 || p.z >= camera.z || p.z + r <= 0.0 {
        return false;
    }
    let d = p - camera;
    let t = camera.z / (camera.z - p.z);
    let hit = camera + d * t;
    let cos = (camera.z - p.z) / d.norm().max(1e-12);
    let spread = r * t / cos.max(1e-3);
    (hit.x - center[0]).abs() <= half[0] + spread && (hit.y - center[1]).abs() <= half[1] + spread
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sphere_above_the_rectangle_hides_it_and_one_beside_it_does_not() {
        let camera = Point3::new(0.0, 0.0, 1.5);
        let center = [0.0, 0.05];
        let half = [0.05, 0.04];
        assert!(shadow_hits(
            &camera,
            &Point3::new(0.0, 0.05, 0.4),
            0.01,
            center,
            half
        ));
        // Beside the rectangle, but its shadow reaches in.
        assert!(shadow_hits(
            &camera,
            &Point3::new(0.0, 0.12, 0.3),
            0.06,
            center,
            half
        ));
        // Far beside it.
        assert!(!shadow_hits(
            &camera,
            &Point3::new(0.3, 0.3, 0.3),
            0.06,
            center,
            half
        ));
        // Above the camera, or below the table.
        assert!(!shadow_hits(
            &camera,
            &Point3::new(0.0, 0.05, 1.6),
            0.06,
            center,
            half
        ));
        assert!(!shadow_hits(
            &camera,
            &Point3::new(0.0, 0.05, -0.2),
            0.06,
            center,
            half
        ));
    }
}
