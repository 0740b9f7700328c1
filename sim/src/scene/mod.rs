//! Scenes like the seed's cell: the tag board on a table, parts dropped onto it with rapier,
//! lights, materials and camera randomised within documented ranges, and per-instance labels.

#![allow(non_snake_case)]

mod compose;
mod drop;
mod labels;
mod model;
mod randomisation;

pub use compose::{
    METER_FLOOR, METER_SHARE, METER_TARGET, SampledScene, SceneError, SceneRequest, dress_scene,
    look_at, nominal_scene, sample_scene,
};
pub use drop::{DropError, HeldPart, PlacedPart, drop_parts, drop_parts_around};
pub use labels::{InstanceLabel, keypoint_vectors, label_instance, label_instances};
pub use model::{PartModel, PartModelError};
pub use randomisation::{Randomisation, RandomisationError, Range};
