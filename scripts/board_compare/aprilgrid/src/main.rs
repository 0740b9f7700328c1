//! Runs `aprilgrid` (tag36h11 with a one-cell border, the printed board's) on every
//! `board_NNNN.png` of a folder written by `cell board-study --save`, pasted into a 20 MP frame
//! as the study does, and compares its corners with `board_NNNN.json`'s truth.

use std::collections::HashMap;
use std::path::PathBuf;
use std::time::Instant;

use aprilgrid::TagFamily;
use aprilgrid::detector::TagDetector;
use image::{DynamicImage, GrayImage, Luma};
use serde::Deserialize;

#[derive(Deserialize)]
struct Truth {
    origin: [u32; 2],
    camera: CameraJson,
    tags: Vec<TagTruth>,
}

#[derive(Deserialize)]
struct CameraJson {
    width: u32,
    height: u32,
}

#[derive(Deserialize)]
struct TagTruth {
    id: u32,
    pixels: [[f64; 2]; 4],
    visible: bool,
}

fn main() {
    let dir = PathBuf::from(std::env::args().nth(1).expect("usage: board-compare-aprilgrid DIR"));
    let mut pngs: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "png"))
        .collect();
    pngs.sort();
    let detector = TagDetector::new(&TagFamily::T36H11B1, None);
    let (mut visible, mut decoded, mut false_ids) = (0usize, 0usize, 0usize);
    let (mut sq, mut n) = (0f64, 0usize);
    let mut times = Vec::new();
    for png in &pngs {
        let truth: Truth = serde_json::from_str(
            &std::fs::read_to_string(png.with_extension("json"))
                .unwrap_or_else(|e| panic!("{}: {e}", png.display())),
        )
        .unwrap_or_else(|e| panic!("{}: {e}", png.display()));
        let window = image::open(png).unwrap_or_else(|e| panic!("{}: {e}", png.display())).to_luma8();
        let full = full_frame(&window, &truth);
        let started = Instant::now();
        let tags: HashMap<u32, [(f32, f32); 4]> = detector.detect(&full);
        times.push(started.elapsed().as_secs_f64() * 1e3);
        let by_id: HashMap<u32, &TagTruth> = truth.tags.iter().map(|t| (t.id, t)).collect();
        visible += truth.tags.iter().filter(|t| t.visible).count();
        for (id, corners) in &tags {
            let Some(t) = by_id.get(id) else {
                false_ids += 1;
                continue;
            };
            if t.visible {
                decoded += 1;
            }
            // Its corner order may differ from the reference detector's: nearest true corner.
            for c in corners {
                let (x, y) = (f64::from(c.0), f64::from(c.1));
                let d = t
                    .pixels
                    .iter()
                    .map(|p| (p[0] - x).powi(2) + (p[1] - y).powi(2))
                    .fold(f64::INFINITY, f64::min);
                sq += d;
                n += 1;
            }
        }
    }
    times.sort_by(f64::total_cmp);
    let mean = times.iter().sum::<f64>() / times.len().max(1) as f64;
    println!("aprilgrid {} on {} images ({})", "0.8.0", pngs.len(), dir.display());
    println!(
        "tags decoded: {decoded} of {visible} visible ({:.3} %), false ids: {false_ids}",
        100.0 * decoded as f64 / visible.max(1) as f64
    );
    if n > 0 {
        println!("corner error (rms, px): {:.4}", (sq / n as f64).sqrt());
    } else {
        println!("corner error: no corners to compare");
    }
    println!(
        "time per 20 MP image, ms: mean {mean:.1}, max {:.1}",
        times.last().copied().unwrap_or(f64::NAN)
    );
}

/// The window pasted at its origin into a full frame of its border's grey (as the study does,
/// without the noise: this only makes aprilgrid faster, not slower).
fn full_frame(window: &GrayImage, truth: &Truth) -> DynamicImage {
    let fill = border_grey(window);
    let mut full = GrayImage::from_pixel(truth.camera.width, truth.camera.height, Luma([fill]));
    image::imageops::replace(
        &mut full,
        window,
        i64::from(truth.origin[0]),
        i64::from(truth.origin[1]),
    );
    DynamicImage::ImageLuma8(full)
}

fn border_grey(g: &GrayImage) -> u8 {
    let (w, h) = (g.width(), g.height());
    let mut v: Vec<u8> = (0..w)
        .flat_map(|x| [g.get_pixel(x, 0).0[0], g.get_pixel(x, h - 1).0[0]])
        .chain((0..h).flat_map(|y| [g.get_pixel(0, y).0[0], g.get_pixel(w - 1, y).0[0]]))
        .collect();
    let k = v.len() / 2;
    *v.select_nth_unstable(k).1
}
