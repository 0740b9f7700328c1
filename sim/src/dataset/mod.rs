//! Datasets for training and evaluating perception: BOP-format scenes (overview images with all
//! parts, for segmentation) and the keypoint crop set (128 × 128 crops with shifted intrinsics),
//! feeder frames (crowded parts at full resolution, for segmentation), written deterministically, in parallel, resumably and atomically; and a BOP reader.

#![allow(non_snake_case)]

mod bop;
mod config;
mod crops;
mod error;
mod families;
mod feeder;
mod files;
mod generate;
mod look;
mod overview;
mod preview;
mod reader;

pub use bop::{
    BopCamera, GtInfo, GtPose, ModelInfo, SceneCamera, pose_from_bop, pose_to_bop, write_models,
};
pub use config::{DatasetConfig, Split};
pub use crops::CropLabel;
pub use error::DatasetError;
pub use families::{
    DistractorFamily, FAMILY_NAMES, Families, FamilyDraw, FamilyError, LightFamily, PLATINGS,
    PlasticFamily, PlatingFamily, SensorFamily, TextureFamily,
};
pub use generate::{GenerateSummary, generate};
pub use look::{AreaLightRanges, BacklightRanges, LookError, LookOptions, RoomRanges};
pub use preview::write_preview;
pub use reader::{BopDataset, BopImage, BopScene};
