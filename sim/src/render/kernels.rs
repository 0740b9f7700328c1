//! Image-plane kernels of the sensor model: Gaussian optical blur, the defocus disk, the motion
//! streak, and JPEG-like 8 × 8 block compression. Edges are clamped (replicated).

use image::RgbImage;

/// Separable Gaussian blur with clamped edges.
pub(crate) fn gaussian_blur(src: &[[f64; 3]], w: usize, h: usize, sigma: f64) -> Vec<[f64; 3]> {
    let r = (3.0 * sigma).ceil() as isize;
    let kernel: Vec<f64> = (-r..=r)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp())
        .collect();
    let sum: f64 = kernel.iter().sum();
    let kernel: Vec<f64> = kernel.iter().map(|k| k / sum).collect();
    let pass = |src: &[[f64; 3]], horizontal: bool| -> Vec<[f64; 3]> {
        let mut dst = vec![[0.0; 3]; src.len()];
        for y in 0..h {
            for x in 0..w {
                let mut acc = [0.0; 3];
                for (k, kv) in kernel.iter().enumerate() {
                    let o = k as isize - r;
                    let (sx, sy) = if horizontal {
                        ((x as isize + o).clamp(0, w as isize - 1) as usize, y)
                    } else {
                        (x, (y as isize + o).clamp(0, h as isize - 1) as usize)
                    };
                    let s = src[sy * w + sx];
                    for c in 0..3 {
                        acc[c] += kv * s[c];
                    }
                }
                dst[y * w + x] = acc;
            }
        }
        dst
    };
    pass(&pass(src, true), false)
}

/// A sparse convolution kernel: (dx, dy, weight), weights summing to 1.
pub(crate) type Kernel = Vec<(isize, isize, f64)>;

/// The defocus disk of `radius` px: each tap weighted by the disk's area over its pixel
/// (4 × 4 sub-samples), so small radii blur smoothly.
pub(crate) fn disk_kernel(radius: f64) -> Kernel {
    let r = radius.ceil() as isize;
    let mut k = Vec::new();
    for dy in -r..=r {
        for dx in -r..=r {
            let mut inside = 0;
            for sy in 0..4 {
                for sx in 0..4 {
                    let x = dx as f64 + (sx as f64 + 0.5) / 4.0 - 0.5;
                    let y = dy as f64 + (sy as f64 + 0.5) / 4.0 - 0.5;
                    if x * x + y * y <= radius * radius {
                        inside += 1;
                    }
                }
            }
            if inside > 0 {
                k.push((dx, dy, inside as f64));
            }
        }
    }
    // A disk smaller than the sub-samples' spacing covers none of them: it is the identity.
    if k.is_empty() {
        k.push((0, 0, 1.0));
    }
    normalised(k)
}

/// A motion streak `length` px long in direction `angle` (radians from +x), centred on the pixel.
pub(crate) fn line_kernel(length: f64, angle: f64) -> Kernel {
    let n = (length * 4.0).ceil().max(1.0) as usize;
    let (c, s) = (angle.cos(), angle.sin());
    let mut taps: Vec<(isize, isize, f64)> = Vec::new();
    for i in 0..=n {
        let t = (i as f64 / n as f64 - 0.5) * length;
        let (dx, dy) = ((t * c).round() as isize, (t * s).round() as isize);
        match taps.iter_mut().find(|(x, y, _)| *x == dx && *y == dy) {
            Some(tap) => tap.2 += 1.0,
            None => taps.push((dx, dy, 1.0)),
        }
    }
    normalised(taps)
}

fn normalised(k: Kernel) -> Kernel {
    let sum: f64 = k.iter().map(|t| t.2).sum();
    k.into_iter().map(|(x, y, v)| (x, y, v / sum)).collect()
}

/// Convolves an image with a sparse kernel, clamping at the edges.
pub(crate) fn convolve(src: &[[f64; 3]], w: usize, h: usize, kernel: &Kernel) -> Vec<[f64; 3]> {
    let mut dst = vec![[0.0; 3]; src.len()];
    for y in 0..h {
        for x in 0..w {
            let mut acc = [0.0; 3];
            for &(dx, dy, k) in kernel {
                let sx = (x as isize + dx).clamp(0, w as isize - 1) as usize;
                let sy = (y as isize + dy).clamp(0, h as isize - 1) as usize;
                let s = src[sy * w + sx];
                for c in 0..3 {
                    acc[c] += k * s[c];
                }
            }
            dst[y * w + x] = acc;
        }
    }
    dst
}

/// The JPEG standard's luminance quantisation table (Annex K), row-major.
const LUMA_Q: [f64; 64] = [
    16., 11., 10., 16., 24., 40., 51., 61., 12., 12., 14., 19., 26., 58., 60., 55., 14., 13., 16.,
    24., 40., 57., 69., 56., 14., 17., 22., 29., 51., 87., 80., 62., 18., 22., 37., 56., 68., 109.,
    103., 77., 24., 35., 55., 64., 81., 104., 113., 92., 49., 64., 78., 87., 103., 121., 120.,
    101., 72., 92., 95., 98., 112., 100., 103., 99.,
];

/// The JPEG standard's chrominance quantisation table (Annex K), row-major.
const CHROMA_Q: [f64; 64] = [
    17., 18., 24., 47., 99., 99., 99., 99., 18., 21., 26., 66., 99., 99., 99., 99., 24., 26., 56.,
    99., 99., 99., 99., 99., 47., 66., 99., 99., 99., 99., 99., 99., 99., 99., 99., 99., 99., 99.,
    99., 99., 99., 99., 99., 99., 99., 99., 99., 99., 99., 99., 99., 99., 99., 99., 99., 99., 99.,
    99., 99., 99., 99., 99., 99., 99.,
];

/// JPEG-like artefacts: each 8 × 8 block of Y, Cb and Cr is transformed (DCT-II), quantised
/// with the standard tables scaled for `quality` (1–100, the IJG scaling) and transformed back,
/// giving the blocking and ringing of a JPEG at that quality (no chroma subsampling, no entropy
/// coding: those do not change pixels).
// The three colour planes are read and written together, pixel by pixel.
#[allow(clippy::needless_range_loop)]
pub(crate) fn jpeg_like(img: &mut RgbImage, quality: f64) {
    let q = quality.clamp(1.0, 100.0);
    let scale = if q < 50.0 {
        5000.0 / q
    } else {
        200.0 - 2.0 * q
    };
    let table = |t: &[f64; 64]| t.map(|v| ((v * scale + 50.0) / 100.0).floor().clamp(1.0, 255.0));
    let tables = [table(&LUMA_Q), table(&CHROMA_Q), table(&CHROMA_Q)];
    // The orthonormal DCT-II matrix: c[u][x] = α(u) cos((2x + 1) u π / 16).
    let c: Vec<f64> = (0..64)
        .map(|i| {
            let (u, x) = (i / 8, (i % 8) as f64);
            let alpha = if u == 0 { 0.125f64.sqrt() } else { 0.5 };
            alpha * ((2.0 * x + 1.0) * u as f64 * std::f64::consts::PI / 16.0).cos()
        })
        .collect();
    let (w, h) = (img.width() as usize, img.height() as usize);
    for by in (0..h).step_by(8) {
        for bx in (0..w).step_by(8) {
            // Y, Cb, Cr of the block, edge pixels replicated.
            let mut planes = [[0.0f64; 64]; 3];
            for i in 0..64 {
                let x = (bx + i % 8).min(w - 1) as u32;
                let y = (by + i / 8).min(h - 1) as u32;
                let [r, g, b] = img.get_pixel(x, y).0.map(f64::from);
                planes[0][i] = 0.299 * r + 0.587 * g + 0.114 * b - 128.0;
                planes[1][i] = -0.168_736 * r - 0.331_264 * g + 0.5 * b;
                planes[2][i] = 0.5 * r - 0.418_688 * g - 0.081_312 * b;
            }
            for (plane, q) in planes.iter_mut().zip(&tables) {
                // Separable DCT-II: coef = C · P · Cᵀ, quantised, then P = Cᵀ · coef · C.
                let mut tmp = [0.0f64; 64];
                for v in 0..8 {
                    for x in 0..8 {
                        tmp[v * 8 + x] = (0..8).map(|y| c[v * 8 + y] * plane[y * 8 + x]).sum();
                    }
                }
                let mut coef = [0.0f64; 64];
                for v in 0..8 {
                    for u in 0..8 {
                        let k = v * 8 + u;
                        let f: f64 = (0..8).map(|x| tmp[v * 8 + x] * c[u * 8 + x]).sum();
                        coef[k] = (f / q[k]).round() * q[k];
                    }
                }
                for y in 0..8 {
                    for u in 0..8 {
                        tmp[y * 8 + u] = (0..8).map(|v| c[v * 8 + y] * coef[v * 8 + u]).sum();
                    }
                }
                for y in 0..8 {
                    for x in 0..8 {
                        plane[y * 8 + x] = (0..8).map(|u| tmp[y * 8 + u] * c[u * 8 + x]).sum();
                    }
                }
            }
            for i in 0..64 {
                let (x, y) = (bx + i % 8, by + i / 8);
                if x >= w || y >= h {
                    continue;
                }
                let (l, cb, cr) = (planes[0][i] + 128.0, planes[1][i], planes[2][i]);
                let rgb = [
                    l + 1.402 * cr,
                    l - 0.344_136 * cb - 0.714_136 * cr,
                    l + 1.772 * cb,
                ];
                img.put_pixel(
                    x as u32,
                    y as u32,
                    image::Rgb(rgb.map(|v| v.round().clamp(0.0, 255.0) as u8)),
                );
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kernels_keep_brightness_and_jpeg_quality_orders_the_error() {
        for k in [
            disk_kernel(0.001),
            disk_kernel(0.6),
            disk_kernel(2.5),
            line_kernel(0.001, 0.3),
            line_kernel(3.0, 0.7),
        ] {
            let sum: f64 = k.iter().map(|t| t.2).sum();
            assert!((sum - 1.0).abs() < 1e-12);
        }
        assert!(disk_kernel(2.5).len() > disk_kernel(0.6).len());
        // A sharp edge with a gradient: low quality loses more than high quality.
        let img = RgbImage::from_fn(32, 24, |x, y| {
            let v = if x > 13 { 200 } else { 40 } + (y * 2) as u8;
            image::Rgb([v, v / 2, 255 - v])
        });
        let err = |q: f64| {
            let mut j = img.clone();
            jpeg_like(&mut j, q);
            j.as_raw()
                .iter()
                .zip(img.as_raw())
                .map(|(a, b)| (*a as f64 - *b as f64).abs())
                .sum::<f64>()
        };
        let (lo, hi) = (err(10.0), err(95.0));
        assert!(lo > 2.0 * hi && hi > 0.0, "error at q10 {lo}, at q95 {hi}");
    }
}
