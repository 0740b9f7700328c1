//! Stable poses: the ways a part comes to rest on a flat table.

use super::convex_hull;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use parry3d_f64::math::Vector3 as HullVector;
use serde::{Deserialize, Serialize};

use super::TriMesh;

/// One class of resting orientations: the face a part lies on, with yaw about the table normal free.
///
/// The pose of a part resting in this class is `table_T_part = Rz(yaw) · rotation`, translated to
/// (x, y, `rest_height`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StablePose {
    /// Name derived from the resting face, e.g. "+z" (part z axis up) or "-z"; grasps refer to it.
    pub name: String,
    /// Fraction of physics drops that came to rest in this class.
    pub probability: f64,
    /// The table's up direction expressed in the part frame (unit vector): what defines the class.
    pub up_in_part: [f64; 3],
    /// Canonical rest rotation `table_R_part` at yaw 0, as a rotation vector in radians.
    pub rotation: [f64; 3],
    /// Height of the part origin above the table in metres, from the mesh geometry.
    pub rest_height: f64,
}

impl StablePose {
    /// The canonical rest rotation `table_R_part` at yaw 0.
    pub fn rest_rotation(&self) -> UnitQuaternion<f64> {
        UnitQuaternion::from_scaled_axis(Vector3::from(self.rotation))
    }

    /// How far a part turned by `table_r_part` is tilted from lying in this class, radians: the
    /// angle between the table's up in the part frame and this class's.
    pub fn tilt(&self, table_r_part: &UnitQuaternion<f64>) -> f64 {
        (table_r_part.inverse() * Vector3::z()).angle(&Vector3::from(self.up_in_part))
    }

    /// The class of `poses` a part turned by `table_r_part` lies nearest to, with its
    /// [`tilt`](Self::tilt) from it; `None` for no classes.
    pub fn nearest<'a>(
        poses: &'a [StablePose],
        table_r_part: &UnitQuaternion<f64>,
    ) -> Option<(&'a StablePose, f64)> {
        Self::nearest_up_to(poses, table_r_part, &[UnitQuaternion::identity()])
    }

    /// [`nearest`](Self::nearest) up to the part's exact symmetries `group` (the rotations that
    /// map it onto itself, e.g. `crate::symmetry::symmetry_group`): a class also holds its twins,
    /// so a peg on its other end lies in the one class its table names, tilted 0 from it.
    pub fn nearest_up_to<'a>(
        poses: &'a [StablePose],
        table_r_part: &UnitQuaternion<f64>,
        group: &[UnitQuaternion<f64>],
    ) -> Option<(&'a StablePose, f64)> {
        let up = table_r_part.inverse() * Vector3::z();
        let tilt = |s: &StablePose| {
            let u = Vector3::from(s.up_in_part);
            (group.iter())
                .map(|g| up.angle(&(g * u)))
                .fold(up.angle(&u), f64::min)
        };
        poses
            .iter()
            .map(|s| (s, tilt(s)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
    }

    /// `table_T_part` for a part resting in this class at (x, y) with the given yaw.
    #[allow(non_snake_case)]
    pub fn table_T_part(&self, x: f64, y: f64, yaw: f64) -> Isometry3<f64> {
        let r = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw) * self.rest_rotation();
        Isometry3::from_parts(Translation3::new(x, y, self.rest_height), r)
    }

    /// The shortest-arc rotation that turns `up_in_part` onto the table's +z: the canonical
    /// rest rotation for a class (yaw 0).
    pub fn canonical_rotation(up_in_part: &Vector3<f64>) -> UnitQuaternion<f64> {
        UnitQuaternion::rotation_between(up_in_part, &Vector3::z()).unwrap_or_else(|| {
            // Antiparallel: up is the part's -z; turn half a revolution about x (the seed's roll 180°).
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
        })
    }

    /// A short name for the resting direction, from the direction alone (so it stays the same
    /// across seeds and drop counts): "+x" … "-z" within 1° of a part axis, otherwise the nearest
    /// axis, "~", the axis it tilts toward and the tilt in degrees, e.g. "-x~+z2.1".
    pub fn name_for(up_in_part: &Vector3<f64>) -> String {
        let letter = |i: usize| ["x", "y", "z"][i];
        let signed = |i: usize| {
            format!(
                "{}{}",
                if up_in_part[i] < 0.0 { '-' } else { '+' },
                letter(i)
            )
        };
        let by_size = {
            let mut axes = [0, 1, 2];
            axes.sort_by(|&a, &b| up_in_part[b].abs().total_cmp(&up_in_part[a].abs()));
            axes
        };
        let (main, toward) = (by_size[0], by_size[1]);
        let norm = up_in_part.norm();
        let tilt = if norm > 0.0 {
            (up_in_part[main].abs() / norm)
                .clamp(-1.0, 1.0)
                .acos()
                .to_degrees()
        } else {
            0.0
        };
        if tilt < 1.0 {
            signed(main)
        } else {
            format!("{}~{}{tilt:.1}", signed(main), signed(toward))
        }
    }
}

/// The area the part (`mesh`, its frame in metres) covers seen from above when it rests in each
/// of `poses`, mm²: its convex hull's faces that look up, each by its area projected onto the
/// table. A segmentation mask much larger than this cannot be the part in that pose.
pub fn footprints_mm2(mesh: &TriMesh, poses: &[StablePose]) -> Vec<f64> {
    let points: Vec<HullVector> = mesh
        .vertices
        .iter()
        .map(|p| HullVector::new(p.x, p.y, p.z) * 1e3)
        .collect();
    let (vertices, triangles) = convex_hull(&points);
    poses
        .iter()
        .map(|pose| {
            let up = HullVector::from(pose.up_in_part).normalize();
            triangles
                .iter()
                .map(|t| {
                    let [a, b, c] = t.map(|i| vertices[i as usize]);
                    (0.5 * (b - a).cross(c - a).dot(up)).max(0.0)
                })
                .sum()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A peg's classes "+z" (on an end) and "+x" (on a side): turned end over end it lies in
    /// "+z" only up to its symmetry, and without the symmetry nearer a side than "+z".
    #[test]
    fn a_twin_lies_in_its_class_up_to_the_symmetries() {
        let class = |name: &str, up: [f64; 3]| StablePose {
            name: name.into(),
            probability: 0.5,
            up_in_part: up,
            rotation: StablePose::canonical_rotation(&Vector3::from(up))
                .scaled_axis()
                .into(),
            rest_height: 0.006,
        };
        let poses = [class("+z", [0.0, 0.0, 1.0]), class("+x", [1.0, 0.0, 0.0])];
        let flip = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
        let group = [UnitQuaternion::identity(), flip];
        let on_other_end = poses[0].rest_rotation() * flip;
        let (s, tilt) = StablePose::nearest_up_to(&poses, &on_other_end, &group).unwrap();
        assert_eq!((s.name.as_str(), tilt < 1e-9), ("+z", true), "{tilt}");
        let (s, _) = StablePose::nearest(&poses, &on_other_end).unwrap();
        assert_eq!(s.name, "+x");
    }

    #[test]
    fn canonical_rotation_maps_up_to_table_z() {
        for up in [
            Vector3::z(),
            -Vector3::z(),
            Vector3::x(),
            Vector3::new(0.3, -0.5, 0.8).normalize(),
        ] {
            let r = StablePose::canonical_rotation(&up);
            assert!((r * up - Vector3::z()).norm() < 1e-12);
        }
        assert_eq!(StablePose::name_for(&-Vector3::z()), "-z");
        assert_eq!(
            StablePose::name_for(&Vector3::new(0.0, 0.0153, 0.99988).normalize()),
            "+z"
        );
        assert_eq!(
            StablePose::name_for(&Vector3::new(-0.999314835, 0.0, 0.037011625)),
            "-x~+z2.1"
        );
        assert_eq!(
            StablePose::name_for(&Vector3::new(0.0, -0.651847488, 0.758350085)),
            "+z~-y40.7"
        );
    }

    #[test]
    fn the_insert_mold_covers_its_floor_upside_down_and_half_of_it_on_its_side() {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/parts/usbc.toml");
        let catalog = crate::part::Catalog::load(&path).unwrap();
        let mold = catalog.part("insert_mold").unwrap();
        let mesh = catalog.load_mesh(mold).unwrap();
        let footprints = footprints_mm2(&mesh, &mold.stable_poses);
        let area = |pose: &str| {
            let class = mold.stable_poses.iter().position(|s| s.name == pose);
            footprints[class.unwrap()]
        };
        // An 8.4 × 8.5 × 4.2 mm block: its floor from above, a side face on its side.
        assert!((area("-z") - 8.4 * 8.5).abs() < 1.5, "{}", area("-z"));
        assert!((area("-z") - area("+z")).abs() < 0.5);
        assert!(
            (area("+x~+z2.1") - 8.5 * 4.2).abs() < 2.0,
            "{}",
            area("+x~+z2.1")
        );
    }
}
