//! Rendering a scene again after a few of its parts changed: a cell's camera sees the same feeder
//! capture after capture, with one part picked out of it. Only the pixels an added, removed or
//! moved part can affect are rendered again (its image, the shadows it casts, their edges); every
//! other pixel is the previous render's. The result is exactly what a full render gives, because
//! every pixel depends only on its own rays and its neighbours' centre rays (see
//! [`render`](super::render)).

use nalgebra::Isometry3;
use perception::camera::Camera;

use super::aabb::box_corners;
use super::light::light_cube;
use super::renderer::full_masks;
use super::{CentreRays, RenderOutput, RenderScene, RenderSettings, Window, render_with_rays};

/// Pixels added around an affected region's projected bounds: the neighbours whose centre rays
/// decide a pixel's edge supersampling (1), the samples' half-pixel reach, and the curvature of
/// projected box edges under lens distortion.
const MARGIN_PX: f64 = 4.0;

/// When the affected regions cover more than this share of the window, everything is rendered.
const MAX_DIRTY_SHARE: f64 = 0.6;

/// A renderer that remembers its last render and renders again only what changed.
#[derive(Debug, Clone, Default)]
pub struct IncrementalRenderer {
    last: Option<Last>,
    rendered: usize,
}

/// The last render and everything it depended on.
#[derive(Debug, Clone)]
#[allow(non_snake_case)]
struct Last {
    scene: RenderScene,
    camera: Camera,
    table_T_camera: Isometry3<f64>,
    window: Window,
    settings: RenderSettings,
    output: RenderOutput,
}

impl IncrementalRenderer {
    /// A renderer with nothing to reuse yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Renders `window` of `scene` as [`render_with_rays`](super::render_with_rays) does, reusing
    /// the previous render's pixels that no changed part can affect.
    #[allow(non_snake_case)]
    pub fn render(
        &mut self,
        scene: &RenderScene,
        camera: &Camera,
        table_T_camera: &Isometry3<f64>,
        window: Window,
        settings: &RenderSettings,
        rays: Option<&CentreRays>,
    ) -> &RenderOutput {
        let reused = self.last.take().and_then(|last| {
            let same_view = last.camera == *camera
                && last.table_T_camera == *table_T_camera
                && last.window == window
                && last.settings == *settings;
            (same_view && same_setting(&last.scene, scene)).then(|| update(last, scene, rays))?
        });
        let (output, rendered) = match reused {
            Some(done) => done,
            None => (
                render_with_rays(scene, camera, table_T_camera, window, settings, rays),
                window.len(),
            ),
        };
        self.rendered = rendered;
        let last = self.last.insert(Last {
            scene: scene.clone(),
            camera: *camera,
            table_T_camera: *table_T_camera,
            window,
            settings: *settings,
            output,
        });
        &last.output
    }

    /// How many pixels the last call rendered (the window's size when nothing was reused).
    pub fn rendered_pixels(&self) -> usize {
        self.rendered
    }
}

/// Whether two scenes share everything but their parts: board, table, lights and ambient light.
fn same_setting(a: &RenderScene, b: &RenderScene) -> bool {
    a.board == b.board && a.table == b.table && a.lights == b.lights && a.ambient == b.ambient
}

/// The last render brought up to `scene`, and how many pixels that rendered; `None` when too much
/// changed (or the change cannot be bounded) for reuse to pay.
fn update(
    last: Last,
    scene: &RenderScene,
    rays: Option<&CentreRays>,
) -> Option<(RenderOutput, usize)> {
    let old = &last.scene;
    let (new_of_old, added) = match_instances(old, scene)?;
    let floor = lowest_surface(old).min(lowest_surface(scene));
    let mut dirty = Vec::new();
    for (i, matched) in new_of_old.iter().enumerate() {
        if matched.is_none() {
            dirty.push(affected_pixels(old, i, &last, floor)?);
        }
    }
    for &j in &added {
        dirty.push(affected_pixels(scene, j, &last, floor)?);
    }
    let dirty: Vec<Window> = dirty.into_iter().filter(|w| !w.is_empty()).collect();
    let area: usize = dirty.iter().map(Window::len).sum();
    if area as f64 > MAX_DIRTY_SHARE * last.window.len() as f64 {
        return None;
    }
    let Last {
        camera,
        table_T_camera,
        window,
        settings,
        mut output,
        ..
    } = last;
    // Instance ids follow the new scene's order; a removed part's pixels are all re-rendered.
    for v in &mut output.visible {
        if *v > 0 {
            *v = new_of_old[*v as usize - 1].map_or(0, |j| j as u16 + 1);
        }
    }
    let pixels_only = RenderSettings {
        full_masks: false,
        ..settings
    };
    for sub in &dirty {
        let fresh = render_with_rays(scene, &camera, &table_T_camera, *sub, &pixels_only, rays);
        let w = sub.width as usize;
        for r in 0..sub.height as usize {
            let start = output
                .index(sub.x0, sub.y0 + r as u32)
                .expect("dirty windows lie inside the render window");
            let row = r * w..(r + 1) * w;
            output.radiance[start..start + w].copy_from_slice(&fresh.radiance[row.clone()]);
            output.depth[start..start + w].copy_from_slice(&fresh.depth[row.clone()]);
            output.visible[start..start + w].copy_from_slice(&fresh.visible[row]);
        }
    }
    output.full_masks = if settings.full_masks {
        full_masks(scene, &camera, &table_T_camera, &output)
    } else {
        Vec::new()
    };
    debug_assert_eq!(output.window, window);
    Some((output, area))
}

/// Pairs the parts of `old` and `new` that are the same (mesh, pose and looks) in the same order:
/// for each old part its index in `new`, if kept, and the new parts that were not there. `None`
/// when kept parts changed order (nearest-hit ties are broken by order).
fn match_instances(
    old: &RenderScene,
    new: &RenderScene,
) -> Option<(Vec<Option<usize>>, Vec<usize>)> {
    let same = |a: &super::Instance, b: &super::Instance| {
        std::sync::Arc::ptr_eq(&a.mesh, &b.mesh)
            && a.table_T_part == b.table_T_part
            && a.appearance == b.appearance
            && a.accent == b.accent
    };
    let mut new_of_old = vec![None; old.instances.len()];
    let mut added = Vec::new();
    let mut next = 0;
    for (j, b) in new.instances.iter().enumerate() {
        match (next..old.instances.len()).find(|&i| same(&old.instances[i], b)) {
            Some(i) => {
                new_of_old[i] = Some(j);
                next = i + 1;
            }
            None => added.push(j),
        }
    }
    // An unmatched new part equal to an earlier old one means the order changed.
    let reordered = added.iter().any(|&j| {
        old.instances
            .iter()
            .zip(&new_of_old)
            .any(|(a, m)| m.is_none() && same(a, &new.instances[j]))
    });
    (!reordered).then_some((new_of_old, added))
}

/// The lowest height any surface of the scene reaches: no shadow falls below it.
fn lowest_surface(scene: &RenderScene) -> f64 {
    let mut z = f64::INFINITY;
    if let Some(t) = &scene.table {
        z = z.min(t.height);
    }
    if let Some(b) = &scene.board {
        z = z.min(b.lowest_z());
    }
    for i in 0..scene.instances.len() {
        z = z.min(scene.instance_bounds(i).0.z);
    }
    z
}

/// The window pixels whose value part `i` of `scene` can change: the image of its bounding box
/// together with the box's shadow volume from every light down to `floor`, with a margin. `None`
/// when that cannot be bounded (a light not above the part, a corner behind the camera).
#[allow(non_snake_case)]
fn affected_pixels(scene: &RenderScene, i: usize, last: &Last, floor: f64) -> Option<Window> {
    let (lo, hi) = scene.instance_bounds(i);
    let corners = box_corners(&lo, &hi);
    let mut points = corners.to_vec();
    for light in &scene.lights {
        // A sphere light lies inside the cube around it; its shadow inside the cube corners'.
        for l in light_cube(light) {
            if l.z <= hi.z {
                return None;
            }
            for c in &corners {
                let s = (l.z - floor) / (l.z - c.z);
                points.push(l + (c - l) * s);
            }
        }
    }
    let camera_T_table = last.table_T_camera.inverse();
    let (mut u0, mut v0, mut u1, mut v1) = (
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    );
    for p in &points {
        let q = camera_T_table * p;
        if q.z <= 0.0 {
            return None;
        }
        let px = last.camera.project(&q).ok()?;
        u0 = u0.min(px.x);
        v0 = v0.min(px.y);
        u1 = u1.max(px.x);
        v1 = v1.max(px.y);
    }
    Some(last.window.around([u0, v0, u1, v1], MARGIN_PX))
}
