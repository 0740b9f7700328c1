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

/// A rectangular area light (a light box or panel) emitting downwards from one face, table
/// frame. Rendered as `samples` × `samples` small sphere lights over its face, so it casts soft
/// shadows and broad highlights through the same path as [`PointLight`]s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AreaLight {
    /// Centre of the emitting face, metres.
    pub centre: Point3<f64>,
    /// Half the face's first side (a vector along it), metres.
    pub half_u: Vector3<f64>,
    /// Half the face's second side, metres; the face emits towards `half_u × half_v`.
    pub half_v: Vector3<f64>,
    /// Emitted radiance per channel (a Lambertian emitter).
    pub radiance: [f64; 3],
}

impl AreaLight {
    /// The face's `samples` × `samples` cells as sphere lights (radius half a cell's side), each
    /// of the intensity its cell sends towards `target` (radiance × area × the emission cosine
    /// there; none when `target` is behind the face).
    pub fn point_lights(&self, samples: usize, target: &Point3<f64>) -> Vec<PointLight> {
        let n = samples.max(1);
        let normal = self.half_u.cross(&self.half_v);
        let area = 4.0 * normal.norm();
        let Some(normal) = normal.try_normalize(1e-15) else {
            return Vec::new();
        };
        let cell = area / (n * n) as f64;
        let side = (2.0 * self.half_u.norm()).min(2.0 * self.half_v.norm()) / n as f64;
        let mut out = Vec::with_capacity(n * n);
        for j in 0..n {
            for i in 0..n {
                let fu = (i as f64 + 0.5) / n as f64 * 2.0 - 1.0;
                let fv = (j as f64 + 0.5) / n as f64 * 2.0 - 1.0;
                let position = self.centre + self.half_u * fu + self.half_v * fv;
                let cos = (target - position)
                    .try_normalize(1e-15)
                    .map_or(0.0, |d| d.dot(&normal).max(0.0));
                out.push(PointLight {
                    position,
                    intensity: self.radiance.map(|l| l * cell * cos),
                    radius: side / 2.0,
                });
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Below its centre an area light's sphere lights deliver the face's exact irradiance; above
    /// its face, nothing.
    #[test]
    fn an_area_light_sends_radiance_times_area() {
        let light = AreaLight {
            centre: Point3::new(0.0, 0.0, 1.0),
            half_u: Vector3::new(0.1, 0.0, 0.0),
            half_v: Vector3::new(0.0, -0.2, 0.0),
            radiance: [2.0, 1.0, 0.5],
        };
        let target = Point3::origin();
        let points = light.point_lights(3, &target);
        assert_eq!(points.len(), 9);
        let e: f64 = points
            .iter()
            .map(|p| {
                let d = p.position - target;
                p.intensity[0] * d.z / d.norm() / d.norm_squared()
            })
            .sum();
        // The exact irradiance: L ∫∫ h² / (h² + x² + y²)² over the face (midpoint rule).
        let m = 400;
        let mut want = 0.0;
        for i in 0..m {
            for j in 0..m {
                let x = -0.1 + 0.2 * (i as f64 + 0.5) / m as f64;
                let y = -0.2 + 0.4 * (j as f64 + 0.5) / m as f64;
                want += 2.0 / (1.0 + x * x + y * y).powi(2) * (0.2 * 0.4) / (m * m) as f64;
            }
        }
        assert!((e - want).abs() < 0.005 * want, "{e} vs {want}");
        let above = light.point_lights(2, &Point3::new(0.0, 0.0, 2.0));
        assert!(above.iter().all(|p| p.intensity == [0.0; 3]));
    }
}
