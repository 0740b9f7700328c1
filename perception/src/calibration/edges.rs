//! Sub-pixel tag corners: each border edge located across its length on the full-resolution
//! image, fitted as a straight line, and neighbouring lines intersected.
//!
//! Across an edge, the derivative of the (linearised) grey profile is the blurred edge's line
//! spread function; for a symmetric blur its centroid is the edge. The centroid takes the signed
//! derivative over a window around the current edge, so zero-mean noise adds no bias.

use image::GrayImage;
use nalgebra::{Matrix2, Point2, SymmetricEigen, Vector2};

/// How grey levels encode light.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transfer {
    /// Grey level proportional to light (raw machine-vision output).
    Linear,
    /// The sRGB transfer curve (what the simulated sensor and most colour pipelines deliver).
    Srgb,
}

impl Transfer {
    /// Linear light of each 8-bit grey level, full scale 1.
    fn table(self) -> [f32; 256] {
        let mut t = [0f32; 256];
        for (i, v) in t.iter_mut().enumerate() {
            let s = i as f64 / 255.0;
            *v = match self {
                Self::Linear => s,
                Self::Srgb if s <= 0.04045 => s / 12.92,
                Self::Srgb => ((s + 0.055) / 1.055).powf(2.4),
            } as f32;
        }
        t
    }
}

/// Spacing of the profile samples across an edge, pixels.
const PROFILE_STEP: f64 = 0.5;
/// Spacing of the profiles along an edge, pixels.
const ALONG_STEP: f64 = 1.0;
/// Smallest step of linear light across an edge (summed central differences, twice the step)
/// that locates it.
const MIN_STEP: f64 = 0.02;
/// Fewest edge points a line is fitted to.
const MIN_POINTS: usize = 8;
/// Refinement passes (each re-centres the profiles on the previous pass's edges).
const PASSES: usize = 2;

/// A straight line `normal · p = offset`.
#[derive(Debug, Clone, Copy)]
struct Line {
    normal: Vector2<f64>,
    offset: f64,
}

/// Refines a tag's four corners (image pixels, centres at integers, in order around the quad) by
/// fitting its border edges within `reach` pixels of the current quad; `None` when an edge cannot
/// be measured (too short, off the image, no contrast) or the result strays beyond `reach`.
pub fn refine_quad(
    grey: &GrayImage,
    quad: &[Point2<f64>; 4],
    reach: f64,
    transfer: Transfer,
) -> Option<[Point2<f64>; 4]> {
    let lut = transfer.table();
    let mut q = *quad;
    for _ in 0..PASSES {
        let centre = Point2::from((q[0].coords + q[1].coords + q[2].coords + q[3].coords) / 4.0);
        let mut lines = [Line {
            normal: Vector2::zeros(),
            offset: 0.0,
        }; 4];
        for (k, line) in lines.iter_mut().enumerate() {
            *line = fit_edge(grey, &lut, q[k], q[(k + 1) % 4], centre, reach)?;
        }
        let mut next = q;
        for (k, corner) in next.iter_mut().enumerate() {
            *corner = intersect(&lines[(k + 3) % 4], &lines[k])?;
        }
        if next.iter().zip(quad).any(|(a, b)| (a - b).norm() > reach) {
            return None;
        }
        q = next;
    }
    Some(q)
}

/// The share of pixels at full scale (255) within `reach` pixels either side of a quad's edges:
/// where the light side of an edge clips, the blurred edge's profile is cut and its centre moves,
/// so a pose from such corners is biased.
pub fn clipped_share(grey: &GrayImage, quad: &[Point2<f64>; 4], reach: f64) -> f64 {
    let (mut clipped, mut total) = (0usize, 0usize);
    for k in 0..4 {
        let (a, b) = (quad[k], quad[(k + 1) % 4]);
        let length = (b - a).norm();
        if length <= 0.0 {
            continue;
        }
        let d = (b - a) / length;
        let n = Vector2::new(-d.y, d.x);
        let mut t = 0.0;
        while t <= length {
            let mut s = -reach;
            while s <= reach {
                let p = a + d * t + n * s;
                let (x, y) = (p.x.round(), p.y.round());
                if x >= 0.0 && y >= 0.0 && (x as u32) < grey.width() && (y as u32) < grey.height() {
                    total += 1;
                    clipped += usize::from(grey.get_pixel(x as u32, y as u32).0[0] == u8::MAX);
                }
                s += 1.0;
            }
            t += ALONG_STEP;
        }
    }
    if total == 0 {
        0.0
    } else {
        clipped as f64 / total as f64
    }
}

/// The line of the edge from `a` to `b` of a quad centred at `centre`.
fn fit_edge(
    grey: &GrayImage,
    lut: &[f32; 256],
    a: Point2<f64>,
    b: Point2<f64>,
    centre: Point2<f64>,
    reach: f64,
) -> Option<Line> {
    let length = (b - a).norm();
    // Stay clear of the corners, where the neighbouring edge enters the profile.
    let margin = reach + 3.0;
    if length < 2.0 * margin + ALONG_STEP * MIN_POINTS as f64 {
        return None;
    }
    let d = (b - a) / length;
    let mut n = Vector2::new(-d.y, d.x);
    if n.dot(&(Point2::from((a.coords + b.coords) / 2.0) - centre)) < 0.0 {
        n = -n;
    }
    let m = (2.0 * reach / PROFILE_STEP).round() as usize + 1;
    let mut profile = vec![0f32; m];
    let mut points: Vec<Point2<f64>> = Vec::new();
    let mut t = margin;
    'along: while t <= length - margin {
        let p = a + d * t;
        t += ALONG_STEP;
        for (j, v) in profile.iter_mut().enumerate() {
            let s = -reach + j as f64 * PROFILE_STEP;
            match bilinear(grey, lut, p + n * s) {
                Some(x) => *v = x,
                None => continue 'along,
            }
        }
        // Signed derivative: its sum telescopes to the step, and noise, zero-mean, adds no bias.
        let (mut sw, mut sws) = (0f64, 0f64);
        for j in 1..m - 1 {
            let g = f64::from(profile[j + 1] - profile[j - 1]);
            sw += g;
            sws += g * (-reach + j as f64 * PROFILE_STEP);
        }
        if sw.abs() > MIN_STEP {
            points.push(p + n * (sws / sw));
        }
    }
    fit_line(&points)
}

/// The total-least-squares line through `points`, refitted once without the points beyond three
/// robust standard deviations (dust, scratches).
fn fit_line(points: &[Point2<f64>]) -> Option<Line> {
    let line = tls(points.iter())?;
    let residuals: Vec<f64> = points
        .iter()
        .map(|p| (line.normal.dot(&p.coords) - line.offset).abs())
        .collect();
    let mut sorted = residuals.clone();
    sorted.sort_by(f64::total_cmp);
    let mad = sorted[sorted.len() / 2];
    let bound = (3.0 * 1.4826 * mad).max(0.02);
    let kept = points
        .iter()
        .zip(&residuals)
        .filter(|(_, r)| **r <= bound)
        .map(|(p, _)| p);
    tls(kept)
}

/// Total least squares over at least [`MIN_POINTS`] points: the normal is the scatter matrix's
/// eigenvector of the smaller eigenvalue.
fn tls<'a>(points: impl Iterator<Item = &'a Point2<f64>> + Clone) -> Option<Line> {
    let n = points.clone().count();
    if n < MIN_POINTS {
        return None;
    }
    let mean = points.clone().fold(Vector2::zeros(), |s, p| s + p.coords) / n as f64;
    let scatter = points.fold(Matrix2::zeros(), |s, p| {
        let r = p.coords - mean;
        s + r * r.transpose()
    });
    let eig = SymmetricEigen::new(scatter);
    let k = if eig.eigenvalues[0] <= eig.eigenvalues[1] {
        0
    } else {
        1
    };
    let normal: Vector2<f64> = eig.eigenvectors.column(k).into_owned();
    Some(Line {
        normal,
        offset: normal.dot(&mean),
    })
}

/// Where two lines cross; `None` for (near-)parallel lines.
fn intersect(l1: &Line, l2: &Line) -> Option<Point2<f64>> {
    let m = Matrix2::new(l1.normal.x, l1.normal.y, l2.normal.x, l2.normal.y);
    let p = m.try_inverse()? * Vector2::new(l1.offset, l2.offset);
    (p.x.is_finite() && p.y.is_finite()).then(|| Point2::from(p))
}

/// Linear light at `p` (pixel centres at integers), bilinearly interpolated; `None` off the image.
fn bilinear(grey: &GrayImage, lut: &[f32; 256], p: Point2<f64>) -> Option<f32> {
    let (x0, y0) = (p.x.floor(), p.y.floor());
    if x0 < 0.0 || y0 < 0.0 {
        return None;
    }
    let (x, y) = (x0 as u32, y0 as u32);
    if x + 1 >= grey.width() || y + 1 >= grey.height() {
        return None;
    }
    let (fx, fy) = ((p.x - x0) as f32, (p.y - y0) as f32);
    let at = |x: u32, y: u32| lut[usize::from(grey.get_pixel(x, y).0[0])];
    let top = at(x, y) * (1.0 - fx) + at(x + 1, y) * fx;
    let bottom = at(x, y + 1) * (1.0 - fx) + at(x + 1, y + 1) * fx;
    Some(top * (1.0 - fy) + bottom * fy)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A dark square from `lo` to `hi` (pixel edges, centres at integers) on white, each pixel the
    /// exact area average of the ideal square in linear light, sRGB encoded.
    fn square(lo: f64, hi: f64, size: u32) -> GrayImage {
        let cover = |c: f64| -> f64 {
            // Share of pixel [c − ½, c + ½] inside [lo, hi].
            ((c + 0.5).min(hi) - (c - 0.5).max(lo)).clamp(0.0, 1.0)
        };
        GrayImage::from_fn(size, size, |x, y| {
            let dark = cover(f64::from(x)) * cover(f64::from(y));
            let lin = 0.8 * (1.0 - dark) + 0.02 * dark;
            let s = if lin <= 0.003_130_8 {
                12.92 * lin
            } else {
                1.055 * lin.powf(1.0 / 2.4) - 0.055
            };
            image::Luma([(s * 255.0).round() as u8])
        })
    }

    #[test]
    fn corners_of_a_sharp_square_come_back_to_a_few_hundredths_of_a_pixel() {
        let (lo, hi) = (20.3, 79.6);
        let img = square(lo, hi, 100);
        // Corners in the reference detector's order, each off by up to 0.8 px.
        let truth = [
            Point2::new(lo, hi),
            Point2::new(hi, hi),
            Point2::new(hi, lo),
            Point2::new(lo, lo),
        ];
        let start = [
            Point2::new(lo + 0.6, hi - 0.5),
            Point2::new(hi - 0.4, hi + 0.7),
            Point2::new(hi + 0.8, lo - 0.3),
            Point2::new(lo - 0.5, lo + 0.6),
        ];
        let srgb = refine_quad(&img, &start, 4.0, Transfer::Srgb).unwrap();
        for (p, t) in srgb.iter().zip(&truth) {
            assert!((p - t).norm() < 0.02, "{p} vs {t}");
        }
        // Reading sRGB as linear light moves each edge towards the dark side.
        let linear = refine_quad(&img, &start, 4.0, Transfer::Linear).unwrap();
        let shrink = (linear[1] - linear[3]).norm() - (srgb[1] - srgb[3]).norm();
        assert!(shrink < -0.05, "{shrink}");
    }

    #[test]
    fn clipping_is_the_share_of_full_scale_pixels_around_the_edges() {
        let quad = [
            Point2::new(20.0, 80.0),
            Point2::new(80.0, 80.0),
            Point2::new(80.0, 20.0),
            Point2::new(20.0, 20.0),
        ];
        assert_eq!(clipped_share(&square(20.0, 80.0, 100), &quad, 4.0), 0.0);
        // White at full scale outside, black inside: about half the samples clip.
        let img = GrayImage::from_fn(100, 100, |x, y| {
            let inside = (20..80).contains(&x) && (20..80).contains(&y);
            image::Luma([if inside { 10 } else { 255 }])
        });
        let share = clipped_share(&img, &quad, 4.0);
        assert!((0.45..0.55).contains(&share), "{share}");
    }

    #[test]
    fn an_edge_off_the_image_or_without_contrast_is_not_refined() {
        let img = GrayImage::from_pixel(50, 50, image::Luma([128]));
        let quad = [
            Point2::new(10.0, 40.0),
            Point2::new(40.0, 40.0),
            Point2::new(40.0, 10.0),
            Point2::new(10.0, 10.0),
        ];
        assert!(refine_quad(&img, &quad, 4.0, Transfer::Srgb).is_none());
        let off = quad.map(|p| p + Vector2::new(30.0, 0.0));
        assert!(refine_quad(&img, &off, 4.0, Transfer::Srgb).is_none());
    }
}
