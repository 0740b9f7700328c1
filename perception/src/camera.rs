//! The workspace's one camera model: pinhole intrinsics with Brown–Conrady distortion, in OpenCV's
//! conventions (camera frame x right, y down, z forward; pixel centres at integer coordinates).
//!
//! The simulator renders through [`Camera::project`] and perception inverts it with
//! [`Camera::unproject`] and [`Camera::pixel_ray`], so the two cannot disagree.

use nalgebra::{Isometry3, Matrix2, Matrix2x3, Matrix3, Point2, Point3, Unit, Vector2, Vector3};
use serde::{Deserialize, Serialize};

/// Why a camera operation could not produce a result.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CameraError {
    /// The point is on or behind the image plane (z ≤ 0 in the camera frame).
    #[error("point is behind the camera (z = {z} m); it has no projection")]
    BehindCamera {
        /// Its depth in metres.
        z: f64,
    },
    /// An input coordinate is NaN or infinite.
    #[error("non-finite input: {0}")]
    NonFinite(&'static str),
    /// The intrinsics are unusable (non-positive focal length or size, non-finite value).
    #[error("invalid camera intrinsics: {0}")]
    InvalidIntrinsics(String),
    /// Undistortion did not converge: the pixel lies where the distortion model folds over.
    #[error(
        "cannot undistort pixel ({u:.2}, {v:.2}): outside the region where the distortion is invertible"
    )]
    NotInvertible {
        /// Pixel column.
        u: f64,
        /// Pixel row.
        v: f64,
    },
}

/// Brown–Conrady lens distortion in OpenCV's order (k1, k2, p1, p2, k3), on normalised coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Distortion {
    /// First radial coefficient.
    pub k1: f64,
    /// Second radial coefficient.
    pub k2: f64,
    /// First tangential coefficient.
    pub p1: f64,
    /// Second tangential coefficient.
    pub p2: f64,
    /// Third radial coefficient.
    #[serde(default)]
    pub k3: f64,
}

impl Distortion {
    /// No distortion.
    pub const NONE: Distortion = Distortion {
        k1: 0.0,
        k2: 0.0,
        p1: 0.0,
        p2: 0.0,
        k3: 0.0,
    };

    /// Whether every coefficient is zero.
    pub fn is_none(&self) -> bool {
        *self == Self::NONE
    }

    /// The coefficients as OpenCV's array `[k1, k2, p1, p2, k3]`.
    pub fn as_array(&self) -> [f64; 5] {
        [self.k1, self.k2, self.p1, self.p2, self.k3]
    }

    /// Distorts an ideal normalised point (x/z, y/z).
    pub fn apply(&self, p: Vector2<f64>) -> Vector2<f64> {
        let (x, y) = (p.x, p.y);
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        Vector2::new(
            x * radial + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x),
            y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y,
        )
    }

    /// Jacobian of [`Distortion::apply`] with respect to the ideal normalised point.
    pub fn jacobian(&self, p: Vector2<f64>) -> Matrix2<f64> {
        let (x, y) = (p.x, p.y);
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        // d(radial)/d(r2)
        let dradial = self.k1 + r2 * (2.0 * self.k2 + 3.0 * r2 * self.k3);
        let dxx = radial + x * dradial * 2.0 * x + 2.0 * self.p1 * y + self.p2 * 6.0 * x;
        let dxy = x * dradial * 2.0 * y + 2.0 * self.p1 * x + self.p2 * 2.0 * y;
        let dyx = y * dradial * 2.0 * x + self.p1 * 2.0 * x + 2.0 * self.p2 * y;
        let dyy = radial + y * dradial * 2.0 * y + self.p1 * 6.0 * y + 2.0 * self.p2 * x;
        Matrix2::new(dxx, dxy, dyx, dyy)
    }

    /// Inverts [`Distortion::apply`] by damped Newton iterations from the distorted point moved
    /// back by its own distortion (where that is closer; the renderer inverts every ray, so a
    /// start one iteration nearer matters).
    ///
    /// Returns `None` when it does not converge to 1e-13 (normalised units), which happens only
    /// where the model folds over (far outside any real lens's field of view).
    pub fn remove(&self, distorted: Vector2<f64>) -> Option<Vector2<f64>> {
        if self.is_none() {
            return Some(distorted);
        }
        let mut p = distorted;
        let mut residual = self.apply(p) - distorted;
        let nearer = distorted - residual;
        let r = self.apply(nearer) - distorted;
        if r.norm() < residual.norm() {
            (p, residual) = (nearer, r);
        }
        for _ in 0..50 {
            let err = residual.norm();
            if err < 1e-13 {
                return self.is_unfolded(p, distorted).then_some(p);
            }
            let step = self.jacobian(p).try_inverse()? * residual;
            // Backtrack until the residual shrinks: robust where the model is strongly non-linear.
            let mut scale = 1.0;
            loop {
                let candidate = p - step * scale;
                let r = self.apply(candidate) - distorted;
                if r.norm() < err || scale < 1e-6 {
                    p = candidate;
                    residual = r;
                    break;
                }
                scale *= 0.5;
            }
        }
        (residual.norm() < 1e-12 && self.is_unfolded(p, distorted)).then_some(p)
    }

    /// Whether `p` lies where the model is locally invertible and keeps its side of the axis: past
    /// the fold a root exists on the opposite side, which is not the ray the pixel saw.
    fn is_unfolded(&self, p: Vector2<f64>, distorted: Vector2<f64>) -> bool {
        self.jacobian(p).determinant() > 0.0 && p.dot(&distorted) >= 0.0
    }
}

/// A pinhole camera with Brown–Conrady distortion: intrinsics in pixels, image size in pixels.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Camera {
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point column, pixels (pixel centres at integers).
    pub cx: f64,
    /// Principal point row, pixels.
    pub cy: f64,
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Lens distortion.
    #[serde(default)]
    pub distortion: Distortion,
}

impl Camera {
    /// The image scale on the table at `camera_T_table`, pixels per mm: the focal length over
    /// the table plane's distance from the camera.
    #[allow(non_snake_case)]
    pub fn table_px_per_mm(&self, camera_T_table: &Isometry3<f64>) -> f64 {
        let normal = camera_T_table.rotation * Vector3::z();
        let distance_mm = 1000.0 * normal.dot(&camera_T_table.translation.vector).abs();
        self.fx / distance_mm.max(1.0)
    }

    /// A camera from intrinsics, checked: focal lengths and size positive, everything finite.
    pub fn new(
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
        width: u32,
        height: u32,
        distortion: Distortion,
    ) -> Result<Self, CameraError> {
        let camera = Self {
            fx,
            fy,
            cx,
            cy,
            width,
            height,
            distortion,
        };
        camera.validate()?;
        Ok(camera)
    }

    /// Checks the intrinsics (for cameras read from files).
    pub fn validate(&self) -> Result<(), CameraError> {
        let values = [self.fx, self.fy, self.cx, self.cy];
        if values
            .iter()
            .chain(&self.distortion.as_array())
            .any(|v| !v.is_finite())
        {
            return Err(CameraError::InvalidIntrinsics(
                "a value is NaN or infinite".into(),
            ));
        }
        if self.fx <= 0.0 || self.fy <= 0.0 {
            return Err(CameraError::InvalidIntrinsics(format!(
                "focal lengths must be positive (fx = {}, fy = {})",
                self.fx, self.fy
            )));
        }
        if self.width == 0 || self.height == 0 {
            return Err(CameraError::InvalidIntrinsics(format!(
                "image size must be positive ({} × {})",
                self.width, self.height
            )));
        }
        Ok(())
    }

    /// The seed's Basler 20 MP camera with its 25 mm lens (5472 × 3648 px, calibrated intrinsics).
    pub fn basler_seed() -> Self {
        Self {
            fx: 10704.06,
            fy: 10727.44,
            cx: 2694.11,
            cy: 1669.17,
            width: 5472,
            height: 3648,
            distortion: Distortion {
                k1: 0.0079,
                k2: -0.389,
                p1: -0.0027,
                p2: 0.0032,
                k3: 0.0,
            },
        }
    }

    /// The intrinsic matrix K.
    pub fn k_matrix(&self) -> Matrix3<f64> {
        Matrix3::new(self.fx, 0.0, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0)
    }

    /// Pixel of a distorted normalised point.
    pub fn normalized_to_pixel(&self, distorted: Vector2<f64>) -> Point2<f64> {
        Point2::new(
            self.fx * distorted.x + self.cx,
            self.fy * distorted.y + self.cy,
        )
    }

    /// Distorted normalised point of a pixel.
    pub fn pixel_to_normalized(&self, pixel: Point2<f64>) -> Vector2<f64> {
        Vector2::new((pixel.x - self.cx) / self.fx, (pixel.y - self.cy) / self.fy)
    }

    /// Projects a camera-frame point to pixels, with distortion.
    pub fn project(&self, p: &Point3<f64>) -> Result<Point2<f64>, CameraError> {
        if !(p.x.is_finite() && p.y.is_finite() && p.z.is_finite()) {
            return Err(CameraError::NonFinite("point to project"));
        }
        if p.z <= 0.0 {
            return Err(CameraError::BehindCamera { z: p.z });
        }
        let ideal = Vector2::new(p.x / p.z, p.y / p.z);
        Ok(self.normalized_to_pixel(self.distortion.apply(ideal)))
    }

    /// [`Camera::project`] with its Jacobian: the pixel and d(pixel)/d(point).
    pub fn project_with_jacobian(
        &self,
        p: &Point3<f64>,
    ) -> Result<(Point2<f64>, Matrix2x3<f64>), CameraError> {
        let pixel = self.project(p)?;
        let iz = 1.0 / p.z;
        let ideal = Vector2::new(p.x * iz, p.y * iz);
        let d_ideal = Matrix2x3::new(iz, 0.0, -ideal.x * iz, 0.0, iz, -ideal.y * iz);
        let d_pixel = Matrix2::new(self.fx, 0.0, 0.0, self.fy) * self.distortion.jacobian(ideal);
        Ok((pixel, d_pixel * d_ideal))
    }

    /// The ideal (undistorted) normalised coordinates (x/z, y/z) seen at a pixel.
    pub fn unproject(&self, pixel: Point2<f64>) -> Result<Vector2<f64>, CameraError> {
        if !(pixel.x.is_finite() && pixel.y.is_finite()) {
            return Err(CameraError::NonFinite("pixel to unproject"));
        }
        self.distortion
            .remove(self.pixel_to_normalized(pixel))
            .ok_or(CameraError::NotInvertible {
                u: pixel.x,
                v: pixel.y,
            })
    }

    /// Unit direction, in the camera frame, of the ray seen at a pixel.
    pub fn pixel_ray(&self, pixel: Point2<f64>) -> Result<Unit<Vector3<f64>>, CameraError> {
        let n = self.unproject(pixel)?;
        Ok(Unit::new_normalize(Vector3::new(n.x, n.y, 1.0)))
    }

    /// Whether a pixel lies inside the image (centres at integers, so the image spans −0.5 … w − 0.5).
    pub fn contains(&self, pixel: Point2<f64>) -> bool {
        pixel.x >= -0.5
            && pixel.y >= -0.5
            && pixel.x < f64::from(self.width) - 0.5
            && pixel.y < f64::from(self.height) - 0.5
    }

    /// The camera of a `w × h` window whose top-left pixel is `(u0, v0)` of this image.
    ///
    /// Pixel `(u, v)` here is pixel `(u − u0, v − v0)` there: the principal point shifts, the
    /// focal lengths and distortion (defined on normalised coordinates) do not change.
    pub fn crop(&self, u0: f64, v0: f64, w: u32, h: u32) -> Self {
        Self {
            cx: self.cx - u0,
            cy: self.cy - v0,
            width: w,
            height: h,
            ..*self
        }
    }

    /// The camera of a `size × size` crop centred on pixel `(u, v)`, as the seed cuts keypoint
    /// crops: cx' = cx + size/2 − u, cy' = cy + size/2 − v.
    pub fn crop_centred(&self, u: f64, v: f64, size: u32) -> Self {
        let half = f64::from(size) / 2.0;
        self.crop(u - half, v - half, size, size)
    }

    /// The camera of this image resampled by `factor` (0.25 for a quarter-size overview).
    ///
    /// Pixel centres stay at integers: the edge of the image maps to the edge, so
    /// u' = factor · (u + ½) − ½. The size is rounded to whole pixels.
    pub fn scaled(&self, factor: f64) -> Result<Self, CameraError> {
        if !factor.is_finite() || factor <= 0.0 {
            return Err(CameraError::InvalidIntrinsics(format!(
                "scale factor must be positive and finite, got {factor}"
            )));
        }
        let scaled = Self {
            fx: self.fx * factor,
            fy: self.fy * factor,
            cx: factor * (self.cx + 0.5) - 0.5,
            cy: factor * (self.cy + 0.5) - 0.5,
            width: (f64::from(self.width) * factor).round().max(1.0) as u32,
            height: (f64::from(self.height) * factor).round().max(1.0) as u32,
            distortion: self.distortion,
        };
        scaled.validate()?;
        Ok(scaled)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn the_projection_jacobian_matches_finite_differences() {
        let cam = Camera::basler_seed();
        for p in [
            Point3::new(0.0, 0.0, 1.5),
            Point3::new(0.2, -0.15, 1.4),
            Point3::new(-0.5, 0.3, 1.2),
        ] {
            let (pixel, j) = cam.project_with_jacobian(&p).unwrap();
            assert_eq!(pixel, cam.project(&p).unwrap());
            for axis in 0..3 {
                let h = 1e-7;
                let mut q = p;
                q[axis] += h;
                let numeric = (cam.project(&q).unwrap() - pixel) / h;
                let analytic = j.column(axis);
                assert!(
                    (numeric - analytic).norm() < 1e-3 * analytic.norm().max(1.0),
                    "axis {axis} at {p}: {numeric} vs {analytic}"
                );
            }
        }
    }

    #[test]
    fn projection_round_trips_with_distortion_over_the_whole_image() {
        let cam = Camera::basler_seed();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for _ in 0..2000 {
            let u = rng.random_range(0.0..f64::from(cam.width));
            let v = rng.random_range(0.0..f64::from(cam.height));
            let depth = rng.random_range(0.3..3.0);
            let ray = cam.pixel_ray(Point2::new(u, v)).unwrap();
            let p = Point3::from(ray.into_inner() * depth / ray.z);
            assert!((p.z - depth).abs() < 1e-12);
            let back = cam.project(&p).unwrap();
            assert!(
                (back - Point2::new(u, v)).norm() < 1e-8,
                "({u}, {v}) came back as {back}"
            );
        }
    }

    #[test]
    fn distortion_moves_points_and_removal_inverts_it() {
        let d = Camera::basler_seed().distortion;
        let p = Vector2::new(0.2, -0.15);
        let q = d.apply(p);
        assert!((q - p).norm() > 1e-4, "the seed lens distorts measurably");
        assert!((d.remove(q).unwrap() - p).norm() < 1e-13);
        // Jacobian against central differences.
        let j = d.jacobian(p);
        let h = 1e-7;
        for i in 0..2 {
            let mut e = Vector2::zeros();
            e[i] = h;
            let num = (d.apply(p + e) - d.apply(p - e)) / (2.0 * h);
            assert!((num - j.column(i)).norm() < 1e-7);
        }
    }

    #[test]
    fn principal_point_projects_to_optical_axis() {
        let cam = Camera::basler_seed();
        let px = cam.project(&Point3::new(0.0, 0.0, 1.5)).unwrap();
        assert!((px - Point2::new(cam.cx, cam.cy)).norm() < 1e-12);
        let ray = cam.pixel_ray(Point2::new(cam.cx, cam.cy)).unwrap();
        assert!((ray.into_inner() - Vector3::z()).norm() < 1e-12);
    }

    #[test]
    fn crop_shifts_the_principal_point_as_the_seed_does() {
        let cam = Camera::basler_seed();
        let (u, v) = (3001.0, 1200.0);
        let crop = cam.crop_centred(u, v, 128);
        assert_eq!((crop.width, crop.height), (128, 128));
        assert!((crop.cx - (cam.cx + 64.0 - u)).abs() < 1e-12);
        assert!((crop.cy - (cam.cy + 64.0 - v)).abs() < 1e-12);
        // A point imaged at (u, v) in the full frame lands at the crop's centre (64, 64).
        let ray = cam.pixel_ray(Point2::new(u, v)).unwrap();
        let p = Point3::from(ray.into_inner() * 1.6);
        let in_crop = crop.project(&p).unwrap();
        assert!((in_crop - Point2::new(64.0, 64.0)).norm() < 1e-9);
        assert!(crop.contains(in_crop));
    }

    #[test]
    fn scaling_keeps_image_edges_and_rays() {
        let cam = Camera::basler_seed();
        let small = cam.scaled(0.25).unwrap();
        assert_eq!((small.width, small.height), (1368, 912));
        let p = Point3::new(0.1, -0.05, 1.5);
        let full = cam.project(&p).unwrap();
        let quarter = small.project(&p).unwrap();
        assert!((quarter.x - (0.25 * (full.x + 0.5) - 0.5)).abs() < 1e-9);
        assert!((quarter.y - (0.25 * (full.y + 0.5) - 0.5)).abs() < 1e-9);
        assert!(cam.scaled(0.0).is_err());
        assert!(cam.scaled(f64::NAN).is_err());
    }

    #[test]
    fn bad_input_is_a_typed_error() {
        let cam = Camera::basler_seed();
        assert_eq!(
            cam.project(&Point3::new(0.0, 0.0, -1.0)),
            Err(CameraError::BehindCamera { z: -1.0 })
        );
        assert!(matches!(
            cam.project(&Point3::new(0.0, 0.0, 0.0)),
            Err(CameraError::BehindCamera { .. })
        ));
        assert!(matches!(
            cam.project(&Point3::new(f64::NAN, 0.0, 1.0)),
            Err(CameraError::NonFinite(_))
        ));
        assert!(matches!(
            cam.pixel_ray(Point2::new(f64::INFINITY, 0.0)),
            Err(CameraError::NonFinite(_))
        ));
        assert!(Camera::new(-1.0, 1.0, 0.0, 0.0, 10, 10, Distortion::NONE).is_err());
        assert!(Camera::new(1.0, 1.0, 0.0, 0.0, 0, 10, Distortion::NONE).is_err());
        // Far outside the field of view the seed's model folds over: a typed error, not garbage.
        assert!(matches!(
            cam.unproject(Point2::new(1e6, 1e6)),
            Err(CameraError::NotInvertible { .. })
        ));
    }

    #[test]
    fn serde_round_trip() {
        let cam = Camera::basler_seed();
        let text = toml::to_string(&cam).unwrap();
        let back: Camera = toml::from_str(&text).unwrap();
        assert_eq!(cam, back);
    }
}
