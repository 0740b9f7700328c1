//! What the simulated camera delivers for a seat check: the window where the calibrated camera
//! sees the fixture, rendered from the TRUE world state (true camera pose, the fixture, and the
//! parts placed in it at their true poses) through the sensor, as [`super::capture`] renders
//! the feeder. The arm is not drawn: the orchestrator never takes this capture with the arm or
//! a held part in the camera's view of the window (its own check, from the joints).

use image::RgbImage;
use nalgebra::{Isometry3, Point3};
use perception::calibration::Board;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::error::CellError;
use super::model::CellModel;
use super::sim_cell::SimCell;
use crate::render::{
    IncrementalRenderer, RenderSettings, SensorModel, TagBoard, Window, window_covering,
};
use crate::scene::{METER_SHARE, METER_TARGET, PartModel, PlacedPart, nominal_scene_on};

/// Margin around the fixture's footprint that the window also covers, metres.
const FIXTURE_MARGIN: f64 = 0.004;
/// Height above the fixture's top the window also covers (parts standing out of the nest),
/// metres.
const PARTS_ABOVE: f64 = 0.012;

/// A rendered fixture window.
#[derive(Debug, Clone)]
pub struct FixtureImage {
    /// The 8-bit image of the window.
    pub image: RgbImage,
    /// Which pixels of the full sensor it covers.
    pub window: Window,
}

/// The table-frame box (low and high corners) that the fixture and the parts standing in it
/// fill: the fixture's bounding box at its pose, a margin around it, up to [`PARTS_ABOVE`]
/// over its top.
#[allow(non_snake_case)]
pub fn fixture_box(model: &CellModel) -> Result<(Point3<f64>, Point3<f64>), CellError> {
    let g = model.part(&model.geometry.fixture_part)?;
    let table_T_fixture = model.geometry.base_T_table.inverse() * model.geometry.base_T_fixture;
    let (lo, hi) = g.aabb;
    let mut min = Point3::new(f64::INFINITY, f64::INFINITY, f64::INFINITY);
    let mut max = Point3::new(f64::NEG_INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY);
    for i in 0..8 {
        let c = Point3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        );
        let p = table_T_fixture * c;
        min = min.inf(&p);
        max = max.sup(&p);
    }
    Ok((
        Point3::new(
            min.x - FIXTURE_MARGIN,
            min.y - FIXTURE_MARGIN,
            min.z.max(0.0),
        ),
        Point3::new(
            max.x + FIXTURE_MARGIN,
            max.y + FIXTURE_MARGIN,
            max.z + PARTS_ABOVE,
        ),
    ))
}

/// The window of the image that the calibrated camera sees the fixture box ([`fixture_box`])
/// in: what a seat-check capture renders.
#[allow(non_snake_case)]
pub fn calibrated_fixture_window(model: &CellModel) -> Result<Window, CellError> {
    let spec = &model.spec;
    let table_T_camera =
        spec.base_T_table.isometry().inverse() * spec.camera.base_T_camera.isometry();
    let (lo, hi) = fixture_box(model)?;
    window_covering(&spec.camera.intrinsics, &table_T_camera, &lo, &hi).ok_or_else(|| {
        CellError::Camera("the fixture is not in the calibrated camera's view".into())
    })
}

/// Renders the fixture with `parts` (catalog name, true pose in the base frame) standing in it
/// as the camera at `base_T_camera` (the true pose) sees them, over the window where the
/// calibrated camera sees the fixture ([`calibrated_fixture_window`]).
#[allow(non_snake_case)]
pub fn render_fixture(
    model: &CellModel,
    parts: &[(&str, Isometry3<f64>)],
    base_T_camera: &Isometry3<f64>,
    rng: &mut ChaCha8Rng,
) -> Result<FixtureImage, CellError> {
    let camera = &model.spec.camera.intrinsics;
    let window = calibrated_fixture_window(model)?;
    let fixture = model.fixture_model.as_ref().ok_or_else(|| {
        CellError::Camera(format!(
            "no render model for the fixture {}",
            model.geometry.fixture_part
        ))
    })?;
    let table_T_base = model.geometry.base_T_table.inverse();
    let table_T_camera = table_T_base * base_T_camera;
    // The feeder's models, then the fixture's.
    let mut models: Vec<PartModel> = model.part_models.clone();
    models.push(fixture.clone());
    let mut placed = vec![PlacedPart {
        model: models.len() - 1,
        table_T_part: table_T_base * model.geometry.base_T_fixture,
    }];
    for (name, base_T_part) in parts {
        let index = model
            .part_models
            .iter()
            .position(|m| m.name == *name)
            .ok_or_else(|| CellError::Camera(format!("no render model for part {name}")))?;
        placed.push(PlacedPart {
            model: index,
            table_T_part: table_T_base * base_T_part,
        });
    }
    let layout = model.spec.board_layout().ok_or_else(|| {
        CellError::Camera("the scenario names a board that was never loaded".into())
    })?;
    let scene = nominal_scene_on(&models, &placed, TagBoard::new(Board::clone(&layout)));
    let settings = RenderSettings {
        full_masks: false,
        ..RenderSettings::default()
    };
    let mut renderer = IncrementalRenderer::new();
    let output = renderer.render(&scene, camera, &table_T_camera, window, &settings, None);
    let sensor = SensorModel::default().metered(output, METER_TARGET, METER_SHARE);
    let image = sensor
        .capture(output, rng)
        .map_err(|e| CellError::Camera(e.to_string()))?;
    Ok(FixtureImage { image, window })
}

impl SimCell {
    /// The fixture window as the camera sees it now: the fixture and every part placed so far
    /// at its true pose, from the true camera, through the sensor. Its noise comes from a
    /// stream of its own (seeded by the episode and how many parts are placed), so a seat
    /// check leaves every other capture's noise as it was.
    pub fn render_fixture(&self) -> Result<FixtureImage, CellError> {
        let (seed, episode) = self.episode();
        let mut rng = ChaCha8Rng::seed_from_u64(
            seed.wrapping_mul(0x2545_F491_4F6C_DD1D)
                ^ episode.wrapping_add(0xF1C7_0BE5)
                ^ (self.placed().len() as u64).wrapping_mul(0x9E37_79B9),
        );
        let parts: Vec<(&str, Isometry3<f64>)> = self
            .placed()
            .iter()
            .map(|p| (p.part.as_str(), p.base_T_part))
            .collect();
        render_fixture(self.model(), &parts, &self.base_T_camera_true(), &mut rng)
    }
}
