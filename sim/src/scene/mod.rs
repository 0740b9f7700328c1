//! Scenes like the seed's cell: the tag board on a table, parts dropped onto it with rapier,
//! lights, materials and camera randomised within documented ranges, and per-instance labels.

#![allow(non_snake_case)]

mod board_view;
mod compose;
mod drop;
mod labels;
mod model;
mod randomisation;

pub use board_view::{
    BoardImage, BoardView, NOMINAL_HEIGHT, board_render_settings, embed_in_full_frame,
    nominal_table_T_camera, sample_board_view,
};
pub use compose::{
    METER_FLOOR, METER_SHARE, METER_TARGET, SampledScene, SceneError, SceneRequest, dress_scene,
    look_at, nominal_scene, nominal_scene_on, sample_scene,
};
pub use drop::{DropError, HeldPart, PlacedPart, drop_parts, drop_parts_around};
pub use labels::{InstanceLabel, keypoint_vectors, label_instance, label_instances};
pub use model::{PartModel, PartModelError};
pub use randomisation::{Randomisation, RandomisationError, Range, RangeError};
