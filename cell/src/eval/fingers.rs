//! The cell's fingers in an evaluation: how near the open fingers of each pick come to the other
//! parts of the frame, with a scenario's gripper, grasps and finger margin, against exactly what
//! the cell's selection checks (every other posed detection, and the space of every part found
//! but not posed). Reach is not checked: a dataset frame's parts lie wherever its drop put them,
//! not at the cell's feeder.

use std::sync::Arc;

use nalgebra::{Isometry3, Vector3};
use perception::Camera;
use perception::learned::LearnedDetections;
use perception::part::Catalog;

use crate::orchestrator::{
    CellKnowledge, KnowledgeError, Setup, UnposedObstacle, nearest_to_fingers,
};
use crate::scenario::Scenario;

/// A scenario's gripper and grasps, to measure each pick's finger clearance in dataset frames.
pub struct FingerCheck {
    knowledge: Arc<CellKnowledge>,
    catalog: Catalog,
    margin: f64,
}

impl FingerCheck {
    /// The gripper, grasps and finger margin the cell of `scenario` selects picks with.
    pub fn new(scenario: &Scenario) -> Result<Self, KnowledgeError> {
        let setup = Setup::new(scenario.clone())?;
        Ok(Self {
            margin: setup.settings.selection.finger_margin,
            knowledge: setup.knowledge,
            catalog: setup.scenario.catalog,
        })
    }

    /// The least clearance the cell's selection accepts between an open finger and anything
    /// else, metres.
    pub fn margin(&self) -> f64 {
        self.margin
    }

    /// For each detection of a frame of `camera` looking at the table at `camera_T_table`: the
    /// clearance of the open fingers of its grasp to the nearest other part, metres; `None`
    /// without a pose, without a grasp for its stable pose, or alone in the frame.
    #[allow(non_snake_case)]
    pub fn clearances(
        &self,
        found: &LearnedDetections,
        camera: &Camera,
        camera_T_table: &Isometry3<f64>,
    ) -> Vec<Option<f64>> {
        let k = &self.knowledge;
        let base_T_table = &k.geometry.base_T_table;
        let extent = |part: &str| k.part(part).map_or(0.0, |p| (p.aabb.1 - p.aabb.0).max());
        let perceived = found.perceived(camera, camera_T_table, base_T_table, extent);
        let unposed = UnposedObstacle::all(&perceived.unposed, base_T_table);
        let mut out = vec![None; found.detections.len()];
        for d in &perceived.parts {
            let Some(grasp) =
                (self.catalog.part(&d.part)).and_then(|p| p.grasp_for(&d.stable_pose))
            else {
                continue;
            };
            // The jaws are symmetric: either of the two yaws gives the same clearance.
            let Some(base_T_grasp) = k.grasp_tcp(
                &d.base_T_part,
                &Vector3::from(grasp.closing_axis),
                grasp.grip_height,
                0.0,
            ) else {
                continue;
            };
            let opening = k.grasp_opening(&d.part, &Vector3::from(grasp.closing_axis));
            let near = nearest_to_fingers(
                k,
                (&base_T_grasp, opening),
                d.index,
                &perceived.parts,
                &unposed,
            );
            out[d.index] = near.map(|(distance, _)| distance);
        }
        out
    }
}
