//! The board study behind `cell board-study`: boards rendered under the renderer's
//! randomisation at 1.4–1.9 m, detected and posed as `cell calibrate` does, and compared with the
//! simulator's truth (tags decoded, corner error before and after refinement, board pose error
//! against its Cramér–Rao bound, time per stage on the full 20 MP frame).

#![allow(non_snake_case)]

use std::path::Path;
use std::time::Duration;

use anyhow::Context;
use nalgebra::{Isometry3, Point2, Vector6};
use perception::calibration::board_pose::{board_error, board_pose, cramer_rao, to_board_frame};
use perception::calibration::detect::BoardDetector;
use perception::calibration::{Board, DetectorSettings};
use perception::{Camera, FrameImage};
use serde::Serialize;
use sim::scene::{Randomisation, board_render_settings, embed_in_full_frame, sample_board_view};

/// Grey levels of noise on the table around the board window in a full frame.
const TABLE_NOISE: u8 = 4;

/// One rendered board and the truth about it.
pub struct Render {
    image: FrameImage,
    camera_T_board: Isometry3<f64>,
    /// Ids whose four corners lie inside the image, at least a blur's width from its border.
    visible: Vec<u32>,
    height_m: f64,
    tilt_deg: f64,
}

/// What was measured on one image.
#[derive(Debug, Clone, Serialize)]
pub struct ImageResult {
    index: usize,
    height_m: f64,
    tilt_deg: f64,
    visible: usize,
    decoded: usize,
    false_ids: Vec<u32>,
    missed: Vec<u32>,
    corner_rms_raw_px: f64,
    corner_rms_refined_px: f64,
    reprojection_rms_px: f64,
    /// Board-frame error `[x, y, z]` µm and `[rx, ry, rz]` µrad (truth relative to estimate).
    error_um: [f64; 3],
    error_urad: [f64; 3],
    /// The pose's own 1σ (from its residuals), µm and µrad.
    sigma_um: [f64; 3],
    sigma_urad: [f64; 3],
    /// Time per stage, ms.
    convert_ms: f64,
    decode_ms: f64,
    refine_ms: f64,
    pose_ms: f64,
    /// Why no pose, if none.
    refused: Option<String>,
    #[serde(skip)]
    corner_errors: Vec<[f64; 2]>,
    #[serde(skip)]
    camera_T_board: Isometry3<f64>,
    #[serde(skip)]
    ids: Vec<u32>,
}

/// Mean, 1σ and 95th percentile of a sample.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Spread {
    mean: f64,
    sd: f64,
    p95: f64,
    max: f64,
}

fn spread(values: &[f64]) -> Spread {
    let n = values.len().max(1) as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let at = |q: f64| {
        sorted
            .get(((q * (sorted.len() as f64 - 1.0)).round()) as usize)
            .copied()
            .unwrap_or(f64::NAN)
    };
    Spread {
        mean,
        sd: var.sqrt(),
        p95: at(0.95),
        max: at(1.0),
    }
}

/// The overall figures.
#[derive(Debug, Serialize)]
pub struct Summary {
    images: usize,
    board: String,
    full_frame: bool,
    settings: String,
    tags_visible: usize,
    tags_decoded: usize,
    decode_rate: f64,
    false_ids: usize,
    poses: usize,
    /// Images without a pose, and why.
    refusals: Vec<String>,
    corner_rms_raw_px: f64,
    corner_rms_refined_px: f64,
    /// Measured corner noise per axis (refined corners against the truth), pixels.
    corner_sigma_px: f64,
    /// Board pose error over images, per board axis: translation µm, rotation µrad.
    error_um: [Spread; 3],
    error_urad: [Spread; 3],
    /// 1σ over images (root mean square of the error).
    rms_error_um: [f64; 3],
    rms_error_urad: [f64; 3],
    /// The Cramér–Rao bound at each image's measured corner noise (root mean square over images).
    crb_um: [f64; 3],
    crb_urad: [f64; 3],
    /// Achieved 1σ over the bound, per component.
    ratio_to_crb: [f64; 6],
    convert_ms: Spread,
    decode_ms: Spread,
    refine_ms: Spread,
    pose_ms: Spread,
    total_ms: Spread,
}

/// A study's JSON file: the overall figures and each image's.
#[derive(Serialize)]
pub struct Report<'a> {
    /// The overall figures.
    pub summary: &'a Summary,
    /// Each image's.
    pub images: &'a [ImageResult],
}

/// Renders board view `i` of the study seeded `seed`.
pub fn render(board: &Board, camera: &Camera, seed: u64, i: usize) -> anyhow::Result<Render> {
    let mut rng = sim::seed::stream_rng(seed, i as u64, 0);
    let view = sample_board_view(board, camera, &Randomisation::default(), &mut rng)?;
    let window = view
        .window()
        .context("the board is out of the camera's view")?;
    let image = view.render(window, &board_render_settings(), &mut rng)?;
    let t = image.camera_T_board;
    let table_T_camera = t.inverse();
    let axis = table_T_camera.rotation * nalgebra::Vector3::z();
    let (x0, y0) = (f64::from(window.x0), f64::from(window.y0));
    let (x1, y1) = (
        x0 + f64::from(window.width) - 1.0,
        y0 + f64::from(window.height) - 1.0,
    );
    const BORDER_PX: f64 = 8.0;
    let visible = board
        .tags()
        .iter()
        .filter(|tag| {
            board.corners(tag.id).is_some_and(|c| {
                c.iter().all(|p| {
                    camera.project(&(t * p)).is_ok_and(|q| {
                        q.x >= x0 + BORDER_PX
                            && q.y >= y0 + BORDER_PX
                            && q.x <= x1 - BORDER_PX
                            && q.y <= y1 - BORDER_PX
                    })
                })
            })
        })
        .map(|tag| tag.id)
        .collect();
    Ok(Render {
        image: image.image,
        camera_T_board: t,
        visible,
        height_m: table_T_camera.translation.vector.z,
        tilt_deg: (-axis.z).clamp(-1.0, 1.0).acos().to_degrees(),
    })
}

/// What the detector is given for `r`: its board window alone, or (`full_frame`) the window
/// pasted into the camera's full 20 MP frame of noisy table, as a camera delivers it.
pub fn frame(r: &Render, camera: &Camera, full_frame: bool) -> FrameImage {
    if full_frame {
        embed_in_full_frame(&r.image, camera, border_grey(&r.image), TABLE_NOISE)
    } else {
        r.image.clone()
    }
}

/// The median grey of an image's outermost rows and columns: the table around the board.
fn border_grey(image: &FrameImage) -> u8 {
    let g = image.pixels.to_luma8();
    let (w, h) = (g.width(), g.height());
    let mut v: Vec<u8> = (0..w)
        .flat_map(|x| [g.get_pixel(x, 0).0[0], g.get_pixel(x, h - 1).0[0]])
        .chain((0..h).flat_map(|y| [g.get_pixel(0, y).0[0], g.get_pixel(w - 1, y).0[0]]))
        .collect();
    let k = v.len() / 2;
    *v.select_nth_unstable(k).1
}

/// Detects, solves and compares one image with its truth.
pub fn measure(
    index: usize,
    r: &Render,
    frame: &FrameImage,
    detector: &mut BoardDetector,
    board: &Board,
    camera: &Camera,
) -> ImageResult {
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    let mut out = ImageResult {
        index,
        height_m: r.height_m,
        tilt_deg: r.tilt_deg,
        visible: r.visible.len(),
        decoded: 0,
        false_ids: Vec::new(),
        missed: r.visible.clone(),
        corner_rms_raw_px: f64::NAN,
        corner_rms_refined_px: f64::NAN,
        reprojection_rms_px: f64::NAN,
        error_um: [f64::NAN; 3],
        error_urad: [f64::NAN; 3],
        sigma_um: [f64::NAN; 3],
        sigma_urad: [f64::NAN; 3],
        convert_ms: f64::NAN,
        decode_ms: f64::NAN,
        refine_ms: f64::NAN,
        pose_ms: f64::NAN,
        refused: None,
        corner_errors: Vec::new(),
        camera_T_board: r.camera_T_board,
        ids: Vec::new(),
    };
    let sighting = match detector.sight(frame) {
        Ok(s) => s,
        Err(e) => {
            out.refused = Some(e.to_string());
            return out;
        }
    };
    out.convert_ms = ms(sighting.timings.convert);
    out.decode_ms = ms(sighting.timings.decode);
    out.refine_ms = ms(sighting.timings.refine);
    out.false_ids = sighting.foreign.clone();
    out.decoded = sighting
        .tags
        .iter()
        .filter(|t| r.visible.contains(&t.id))
        .count();
    out.missed
        .retain(|id| !sighting.tags.iter().any(|t| t.id == *id));
    let (mut raw, mut refined) = (0.0, 0.0);
    for t in &sighting.tags {
        let Some(model) = board.corners(t.id) else {
            continue;
        };
        for (k, point) in model.iter().enumerate() {
            let truth: Point2<f64> = match camera.project(&(r.camera_T_board * point)) {
                Ok(p) => p,
                Err(_) => continue,
            };
            raw += (t.raw_corners[k] - truth).norm_squared();
            let e = t.corners[k] - truth;
            refined += e.norm_squared();
            out.corner_errors.push([e.x, e.y]);
        }
    }
    let n = out.corner_errors.len().max(1) as f64;
    out.corner_rms_raw_px = (raw / n).sqrt();
    out.corner_rms_refined_px = (refined / n).sqrt();
    out.ids = sighting.tags.iter().map(|t| t.id).collect();
    let started = std::time::Instant::now();
    match board_pose(camera, board, &sighting) {
        Ok(pose) => {
            out.pose_ms = ms(started.elapsed());
            out.reprojection_rms_px = pose.rms_px;
            let e = board_error(&pose.camera_T_board, &r.camera_T_board);
            out.error_um = [e[0] * 1e6, e[1] * 1e6, e[2] * 1e6];
            out.error_urad = [e[3] * 1e6, e[4] * 1e6, e[5] * 1e6];
            let s = pose.sigma_at_table();
            out.sigma_um = s.translation_mm.map(|v| v * 1e3);
            out.sigma_urad = s.rotation_deg.map(|v| v.to_radians() * 1e6);
        }
        Err(e) => out.refused = Some(e.to_string()),
    }
    out
}

/// The overall figures of a study's images.
pub fn summarise(
    results: &[ImageResult],
    board: &Board,
    camera: &Camera,
    settings: &DetectorSettings,
    full_frame: bool,
    board_name: &str,
) -> Summary {
    let visible: usize = results.iter().map(|r| r.visible).sum();
    let decoded: usize = results.iter().map(|r| r.decoded).sum();
    let false_ids: usize = results.iter().map(|r| r.false_ids.len()).sum();
    let pooled = |f: &dyn Fn(&ImageResult) -> f64| {
        let (s, n) =
            results
                .iter()
                .filter(|r| !r.corner_errors.is_empty())
                .fold((0.0, 0.0), |(s, n), r| {
                    let k = r.corner_errors.len() as f64;
                    (s + f(r).powi(2) * k, n + k)
                });
        (s / n).sqrt()
    };
    let corner_rms_raw_px = pooled(&|r| r.corner_rms_raw_px);
    let corner_rms_refined_px = pooled(&|r| r.corner_rms_refined_px);
    // Per-axis corner noise of the images the bound is for (those with a pose): the refined
    // corners' pooled error over both axes.
    let (sq, n) = results
        .iter()
        .filter(|r| r.refused.is_none())
        .flat_map(|r| &r.corner_errors)
        .fold((0.0, 0.0), |(s, n), e| {
            (s + e[0] * e[0] + e[1] * e[1], n + 2.0)
        });
    let corner_sigma_px = (sq / f64::max(n, 1.0)).sqrt();
    let posed: Vec<&ImageResult> = results.iter().filter(|r| r.refused.is_none()).collect();
    let column =
        |f: &dyn Fn(&ImageResult) -> f64| -> Vec<f64> { posed.iter().map(|r| f(r)).collect() };
    let error_um = [0, 1, 2].map(|k| spread(&column(&|r| r.error_um[k])));
    let error_urad = [0, 1, 2].map(|k| spread(&column(&|r| r.error_urad[k])));
    let rms = |v: Vec<f64>| (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt();
    let rms_error_um = [0, 1, 2].map(|k| rms(column(&|r| r.error_um[k])));
    let rms_error_urad = [0, 1, 2].map(|k| rms(column(&|r| r.error_urad[k])));
    // The bound at each image's true pose and tags, at that image's own corner noise (images
    // differ in noise, blur and contrast, so one pooled σ would misstate each).
    let mut crb_sq = Vector6::zeros();
    for r in &posed {
        let sigma = r.corner_rms_refined_px / 2f64.sqrt();
        let c = to_board_frame(
            &r.camera_T_board,
            &cramer_rao(camera, board, &r.ids, &r.camera_T_board, sigma),
        );
        crb_sq += c.diagonal();
    }
    let crb = (crb_sq / posed.len().max(1) as f64).map(f64::sqrt);
    let crb_um = [crb[0] * 1e6, crb[1] * 1e6, crb[2] * 1e6];
    let crb_urad = [crb[3] * 1e6, crb[4] * 1e6, crb[5] * 1e6];
    let achieved = [
        rms_error_um[0],
        rms_error_um[1],
        rms_error_um[2],
        rms_error_urad[0],
        rms_error_urad[1],
        rms_error_urad[2],
    ];
    let bound = [
        crb_um[0],
        crb_um[1],
        crb_um[2],
        crb_urad[0],
        crb_urad[1],
        crb_urad[2],
    ];
    let ratio_to_crb = [0, 1, 2, 3, 4, 5].map(|k| achieved[k] / bound[k]);
    let timed: Vec<&ImageResult> = results.iter().filter(|r| r.decode_ms.is_finite()).collect();
    let times = |f: &dyn Fn(&ImageResult) -> f64| {
        spread(
            &timed
                .iter()
                .map(|r| f(r))
                .filter(|v| v.is_finite())
                .collect::<Vec<_>>(),
        )
    };
    Summary {
        images: results.len(),
        board: board_name.to_string(),
        full_frame,
        settings: format!("{settings:?}"),
        tags_visible: visible,
        tags_decoded: decoded,
        decode_rate: decoded as f64 / visible.max(1) as f64,
        false_ids,
        poses: posed.len(),
        refusals: results
            .iter()
            .filter_map(|r| {
                r.refused
                    .as_ref()
                    .map(|why| format!("image {}: {why}", r.index))
            })
            .collect(),
        corner_rms_raw_px,
        corner_rms_refined_px,
        corner_sigma_px,
        error_um,
        error_urad,
        rms_error_um,
        rms_error_urad,
        crb_um,
        crb_urad,
        ratio_to_crb,
        convert_ms: times(&|r| r.convert_ms),
        decode_ms: times(&|r| r.decode_ms),
        refine_ms: times(&|r| r.refine_ms),
        pose_ms: times(&|r| r.pose_ms),
        total_ms: times(&|r| r.convert_ms + r.decode_ms + r.refine_ms + r.pose_ms),
    }
}

/// Truth saved beside each PNG for the comparison scripts.
#[derive(Serialize)]
struct Truth {
    /// Sensor pixel of the PNG's top-left pixel.
    origin: [u32; 2],
    camera: CameraJson,
    /// Row-major 4 × 4 pose of the board in the camera, metres.
    camera_T_board: [[f64; 4]; 4],
    /// Per tag: id, board-frame corners (metres) and true pixel corners (full sensor), in the
    /// reference detector's order, and whether it is fully in view.
    tags: Vec<TagTruth>,
}

#[derive(Serialize)]
struct CameraJson {
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    width: u32,
    height: u32,
    /// OpenCV order k1, k2, p1, p2, k3.
    distortion: [f64; 5],
}

#[derive(Serialize)]
struct TagTruth {
    id: u32,
    board: [[f64; 3]; 4],
    pixels: [[f64; 2]; 4],
    visible: bool,
}

/// Saves render `i` as a PNG with its truth beside it (JSON), for the comparison scripts.
pub fn save(
    dir: &Path,
    i: usize,
    r: &Render,
    board: &Board,
    camera: &Camera,
) -> anyhow::Result<()> {
    let png = dir.join(format!("board_{i:04}.png"));
    let mut bytes = Vec::new();
    r.image.pixels.write_to(
        &mut std::io::Cursor::new(&mut bytes),
        image::ImageFormat::Png,
    )?;
    sim::fsutil::write_atomic(&png, &bytes)
        .with_context(|| format!("cannot write {}", png.display()))?;
    let m = r.camera_T_board.to_homogeneous();
    let tags = board
        .tags()
        .iter()
        .filter_map(|t| {
            let c = board.corners(t.id)?;
            let pixels = c.map(|p| {
                camera
                    .project(&(r.camera_T_board * p))
                    .map_or([f64::NAN; 2], |q| [q.x, q.y])
            });
            Some(TagTruth {
                id: t.id,
                board: c.map(|p| [p.x, p.y, p.z]),
                pixels,
                visible: r.visible.contains(&t.id),
            })
        })
        .collect();
    let truth = Truth {
        origin: r.image.origin,
        camera: CameraJson {
            fx: camera.fx,
            fy: camera.fy,
            cx: camera.cx,
            cy: camera.cy,
            width: camera.width,
            height: camera.height,
            distortion: camera.distortion.as_array(),
        },
        camera_T_board: std::array::from_fn(|row| std::array::from_fn(|col| m[(row, col)])),
        tags,
    };
    let json = dir.join(format!("board_{i:04}.json"));
    sim::fsutil::write_atomic(&json, &serde_json::to_vec_pretty(&truth)?)
        .with_context(|| format!("cannot write {}", json.display()))?;
    Ok(())
}

/// The study's figures as the command prints them.
pub fn summary_text(s: &Summary) -> String {
    let mut out = String::new();
    let mut line = |l: String| {
        out.push_str(&l);
        out.push('\n');
    };
    line(format!(
        "{} images ({}), board {}",
        s.images,
        if s.full_frame {
            "full 5472 × 3648 frames"
        } else {
            "board windows"
        },
        s.board
    ));
    line(format!(
        "tags decoded: {} of {} visible ({:.3} %), false ids: {}, poses: {}",
        s.tags_decoded,
        s.tags_visible,
        100.0 * s.decode_rate,
        s.false_ids,
        s.poses
    ));
    for r in &s.refusals {
        line(format!("  no pose: {r}"));
    }
    line(format!(
        "corner error (rms, px): reference detector {:.4}, refined {:.4} (σ per axis where posed {:.4})",
        s.corner_rms_raw_px, s.corner_rms_refined_px, s.corner_sigma_px
    ));
    line("board pose error, 1σ over images (mean) | Cramér–Rao bound | ratio:".to_string());
    for (k, name) in ["x (in plane)", "y (in plane)", "z (height)"]
        .iter()
        .enumerate()
    {
        line(format!(
            "  {name:<14} {:>8.2} µm ({:+.2}) | {:>7.2} µm | {:.2}",
            s.rms_error_um[k], s.error_um[k].mean, s.crb_um[k], s.ratio_to_crb[k]
        ));
    }
    for (k, name) in ["about x", "about y", "about z"].iter().enumerate() {
        line(format!(
            "  {name:<14} {:>8.2} µrad ({:+.2}) | {:>7.2} µrad | {:.2}",
            s.rms_error_urad[k],
            s.error_urad[k].mean,
            s.crb_urad[k],
            s.ratio_to_crb[k + 3]
        ));
    }
    line("time per image, ms (mean / p95 / max):".to_string());
    for (name, t) in [
        ("convert", s.convert_ms),
        ("decode", s.decode_ms),
        ("refine", s.refine_ms),
        ("pose", s.pose_ms),
        ("total", s.total_ms),
    ] {
        line(format!(
            "  {name:<8} {:>8.1} / {:>8.1} / {:>8.1}",
            t.mean, t.p95, t.max
        ));
    }
    out
}
