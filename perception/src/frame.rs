//! What the camera delivers: a frame of pixels (or, in simulation only, the true scene) with the
//! calibration it is read with. This is the input side of the perception seam.

use nalgebra::Isometry3;

use crate::Camera;

/// Pixels of a region of the camera sensor: the whole sensor in production, the feeder window
/// when the simulator renders only what the feeder covers.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameImage {
    /// The pixels: 8- or 16-bit, mono or colour.
    pub pixels: image::DynamicImage,
    /// Sensor pixel of the image's top-left pixel (`[column, row]`).
    pub origin: [u32; 2],
}

impl FrameImage {
    /// An image that covers the whole sensor.
    pub fn full(pixels: image::DynamicImage) -> Self {
        Self {
            pixels,
            origin: [0, 0],
        }
    }

    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.pixels.width()
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.pixels.height()
    }

    /// Checks that the image lies on the sensor of `camera`; the error says how it does not.
    pub fn check_on_sensor(&self, camera: &Camera) -> Result<(), String> {
        let (w, h) = (u64::from(self.width()), u64::from(self.height()));
        let (x0, y0) = (u64::from(self.origin[0]), u64::from(self.origin[1]));
        let (cw, ch) = (u64::from(camera.width), u64::from(camera.height));
        if w == 0 || h == 0 {
            return Err("the image is empty".into());
        }
        if x0 + w > cw || y0 + h > ch {
            return Err(format!(
                "a {w} × {h} image at sensor pixel ({x0}, {y0}) does not fit the {cw} × {ch} sensor"
            ));
        }
        Ok(())
    }
}

/// A part the camera sees, as the simulator knows it (never available in production).
#[derive(Debug, Clone, PartialEq)]
#[allow(non_snake_case)]
pub struct TruePart {
    /// Instance id in the simulated world (diagnostics only).
    pub instance: u32,
    /// Catalog name.
    pub part: String,
    /// True pose of the part in the true camera frame.
    pub camera_T_part: Isometry3<f64>,
}

/// What the camera delivered.
#[derive(Debug, Clone, PartialEq)]
pub enum FrameContent {
    /// The simulated scene as poses (keypoint-noise perception only; the learned pipeline
    /// refuses it, so no simulator truth can reach it).
    Simulated(Vec<TruePart>),
    /// Pixels from a camera, real or rendered.
    Image(FrameImage),
}

/// One camera frame with the calibration it is interpreted with.
#[derive(Debug, Clone, PartialEq)]
#[allow(non_snake_case)]
pub struct Frame {
    /// Intrinsics and distortion of the whole sensor.
    pub camera: Camera,
    /// Calibrated camera pose in the robot base frame (the true one may differ).
    pub base_T_camera: Isometry3<f64>,
    /// The pixels, or the simulated scene.
    pub content: FrameContent,
}
