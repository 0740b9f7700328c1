//! Stable-pose classes that a part's exact symmetries make one pose.
//!
//! Drops cluster rests by the face a part lies on. A part that maps onto itself under a turn (a
//! square peg every quarter turn about its axis, a round one modelled as a 48-gon every 7.5°)
//! lies on faces that differ only by that turn: the same pose, which drops split into several
//! classes (a faceted round peg on its side: dozens of 1–3 % classes). Merging them gives the
//! pose its whole probability, so selection, the feeder and reports see one class.

use nalgebra::{UnitQuaternion, Vector3};

use super::{CLASS_ANGLE_RAD, StablePoseReport};

impl StablePoseReport {
    /// Merges the classes whose resting directions a rotation of `group` (the part's exact
    /// symmetries, [`perception::symmetry::symmetry_group`]) maps onto each other. Each merged
    /// class keeps the name, rest rotation and height of its most probable member and adds up the
    /// drops; most probable first, as before. With the identity alone nothing changes.
    pub fn merge_symmetric(&mut self, group: &[UnitQuaternion<f64>]) {
        self.merge_symmetric_keeping(group, |_| false);
    }

    /// [`Self::merge_symmetric`], where a merged class whose members include one that `keep`
    /// accepts (by name: a stable pose the catalog has a grasp for) is named, turned and raised
    /// as that member: a peg's two ends merge into the end its grasp names, however the drops
    /// split between them, so the grasp still applies.
    pub fn merge_symmetric_keeping(
        &mut self,
        group: &[UnitQuaternion<f64>],
        keep: impl Fn(&str) -> bool,
    ) {
        if group.len() < 2 {
            return;
        }
        let up = |c: &super::PoseClass| Vector3::from(c.pose.up_in_part);
        let mut merged: Vec<super::PoseClass> = Vec::new();
        for class in self.classes.drain(..) {
            let u = up(&class);
            match merged.iter_mut().find(|m| {
                group
                    .iter()
                    .any(|g| (g * u).angle(&up(m)) < CLASS_ANGLE_RAD)
            }) {
                Some(into) => {
                    if keep(&class.pose.name) && !keep(&into.pose.name) {
                        into.pose.name = class.pose.name.clone();
                        into.pose.up_in_part = class.pose.up_in_part;
                        into.pose.rotation = class.pose.rotation;
                        into.pose.rest_height = class.pose.rest_height;
                    }
                    into.count += class.count;
                    into.jittering += class.jittering;
                    into.pose.probability += class.pose.probability;
                    into.max_height_error = into.max_height_error.max(class.max_height_error);
                    into.spread = into.spread.max(class.spread);
                }
                None => merged.push(class),
            }
        }
        // Stable: equal counts keep the order drops gave them.
        merged.sort_by_key(|c| std::cmp::Reverse(c.count));
        self.classes = merged;
    }
}

#[cfg(test)]
mod tests {
    use super::super::PoseClass;
    use super::*;
    use perception::part::{StablePose, Symmetry};
    use perception::symmetry::symmetry_group;

    /// A class resting with `up` (part frame) up, counted `count` times of 100.
    fn class(name: &str, up: [f64; 3], count: usize) -> PoseClass {
        PoseClass {
            pose: StablePose {
                name: name.into(),
                probability: count as f64 / 100.0,
                up_in_part: up,
                rotation: [0.0; 3],
                rest_height: 0.001,
            },
            count,
            jittering: usize::from(name == "+y"),
            max_height_error: if name == "-x" { 2e-6 } else { 1e-6 },
            spread: 0.001,
        }
    }

    /// A square bar's drops: on either end, or on one of its four sides.
    fn square_bar() -> StablePoseReport {
        StablePoseReport {
            classes: vec![
                class("+x", [1.0, 0.0, 0.0], 22),
                class("-y", [0.0, -1.0, 0.0], 21),
                class("-x", [-1.0, 0.0, 0.0], 20),
                class("+y", [0.0, 1.0, 0.0], 19),
                class("+z", [0.0, 0.0, 1.0], 9),
                class("-z", [0.0, 0.0, -1.0], 9),
            ],
            drops: 100,
            unsettled: 1,
            leaning: 0,
            rare: 0,
            mass: 1.0,
            center_of_mass: nalgebra::Point3::origin(),
            mean_rest_time: 0.3,
        }
    }

    fn summary(r: &StablePoseReport) -> Vec<(String, usize)> {
        r.classes
            .iter()
            .map(|c| (c.pose.name.clone(), c.count))
            .collect()
    }

    #[test]
    fn a_quarter_turn_about_the_axis_makes_the_four_sides_one_pose() {
        let mut r = square_bar();
        let about_z = Symmetry {
            axis: [0.0, 0.0, 1.0],
            order: 4,
            exact: true,
        };
        r.merge_symmetric(&symmetry_group(&[about_z]));
        assert_eq!(
            summary(&r),
            [("+x".into(), 82), ("+z".into(), 9), ("-z".into(), 9)]
        );
        let side = &r.classes[0];
        assert!((side.pose.probability - 0.82).abs() < 1e-12);
        assert_eq!(side.jittering, 1);
        assert_eq!(side.max_height_error, 2e-6);
    }

    /// A square bar's exact symmetries: quarter turns about its axis, a half turn end over end.
    fn square_bar_symmetries() -> [Symmetry; 2] {
        [
            Symmetry {
                axis: [0.0, 0.0, 1.0],
                order: 4,
                exact: true,
            },
            Symmetry {
                axis: [1.0, 0.0, 0.0],
                order: 2,
                exact: true,
            },
        ]
    }

    #[test]
    fn a_half_turn_end_over_end_also_makes_the_two_ends_one_pose() {
        let mut r = square_bar();
        r.merge_symmetric(&symmetry_group(&square_bar_symmetries()));
        assert_eq!(summary(&r), [("+x".into(), 82), ("+z".into(), 18)]);
    }

    #[test]
    fn the_merged_ends_keep_the_name_of_the_grasped_one() {
        let mut r = square_bar();
        // The drops favour neither end; name "-z" first so it would lead the merge.
        r.classes.swap(4, 5);
        assert_eq!(r.classes[4].pose.name, "-z");
        let group = symmetry_group(&square_bar_symmetries());
        let mut plain = r.clone();
        plain.merge_symmetric(&group);
        assert_eq!(summary(&plain), [("+x".into(), 82), ("-z".into(), 18)]);
        r.merge_symmetric_keeping(&group, |name| name == "+z");
        assert_eq!(summary(&r), [("+x".into(), 82), ("+z".into(), 18)]);
        assert_eq!(r.classes[1].pose.up_in_part, [0.0, 0.0, 1.0]);
    }

    #[test]
    fn near_symmetries_and_a_half_turn_about_the_axis_keep_the_sides_apart() {
        let mut near = square_bar();
        near.merge_symmetric(&symmetry_group(&[Symmetry {
            axis: [0.0, 0.0, 1.0],
            order: 4,
            exact: false,
        }]));
        assert_eq!(
            near.classes.len(),
            6,
            "a near-symmetry is not an equivalence"
        );
        let mut half = square_bar();
        half.merge_symmetric(&symmetry_group(&[Symmetry {
            axis: [0.0, 0.0, 1.0],
            order: 2,
            exact: true,
        }]));
        assert_eq!(
            summary(&half),
            [
                ("+x".into(), 42),
                ("-y".into(), 40),
                ("+z".into(), 9),
                ("-z".into(), 9)
            ]
        );
    }
}
