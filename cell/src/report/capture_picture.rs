//! A capture with what perception made of it. For a failed learned-perception episode: the
//! rendered feeder window of its last capture. For the report's opening picture: the first
//! capture of the run's first episode, or, where perception reads no pixels (keypoint noise), the
//! feeder rendered from above as that capture found it. Over the picture, each posed detection's
//! outline (the part's mesh projected from its estimated pose), keypoints, centre and a label
//! (part, confidence), and the outline on the table of each part found but not posed, so a
//! person sees at once whether a part was missed, mistaken, misplaced or left unposed.

#![allow(non_snake_case)]

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use image::{Rgb, RgbImage};
use nalgebra::{Isometry3, Point3};
use perception::{Camera, Frame, FrameContent, PartPerception, Perceived, PerceptionError};
use plotters::prelude::*;

use super::pictures::{PictureError, feeder_view};
use crate::episode::EpisodeRecord;
use crate::harness::{SimSetup, run_sim_episode_with};

/// The report's opening picture where perception reads pixels: the first capture with the
/// detections drawn, in the results' `pictures/` folder.
pub const FIRST_CAPTURE_FILE: &str = "first-capture.png";
/// The report's opening picture where perception reads no pixels (keypoint noise): the feeder
/// rendered from above with what perception reported drawn, in `pictures/`.
pub const FIRST_FEEDER_FILE: &str = "first-feeder.png";
/// Width of the rendered feeder of [`FIRST_FEEDER_FILE`], pixels.
const FIRST_FEEDER_PX: u32 = 720;

/// Colour of projected keypoints.
const KEYPOINT: Rgb<u8> = Rgb([255, 220, 0]);
/// Colour of a detection's centre box.
const CENTRE: Rgb<u8> = Rgb([255, 40, 200]);
/// Colour of the outline of a part found but not posed.
const UNPOSED: Rgb<u8> = Rgb([0, 220, 255]);
/// Outline and label colours of posed detections, by the part's place in the catalog.
const PART_COLOURS: [Rgb<u8>; 4] = [
    Rgb([255, 140, 30]),
    Rgb([80, 230, 80]),
    Rgb([120, 160, 255]),
    Rgb([255, 90, 90]),
];
/// Label text size, pixels.
const LABEL_PX: u32 = 14;

/// Which of an episode's captures to keep.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Keep {
    First,
    Last,
}

/// Perception that remembers a frame it saw and what it found there.
struct Recording<'a> {
    inner: &'a mut dyn PartPerception,
    keep: Keep,
    seen: Option<(Frame, Perceived)>,
}

impl PartPerception for Recording<'_> {
    fn perceive(&mut self, frame: &Frame) -> Result<Perceived, PerceptionError> {
        let found = self.inner.perceive(frame)?;
        if self.keep == Keep::Last || self.seen.is_none() {
            self.seen = Some((frame.clone(), found.clone()));
        }
        Ok(found)
    }
}

fn cell_err(e: impl std::fmt::Display) -> PictureError {
    PictureError::Cell(e.to_string())
}

/// Replays `episode` (same seed, same world) and returns its first or last capture with what
/// perception found there; `None` when it captured nothing.
fn replay(
    setup: &SimSetup,
    episode: u32,
    keep: Keep,
) -> Result<Option<(Frame, Perceived)>, PictureError> {
    let mut perception = setup
        .perception
        .for_episode(setup.scenario(), episode)
        .map_err(cell_err)?;
    let mut recording = Recording {
        inner: &mut perception,
        keep,
        seen: None,
    };
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_time()
        .build()
        .map_err(cell_err)?;
    rt.block_on(run_sim_episode_with(setup, episode, &mut recording))
        .map_err(cell_err)?;
    Ok(recording.seen)
}

/// How table-frame points land in a picture.
struct View<'a> {
    camera: &'a Camera,
    camera_T_table: Isometry3<f64>,
    /// Sensor pixel of the picture's top-left pixel.
    origin: [f64; 2],
}

impl View<'_> {
    fn pixel(&self, p: &Point3<f64>) -> Option<(f64, f64)> {
        let px = self.camera.project(&(self.camera_T_table * p)).ok()?;
        Some((px.x - self.origin[0], px.y - self.origin[1]))
    }
}

/// The captured pixels of `frame` with the detections of `found` drawn; `None` when the frame
/// carries no pixels.
fn annotated_capture(setup: &SimSetup, frame: &Frame, found: &Perceived) -> Option<RgbImage> {
    let FrameContent::Image(shot) = &frame.content else {
        return None;
    };
    let mut picture = shot.pixels.to_rgb8();
    let view = View {
        camera: &frame.camera,
        camera_T_table: frame.base_T_camera.inverse()
            * setup.engine.knowledge.geometry.base_T_table,
        origin: shot.origin.map(f64::from),
    };
    annotate(&mut picture, &view, found, setup);
    Some(picture)
}

fn save(picture: &RgbImage, path: PathBuf) -> Result<PathBuf, PictureError> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| PictureError::Write {
            path: dir.into(),
            reason: e.to_string(),
        })?;
    }
    picture.save(&path).map_err(|e| PictureError::Write {
        path: path.clone(),
        reason: e.to_string(),
    })?;
    Ok(path)
}

/// Replays `record`'s episode (same seed, same world) and draws its last capture with the
/// detections into `dir/episode-NNNNNN-capture.png`; `None` when its frames carry no pixels.
pub fn capture_picture(
    setup: &SimSetup,
    record: &EpisodeRecord,
    dir: &Path,
) -> Result<Option<PathBuf>, PictureError> {
    let Some((frame, found)) = replay(setup, record.episode, Keep::Last)? else {
        return Ok(None);
    };
    let Some(picture) = annotated_capture(setup, &frame, &found) else {
        return Ok(None);
    };
    let path = dir.join(format!("episode-{:06}-capture.png", record.episode));
    save(&picture, path).map(Some)
}

/// Replays `episode` and draws its first capture with the detections into
/// `dir/`[`FIRST_CAPTURE_FILE`]; where its frames carry no pixels (keypoint-noise perception
/// works from the true poses), draws the feeder as that capture found it, rendered from above,
/// with what perception reported, into `dir/`[`FIRST_FEEDER_FILE`]. `None` when the episode
/// captured nothing.
pub fn first_capture_picture(
    setup: &SimSetup,
    episode: u32,
    dir: &Path,
) -> Result<Option<PathBuf>, PictureError> {
    // The feeder as the episode starts: its first capture comes before any pick or shake.
    let feeder = setup
        .cell(episode)
        .map_err(cell_err)?
        .lock()
        .map(|c| c.feeder_parts().to_vec())
        .unwrap_or_default();
    let Some((frame, found)) = replay(setup, episode, Keep::First)? else {
        return Ok(None);
    };
    if let Some(picture) = annotated_capture(setup, &frame, &found) {
        return save(&picture, dir.join(FIRST_CAPTURE_FILE)).map(Some);
    }
    let (mut picture, camera, table_T_camera) =
        feeder_view(setup.scenario(), &feeder, FIRST_FEEDER_PX)?;
    let view = View {
        camera: &camera,
        camera_T_table: table_T_camera.inverse(),
        origin: [0.0, 0.0],
    };
    annotate(&mut picture, &view, &found, setup);
    save(&picture, dir.join(FIRST_FEEDER_FILE)).map(Some)
}

/// A text label at a pixel.
struct Label {
    text: String,
    at: (i32, i32),
    colour: Rgb<u8>,
}

/// Draws each posed detection of `found` (outline, keypoints, centre, label) and each unposed
/// part's outline on the table into `picture`.
fn annotate(picture: &mut RgbImage, view: &View<'_>, found: &Perceived, setup: &SimSetup) {
    let catalog = &setup.scenario().catalog;
    let mut meshes: HashMap<&str, Vec<Point3<f64>>> = HashMap::new();
    let mut labels = Vec::new();
    for d in &found.parts {
        let Some((k, part)) = catalog
            .parts
            .iter()
            .enumerate()
            .find(|(_, p)| p.name == d.part)
        else {
            continue;
        };
        let colour = PART_COLOURS[k % PART_COLOURS.len()];
        let vertices = meshes.entry(part.name.as_str()).or_insert_with(|| {
            catalog
                .load_mesh(part)
                .map(|m| m.vertices)
                .unwrap_or_default()
        });
        let outline = convex_hull(
            vertices
                .iter()
                .filter_map(|v| view.pixel(&(d.table_T_part * v)))
                .collect(),
        );
        polyline(picture, &outline, true, colour);
        let keypoints = part.keypoint_points();
        for (i, p) in keypoints.iter().enumerate() {
            let Some((x, y)) = view.pixel(&(d.table_T_part * p)) else {
                continue;
            };
            if i + 1 == keypoints.len() {
                square(picture, x, y, 5, CENTRE);
            } else {
                cross(picture, x, y, 3, KEYPOINT);
            }
        }
        if let Some(at) = label_anchor(&outline) {
            labels.push(Label {
                text: format!("{} {:.2}", d.part, d.confidence),
                at,
                colour,
            });
        }
    }
    for u in &found.unposed {
        // Where its mask's outline meets the table (the points on the table plane).
        let outline = convex_hull(
            u.table_points
                .iter()
                .filter(|p| p.z == 0.0)
                .filter_map(|p| view.pixel(p))
                .collect(),
        );
        polyline(picture, &outline, true, UNPOSED);
        if let Some(at) = label_anchor(&outline) {
            labels.push(Label {
                text: format!("{}: not posed", u.part),
                at,
                colour: UNPOSED,
            });
        }
    }
    draw_labels(picture, &labels);
}

/// Where a label of an outline goes: above its top-left corner.
fn label_anchor(outline: &[(f64, f64)]) -> Option<(i32, i32)> {
    let x = outline.iter().map(|p| p.0).fold(f64::INFINITY, f64::min);
    let y = outline.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
    (x.is_finite() && y.is_finite()).then(|| (x.round() as i32, y.round() as i32 - 4))
}

/// Draws `labels` on dark boxes, kept inside the picture.
fn draw_labels(picture: &mut RgbImage, labels: &[Label]) {
    if labels.is_empty() {
        return;
    }
    super::plots::register_font();
    let (w, h) = picture.dimensions();
    let root = BitMapBackend::with_buffer(picture, (w, h)).into_drawing_area();
    let font = ("sans-serif", LABEL_PX).into_font();
    for l in labels {
        let (tw, th) = font
            .box_size(&l.text)
            .unwrap_or((LABEL_PX * l.text.len() as u32 * 6 / 10, LABEL_PX));
        let (tw, th) = (tw as i32, th as i32);
        let x = l.at.0.clamp(2, (w as i32 - tw - 4).max(2));
        let y = (l.at.1 - th).clamp(2, (h as i32 - th - 4).max(2));
        let colour = RGBColor(l.colour[0], l.colour[1], l.colour[2]);
        let _ = root.draw(&Rectangle::new(
            [(x - 2, y - 1), (x + tw + 2, y + th + 2)],
            BLACK.mix(0.65).filled(),
        ));
        let _ = root.draw(&Text::new(l.text.clone(), (x, y), font.color(&colour)));
    }
    let _ = root.present();
}

/// The convex hull of pixels, counter-clockwise (Andrew's monotone chain).
fn convex_hull(mut p: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    p.retain(|q| q.0.is_finite() && q.1.is_finite());
    p.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let turn = |o: (f64, f64), a: (f64, f64), b: (f64, f64)| {
        (a.0 - o.0) * (b.1 - o.1) - (a.1 - o.1) * (b.0 - o.0)
    };
    let mut hull: Vec<(f64, f64)> = Vec::with_capacity(2 * p.len());
    for pass in [p.clone(), p.into_iter().rev().collect()] {
        let start = hull.len();
        for q in pass {
            while hull.len() >= start + 2
                && turn(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0
            {
                hull.pop();
            }
            hull.push(q);
        }
        hull.pop();
    }
    hull
}

fn put(img: &mut RgbImage, x: i64, y: i64, c: Rgb<u8>) {
    if x >= 0 && y >= 0 && x < i64::from(img.width()) && y < i64::from(img.height()) {
        img.put_pixel(x as u32, y as u32, c);
    }
}

/// A two-pixel line through `points`, closed when `closed`.
fn polyline(img: &mut RgbImage, points: &[(f64, f64)], closed: bool, c: Rgb<u8>) {
    let n = points.len();
    let segments = if closed { n } else { n.saturating_sub(1) };
    for k in 0..segments {
        let (a, b) = (points[k], points[(k + 1) % n]);
        let steps = ((b.0 - a.0).abs().max((b.1 - a.1).abs()).ceil() as usize).clamp(1, 20_000);
        for s in 0..=steps {
            let t = s as f64 / steps as f64;
            let (x, y) = (a.0 + (b.0 - a.0) * t, a.1 + (b.1 - a.1) * t);
            let (x, y) = (x.round() as i64, y.round() as i64);
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                put(img, x + dx, y + dy, c);
            }
        }
    }
}

/// A diagonal cross of half size `r` pixels centred at (x, y).
fn cross(img: &mut RgbImage, x: f64, y: f64, r: i64, c: Rgb<u8>) {
    let (x, y) = (x.round() as i64, y.round() as i64);
    for t in -r..=r {
        put(img, x + t, y + t, c);
        put(img, x + t, y - t, c);
    }
}

/// A square outline of half size `r` pixels centred at (x, y).
fn square(img: &mut RgbImage, x: f64, y: f64, r: i64, c: Rgb<u8>) {
    let (x, y) = (x.round() as i64, y.round() as i64);
    for t in -r..=r {
        put(img, x + t, y - r, c);
        put(img, x + t, y + r, c);
        put(img, x - r, y + t, c);
        put(img, x + r, y + t, c);
    }
}
