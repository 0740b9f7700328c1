//! The BOP format's files (https://github.com/thodan/bop_toolkit/blob/master/docs/bop_datasets_format.md):
//! millimetres, OpenCV camera frame, rotations as row-major 3 × 3 lists.

use std::collections::BTreeMap;
use std::path::Path;

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use perception::camera::Camera;
use serde::{Deserialize, Serialize};

use super::DatasetError;
use super::files::{create_dir, write_bytes, write_json};
use crate::scene::PartModel;

/// camera.json: the dataset's nominal camera.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BopCamera {
    /// Principal point column, px.
    pub cx: f64,
    /// Principal point row, px.
    pub cy: f64,
    /// Millimetres per depth PNG unit.
    pub depth_scale: f64,
    /// Focal length x, px.
    pub fx: f64,
    /// Focal length y, px.
    pub fy: f64,
    /// Image height, px.
    pub height: u32,
    /// Image width, px.
    pub width: u32,
    /// OpenCV distortion (k1, k2, p1, p2, k3): an extension; BOP assumes undistorted images,
    /// ours are rendered through the lens.
    #[serde(default)]
    pub dist_coeffs: [f64; 5],
}

impl BopCamera {
    /// camera.json for a camera.
    pub fn new(camera: &Camera, depth_scale: f64) -> Self {
        Self {
            cx: camera.cx,
            cy: camera.cy,
            depth_scale,
            fx: camera.fx,
            fy: camera.fy,
            height: camera.height,
            width: camera.width,
            dist_coeffs: camera.distortion.as_array(),
        }
    }
}

/// One entry of scene_camera.json.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneCamera {
    /// Intrinsic matrix, row-major.
    pub cam_K: [f64; 9],
    /// Millimetres per depth PNG unit.
    pub depth_scale: f64,
    /// World (table) to camera rotation, row-major.
    pub cam_R_w2c: [f64; 9],
    /// World (table) to camera translation, mm.
    pub cam_t_w2c: [f64; 3],
    /// Image width, px (extension: overview windows differ from camera.json).
    pub width: u32,
    /// Image height, px (extension).
    pub height: u32,
    /// Distortion (k1, k2, p1, p2, k3) (extension).
    pub dist_coeffs: [f64; 5],
}

/// One entry of scene_gt.json.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GtPose {
    /// Model to camera rotation, row-major.
    pub cam_R_m2c: [f64; 9],
    /// Model to camera translation, mm.
    pub cam_t_m2c: [f64; 3],
    /// Object id (1-based).
    pub obj_id: u32,
}

/// One entry of scene_gt_info.json.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GtInfo {
    /// Box of the full silhouette (x, y, w, h), −1s when outside.
    pub bbox_obj: [i64; 4],
    /// Box of the visible part.
    pub bbox_visib: [i64; 4],
    /// Pixels of the full silhouette inside the image.
    pub px_count_all: u64,
    /// Silhouette pixels with a valid depth.
    pub px_count_valid: u64,
    /// Visible pixels.
    pub px_count_visib: u64,
    /// px_count_visib / px_count_all.
    pub visib_fract: f64,
}

/// One entry of models_info.json (millimetres).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModelInfo {
    /// Largest distance between two vertices, mm.
    pub diameter: f64,
    /// Bounding box minimum x, mm.
    pub min_x: f64,
    /// Bounding box minimum y, mm.
    pub min_y: f64,
    /// Bounding box minimum z, mm.
    pub min_z: f64,
    /// Bounding box size x, mm.
    pub size_x: f64,
    /// Bounding box size y, mm.
    pub size_y: f64,
    /// Bounding box size z, mm.
    pub size_z: f64,
    /// Discrete symmetries as row-major 4 × 4 matrices (translation in mm).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub symmetries_discrete: Vec<[f64; 16]>,
}

/// Row-major list of a rotation matrix.
pub(crate) fn row_major(r: &Matrix3<f64>) -> [f64; 9] {
    [
        r[(0, 0)],
        r[(0, 1)],
        r[(0, 2)],
        r[(1, 0)],
        r[(1, 1)],
        r[(1, 2)],
        r[(2, 0)],
        r[(2, 1)],
        r[(2, 2)],
    ]
}

/// (R row-major, t in mm) of a pose.
pub fn pose_to_bop(pose: &Isometry3<f64>) -> ([f64; 9], [f64; 3]) {
    let r = pose.rotation.to_rotation_matrix();
    let t = pose.translation.vector * 1000.0;
    (row_major(r.matrix()), [t.x, t.y, t.z])
}

/// The pose (metres) of BOP's R (row-major) and t (mm); `None` if R is not a rotation.
pub fn pose_from_bop(r: &[f64; 9], t_mm: &[f64; 3]) -> Option<Isometry3<f64>> {
    let m = Matrix3::from_row_slice(r);
    if ((m.transpose() * m) - Matrix3::identity()).norm() > 1e-6 || m.determinant() < 0.0 {
        return None;
    }
    let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m));
    let t = Vector3::new(t_mm[0], t_mm[1], t_mm[2]) / 1000.0;
    Some(Isometry3::from_parts(Translation3::from(t), rot))
}

/// Writes models/obj_XXXXXX.ply (ASCII, mm) and models/models_info.json for the parts.
pub fn write_models(dir: &Path, models: &[PartModel]) -> Result<(), DatasetError> {
    let models_dir = dir.join("models");
    create_dir(&models_dir)?;
    let mut info = BTreeMap::new();
    for m in models {
        let mut ply = String::new();
        ply.push_str(
            "ply\nformat ascii 1.0\ncomment units: mm, part frame (bounding-box centre)\n",
        );
        ply.push_str(&format!("element vertex {}\n", m.mesh.vertices.len()));
        ply.push_str("property float x\nproperty float y\nproperty float z\n");
        ply.push_str(&format!("element face {}\n", m.mesh.triangles.len()));
        ply.push_str("property list uchar int vertex_indices\nend_header\n");
        for v in &m.mesh.vertices {
            ply.push_str(&format!(
                "{} {} {}\n",
                v.x * 1000.0,
                v.y * 1000.0,
                v.z * 1000.0
            ));
        }
        for t in &m.mesh.triangles {
            ply.push_str(&format!("3 {} {} {}\n", t[0], t[1], t[2]));
        }
        write_bytes(
            &models_dir.join(format!("obj_{:06}.ply", m.obj_id)),
            ply.as_bytes(),
        )?;
        let (lo, hi) = m.mesh.aabb();
        let size = (hi - lo) * 1000.0;
        let mut symmetries = Vec::new();
        for (axis, order) in m.spec.exact_symmetries() {
            for k in 1..order {
                let angle = std::f64::consts::TAU * k as f64 / order as f64;
                let r = Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), angle);
                let rm = r.matrix();
                symmetries.push([
                    rm[(0, 0)],
                    rm[(0, 1)],
                    rm[(0, 2)],
                    0.0,
                    rm[(1, 0)],
                    rm[(1, 1)],
                    rm[(1, 2)],
                    0.0,
                    rm[(2, 0)],
                    rm[(2, 1)],
                    rm[(2, 2)],
                    0.0,
                    0.0,
                    0.0,
                    0.0,
                    1.0,
                ]);
            }
        }
        info.insert(
            m.obj_id,
            ModelInfo {
                diameter: m.diameter() * 1000.0,
                min_x: lo.x * 1000.0,
                min_y: lo.y * 1000.0,
                min_z: lo.z * 1000.0,
                size_x: size.x,
                size_y: size.y,
                size_z: size.z,
                symmetries_discrete: symmetries,
            },
        );
    }
    write_json(&models_dir.join("models_info.json"), &info)
}
