//! The capture of a failed learned-perception episode with what perception made of it: the
//! rendered feeder window of its last capture, and over it each detection's keypoints (projected
//! from its estimated pose through the calibrated camera) and centre, and the outline on the table
//! of each part it found but could not pose, so a person sees at once whether a part was missed,
//! mistaken, misplaced or left unposed.

use std::path::{Path, PathBuf};

use image::{Rgb, RgbImage};
use perception::{Frame, FrameContent, PartPerception, Perceived, PerceptionError};

use super::pictures::PictureError;
use crate::episode::EpisodeRecord;
use crate::harness::{SimSetup, run_sim_episode_with};

/// Colour of projected keypoints.
const KEYPOINT: Rgb<u8> = Rgb([255, 220, 0]);
/// Colour of a detection's centre box.
const CENTRE: Rgb<u8> = Rgb([255, 40, 200]);
/// Colour of the outline of a part found but not posed.
const UNPOSED: Rgb<u8> = Rgb([0, 220, 255]);

/// Perception that remembers the last frame it saw and what it found there.
struct Recording<'a> {
    inner: &'a mut dyn PartPerception,
    last: Option<(Frame, Perceived)>,
}

impl PartPerception for Recording<'_> {
    fn perceive(&mut self, frame: &Frame) -> Result<Perceived, PerceptionError> {
        let found = self.inner.perceive(frame)?;
        self.last = Some((frame.clone(), found.clone()));
        Ok(found)
    }
}

/// Replays `record`'s episode (same seed, same world) and draws its last capture with the
/// detections into `dir/episode-NNNNNN-capture.png`; `None` when its frames carry no pixels.
#[allow(non_snake_case)]
pub fn capture_picture(
    setup: &SimSetup,
    record: &EpisodeRecord,
    dir: &Path,
) -> Result<Option<PathBuf>, PictureError> {
    let scenario = setup.scenario();
    let cell_err = |e: String| PictureError::Cell(e);
    let mut perception = setup
        .perception
        .for_episode(scenario, record.episode)
        .map_err(|e| cell_err(e.to_string()))?;
    let mut recording = Recording {
        inner: &mut perception,
        last: None,
    };
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_time()
        .build()
        .map_err(|e| cell_err(e.to_string()))?;
    rt.block_on(run_sim_episode_with(setup, record.episode, &mut recording))
        .map_err(|e| cell_err(e.to_string()))?;
    let Some((frame, found)) = recording.last else {
        return Ok(None);
    };
    let FrameContent::Image(shot) = &frame.content else {
        return Ok(None);
    };
    let mut picture = shot.pixels.to_rgb8();
    let [ox, oy] = shot.origin.map(f64::from);
    let camera_T_base = frame.base_T_camera.inverse();
    for d in &found.parts {
        let Some(part) = scenario.catalog.parts.iter().find(|p| p.name == d.part) else {
            continue;
        };
        let camera_T_part = camera_T_base * d.base_T_part;
        let keypoints = part.keypoint_points();
        for (k, p) in keypoints.iter().enumerate() {
            let Ok(px) = frame.camera.project(&(camera_T_part * p)) else {
                continue;
            };
            let (x, y) = (px.x - ox, px.y - oy);
            if k + 1 == keypoints.len() {
                square(&mut picture, x, y, 5, CENTRE);
            } else {
                cross(&mut picture, x, y, 3, KEYPOINT);
            }
        }
    }
    let camera_T_table = camera_T_base * setup.engine.knowledge.geometry.base_T_table;
    for u in &found.unposed {
        // Where its mask's outline meets the table (the points on the table plane).
        for p in u.table_points.iter().filter(|p| p.z == 0.0) {
            if let Ok(px) = frame.camera.project(&(camera_T_table * p)) {
                put(
                    &mut picture,
                    (px.x - ox).round() as i64,
                    (px.y - oy).round() as i64,
                    UNPOSED,
                );
            }
        }
    }
    std::fs::create_dir_all(dir).map_err(|e| PictureError::Write {
        path: dir.into(),
        reason: e.to_string(),
    })?;
    let path = dir.join(format!("episode-{:06}-capture.png", record.episode));
    picture.save(&path).map_err(|e| PictureError::Write {
        path: path.clone(),
        reason: e.to_string(),
    })?;
    Ok(Some(path))
}

fn put(img: &mut RgbImage, x: i64, y: i64, c: Rgb<u8>) {
    if x >= 0 && y >= 0 && x < i64::from(img.width()) && y < i64::from(img.height()) {
        img.put_pixel(x as u32, y as u32, c);
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
