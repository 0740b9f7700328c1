//! Axis-aligned boxes as the renderer bounds things with them: a box's eight corners, to project
//! or transform.

use nalgebra::Point3;

/// The eight corners of the box from `lo` to `hi`.
pub(crate) fn box_corners(lo: &Point3<f64>, hi: &Point3<f64>) -> [Point3<f64>; 8] {
    std::array::from_fn(|k| {
        Point3::new(
            if k & 1 == 0 { lo.x } else { hi.x },
            if k & 2 == 0 { lo.y } else { hi.y },
            if k & 4 == 0 { lo.z } else { hi.z },
        )
    })
}
