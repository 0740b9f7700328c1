//! Finding the board in an image: tag detection by the reference AprilTag library and sub-pixel corners.
//!
//! The reference detector ([`apriltag`], which links the C library) finds and decodes the tags;
//! its corners are good to a few tenths of a pixel. [`refine_tag`](super::edges) then fits each of
//! a tag's four border edges as a straight line to the edge positions measured across it on the
//! full-resolution image, and intersects neighbouring lines.

use std::time::{Duration, Instant};

use apriltag::{Detector, Family, Image};
use image::GrayImage;
use nalgebra::Point2;

use super::edges::{Transfer, clipped_share, refine_quad};
use super::{Board, CalibrationError};
use crate::FrameImage;

/// How the board is detected. The defaults are measured on 20 MP renders of the seed's board at
/// 1.4–1.9 m (`cell board-study`; figures in docs/reference/calibration-figures.md).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectorSettings {
    /// Quad detection runs on the image shrunk by this factor (decoding reads full resolution).
    pub decimation: f32,
    /// Threads the reference detector uses.
    pub threads: u8,
    /// Gaussian blur sigma, pixels, applied before quad segmentation (0 for none).
    pub sigma: f32,
    /// Whether the reference detector snaps its decimated quads to the full-resolution edges.
    pub refine_edges: bool,
    /// Code bits the decoder may correct; decodes needing more are rejected. tag36h11 codes are
    /// 11 bits apart, so 1–2 corrected bits leave false ids practically impossible.
    pub max_hamming: u8,
    /// Whether to refine the corners to sub-pixel accuracy by edge-line fits.
    pub refine_corners: bool,
    /// How far across an edge the refinement looks for it, pixels (covers the initial corner
    /// error and the optical blur).
    pub edge_reach_px: f64,
    /// How the image's grey levels relate to light, undone before edges are located (an edge of a
    /// blurred step lies midway only in linear light).
    pub transfer: Transfer,
}

impl Default for DetectorSettings {
    fn default() -> Self {
        Self {
            decimation: 6.0,
            threads: 2,
            sigma: 0.8,
            refine_edges: true,
            max_hamming: 1,
            refine_corners: true,
            edge_reach_px: 4.0,
            transfer: Transfer::Srgb,
        }
    }
}

/// One decoded tag of the board.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TagSighting {
    /// Its id.
    pub id: u32,
    /// Its border corners in full-sensor pixels (distorted, as observed), in the order of
    /// [`Board::corners`]; refined when the settings ask for it.
    pub corners: [Point2<f64>; 4],
    /// The same corners as the reference detector reported them.
    pub raw_corners: [Point2<f64>; 4],
    /// The decoder's decision margin (higher is surer).
    pub margin: f32,
    /// Code bits the decoder corrected.
    pub hamming: u8,
    /// Share of the pixels around its border edges at full scale ([`clipped_share`]).
    pub clipped: f64,
}

/// Time spent in each stage of a detection.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct DetectionTimings {
    /// Converting the pixels to the detector's 8-bit grey buffer.
    pub convert: Duration,
    /// The reference detector: quads and decoding.
    pub decode: Duration,
    /// Sub-pixel corner refinement.
    pub refine: Duration,
}

impl DetectionTimings {
    /// All stages together.
    pub fn total(&self) -> Duration {
        self.convert + self.decode + self.refine
    }
}

/// What detection found of the board in one image.
#[derive(Debug, Clone, PartialEq)]
pub struct BoardSighting {
    /// The board's tags that decoded, in id order.
    pub tags: Vec<TagSighting>,
    /// Ids of the family that decoded but are not on the board.
    pub foreign: Vec<u32>,
    /// The sensor pixels the image covered: `[column, row]` of its top-left pixel and its size.
    pub origin: [u32; 2],
    /// Image size `[width, height]`.
    pub size: [u32; 2],
    /// Time per stage.
    pub timings: DetectionTimings,
}

/// The reference detector set up for one board's family, reusable across images.
pub struct BoardDetector {
    detector: Detector,
    board: Board,
    settings: DetectorSettings,
}

impl std::fmt::Debug for BoardDetector {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BoardDetector")
            .field("family", &self.board.family().name)
            .field("settings", &self.settings)
            .finish()
    }
}

impl BoardDetector {
    /// A detector for `board`'s family with `settings`.
    pub fn new(board: &Board, settings: &DetectorSettings) -> Result<Self, CalibrationError> {
        let family: Family = board.family().name.parse().map_err(|_| {
            CalibrationError::Detector(format!(
                "the reference library has no family `{}`",
                board.family().name
            ))
        })?;
        let mut detector = Detector::builder()
            .add_family_bits(family, usize::from(settings.max_hamming))
            .build()
            .map_err(|e| CalibrationError::Detector(e.to_string()))?;
        detector.set_thread_number(settings.threads.max(1));
        detector.set_decimation(settings.decimation.max(1.0));
        detector.set_sigma(settings.sigma.max(0.0));
        detector.set_refine_edges(settings.refine_edges);
        Ok(Self {
            detector,
            board: board.clone(),
            settings: *settings,
        })
    }

    /// Every tag of the family in `image`, the board's and foreign ones, without refusing
    /// anything ([`BoardDetector::detect`] refuses).
    pub fn sight(&mut self, image: &FrameImage) -> Result<BoardSighting, CalibrationError> {
        let t0 = Instant::now();
        let owned;
        let grey: &GrayImage = match image.pixels.as_luma8() {
            Some(g) => g,
            None => {
                owned = image.pixels.to_luma8();
                &owned
            }
        };
        let buffer = to_detector_image(grey)?;
        let t1 = Instant::now();
        let detections = self.detector.detect(&buffer);
        let t2 = Instant::now();
        let (ox, oy) = (f64::from(image.origin[0]), f64::from(image.origin[1]));
        let mut tags: Vec<TagSighting> = Vec::new();
        let mut foreign = Vec::new();
        for d in &detections {
            let id = d.id() as u32;
            if d.hamming() > usize::from(self.settings.max_hamming) {
                continue;
            }
            if self.board.tag(id).is_none() {
                foreign.push(id);
                continue;
            }
            // The reference library puts pixel centres at half-integers; ours are at integers.
            let window = d.corners().map(|[x, y]| Point2::new(x - 0.5, y - 0.5));
            let refined = if self.settings.refine_corners {
                refine_quad(
                    grey,
                    &window,
                    self.settings.edge_reach_px,
                    self.settings.transfer,
                )
                .unwrap_or(window)
            } else {
                window
            };
            let shift = |p: Point2<f64>| Point2::new(p.x + ox, p.y + oy);
            let sighting = TagSighting {
                id,
                corners: refined.map(shift),
                raw_corners: window.map(shift),
                margin: d.decision_margin(),
                hamming: d.hamming() as u8,
                clipped: clipped_share(grey, &refined, self.settings.edge_reach_px),
            };
            // A tag decoded twice (it should not be) keeps its surest decode.
            match tags.iter_mut().find(|t| t.id == id) {
                Some(t) if t.margin < sighting.margin => *t = sighting,
                Some(_) => {}
                None => tags.push(sighting),
            }
        }
        tags.sort_by_key(|t| t.id);
        foreign.sort_unstable();
        foreign.dedup();
        let t3 = Instant::now();
        Ok(BoardSighting {
            tags,
            foreign,
            origin: image.origin,
            size: [image.width(), image.height()],
            timings: DetectionTimings {
                convert: t1 - t0,
                decode: t2 - t1,
                refine: t3 - t2,
            },
        })
    }

    /// The board's tags in `image`; refuses an image with no tag of the board (`NoBoard`) and
    /// one with a decoded id that is not on the board (`ForeignTag`).
    pub fn detect(&mut self, image: &FrameImage) -> Result<BoardSighting, CalibrationError> {
        let sighting = self.sight(image)?;
        let tags = self.board.tags();
        let (first, last) = (tags[0].id, tags[tags.len() - 1].id);
        if !sighting.foreign.is_empty() {
            return Err(CalibrationError::ForeignTag {
                ids: sighting.foreign,
                first,
                last,
            });
        }
        if sighting.tags.is_empty() {
            return Err(CalibrationError::NoBoard {
                family: self.board.family().name.clone(),
                first,
                last,
            });
        }
        Ok(sighting)
    }
}

/// Finds `board` in `image` (a window of the sensor at `image.origin`, or the whole of it):
/// decoded tags with sub-pixel corners in full-sensor pixels, and the time each stage took.
pub fn detect_board(
    image: &FrameImage,
    board: &Board,
    settings: &DetectorSettings,
) -> Result<BoardSighting, CalibrationError> {
    BoardDetector::new(board, settings)?.detect(image)
}

/// The reference detector's image of `grey` (its rows padded to the library's alignment).
fn to_detector_image(grey: &GrayImage) -> Result<Image, CalibrationError> {
    let (w, h) = (grey.width() as usize, grey.height() as usize);
    if w == 0 || h == 0 {
        return Err(CalibrationError::Detector("the image is empty".into()));
    }
    let mut image = Image::zeros_with_alignment(w, h, apriltag::image_buf::DEFAULT_ALIGNMENT_U8)
        .map_err(|e| CalibrationError::Detector(e.to_string()))?;
    let stride = image.stride();
    let dst = image.as_slice_mut();
    for (row, src) in grey.as_raw().chunks_exact(w).enumerate() {
        dst[row * stride..row * stride + w].copy_from_slice(src);
    }
    Ok(image)
}
