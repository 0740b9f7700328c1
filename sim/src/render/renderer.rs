//! The ray tracer: one label ray per pixel centre (depth, visible instance), n × n stratified
//! samples per pixel for colour, shadow rays to every light, full masks per instance.

use nalgebra::{Isometry3, Point2, Point3, Vector3};
use perception::camera::Camera;
use rayon::prelude::*;

use super::geometry::SurfaceKind;
use super::shading::{ambient, brdf_cos};
use super::{Appearance, Hit, InstanceMask, RenderOutput, RenderScene, Window};

/// How to render.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RenderSettings {
    /// Colour samples per pixel along each axis (n × n stratified supersampling); 1 for none.
    pub supersampling: u32,
    /// Whether lights cast shadows.
    pub shadows: bool,
    /// Whether to compute each instance's full (unoccluded) silhouette.
    pub full_masks: bool,
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            supersampling: 2,
            shadows: true,
            full_masks: true,
        }
    }
}

/// Offset of shadow-ray origins along the normal, metres (well below the parts' 0.1 mm features).
const SHADOW_BIAS: f64 = 1e-7;

/// Renders `window` of the image of `camera` placed at `table_T_camera`.
///
/// Every pixel depends only on its own coordinates, so a window renders exactly the same pixels
/// as the same region of a larger render.
#[allow(non_snake_case)]
pub fn render(
    scene: &RenderScene,
    camera: &Camera,
    table_T_camera: &Isometry3<f64>,
    window: Window,
    settings: &RenderSettings,
) -> RenderOutput {
    let n = window.len();
    let mut radiance = vec![[0f32; 3]; n];
    let mut depth = vec![0f64; n];
    let mut visible = vec![0u16; n];
    let w = window.width as usize;
    let origin = Point3::from(table_T_camera.translation.vector);
    let ss = settings.supersampling.max(1);
    if w > 0 {
        radiance
            .par_chunks_mut(w)
            .zip(depth.par_chunks_mut(w))
            .zip(visible.par_chunks_mut(w))
            .enumerate()
            .for_each(|(row, ((rad, dep), vis))| {
                let y = (window.y0 as usize + row) as f64;
                for col in 0..w {
                    let x = (window.x0 as usize + col) as f64;
                    let Some(dc) = ray(camera, x, y) else {
                        continue;
                    };
                    let d = table_T_camera.rotation * dc;
                    let hit = scene.intersect(&origin, &d, f64::INFINITY);
                    if let Some(h) = hit {
                        dep[col] = h.t * dc.z;
                        if let SurfaceKind::Part(i) = h.kind {
                            vis[col] = (i + 1) as u16;
                        }
                    }
                    let c = if ss == 1 {
                        shade(scene, &origin, &d, hit.as_ref(), settings.shadows)
                    } else {
                        let mut acc = [0.0; 3];
                        for sy in 0..ss {
                            for sx in 0..ss {
                                let ox = (sx as f64 + 0.5) / ss as f64 - 0.5;
                                let oy = (sy as f64 + 0.5) / ss as f64 - 0.5;
                                let Some(ds) = ray(camera, x + ox, y + oy) else {
                                    continue;
                                };
                                let d = table_T_camera.rotation * ds;
                                let h = scene.intersect(&origin, &d, f64::INFINITY);
                                let s = shade(scene, &origin, &d, h.as_ref(), settings.shadows);
                                for k in 0..3 {
                                    acc[k] += s[k];
                                }
                            }
                        }
                        let m = 1.0 / (ss * ss) as f64;
                        [acc[0] * m, acc[1] * m, acc[2] * m]
                    };
                    rad[col] = [c[0] as f32, c[1] as f32, c[2] as f32];
                }
            });
    }
    let full_masks = if settings.full_masks {
        (0..scene.instances.len())
            .into_par_iter()
            .map(|i| full_mask(scene, i, camera, table_T_camera, window))
            .collect()
    } else {
        Vec::new()
    };
    RenderOutput {
        window,
        radiance,
        depth,
        visible,
        full_masks,
    }
}

/// Appearance of the surface at a hit point.
fn appearance_at(scene: &RenderScene, hit: &Hit, p: &Point3<f64>) -> Appearance {
    match hit.kind {
        SurfaceKind::Part(i) => scene.instances[i].appearance,
        SurfaceKind::Board => match &scene.board {
            Some(b) if hit.normal.z > 0.5 => b.appearance_at(p.x, p.y),
            Some(b) => b.white,
            None => Appearance::for_material(perception::part::Material::Aluminium),
        },
        SurfaceKind::Table => scene
            .table
            .map(|t| t.appearance)
            .unwrap_or_else(|| Appearance::for_material(perception::part::Material::DarkPlastic)),
    }
}

/// Radiance leaving the hit surface towards the camera.
fn shade(
    scene: &RenderScene,
    o: &Point3<f64>,
    d: &Vector3<f64>,
    hit: Option<&Hit>,
    shadows: bool,
) -> [f64; 3] {
    let Some(hit) = hit else {
        return [0.0; 3];
    };
    let p = o + hit.t * d;
    let a = appearance_at(scene, hit, &p);
    let n = hit.normal;
    let v = -d;
    let mut c = ambient(&a, &n, &v, &scene.ambient);
    let start = p + n * SHADOW_BIAS;
    for light in &scene.lights {
        let to = light.position - start;
        let dist = to.norm();
        if dist <= 0.0 {
            continue;
        }
        let l = to / dist;
        if n.dot(&l) <= 0.0 {
            continue;
        }
        if shadows && scene.occluded(&start, &l, dist) {
            continue;
        }
        let f = brdf_cos(&a, &n, &v, &l);
        let inv2 = 1.0 / (dist * dist);
        for k in 0..3 {
            c[k] += f[k] * light.intensity[k] * inv2;
        }
    }
    c
}

/// The full silhouette of instance `i`: pixel-centre rays against that instance alone, over the
/// projection of its bounding box (plus a margin for lens distortion) clipped to the window.
#[allow(non_snake_case)]
fn full_mask(
    scene: &RenderScene,
    i: usize,
    camera: &Camera,
    table_T_camera: &Isometry3<f64>,
    window: Window,
) -> InstanceMask {
    let (lo, hi) = scene.instance_bounds(i);
    let camera_T_table = table_T_camera.inverse();
    let (mut u0, mut v0, mut u1, mut v1) = (
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    );
    let mut whole = false;
    for k in 0..8 {
        let c = Point3::new(
            if k & 1 == 0 { lo.x } else { hi.x },
            if k & 2 == 0 { lo.y } else { hi.y },
            if k & 4 == 0 { lo.z } else { hi.z },
        );
        match camera.project(&(camera_T_table * c)) {
            Ok(px) if px.x.is_finite() && px.y.is_finite() => {
                u0 = u0.min(px.x);
                v0 = v0.min(px.y);
                u1 = u1.max(px.x);
                v1 = v1.max(px.y);
            }
            _ => whole = true,
        }
    }
    let margin = 3.0;
    let (wx0, wy0) = (window.x0 as f64, window.y0 as f64);
    let (wx1, wy1) = (wx0 + window.width as f64, wy0 + window.height as f64);
    let sub = if whole {
        window
    } else {
        let x0 = (u0 - margin).floor().clamp(wx0, wx1);
        let y0 = (v0 - margin).floor().clamp(wy0, wy1);
        let x1 = (u1 + margin).ceil().clamp(wx0, wx1);
        let y1 = (v1 + margin).ceil().clamp(wy0, wy1);
        Window {
            x0: x0 as u32,
            y0: y0 as u32,
            width: (x1 - x0) as u32,
            height: (y1 - y0) as u32,
        }
    };
    let origin = Point3::from(table_T_camera.translation.vector);
    let mut bits = vec![false; sub.len()];
    for (idx, b) in bits.iter_mut().enumerate() {
        let x = sub.x0 as f64 + (idx % sub.width as usize) as f64;
        let y = sub.y0 as f64 + (idx / sub.width as usize) as f64;
        if let Some(dc) = ray(camera, x, y) {
            let d = table_T_camera.rotation * dc;
            *b = scene
                .intersect_instance(i, &origin, &d, f64::INFINITY)
                .is_some();
        }
    }
    InstanceMask { window: sub, bits }
}

/// Unit camera-frame ray at pixel (x, y); `None` where the distortion cannot be inverted.
fn ray(camera: &Camera, x: f64, y: f64) -> Option<Vector3<f64>> {
    camera
        .pixel_ray(Point2::new(x, y))
        .ok()
        .map(|r| r.into_inner())
}
