//! The camera's view of the calibration board under the renderer's randomisation: what
//! `cell board-study` and the calibration tests detect, with the true board pose beside it.
//!
//! The board lies on the table with its top face at z = 0, centred on the origin, so the board
//! frame is the table frame and `camera_T_board` is the inverse of the camera's table pose.

use std::sync::Arc;

use image::{DynamicImage, GrayImage};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use perception::FrameImage;
use perception::calibration::Board;
use perception::camera::Camera;
use rand::Rng;

use super::{
    METER_SHARE, METER_TARGET, Randomisation, SampledScene, SceneError, SceneRequest, dress_scene,
};
use crate::render::{
    RenderOutput, RenderSettings, SensorError, SensorModel, Window, render, window_covering,
};

/// Height of the nominal camera above the board when none is given, metres (the scenarios' 1.51 m).
pub const NOMINAL_HEIGHT: f64 = 1.51;

/// Pixels around the plate's projection that a board window also shows (the blur and the
/// detector's search reach past the plate's edge).
const WINDOW_MARGIN_PX: f64 = 24.0;

/// One randomised view of the board: scene, camera pose and sensor, ready to render.
#[derive(Debug, Clone)]
pub struct BoardView {
    /// The dressed scene (no parts): board print and wear, table, lights, camera pose, sensor.
    pub scene: SampledScene,
    /// The camera that sees it.
    pub camera: Camera,
}

/// A rendered view: the camera's pixels and the truth they were made from.
#[derive(Debug, Clone)]
#[allow(non_snake_case)]
pub struct BoardImage {
    /// The 8-bit grey pixels of the window that covers the board (sensor coordinates in `origin`).
    pub image: FrameImage,
    /// The true pose of the board in the camera frame.
    pub camera_T_board: Isometry3<f64>,
}

/// Draws a view of `board` under `rand`: lights, print, wear, table and sensor as
/// [`dress_scene`] draws them for a feeder scene, and a camera at the randomised height looking
/// down at the board centre from its randomised x, y offset (a few degrees of tilt).
pub fn sample_board_view(
    board: &Board,
    camera: &Camera,
    rand: &Randomisation,
    rng: &mut impl Rng,
) -> Result<BoardView, SceneError> {
    let request = SceneRequest {
        counts: Vec::new(),
        drop_centre: (0.0, 0.0),
        drop_half: 0.0,
        aim_at_part: None,
        nominal_table_T_camera: nominal_table_T_camera(NOMINAL_HEIGHT),
    };
    let mut scene = dress_scene(&[], Vec::new(), &request, rand, rng)?;
    if let Some(b) = scene.render.board.as_mut() {
        b.layout = Arc::new(board.clone());
    }
    Ok(BoardView {
        scene,
        camera: *camera,
    })
}

/// The scenarios' camera orientation (x along table x, y along table −y, looking down) at
/// `height` above the board centre.
#[allow(non_snake_case)]
pub fn nominal_table_T_camera(height: f64) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(0.0, 0.0, height),
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
    )
}

impl BoardView {
    /// The true pose of the board in the camera frame.
    #[allow(non_snake_case)]
    pub fn camera_T_board(&self) -> Isometry3<f64> {
        self.scene.table_T_camera.inverse()
    }

    /// The window of the camera image that shows the whole plate (clipped to the sensor);
    /// `None` when the plate is behind the camera or out of view.
    pub fn window(&self) -> Option<Window> {
        let [hx, hy] = self
            .scene
            .render
            .board
            .as_ref()
            .map_or([0.105, 0.105], |b| b.half_extents());
        let w = window_covering(
            &self.camera,
            &self.scene.table_T_camera,
            &Point3::new(-hx, -hy, 0.0),
            &Point3::new(hx, hy, 0.0),
        )?;
        let m = WINDOW_MARGIN_PX as u32;
        let x0 = w.x0.saturating_sub(m);
        let y0 = w.y0.saturating_sub(m);
        let x1 = (w.x0 + w.width + m).min(self.camera.width);
        let y1 = (w.y0 + w.height + m).min(self.camera.height);
        Some(Window {
            x0,
            y0,
            width: x1 - x0,
            height: y1 - y0,
        })
    }

    /// Renders `window` (by default [`BoardView::window`]) through the view's sensor, with
    /// sensor noise from `rng`, as 8-bit grey (the luma of the sensor's sRGB).
    pub fn render(
        &self,
        window: Window,
        settings: &RenderSettings,
        rng: &mut impl Rng,
    ) -> Result<BoardImage, SensorError> {
        let out = render(
            &self.scene.render,
            &self.camera,
            &self.scene.table_T_camera,
            window,
            settings,
        );
        let sensor = self.metered_sensor(&out);
        let rgb = sensor.capture(&out, rng)?;
        let grey = DynamicImage::ImageRgb8(rgb).into_luma8();
        Ok(BoardImage {
            image: FrameImage {
                pixels: DynamicImage::ImageLuma8(grey),
                origin: [window.x0, window.y0],
            },
            camera_T_board: self.camera_T_board(),
        })
    }
}

impl BoardView {
    /// The sensor for a render of this view: highlight-priority metering on the whole window (the
    /// board's white print stays below [`METER_TARGET`] of full scale in all but [`METER_SHARE`]
    /// of the pixels, as an integrator sets the exposure for the board), then the randomised
    /// over-exposure, if drawn.
    pub fn metered_sensor(&self, out: &RenderOutput) -> SensorModel {
        let sensor = self.scene.sensor;
        let mut peaks: Vec<f32> = out
            .radiance
            .iter()
            .map(|c| c[0].max(c[1]).max(c[2]))
            .collect();
        let mut s = sensor;
        if !peaks.is_empty() {
            let k = (((1.0 - METER_SHARE) * peaks.len() as f64) as usize).min(peaks.len() - 1);
            let (_, peak, _) = peaks.select_nth_unstable_by(k, f32::total_cmp);
            let level = f64::from(*peak) * sensor.exposure * sensor.gain;
            if level > METER_TARGET && level.is_finite() {
                s.exposure *= METER_TARGET / level;
            }
        }
        s.exposure *= self.scene.overexposure;
        s
    }
}

/// Settings for board renders: 3 × 3 supersampling at edges (the tag borders' sub-pixel
/// positions are what calibration measures), shadows, no part masks.
pub fn board_render_settings() -> RenderSettings {
    RenderSettings {
        supersampling: 8,
        shadows: true,
        full_masks: false,
    }
}

/// The full sensor frame of `camera` with `window` pasted at its origin and the rest grey
/// `fill` with ±`noise` levels of deterministic sensor-like noise (a flat fill would let the
/// detector skip most of the frame): what a camera delivers, so detection runs on every pixel.
pub fn embed_in_full_frame(
    window: &FrameImage,
    camera: &Camera,
    fill: u8,
    noise: u8,
) -> FrameImage {
    let grey = window.pixels.to_luma8();
    let span = 2 * u32::from(noise) + 1;
    let mut state = 0x9e37_79b9_u32;
    let mut full = GrayImage::from_fn(camera.width, camera.height, |_, _| {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        let v = (u32::from(fill) + state % span).saturating_sub(u32::from(noise));
        image::Luma([v.min(255) as u8])
    });
    image::imageops::replace(
        &mut full,
        &grey,
        i64::from(window.origin[0]),
        i64::from(window.origin[1]),
    );
    FrameImage::full(DynamicImage::ImageLuma8(full))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn a_view_looks_down_at_the_board_from_the_randomised_height() {
        let rand = Randomisation::default();
        let camera = Camera::basler_seed();
        for seed in 0..20 {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let view = sample_board_view(&Board::seed(), &camera, &rand, &mut rng).unwrap();
            let t = view.camera_T_board();
            // The board's origin is in front of the camera, 1.4–1.9 m away (plus the offset).
            let d = t.translation.vector;
            assert!((1.4..1.95).contains(&d.z), "seed {seed}: {d:?}");
            // The board's normal points back at the camera within the tilt the offsets allow.
            let normal = t.rotation * Vector3::z();
            let tilt = (-normal.z).acos();
            assert!(
                tilt < (0.2f64 * 2f64.sqrt() / 1.4).atan() + 0.01,
                "tilt {tilt}"
            );
            let w = view.window().unwrap();
            assert!(w.width > 1000 && w.width < 2000, "{w:?}");
        }
    }

    #[test]
    fn embedding_keeps_the_window_at_its_origin() {
        let camera = Camera::basler_seed();
        let small = FrameImage {
            pixels: DynamicImage::ImageLuma8(GrayImage::from_pixel(3, 2, image::Luma([200]))),
            origin: [10, 20],
        };
        let full = embed_in_full_frame(&small, &camera, 7, 0);
        let g = full.pixels.as_luma8().unwrap();
        assert_eq!((g.width(), g.height()), (camera.width, camera.height));
        assert_eq!(g.get_pixel(12, 21).0[0], 200);
        assert_eq!(g.get_pixel(13, 21).0[0], 7);
        assert_eq!(g.get_pixel(10, 22).0[0], 7);
    }
}
