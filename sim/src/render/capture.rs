//! Window captures: render only the pixels of the full camera image that cover a region of the
//! table (the feeder, the fixture), through the sensor, with the same pixels as a full render.

use image::RgbImage;
use nalgebra::{Isometry3, Point3};
use perception::camera::Camera;
use rand::Rng;

use super::aabb::box_corners;
use super::{RenderOutput, RenderScene, RenderSettings, SensorError, SensorModel, Window, render};

/// Pixels added around the projected corners of a region: its edges bow slightly between the
/// corners through the lens distortion.
const REGION_MARGIN_PX: f64 = 2.0;

/// The smallest window of `camera`'s image, placed at `table_T_camera`, that shows the
/// table-frame box `lo`–`hi` (e.g. the feeder rectangle from the table up to the parts' height),
/// clipped to the image; `None` when a corner is behind the camera or the box is out of view.
#[allow(non_snake_case)]
pub fn window_covering(
    camera: &Camera,
    table_T_camera: &Isometry3<f64>,
    lo: &Point3<f64>,
    hi: &Point3<f64>,
) -> Option<Window> {
    let camera_T_table = table_T_camera.inverse();
    let (mut u0, mut v0, mut u1, mut v1) = (
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    );
    for c in box_corners(lo, hi) {
        let p = camera.project(&(camera_T_table * c)).ok()?;
        if !(p.x.is_finite() && p.y.is_finite()) {
            return None;
        }
        u0 = u0.min(p.x);
        v0 = v0.min(p.y);
        u1 = u1.max(p.x);
        v1 = v1.max(p.y);
    }
    let (w, h) = (camera.width as f64, camera.height as f64);
    let x0 = (u0 - REGION_MARGIN_PX).floor().clamp(0.0, w);
    let y0 = (v0 - REGION_MARGIN_PX).floor().clamp(0.0, h);
    let x1 = (u1 + REGION_MARGIN_PX).ceil().clamp(0.0, w - 1.0) + 1.0;
    let y1 = (v1 + REGION_MARGIN_PX).ceil().clamp(0.0, h - 1.0) + 1.0;
    (x1 > x0 && y1 > y0).then_some(Window {
        x0: x0 as u32,
        y0: y0 as u32,
        width: (x1 - x0) as u32,
        height: (y1 - y0) as u32,
    })
}

/// A rendered window and its 8-bit image through the sensor.
#[derive(Debug, Clone)]
pub struct Capture {
    /// Radiance, depth, visible ids and masks of the window (camera pixel coordinates).
    pub output: RenderOutput,
    /// What the camera delivers for the window: exposure, blur, noise, sRGB.
    pub image: RgbImage,
}

/// Renders `window` of `camera` at `table_T_camera` and passes it through `sensor`: the capture a
/// simulated run makes of the feeder. The radiance equals the same region of a full-frame render
/// pixel for pixel; the sensor noise comes from `rng`.
#[allow(non_snake_case)]
pub fn capture(
    scene: &RenderScene,
    camera: &Camera,
    table_T_camera: &Isometry3<f64>,
    window: Window,
    settings: &RenderSettings,
    sensor: &SensorModel,
    rng: &mut impl Rng,
) -> Result<Capture, SensorError> {
    sensor.validate()?;
    let output = render(scene, camera, table_T_camera, window, settings);
    let image = sensor.capture(&output, rng)?;
    Ok(Capture { output, image })
}
