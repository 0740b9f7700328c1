//! Keypoint crops: 128 × 128 pixels of the full-resolution image centred on an instance's voted
//! centre (origin = round(centre) − 64, edge pixels replicated outside the image), followed by
//! the part's one-hot planes; the crop's camera is the sensor camera with the principal point
//! shifted by the crop origin (cx' = cx − origin_x, cy' = cy − origin_y).

use image::DynamicImage;

use super::LearnedError;
use super::image::sample_planar;
use super::models::CROP_SIZE;
use crate::Camera;

/// Image pixel of the top-left corner of the crop centred on `centre` (image pixels).
pub fn crop_origin(centre: [f64; 2]) -> [i64; 2] {
    let half = (CROP_SIZE / 2) as i64;
    [
        centre[0].round() as i64 - half,
        centre[1].round() as i64 - half,
    ]
}

/// The camera of a crop whose top-left corner is sensor pixel `origin`.
pub fn crop_camera(camera: &Camera, origin: [i64; 2]) -> Camera {
    camera.crop(
        origin[0] as f64,
        origin[1] as f64,
        CROP_SIZE as u32,
        CROP_SIZE as u32,
    )
}

/// The keypoint net's batch, `[n][3 + parts][128][128]`, built in a buffer reused across frames.
#[derive(Debug, Default)]
pub struct CropBatch {
    buffer: Vec<f32>,
    len: usize,
    channels: usize,
}

impl CropBatch {
    /// Starts a new batch of crops with `parts` one-hot planes.
    pub fn clear(&mut self, parts: usize) {
        self.len = 0;
        self.channels = 3 + parts;
    }

    /// Appends the crop of `image` at image pixel `origin` for part index `part`; pixels
    /// outside `roi` (`[x, y, width, height]` of `image`) repeat its edge, so a crop never
    /// reads beyond the region the pipeline was asked to search.
    pub fn push(
        &mut self,
        image: &DynamicImage,
        roi: [u32; 4],
        origin: [i64; 2],
        part: usize,
    ) -> Result<(), LearnedError> {
        let plane = CROP_SIZE * CROP_SIZE;
        let item = self.channels * plane;
        let start = self.len * item;
        if self.buffer.len() < start + item {
            self.buffer.resize(start + item, 0.0);
        }
        let crop = &mut self.buffer[start..start + item];
        let (rgb, onehot) = crop.split_at_mut(3 * plane);
        sample_planar(image, origin[0], origin[1], CROP_SIZE, CROP_SIZE, roi, rgb)?;
        for (k, p) in onehot.chunks_mut(plane).enumerate() {
            p.fill(if k == part { 1.0 } else { 0.0 });
        }
        self.len += 1;
        Ok(())
    }

    /// Crops in the batch.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether the batch is empty.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The batch's shape `[n, 3 + parts, 128, 128]`.
    pub fn shape(&self) -> [usize; 4] {
        [self.len, self.channels, CROP_SIZE, CROP_SIZE]
    }

    /// The batch's values, row-major.
    pub fn data(&self) -> &[f32] {
        &self.buffer[..self.len * self.channels * CROP_SIZE * CROP_SIZE]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::{Rgb, RgbImage};
    use nalgebra::Point3;

    #[test]
    fn the_crop_camera_sees_points_at_sensor_pixel_minus_origin() {
        let camera = Camera::basler_seed();
        assert!(!camera.distortion.is_none());
        let centre = [2710.4, 1650.6];
        let origin = crop_origin(centre);
        assert_eq!(origin, [2646, 1587]);
        let crop = crop_camera(&camera, origin);
        assert_eq!((crop.width, crop.height), (128, 128));
        assert_eq!(crop.cx, camera.cx - 2646.0);
        assert_eq!(crop.cy, camera.cy - 1587.0);
        for p in [
            Point3::new(0.001, -0.002, 1.5),
            Point3::new(0.004, 0.003, 1.48),
        ] {
            let full = camera.project(&p).unwrap();
            let local = crop.project(&p).unwrap();
            assert!((full.x - 2646.0 - local.x).abs() < 1e-9);
            assert!((full.y - 1587.0 - local.y).abs() < 1e-9);
        }
    }

    #[test]
    fn crops_replicate_the_region_edge_and_carry_the_one_hot_part() {
        let img = DynamicImage::ImageRgb8(RgbImage::from_fn(200, 100, |x, y| {
            Rgb([(x % 256) as u8, (y % 256) as u8, 7])
        }));
        let mut batch = CropBatch::default();
        batch.clear(3);
        let whole = [0, 0, 200, 100];
        batch
            .push(&img, whole, crop_origin([10.2, 90.0]), 2)
            .unwrap();
        batch
            .push(&img, whole, crop_origin([100.0, 50.0]), 0)
            .unwrap();
        // Inside a region of interest, its edge repeats instead of the pixels beyond it.
        batch
            .push(&img, [20, 10, 100, 60], crop_origin([10.2, 90.0]), 1)
            .unwrap();
        assert_eq!(batch.shape(), [3, 6, 128, 128]);
        let plane = 128 * 128;
        let first = &batch.data()[..6 * plane];
        // Crop origin (−54, 26): column 0 replicates image column 0, row 127 image row 99.
        assert_eq!(first[0], 0.0);
        assert_eq!(first[54 + 10], 10.0 / 255.0);
        assert_eq!(first[plane + 127 * 128], 99.0 / 255.0);
        assert_eq!(first[plane], 26.0 / 255.0);
        assert!(first[3 * plane..5 * plane].iter().all(|&v| v == 0.0));
        assert!(first[5 * plane..].iter().all(|&v| v == 1.0));
        let second = &batch.data()[6 * plane..12 * plane];
        assert_eq!(second[0], 36.0 / 255.0);
        assert!(second[3 * plane..4 * plane].iter().all(|&v| v == 1.0));
        assert!(second[4 * plane..].iter().all(|&v| v == 0.0));
        // Crop origin (−54, 26) against the region x 20..120, y 10..70: column 0 is region
        // column 20, row 0 (image row 26) is inside, row 127 repeats region row 69.
        let third = &batch.data()[12 * plane..];
        assert_eq!(third[0], 20.0 / 255.0);
        assert_eq!(third[54 + 30], 30.0 / 255.0);
        assert_eq!(third[plane], 26.0 / 255.0);
        assert_eq!(third[plane + 127 * 128], 69.0 / 255.0);
    }
}
