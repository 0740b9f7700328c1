//! The gallery of the worst estimates: each detection's 128 × 128 keypoint crop, upscaled × 2,
//! with the predicted mask outline (yellow), the part's true outline and keypoints (projected
//! ground-truth pose: green line, green circles), the estimated pose's outline (magenta line)
//! and the voted keypoints (red crosses).

use image::{DynamicImage, GenericImageView, Rgb, RgbImage};
use nalgebra::{Isometry3, Point2};
use perception::Camera;
use perception::learned::{InstanceMask, LearnedDetection, crop_origin};
use perception::metrics::PoseErrors;

use super::PartData;

/// Side of the keypoint crop, pixels.
pub const CROP: u32 = 128;
/// Upscaling of the gallery pictures.
pub const ZOOM: u32 = 2;

pub(super) const YELLOW: Rgb<u8> = Rgb([255, 220, 0]);
pub(super) const GREEN: Rgb<u8> = Rgb([0, 230, 70]);
const RED: Rgb<u8> = Rgb([255, 40, 40]);
const MAGENTA: Rgb<u8> = Rgb([255, 0, 255]);
const OUTSIDE: Rgb<u8> = Rgb([96, 96, 96]);

/// One picture of the gallery and what its caption says.
#[derive(Debug, Clone)]
pub struct GalleryItem {
    /// Scene id.
    pub scene: usize,
    /// Image id.
    pub image: usize,
    /// Detection index in the frame.
    pub detection: usize,
    /// Part name.
    pub part: String,
    /// Mask IoU with the ground truth.
    pub iou: f64,
    /// Errors of the raw PnP pose.
    pub raw: PoseErrors,
    /// Errors after planar refinement.
    pub refined: PoseErrors,
    /// Stable pose the detector chose.
    pub stable_pose: String,
    /// Stable pose of the truth.
    pub true_stable_pose: Option<String>,
    /// The annotated crop, `CROP·ZOOM` pixels square.
    pub crop: RgbImage,
}

impl GalleryItem {
    /// File name of its picture.
    pub fn file_name(&self) -> String {
        format!(
            "scene{:06}-image{:06}-det{:03}-{}.png",
            self.scene, self.image, self.detection, self.part
        )
    }
}

/// A matched detection that got no pose, for the gallery of failures.
#[derive(Debug, Clone)]
pub struct FailedCrop {
    /// Scene id.
    pub scene: usize,
    /// Image id.
    pub image: usize,
    /// Detection index in the frame.
    pub detection: usize,
    /// Part name.
    pub part: String,
    /// Detection score.
    pub score: f64,
    /// Mask IoU with the ground truth.
    pub iou: f64,
    /// Why there is no pose.
    pub reason: String,
    /// The annotated crop, `CROP·ZOOM` pixels square.
    pub crop: RgbImage,
}

impl FailedCrop {
    /// File name of its picture.
    pub fn file_name(&self) -> String {
        format!(
            "failed-scene{:06}-image{:06}-det{:03}-{}.png",
            self.scene, self.image, self.detection, self.part
        )
    }
}

/// Keeps the `capacity` items with the largest keys, building an item only when it gets in.
#[derive(Debug)]
pub struct GalleryKeeper<T = GalleryItem> {
    capacity: usize,
    items: Vec<(f64, T)>,
}

impl<T> GalleryKeeper<T> {
    /// A keeper of `capacity` items (0 keeps none).
    pub fn new(capacity: usize) -> Self {
        Self {
            capacity,
            items: Vec::new(),
        }
    }

    /// Offers an item of error `key` (NaN counts as the worst).
    pub fn offer(&mut self, key: f64, make: impl FnOnce() -> T) {
        if self.capacity == 0 {
            return;
        }
        let key = if key.is_nan() { f64::INFINITY } else { key };
        if self.items.len() == self.capacity && self.items.last().is_some_and(|(k, _)| *k >= key) {
            return;
        }
        let at = self.items.partition_point(|(k, _)| *k >= key);
        self.items.insert(at, (key, make()));
        self.items.truncate(self.capacity);
    }

    /// The kept items, worst first.
    pub fn into_items(self) -> Vec<T> {
        self.items.into_iter().map(|(_, i)| i).collect()
    }
}

/// The 128-pixel window of `image` about the detection's centre, upscaled, with its mask outline, the part's true outline
/// and keypoints (`part` at `truth`, projected by `camera`), the outline at `estimate` (the
/// camera-frame pose, if there is one) and the voted keypoints drawn.
pub fn draw_crop(
    image: &DynamicImage,
    camera: &Camera,
    detection: &LearnedDetection,
    part: &PartData,
    truth: &Isometry3<f64>,
    estimate: Option<&Isometry3<f64>>,
) -> RgbImage {
    // The frame at sensor resolution about the detection's centre: the keypoint crop itself
    // when the nets see frames as captured (the crop of a resampled frame spans more pixels).
    let [ox, oy] = crop_origin(detection.centre);
    let mut out = zoomed_window(image, [ox, oy], |x, y| {
        on_outline(&detection.mask, x, y).then_some(YELLOW)
    });
    // Image pixel → picture pixel (pixel centres at integers in both).
    let z = f64::from(ZOOM);
    let to_pic = |p: Point2<f64>| {
        (
            (p.x - ox as f64) * z + (z - 1.0) / 2.0,
            (p.y - oy as f64) * z + (z - 1.0) / 2.0,
        )
    };
    // Outline samples half a picture pixel apart draw a line.
    let mut outline = |pose: &Isometry3<f64>, colour| {
        for p in part.outline.pixels(camera, pose, 0.5 / z) {
            let (x, y) = to_pic(p);
            put(&mut out, x, y, colour);
        }
    };
    outline(truth, GREEN);
    if let Some(estimate) = estimate {
        outline(estimate, MAGENTA);
    }
    for k in &part.keypoints {
        if let Ok(p) = camera.project(&(truth * k)) {
            circle(&mut out, to_pic(p), 5.0, GREEN);
        }
    }
    for v in &detection.keypoints {
        cross(&mut out, to_pic(v.position), 5.0, RED);
    }
    out
}

/// The `CROP` × `CROP` window of `image` whose top-left is image pixel `origin`, upscaled
/// `ZOOM` times, each pixel in the colour `mark` gives it (else the image's; grey outside it).
pub fn zoomed_window(
    image: &DynamicImage,
    [ox, oy]: [i64; 2],
    mark: impl Fn(i64, i64) -> Option<Rgb<u8>>,
) -> RgbImage {
    let side = CROP * ZOOM;
    let mut out = RgbImage::from_pixel(side, side, OUTSIDE);
    let inside = |x: i64, y: i64| {
        x >= 0
            && y >= 0
            && (x as u64) < u64::from(image.width())
            && (y as u64) < u64::from(image.height())
    };
    for cy in 0..CROP {
        for cx in 0..CROP {
            let (x, y) = (ox + i64::from(cx), oy + i64::from(cy));
            let colour = mark(x, y).unwrap_or_else(|| {
                if inside(x, y) {
                    let p = image.get_pixel(x as u32, y as u32);
                    Rgb([p.0[0], p.0[1], p.0[2]])
                } else {
                    OUTSIDE
                }
            });
            for sy in 0..ZOOM {
                for sx in 0..ZOOM {
                    out.put_pixel(cx * ZOOM + sx, cy * ZOOM + sy, colour);
                }
            }
        }
    }
    out
}

/// Whether image pixel (x, y) is on `mask` with a 4-neighbour off it.
pub fn on_outline(mask: &InstanceMask, x: i64, y: i64) -> bool {
    let on = |x: i64, y: i64| x >= 0 && y >= 0 && mask.contains(x as u32, y as u32);
    on(x, y)
        && [(1, 0), (-1, 0), (0, 1), (0, -1)]
            .iter()
            .any(|(dx, dy)| !on(x + dx, y + dy))
}

fn put(img: &mut RgbImage, x: f64, y: f64, c: Rgb<u8>) {
    let (x, y) = (x.round(), y.round());
    if x >= 0.0 && y >= 0.0 && x < f64::from(img.width()) && y < f64::from(img.height()) {
        img.put_pixel(x as u32, y as u32, c);
    }
}

fn circle(img: &mut RgbImage, (x, y): (f64, f64), r: f64, c: Rgb<u8>) {
    let steps = (r * 8.0).ceil() as usize;
    for i in 0..steps {
        let a = std::f64::consts::TAU * i as f64 / steps as f64;
        put(img, x + r * a.cos(), y + r * a.sin(), c);
    }
}

fn cross(img: &mut RgbImage, (x, y): (f64, f64), r: f64, c: Rgb<u8>) {
    let n = (2.0 * r).ceil() as i32;
    for i in -n..=n {
        let t = f64::from(i) * r / f64::from(n);
        put(img, x + t, y + t, c);
        put(img, x + t, y - t, c);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn item(tag: usize) -> GalleryItem {
        let e = PoseErrors {
            x_mm: 0.0,
            y_mm: 0.0,
            z_mm: 0.0,
            angle_deg: 0.0,
            sym_angle_deg: 0.0,
            add_mm: 0.0,
            adds_mm: 0.0,
            mssd_mm: 0.0,
            mspd_px: 0.0,
        };
        GalleryItem {
            scene: 0,
            image: tag,
            detection: 0,
            part: "p".into(),
            iou: 1.0,
            raw: e,
            refined: e,
            stable_pose: "+z".into(),
            true_stable_pose: None,
            crop: RgbImage::new(1, 1),
        }
    }

    #[test]
    fn keeper_keeps_the_worst_in_order_and_builds_only_those() {
        let mut k = GalleryKeeper::new(3);
        let mut built = 0;
        for (tag, key) in [
            (0, 1.0),
            (1, 5.0),
            (2, 3.0),
            (3, 0.5),
            (4, f64::NAN),
            (5, 4.0),
        ] {
            k.offer(key, || {
                built += 1;
                item(tag)
            });
        }
        let order: Vec<usize> = k.into_items().iter().map(|i| i.image).collect();
        assert_eq!(order, vec![4, 1, 5], "NaN first, then 5.0 and 4.0");
        assert_eq!(built, 5, "0.5 arrived when three larger ones were kept");
        let mut none: GalleryKeeper = GalleryKeeper::new(0);
        none.offer(1.0, || unreachable!("capacity 0 builds nothing"));
        assert!(none.into_items().is_empty());
    }
}
