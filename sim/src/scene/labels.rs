//! Per-instance labels of a render: class, pose in the camera frame, keypoints in pixels,
//! visible fraction, boxes, and PVNet's per-pixel unit vectors to each keypoint.

use nalgebra::{Isometry3, Point2};
use perception::camera::Camera;

use super::{PartModel, PlacedPart};
use crate::render::{InstanceMask, RenderOutput};

/// Labels of one instance, in the coordinates of the rendered window (its top-left pixel is 0, 0).
#[derive(Debug, Clone, PartialEq)]
pub struct InstanceLabel {
    /// Index of the instance in the scene.
    pub instance: usize,
    /// BOP object id of its part.
    pub obj_id: u32,
    /// Pose of the part in the camera frame.
    #[allow(non_snake_case)]
    pub camera_T_part: Isometry3<f64>,
    /// The 9 keypoints projected to window pixels (NaN when behind the camera).
    pub keypoints: Vec<Point2<f64>>,
    /// Window pixels the whole silhouette covers.
    pub px_count_all: usize,
    /// Window pixels where the instance is visible.
    pub px_count_visib: usize,
    /// px_count_visib / px_count_all (0 when the instance is outside the window).
    pub visib_fract: f64,
    /// Box of the full silhouette (x, y, width, height), or (−1, −1, −1, −1) when empty.
    pub bbox_obj: [i64; 4],
    /// Box of the visible pixels, or (−1, −1, −1, −1) when none.
    pub bbox_visib: [i64; 4],
}

/// Labels every instance of a render made with `camera` at `table_T_camera` (full masks required
/// for the silhouette counts; without them px_count_all falls back to the visible count).
#[allow(non_snake_case)]
pub fn label_instances(
    parts: &[PlacedPart],
    models: &[PartModel],
    camera: &Camera,
    table_T_camera: &Isometry3<f64>,
    out: &RenderOutput,
) -> Vec<InstanceLabel> {
    (0..parts.len())
        .map(|i| {
            label_instance(
                i,
                parts,
                models,
                camera,
                table_T_camera,
                out,
                out.full_masks.get(i),
            )
        })
        .collect()
}

/// Labels instance `i` of a render alone, with its full silhouette `full` (from
/// [`crate::render::instance_mask`]) when known: a crop needs only its target's labels and mask.
#[allow(non_snake_case)]
pub fn label_instance(
    i: usize,
    parts: &[PlacedPart],
    models: &[PartModel],
    camera: &Camera,
    table_T_camera: &Isometry3<f64>,
    out: &RenderOutput,
    full: Option<&InstanceMask>,
) -> InstanceLabel {
    let w = out.window;
    let part = &parts[i];
    let model = &models[part.model];
    let camera_T_part = table_T_camera.inverse() * part.table_T_part;
    let keypoints = model
        .keypoints
        .iter()
        .map(|k| match camera.project(&(camera_T_part * k)) {
            Ok(p) => Point2::new(p.x - w.x0 as f64, p.y - w.y0 as f64),
            Err(_) => Point2::new(f64::NAN, f64::NAN),
        })
        .collect();
    let id = (i + 1) as u16;
    let mut vis = BoxAcc::default();
    for (idx, v) in out.visible.iter().enumerate() {
        if *v == id {
            vis.add(idx % w.width as usize, idx / w.width as usize);
        }
    }
    let all = match full {
        Some(mask) => {
            let mut acc = BoxAcc::default();
            let mw = mask.window;
            for (idx, b) in mask.bits.iter().enumerate() {
                if *b {
                    let x = (mw.x0 - w.x0) as usize + idx % mw.width as usize;
                    let y = (mw.y0 - w.y0) as usize + idx / mw.width as usize;
                    acc.add(x, y);
                }
            }
            acc
        }
        None => vis,
    };
    InstanceLabel {
        instance: i,
        obj_id: model.obj_id,
        camera_T_part,
        keypoints,
        px_count_all: all.count,
        px_count_visib: vis.count,
        visib_fract: if all.count > 0 {
            vis.count as f64 / all.count as f64
        } else {
            0.0
        },
        bbox_obj: all.bbox(),
        bbox_visib: vis.bbox(),
    }
}

/// Running pixel count and bounding box.
#[derive(Debug, Clone, Copy)]
struct BoxAcc {
    count: usize,
    x0: usize,
    y0: usize,
    x1: usize,
    y1: usize,
}

impl Default for BoxAcc {
    fn default() -> Self {
        Self {
            count: 0,
            x0: usize::MAX,
            y0: usize::MAX,
            x1: 0,
            y1: 0,
        }
    }
}

impl BoxAcc {
    fn add(&mut self, x: usize, y: usize) {
        self.count += 1;
        self.x0 = self.x0.min(x);
        self.y0 = self.y0.min(y);
        self.x1 = self.x1.max(x);
        self.y1 = self.y1.max(y);
    }

    fn bbox(&self) -> [i64; 4] {
        if self.count == 0 {
            return [-1; 4];
        }
        [
            self.x0 as i64,
            self.y0 as i64,
            (self.x1 - self.x0 + 1) as i64,
            (self.y1 - self.y0 + 1) as i64,
        ]
    }
}

/// PVNet's regression targets: for every pixel of a `width` × `height` mask and every keypoint,
/// the unit vector from the pixel centre to the keypoint inside the mask, (0, 0) outside.
///
/// Layout: `[k][y][x]` → `(dx, dy)`, i.e. index `(k · height + y) · width + x`.
pub fn keypoint_vectors(
    mask: &[bool],
    width: usize,
    height: usize,
    keypoints: &[Point2<f64>],
) -> Vec<[f32; 2]> {
    let mut out = vec![[0f32; 2]; keypoints.len() * width * height];
    for (k, kp) in keypoints.iter().enumerate() {
        for y in 0..height {
            for x in 0..width {
                if !mask.get(y * width + x).copied().unwrap_or(false) {
                    continue;
                }
                let (dx, dy) = (kp.x - x as f64, kp.y - y as f64);
                let n = (dx * dx + dy * dy).sqrt();
                if n > 0.0 && n.is_finite() {
                    out[(k * height + y) * width + x] = [(dx / n) as f32, (dy / n) as f32];
                }
            }
        }
    }
    out
}
