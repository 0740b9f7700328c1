//! What the networks see of a frame: the region of interest resampled to the table scale they
//! were trained at, and the map from their pixels back to the sensor's. A net trained over a
//! range of camera distances learned each part's size in pixels over that range; shown a frame
//! at the range's middle, a part of one size is not taken for its neighbour in the family.

use fast_image_resize::{FilterType, ResizeAlg, ResizeOptions, Resizer};
use image::DynamicImage;
use nalgebra::{Matrix2, Point2};
use serde::{Deserialize, Serialize};

use super::LearnedError;
use super::models::SEGMENTER_STRIDE;

/// Frames within this share of the target scale are shown to the nets as captured.
const SCALE_TOLERANCE: f64 = 0.01;

/// The scale the nets see a frame at; written `"sensor"`, `"trained"` or a number of pixels per
/// mm (in a scenario and on the command line).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "ScaleText", into = "ScaleText")]
pub enum InputScale {
    /// As captured, whatever the camera's distance.
    Sensor,
    /// The geometric middle of the segmenter's training range (its manifest's
    /// `table_px_per_mm`); as captured when the manifest gives none.
    Trained,
    /// This many pixels per mm on the table.
    PxPerMm(f64),
}

impl InputScale {
    /// The table scale to show frames at, pixels per mm (`None`: as captured), for nets trained
    /// over `trained` (lowest, highest).
    pub fn target(&self, trained: Option<[f64; 2]>) -> Option<f64> {
        match *self {
            Self::Sensor => None,
            Self::Trained => trained.map(|[lo, hi]| (lo * hi).sqrt()),
            Self::PxPerMm(s) => Some(s),
        }
    }

    /// Whether the setting is usable (a given scale is positive and finite).
    pub fn is_valid(&self) -> bool {
        match *self {
            Self::PxPerMm(s) => s.is_finite() && s > 0.0,
            _ => true,
        }
    }
}

impl std::str::FromStr for InputScale {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "sensor" => Ok(Self::Sensor),
            "trained" => Ok(Self::Trained),
            _ => match s.parse::<f64>() {
                Ok(v) if Self::PxPerMm(v).is_valid() => Ok(Self::PxPerMm(v)),
                _ => Err(not_a_scale(format!("{s:?}"))),
            },
        }
    }
}

/// What a written input scale must be, and what it was.
fn not_a_scale(got: impl std::fmt::Display) -> String {
    format!(
        "the input scale is \"sensor\", \"trained\" or a positive number of pixels per mm, got {got}"
    )
}

/// [`InputScale`] as written: a name or a number.
#[derive(Serialize, Deserialize)]
#[serde(untagged)]
enum ScaleText {
    Name(String),
    PxPerMm(f64),
}

impl TryFrom<ScaleText> for InputScale {
    type Error = String;

    fn try_from(t: ScaleText) -> Result<Self, String> {
        match t {
            ScaleText::Name(s) => s.parse(),
            ScaleText::PxPerMm(v) if Self::PxPerMm(v).is_valid() => Ok(Self::PxPerMm(v)),
            ScaleText::PxPerMm(v) => Err(not_a_scale(v)),
        }
    }
}

impl From<InputScale> for ScaleText {
    fn from(s: InputScale) -> Self {
        match s {
            InputScale::Sensor => Self::Name("sensor".into()),
            InputScale::Trained => Self::Name("trained".into()),
            InputScale::PxPerMm(v) => Self::PxPerMm(v),
        }
    }
}

/// How a region of the sensor maps to the nets' input: net pixel `n` along an axis is sensor
/// pixel `(n + ½) / f − ½` of the region, pixel centres and edges kept in place.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NetView {
    /// Net pixels per sensor pixel, along x and y.
    pub factor: [f64; 2],
    /// Sensor pixel of the region's top-left pixel.
    pub region: [u32; 2],
}

impl NetView {
    /// The view of a region of `size` sensor pixels at `region` on the sensor, seen at
    /// `px_per_mm` on the table and shown to the nets at `target` px/mm (`None`, or within 1 %:
    /// as captured). The net image's size is rounded to whole pixels, so each axis keeps its
    /// exact factor.
    pub fn new(region: [u32; 2], size: [u32; 2], px_per_mm: f64, target: Option<f64>) -> Self {
        let f = target.map_or(1.0, |t| t / px_per_mm);
        let factor = if (f - 1.0).abs() <= SCALE_TOLERANCE || !f.is_finite() || f <= 0.0 {
            [1.0, 1.0]
        } else {
            size.map(|s| (f64::from(s) * f).round().max(1.0) / f64::from(s.max(1)))
        };
        Self { factor, region }
    }

    /// Whether the nets see the region as captured.
    pub fn is_identity(&self) -> bool {
        self.factor == [1.0, 1.0]
    }

    /// The net image's size for a region of `size` sensor pixels.
    pub fn net_size(&self, size: [u32; 2]) -> [u32; 2] {
        [0, 1].map(|a| (f64::from(size[a]) * self.factor[a]).round().max(1.0) as u32)
    }

    /// The scale of the net image on the table, for a sensor scale of `px_per_mm`.
    pub fn net_px_per_mm(&self, px_per_mm: f64) -> f64 {
        px_per_mm * (self.factor[0] * self.factor[1]).sqrt()
    }

    /// The region resampled for the nets (`roi`: the region in `image`'s pixels); `None` when
    /// the view is the identity.
    pub fn resample(
        &self,
        image: &DynamicImage,
        roi: [u32; 4],
    ) -> Result<Option<DynamicImage>, LearnedError> {
        if self.is_identity() {
            return Ok(None);
        }
        let [w, h] = self.net_size([roi[2], roi[3]]);
        let mut net = DynamicImage::new(w, h, image.color());
        let [x, y, rw, rh] = roi.map(f64::from);
        // A triangle filter as wide as a net pixel: antialiased when shrinking.
        let options = ResizeOptions::new()
            .crop(x, y, rw, rh)
            .resize_alg(ResizeAlg::Convolution(FilterType::Bilinear))
            .use_alpha(false);
        Resizer::new()
            .resize(image, &mut net, &options)
            .map_err(|e| LearnedError::Image(format!("resampling to the nets' scale: {e}")))?;
        Ok(Some(net))
    }

    /// The sensor pixel of net pixel `p` (net pixels counted from the region's corner).
    pub fn to_sensor(&self, p: Point2<f64>) -> Point2<f64> {
        let axis = |a: usize, v: f64| (v + 0.5) / self.factor[a] - 0.5 + f64::from(self.region[a]);
        Point2::new(axis(0, p.x), axis(1, p.y))
    }

    /// A covariance of a net-pixel position, in sensor pixels².
    pub fn covariance_to_sensor(&self, c: &Matrix2<f64>) -> Matrix2<f64> {
        let d = Matrix2::new(1.0 / self.factor[0], 0.0, 0.0, 1.0 / self.factor[1]);
        d * c * d
    }

    /// The sensor window `[x, y, side along x, side along y]` that holds the net pixels
    /// `[origin, origin + side)` (net pixels from the region's corner).
    pub fn sensor_window(&self, origin: [i64; 2], side: usize) -> [i64; 4] {
        let lo = [0, 1].map(|a| (origin[a] as f64 / self.factor[a]).floor() as i64);
        let hi = [0, 1].map(|a| ((origin[a] + side as i64) as f64 / self.factor[a]).ceil() as i64);
        [
            lo[0] + i64::from(self.region[0]),
            lo[1] + i64::from(self.region[1]),
            hi[0] - lo[0],
            hi[1] - lo[1],
        ]
    }

    /// The segmenter cell (column or row, along axis `a`) that holds sensor pixel `x` of the
    /// region (counted from the region's corner).
    pub fn cell_of(&self, a: usize, x: i64) -> i64 {
        (self.factor[a] * (x as f64 + 0.5) / SEGMENTER_STRIDE as f64).floor() as i64
    }

    /// The region's sensor pixels `[first, end)` along axis `a` that lie in cells
    /// `[first, end)`.
    pub fn cells_to_pixels(&self, a: usize, cells: [usize; 2]) -> [i64; 2] {
        let s = SEGMENTER_STRIDE as f64;
        cells.map(|c| (s * c as f64 / self.factor[a] - 0.5).ceil() as i64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::{GrayImage, Luma};

    #[test]
    fn an_input_scale_is_a_name_or_a_positive_number() {
        assert_eq!("trained".parse(), Ok(InputScale::Trained));
        assert_eq!("sensor".parse(), Ok(InputScale::Sensor));
        assert_eq!("6.5".parse(), Ok(InputScale::PxPerMm(6.5)));
        for bad in ["-1", "0", "inf", "scaled"] {
            let e = bad.parse::<InputScale>().unwrap_err();
            assert!(e.contains(&format!("got {bad:?}")), "{e}");
        }
        #[derive(Deserialize)]
        struct S {
            scale: InputScale,
        }
        let read = |t: &str| toml::from_str::<S>(t).map(|s| s.scale);
        assert_eq!(read("scale = 7").unwrap(), InputScale::PxPerMm(7.0));
        assert_eq!(read("scale = \"sensor\"").unwrap(), InputScale::Sensor);
        let e = read("scale = -2.0").unwrap_err().to_string();
        assert!(e.contains("positive number of pixels per mm"), "{e}");
    }

    #[test]
    fn a_frame_near_the_target_scale_is_shown_as_captured() {
        let v = NetView::new([10, 20], [640, 480], 7.0, Some(7.05));
        assert!(v.is_identity());
        assert_eq!(v.to_sensor(Point2::new(3.0, 4.0)), Point2::new(13.0, 24.0));
        assert_eq!(v.sensor_window([-64, 0], 128), [-54, 20, 128, 128]);
        assert_eq!(v.cells_to_pixels(0, [2, 5]), [8, 20]);
        assert!((0..40).all(|x| v.cell_of(0, x) == x / 4));
        assert!(NetView::new([0, 0], [64, 64], 7.0, None).is_identity());
    }

    #[test]
    fn net_pixels_map_back_to_the_sensor_edge_to_edge() {
        let v = NetView::new([100, 50], [700, 500], 7.0, Some(6.3));
        assert!((v.factor[0] - 630.0 / 700.0).abs() < 1e-12);
        assert_eq!(v.net_size([700, 500]), [630, 450]);
        // The net image's outer edges are the region's.
        let edge = v.to_sensor(Point2::new(-0.5, -0.5));
        assert!((edge - Point2::new(99.5, 49.5)).norm() < 1e-9);
        let far = v.to_sensor(Point2::new(629.5, 449.5));
        assert!((far - Point2::new(799.5, 549.5)).norm() < 1e-9);
        assert!((v.net_px_per_mm(7.0) - 6.3).abs() < 1e-9);
        // Every sensor pixel lies in the cell whose pixel span holds it.
        for x in 0..700 {
            let c = v.cell_of(0, x) as usize;
            let [a, b] = v.cells_to_pixels(0, [c, c + 1]);
            assert!((a..b).contains(&x), "pixel {x}, cell {c}: [{a}, {b})");
        }
        let cov = v.covariance_to_sensor(&Matrix2::identity());
        assert!((cov[(0, 0)] - (700.0f64 / 630.0).powi(2)).abs() < 1e-12);
    }

    #[test]
    fn the_resampled_region_keeps_a_feature_where_the_map_says() {
        let mut img = GrayImage::new(200, 160);
        for y in 70..90 {
            for x in 120..140 {
                img.put_pixel(x, y, Luma([255]));
            }
        }
        let image = DynamicImage::ImageLuma8(img);
        let v = NetView::new([20, 10], [180, 150], 10.0, Some(5.0));
        let net = v
            .resample(&image, [20, 10, 180, 150])
            .unwrap()
            .unwrap()
            .to_luma8();
        assert_eq!(net.dimensions(), (90, 75));
        // Centroid of the bright square, in net pixels, maps back to its sensor centre.
        let (mut sx, mut sy, mut sw) = (0.0, 0.0, 0.0);
        for (x, y, p) in net.enumerate_pixels() {
            let w = f64::from(p[0]);
            (sx, sy, sw) = (sx + w * f64::from(x), sy + w * f64::from(y), sw + w);
        }
        let c = v.to_sensor(Point2::new(sx / sw, sy / sw));
        assert!((c - Point2::new(129.5, 79.5)).norm() < 0.3, "{c}");
    }
}
