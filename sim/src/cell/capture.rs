//! What the simulated camera delivers in a learned-perception run: the feeder window rendered
//! from the TRUE world state (true camera pose, true part poses) through the sensor. Only these
//! pixels, with the calibrated camera, reach perception.

use image::RgbImage;
use nalgebra::Isometry3;
use perception::calibration::Board;
use rand_chacha::ChaCha8Rng;

use super::error::CellError;
use super::feeder::FeederPart;
use super::feeder_window::calibrated_feeder_window;
use super::model::CellModel;
use crate::render::{IncrementalRenderer, RenderSettings, SensorModel, TagBoard, Window};
use crate::scene::{METER_SHARE, METER_TARGET, PlacedPart, nominal_scene_on};

/// A rendered feeder window.
#[derive(Debug, Clone)]
pub struct FeederImage {
    /// The 8-bit image of the window.
    pub image: RgbImage,
    /// Which pixels of the full sensor it covers.
    pub window: Window,
}

/// Renders the feeder `parts` as the camera at `base_T_camera` (the true pose) sees them, over
/// the window where the calibrated camera sees the feeder: the pixels a production pipeline
/// searches in a full-sensor image, so both read the same pixels.
#[allow(non_snake_case)]
pub(crate) fn render_feeder(
    model: &CellModel,
    parts: &[FeederPart],
    base_T_camera: &Isometry3<f64>,
    renderer: &mut IncrementalRenderer,
    rng: &mut ChaCha8Rng,
) -> Result<FeederImage, CellError> {
    let camera = &model.spec.camera.intrinsics;
    let window = calibrated_feeder_window(&model.spec).ok_or_else(|| {
        CellError::Camera("the feeder is not in the calibrated camera's view".into())
    })?;
    let table_T_camera = model.geometry.base_T_table.inverse() * base_T_camera;
    let placed = parts
        .iter()
        .map(|p| {
            let index = model
                .part_models
                .iter()
                .position(|m| m.name == p.part)
                .ok_or_else(|| CellError::Camera(format!("no render model for part {}", p.part)))?;
            Ok(PlacedPart {
                model: index,
                table_T_part: p.table_T_part,
            })
        })
        .collect::<Result<Vec<_>, CellError>>()?;
    let layout = model.spec.board_layout().ok_or_else(|| {
        CellError::Camera("the scenario names a board that was never loaded".into())
    })?;
    let scene = nominal_scene_on(
        &model.part_models,
        &placed,
        TagBoard::new(Board::clone(&layout)),
    );
    let settings = RenderSettings {
        full_masks: false,
        ..RenderSettings::default()
    };
    let rays = model.feeder_rays();
    let output = renderer.render(&scene, camera, &table_T_camera, window, &settings, rays);
    let sensor = SensorModel::default().metered(output, METER_TARGET, METER_SHARE);
    let image = sensor
        .capture(output, rng)
        .map_err(|e| CellError::Camera(e.to_string()))?;
    Ok(FeederImage { image, window })
}
