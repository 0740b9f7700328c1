//! Where the camera sees the feeder: the window of the image that covers the feeder rectangle,
//! for any camera pose and for the scenario's calibrated one, so a simulated capture renders and
//! learned perception searches the same pixels.

use nalgebra::{Isometry3, Point3};

use crate::config::CellSpec;
use crate::render::{Window, window_covering};

/// Margin around the feeder rectangle that the window also covers (parts overhanging its edge),
/// metres.
const FEEDER_MARGIN: f64 = 0.008;
/// Height above the table the window covers (the tallest resting part), metres.
const PART_HEIGHT: f64 = 0.006;

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
