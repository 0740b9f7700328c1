//! The scene's lights: point (or small sphere) lights, and the cube around one that bounds where
//! its shadows can come from.

use nalgebra::{Point3, Vector3};

use super::aabb::box_corners;

/// A point light in the table frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointLight {
    /// Position in the table frame, metres.
    pub position: Point3<f64>,
    /// Radiant intensity per channel (linear RGB, W/sr-like units: irradiance at 1 m).
    pub intensity: [f64; 3],
    /// Radius of the emitting sphere, metres (0 for a point): softens shadows and widens
    /// highlights.
    pub radius: f64,
}

/// The corners of the cube around a light's sphere (its centre, eight times, for a point light).
pub(crate) fn light_cube(light: &PointLight) -> [Point3<f64>; 8] {
    let r = Vector3::repeat(light.radius);
    box_corners(&(light.position - r), &(light.position + r))
}
