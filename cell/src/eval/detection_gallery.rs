//! The gallery of detection errors: each missed instance and each false positive as the
//! 128 × 128 window of the frame around it, upscaled × 2, with the true visible mask outlined
//! green, the detection in question yellow (the false positive, or the one overlapping the miss
//! most) and every other detection's mask cyan, so that a split, a merge or a part swallowed by
//! its neighbour's instance shows at a glance.

use image::{DynamicImage, Rgb, RgbImage};
use perception::learned::InstanceMask;

use super::gallery::{CROP, GREEN, YELLOW, on_outline, zoomed_window};

const CYAN: Rgb<u8> = Rgb([0, 200, 255]);

/// Which kind of detection error a picture shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DetectionErrorKind {
    /// A counted ground-truth instance no detection matched.
    Missed,
    /// A detection that matched no instance.
    FalsePositive,
}

/// One detection error and its picture.
#[derive(Debug, Clone)]
pub struct DetectionErrorCrop {
    /// Scene id.
    pub scene: usize,
    /// Image id.
    pub image: usize,
    /// Missed or false positive.
    pub kind: DetectionErrorKind,
    /// Index in its frame of the truth (missed) or of the detection (false positive).
    pub index: usize,
    /// Part name.
    pub part: String,
    /// Why it happened and what overlaps it, for the caption.
    pub caption: String,
    /// The annotated window, `CROP·ZOOM` pixels square.
    pub crop: RgbImage,
}

impl DetectionErrorCrop {
    /// File name of its picture.
    pub fn file_name(&self) -> String {
        let (kind, what) = match self.kind {
            DetectionErrorKind::Missed => ("missed", "truth"),
            DetectionErrorKind::FalsePositive => ("false-positive", "det"),
        };
        format!(
            "{kind}-scene{:06}-image{:06}-{what}{:03}-{}.png",
            self.scene, self.image, self.index, self.part
        )
    }
}

/// The window of `image` centred on `around`'s pixels, with `truth` outlined green, `detection`
/// yellow and `others` cyan (the truth's outline drawn over the rest).
pub fn draw_window(
    image: &DynamicImage,
    around: &InstanceMask,
    truth: Option<&InstanceMask>,
    detection: Option<&InstanceMask>,
    others: &[&InstanceMask],
) -> RgbImage {
    let [cx, cy] = centroid(around);
    let half = i64::from(CROP / 2);
    let origin = [cx.round() as i64 - half, cy.round() as i64 - half];
    zoomed_window(image, origin, |x, y| {
        let on = |m: Option<&InstanceMask>| m.is_some_and(|m| on_outline(m, x, y));
        if on(truth) {
            Some(GREEN)
        } else if on(detection) {
            Some(YELLOW)
        } else if others.iter().any(|m| on_outline(m, x, y)) {
            Some(CYAN)
        } else {
            None
        }
    })
}

/// Mean image pixel of a mask (its box centre when empty).
fn centroid(mask: &InstanceMask) -> [f64; 2] {
    let (mut sx, mut sy, mut n) = (0.0, 0.0, 0.0);
    let w = mask.width.max(1) as usize;
    for (i, _) in mask.bits.iter().enumerate().filter(|(_, b)| **b) {
        sx += (i % w) as f64;
        sy += (i / w) as f64;
        n += 1.0;
    }
    let (bx, by) = if n > 0.0 {
        (sx / n, sy / n)
    } else {
        (f64::from(mask.width) / 2.0, f64::from(mask.height) / 2.0)
    };
    [
        f64::from(mask.origin[0]) + bx,
        f64::from(mask.origin[1]) + by,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_window_is_centred_on_the_mask_and_outlines_each_kind_in_its_colour() {
        let image = DynamicImage::ImageRgb8(RgbImage::from_pixel(400, 300, Rgb([50, 50, 50])));
        let square = |x: u32, y: u32, side: u32| InstanceMask {
            origin: [x, y],
            width: side,
            height: side,
            bits: vec![true; (side * side) as usize],
        };
        // A 20 px truth at (200, 100), the detection over its left half, another beside it.
        let truth = square(200, 100, 20);
        let detection = InstanceMask {
            bits: (0..400).map(|i| i % 20 < 10).collect(),
            ..truth.clone()
        };
        let other = square(230, 100, 10);
        let pic = draw_window(&image, &truth, Some(&truth), Some(&detection), &[&other]);
        assert_eq!(pic.dimensions(), (256, 256));
        // The truth's centroid (209.5, 109.5) is the window's centre: origin (146, 46).
        let at = |x: u32, y: u32| *pic.get_pixel((x - 146) * 2, (y - 46) * 2);
        assert_eq!(at(200, 110), GREEN, "the truth's left edge");
        assert_eq!(
            at(209, 110),
            YELLOW,
            "the detection's right edge, inside the truth"
        );
        assert_eq!(at(230, 105), CYAN);
        assert_eq!(at(205, 105), Rgb([50, 50, 50]), "inside both: the image");
    }
}
