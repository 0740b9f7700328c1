//! Pixels → network input: any 8- or 16-bit mono or colour image (alpha dropped, mono replicated
//! to three channels) sampled into planar f32 RGB in [0, 1] (value / 255 or / 65535), with
//! coordinates outside a clamp rectangle replaced by its nearest edge pixel.

use image::DynamicImage;

use super::LearnedError;

/// A rectangle of image pixels: `[x, y, width, height]`.
pub type Rect = [u32; 4];

/// Checks that the image's pixel format is one the networks can read.
pub fn check_format(image: &DynamicImage) -> Result<(), LearnedError> {
    match image {
        DynamicImage::ImageLuma8(_)
        | DynamicImage::ImageLumaA8(_)
        | DynamicImage::ImageRgb8(_)
        | DynamicImage::ImageRgba8(_)
        | DynamicImage::ImageLuma16(_)
        | DynamicImage::ImageLumaA16(_)
        | DynamicImage::ImageRgb16(_)
        | DynamicImage::ImageRgba16(_) => Ok(()),
        other => Err(LearnedError::Image(format!(
            "pixel format {:?} is not supported (8- or 16-bit mono or colour only)",
            other.color()
        ))),
    }
}

/// Checks that `roi` is non-empty and lies inside the image.
pub fn check_roi(image: &DynamicImage, roi: Rect) -> Result<(), LearnedError> {
    let [x, y, w, h] = roi.map(u64::from);
    let (iw, ih) = (u64::from(image.width()), u64::from(image.height()));
    if w == 0 || h == 0 || x + w > iw || y + h > ih {
        return Err(LearnedError::Image(format!(
            "region of interest {w} × {h} at ({x}, {y}) is empty or leaves the {iw} × {ih} image"
        )));
    }
    Ok(())
}

/// Fills three planes of `width × height` (`dst`, planar RGB) with the image pixels whose top-left
/// is `(x0, y0)`; coordinates outside `clamp` take the nearest pixel inside it (edge replication).
/// `clamp` must be non-empty and inside the image (see [`check_roi`]); the format must pass
/// [`check_format`].
pub fn sample_planar(
    image: &DynamicImage,
    x0: i64,
    y0: i64,
    width: usize,
    height: usize,
    clamp: Rect,
    dst: &mut [f32],
) -> Result<(), LearnedError> {
    debug_assert_eq!(dst.len(), 3 * width * height);
    let w = image.width() as usize;
    let window = Window {
        x0,
        y0,
        width,
        height,
        clamp,
        stride: w,
    };
    // Divided (not multiplied by the reciprocal) so values equal the training's `value / 255`.
    let v8 = |v: u8| EIGHT_BIT_LEVELS[usize::from(v)];
    let v16 = |v: u16| f32::from(v) / 65535.0;
    match image {
        DynamicImage::ImageLuma8(i) => fill(i.as_raw(), 1, v8, &window, dst),
        DynamicImage::ImageLumaA8(i) => fill(i.as_raw(), 2, v8, &window, dst),
        DynamicImage::ImageRgb8(i) => fill(i.as_raw(), 3, v8, &window, dst),
        DynamicImage::ImageRgba8(i) => fill(i.as_raw(), 4, v8, &window, dst),
        DynamicImage::ImageLuma16(i) => fill(i.as_raw(), 1, v16, &window, dst),
        DynamicImage::ImageLumaA16(i) => fill(i.as_raw(), 2, v16, &window, dst),
        DynamicImage::ImageRgb16(i) => fill(i.as_raw(), 3, v16, &window, dst),
        DynamicImage::ImageRgba16(i) => fill(i.as_raw(), 4, v16, &window, dst),
        _ => return check_format(image),
    }
    Ok(())
}

struct Window {
    x0: i64,
    y0: i64,
    width: usize,
    height: usize,
    clamp: Rect,
    stride: usize,
}

/// Fills the planes through `value` (a pixel's channel → [0, 1]), column by column from a table
/// of clamped source columns, so the inner loop has no clamping.
fn fill<T: Copy>(
    raw: &[T],
    channels: usize,
    value: impl Fn(T) -> f32,
    w: &Window,
    dst: &mut [f32],
) {
    let plane = w.width * w.height;
    if plane == 0 {
        return;
    }
    let (cx0, cy0) = (i64::from(w.clamp[0]), i64::from(w.clamp[1]));
    let (cx1, cy1) = (
        cx0 + i64::from(w.clamp[2]) - 1,
        cy0 + i64::from(w.clamp[3]) - 1,
    );
    let columns: Vec<usize> = (0..w.width)
        .map(|col| (w.x0 + col as i64).clamp(cx0, cx1) as usize * channels)
        .collect();
    let (r, rest) = dst.split_at_mut(plane);
    let (g, b) = rest.split_at_mut(plane);
    let rows = r
        .chunks_exact_mut(w.width)
        .zip(g.chunks_exact_mut(w.width))
        .zip(b.chunks_exact_mut(w.width));
    for (row, ((r, g), b)) in rows.enumerate() {
        let sy = (w.y0 + row as i64).clamp(cy0, cy1) as usize;
        let line = &raw[sy * w.stride * channels..(sy + 1) * w.stride * channels];
        let out = columns.iter().zip(r).zip(g).zip(b);
        if channels >= 3 {
            for (((&c, r), g), b) in out {
                *r = value(line[c]);
                *g = value(line[c + 1]);
                *b = value(line[c + 2]);
            }
        } else {
            for (((&c, r), g), b) in out {
                let v = value(line[c]);
                *r = v;
                *g = v;
                *b = v;
            }
        }
    }
}

/// `value / 255` for every 8-bit value (divided at compile time, rounded as at run time), so an
/// 8-bit pixel costs a lookup, not a division.
const EIGHT_BIT_LEVELS: [f32; 256] = {
    let mut levels = [0.0; 256];
    let mut v = 0;
    while v < 256 {
        levels[v] = v as f32 / 255.0;
        v += 1;
    }
    levels
};

/// The segmenter's input for a region of interest: planar RGB of the region padded (edge
/// replication) to multiples of `multiple`; the buffer is reused between frames.
#[derive(Debug, Default)]
pub struct Preprocessor {
    buffer: Vec<f32>,
    width: usize,
    height: usize,
}

impl Preprocessor {
    /// Converts `roi` of `image`; returns the padded `[height, width]`.
    pub fn prepare(
        &mut self,
        image: &DynamicImage,
        roi: Rect,
        multiple: usize,
    ) -> Result<[usize; 2], LearnedError> {
        check_format(image)?;
        check_roi(image, roi)?;
        let pad = |n: u32| (n as usize).div_ceil(multiple) * multiple;
        let (w, h) = (pad(roi[2]), pad(roi[3]));
        self.buffer.resize(3 * w * h, 0.0);
        sample_planar(
            image,
            i64::from(roi[0]),
            i64::from(roi[1]),
            w,
            h,
            roi,
            &mut self.buffer,
        )?;
        self.width = w;
        self.height = h;
        Ok([h, w])
    }

    /// The last prepared tensor, `[3][height][width]`.
    pub fn tensor(&self) -> &[f32] {
        &self.buffer[..3 * self.width * self.height]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::{GrayImage, ImageBuffer, Luma, Rgb, Rgb32FImage, RgbImage, Rgba};

    #[test]
    fn eight_bit_colour_is_scaled_and_padded_by_edge_replication() {
        let img = RgbImage::from_fn(5, 3, |x, y| Rgb([(10 * x + y) as u8, 100, 255]));
        let mut p = Preprocessor::default();
        let [h, w] = p
            .prepare(&DynamicImage::ImageRgb8(img), [1, 1, 3, 2], 4)
            .unwrap();
        assert_eq!([h, w], [4, 4]);
        let t = p.tensor();
        // Row 0 col 0 = pixel (1, 1); col 3 replicates col 2 = pixel (3, 1); row 3 replicates row 1.
        assert_eq!(t[0], 11.0 / 255.0);
        assert_eq!(t[3], 31.0 / 255.0);
        assert_eq!(t[3 * 4 + 3], 32.0 / 255.0);
        assert_eq!(t[16], 100.0 / 255.0);
        assert_eq!(t[32 + 5], 1.0);
    }

    #[test]
    fn mono_and_sixteen_bit_are_replicated_and_scaled() {
        let mono = GrayImage::from_fn(2, 2, |x, _| Luma([if x == 0 { 51 } else { 204 }]));
        let mut dst = vec![0.0; 12];
        let img = DynamicImage::ImageLuma8(mono);
        sample_planar(&img, 0, 0, 2, 2, [0, 0, 2, 2], &mut dst).unwrap();
        for c in 0..3 {
            assert_eq!(&dst[4 * c..4 * c + 4], &[0.2, 0.8, 0.2, 0.8]);
        }
        let deep: ImageBuffer<Luma<u16>, Vec<u16>> =
            ImageBuffer::from_fn(2, 2, |x, y| Luma([(x * 65535).max(y * 13107) as u16]));
        let img = DynamicImage::ImageLuma16(deep);
        sample_planar(&img, 0, 0, 2, 2, [0, 0, 2, 2], &mut dst).unwrap();
        assert_eq!(&dst[8..12], &[0.0, 1.0, 0.2, 1.0]);
        // Alpha is dropped; out-of-image coordinates replicate the edge.
        let rgba: ImageBuffer<Rgba<u16>, Vec<u16>> =
            ImageBuffer::from_fn(1, 1, |_, _| Rgba([0, 65535, 13107, 0]));
        let img = DynamicImage::ImageRgba16(rgba);
        let mut dst = vec![0.0; 3 * 4];
        sample_planar(&img, -3, 5, 2, 2, [0, 0, 1, 1], &mut dst).unwrap();
        assert_eq!(
            dst,
            [0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 0.2, 0.2, 0.2, 0.2]
        );
    }

    #[test]
    fn an_empty_window_fills_nothing() {
        let img = DynamicImage::ImageLuma8(GrayImage::new(4, 4));
        let mut dst = Vec::new();
        sample_planar(&img, 0, 0, 0, 3, [0, 0, 4, 4], &mut dst).unwrap();
        sample_planar(&img, 0, 0, 3, 0, [0, 0, 4, 4], &mut dst).unwrap();
        assert!(dst.is_empty());
    }

    #[test]
    fn float_images_and_bad_regions_are_refused_with_reasons() {
        let img = DynamicImage::ImageRgb32F(Rgb32FImage::new(4, 4));
        let e = Preprocessor::default()
            .prepare(&img, [0, 0, 4, 4], 16)
            .unwrap_err();
        assert!(e.to_string().contains("Rgb32F is not supported"), "{e}");
        let img = DynamicImage::ImageLuma8(GrayImage::new(4, 4));
        let e = Preprocessor::default()
            .prepare(&img, [2, 0, 3, 4], 16)
            .unwrap_err();
        assert!(
            e.to_string().contains("region of interest 3 × 4 at (2, 0)"),
            "{e}"
        );
    }
}
