//! What the simulated camera delivers in a learned-perception run: the feeder window rendered
//! from the TRUE world state (true camera pose, true part poses) through the sensor. Only these
//! pixels, with the calibrated camera, reach perception.

use image::RgbImage;
use nalgebra::{Isometry3, Point3};
use rand_chacha::ChaCha8Rng;

use super::error::CellError;
use super::feeder::FeederPart;
use super::model::CellModel;
use crate::config::CellSpec;
use crate::render::{IncrementalRenderer, RenderSettings, SensorModel, Window, window_covering};
use crate::scene::{METER_SHARE, METER_TARGET, PlacedPart, nominal_scene};

/// Margin around the feeder rectangle that the window also covers (parts overhanging its edge),
/// metres.
const FEEDER_MARGIN: f64 = 0.008;
/// Height above the table the window covers (the tallest resting part), metres.
const PART_HEIGHT: f64 = 0.006;

/// A rendered feeder window.
#[derive(Debug, Clone)]
pub struct FeederImage {
    /// The 8-bit image of the window.
    pub image: RgbImage,
    /// Which pixels of the full sensor it covers.
    pub window: Window,
}

/// The window of the camera image that shows the feeder (its rectangle plus a margin, up to the
/// parts' height) for a camera at `table_T_camera`: what a capture renders, and the region a
/// production pipeline searches.
#[allow(non_snake_case)]
pub fn feeder_window(spec: &CellSpec, table_T_camera: &Isometry3<f64>) -> Option<Window> {
    let feeder = &spec.feeder;
    let half = [
        0.5 * feeder.size[0] + FEEDER_MARGIN,
        0.5 * feeder.size[1] + FEEDER_MARGIN,
    ];
    let lo = Point3::new(feeder.center[0] - half[0], feeder.center[1] - half[1], 0.0);
    let hi = Point3::new(
        feeder.center[0] + half[0],
        feeder.center[1] + half[1],
        PART_HEIGHT,
    );
    window_covering(&spec.camera.intrinsics, table_T_camera, &lo, &hi)
}

/// [`feeder_window`] for the scenario's calibrated camera: the region learned perception
/// searches, and the window a simulated capture renders, so both read the same pixels.
#[allow(non_snake_case)]
pub fn calibrated_feeder_window(spec: &CellSpec) -> Option<Window> {
    let table_T_camera =
        spec.base_T_table.isometry().inverse() * spec.camera.base_T_camera.isometry();
    feeder_window(spec, &table_T_camera)
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
    let scene = nominal_scene(&model.part_models, &placed);
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
