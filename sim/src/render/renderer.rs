//! The ray tracer: one centre ray per pixel gives depth, the visible instance and the colour of
//! flat regions; pixels whose centre differs from a neighbour's (another surface, shadow, facet or
//! depth step) get n × n stratified colour samples. Rows are rendered in bands in parallel; full
//! masks per instance reuse the visible ids and cast only where another surface is in front.

use std::sync::Arc;

use nalgebra::{Isometry3, Point2, Point3, Vector3};
use perception::camera::Camera;
use rayon::prelude::*;

use super::aabb::box_corners;
use super::geometry::SurfaceKind;
use super::shading::{ambient, brdf_cos};
use super::shadow_grid::ShadowGrid;
use super::{Appearance, BoardMark, Hit, InstanceMask, RenderOutput, RenderScene, Window};

/// How to render.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RenderSettings {
    /// Colour samples per pixel along each axis (n × n stratified supersampling at edges: pixels
    /// whose centre ray sees another surface, shadow, facet or depth than one of its four
    /// neighbours'; elsewhere the centre ray's colour); 1 for none.
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

/// Edge class of the first part (see [`CentreSample::surface`]).
const FIRST_PART_CLASS: u32 = 6;

/// Rows rendered together by one task: small enough to spread a crop over the cores, large
/// enough that the one-row border shared with neighbouring bands costs little.
const BAND_ROWS: usize = 16;

/// Neighbouring centre normals closer than this cosine (about 3.6°) count as one smooth surface.
const SMOOTH_COS: f32 = 0.998;

/// A depth step larger than this many pixel footprints between neighbours counts as an edge.
const DEPTH_STEP_PX: f32 = 3.0;

/// What the centre ray of one pixel saw.
#[derive(Debug, Clone, Copy)]
struct CentreSample {
    /// Linear radiance.
    rgb: [f32; 3],
    /// Camera-frame z of the hit, metres (0 for none).
    depth: f64,
    /// 0 or instance + 1.
    visible: u16,
    /// Surface class: 0 nothing (or no ray), 1 table, 2 board white, 3 board black, 4 dust,
    /// 5 scratch, 6 + 2i part i, 7 + 2i part i's accent material.
    surface: u32,
    /// Bit k set when light k reaches the point.
    lit: u32,
    /// Unit normal.
    normal: [f32; 3],
    /// Ray distance, metres.
    t: f32,
}

impl CentreSample {
    const MISS: Self = Self {
        rgb: [0.0; 3],
        depth: 0.0,
        visible: 0,
        surface: 0,
        lit: 0,
        normal: [0.0; 3],
        t: 0.0,
    };

    /// Whether the colour may change between this pixel centre and a neighbour's.
    fn differs(&self, other: &Self, footprint: f32) -> bool {
        if self.surface != other.surface || self.lit != other.lit {
            return true;
        }
        if self.surface == 0 {
            return false;
        }
        let dot = self.normal[0] * other.normal[0]
            + self.normal[1] * other.normal[1]
            + self.normal[2] * other.normal[2];
        dot < SMOOTH_COS || (self.t - other.t).abs() > DEPTH_STEP_PX * footprint * self.t
    }
}

/// Renders `window` of the image of `camera` placed at `table_T_camera`.
///
/// Every pixel depends only on its own coordinates and its four neighbours' centre rays (computed
/// also outside the window), so a window renders exactly the same pixels as the same region of a
/// larger render.
#[allow(non_snake_case)]
pub fn render(
    scene: &RenderScene,
    camera: &Camera,
    table_T_camera: &Isometry3<f64>,
    window: Window,
    settings: &RenderSettings,
) -> RenderOutput {
    render_with_rays(scene, camera, table_T_camera, window, settings, None)
}

/// The camera-frame centre rays of a window's pixels and of the one-pixel border that edge
/// detection reads. They depend on the lens alone, so every render of one camera's window, in
/// any pose, can share them instead of inverting the distortion for each pixel again.
#[derive(Debug, Clone)]
pub struct CentreRays {
    camera: Camera,
    /// The window grown by one pixel on every side.
    x0: i64,
    y0: i64,
    width: usize,
    height: usize,
    rays: Arc<Vec<Option<Vector3<f64>>>>,
}

impl CentreRays {
    /// The centre rays of `window` of `camera` (and its one-pixel border).
    pub fn new(camera: &Camera, window: Window) -> Self {
        let (x0, y0) = (window.x0 as i64 - 1, window.y0 as i64 - 1);
        let (width, height) = (window.width as usize + 2, window.height as usize + 2);
        let rays = (0..width * height)
            .into_par_iter()
            .map(|k| {
                let (x, y) = (x0 + (k % width) as i64, y0 + (k / width) as i64);
                ray(camera, x as f64, y as f64)
            })
            .collect();
        Self {
            camera: *camera,
            x0,
            y0,
            width,
            height,
            rays: Arc::new(rays),
        }
    }

    /// The ray at pixel (x, y), if the table covers it.
    fn get(&self, x: i64, y: i64) -> Option<Option<Vector3<f64>>> {
        let (cx, cy) = (x - self.x0, y - self.y0);
        (cx >= 0 && cy >= 0 && (cx as usize) < self.width && (cy as usize) < self.height)
            .then(|| self.rays[cy as usize * self.width + cx as usize])
    }
}

/// [`render`] reading centre rays from `rays` where it covers the pixels (rays of another camera
/// are not used).
#[allow(non_snake_case)]
pub fn render_with_rays(
    scene: &RenderScene,
    camera: &Camera,
    table_T_camera: &Isometry3<f64>,
    window: Window,
    settings: &RenderSettings,
    rays: Option<&CentreRays>,
) -> RenderOutput {
    let n = window.len();
    let mut radiance = vec![[0f32; 3]; n];
    let mut depth = vec![0f64; n];
    let mut visible = vec![0u16; n];
    let w = window.width as usize;
    let tracer = Tracer {
        scene,
        camera,
        table_T_camera,
        origin: Point3::from(table_T_camera.translation.vector),
        shadow_grids: settings.shadows.then(|| scene.shadow_grids()),
        rays: rays.filter(|r| r.camera == *camera),
    };
    let ss = settings.supersampling.max(1);
    // Edge detection needs the neighbours' centre samples; without supersampling none is needed.
    let border = usize::from(ss > 1);
    let footprint = (1.0 / camera.fx.min(camera.fy)) as f32;
    if w > 0 {
        radiance
            .par_chunks_mut(BAND_ROWS * w)
            .zip(depth.par_chunks_mut(BAND_ROWS * w))
            .zip(visible.par_chunks_mut(BAND_ROWS * w))
            .enumerate()
            .for_each(|(band, ((rad, dep), vis))| {
                let rows = rad.len() / w;
                let gw = w + 2 * border;
                let gx0 = window.x0 as i64 - border as i64;
                let gy0 = (window.y0 as usize + band * BAND_ROWS) as i64 - border as i64;
                let mut grid = Vec::with_capacity(gw * (rows + 2 * border));
                for gy in 0..(rows + 2 * border) as i64 {
                    for gx in 0..gw as i64 {
                        grid.push(tracer.centre(gx0 + gx, gy0 + gy));
                    }
                }
                for r in 0..rows {
                    for c in 0..w {
                        let g = (r + border) * gw + c + border;
                        let s = &grid[g];
                        let i = r * w + c;
                        dep[i] = s.depth;
                        vis[i] = s.visible;
                        let edge = border == 1
                            && [g - 1, g + 1, g - gw, g + gw]
                                .iter()
                                .any(|&k| s.differs(&grid[k], footprint));
                        rad[i] = if edge {
                            let x = (window.x0 as usize + c) as f64;
                            let y = (window.y0 as usize + band * BAND_ROWS + r) as f64;
                            let c = tracer.supersample(x, y, ss);
                            [c[0] as f32, c[1] as f32, c[2] as f32]
                        } else {
                            s.rgb
                        };
                    }
                }
            });
    }
    let mut out = RenderOutput {
        window,
        radiance,
        depth,
        visible,
        full_masks: Vec::new(),
    };
    if settings.full_masks {
        out.full_masks = full_masks(scene, camera, table_T_camera, &out);
    }
    out
}

/// Every instance's full silhouette over the window of a render `out` of this scene and view.
#[allow(non_snake_case)]
pub(crate) fn full_masks(
    scene: &RenderScene,
    camera: &Camera,
    table_T_camera: &Isometry3<f64>,
    out: &RenderOutput,
) -> Vec<InstanceMask> {
    (0..scene.instances.len())
        .into_par_iter()
        .map(|i| instance_mask(scene, i, camera, table_T_camera, out))
        .collect()
}

/// The rays of one render.
#[allow(non_snake_case)]
struct Tracer<'a> {
    scene: &'a RenderScene,
    camera: &'a Camera,
    table_T_camera: &'a Isometry3<f64>,
    origin: Point3<f64>,
    /// Each light's shadow grid, when lights cast shadows.
    shadow_grids: Option<Vec<Option<ShadowGrid>>>,
    rays: Option<&'a CentreRays>,
}

impl Tracer<'_> {
    /// The centre ray of pixel (x, y): colour, depth, visible instance and edge signature.
    fn centre(&self, x: i64, y: i64) -> CentreSample {
        let dc = match self.rays.and_then(|r| r.get(x, y)) {
            Some(dc) => dc,
            None => ray(self.camera, x as f64, y as f64),
        };
        let Some(dc) = dc else {
            return CentreSample::MISS;
        };
        let d = self.table_T_camera.rotation * dc;
        let Some(hit) = self.scene.intersect(&self.origin, &d, f64::INFINITY) else {
            return CentreSample::MISS;
        };
        let (rgb, lit, surface) = self.shade(&d, &hit);
        let visible = match hit.kind {
            SurfaceKind::Part(i) => (i + 1) as u16,
            SurfaceKind::Table | SurfaceKind::Board => 0,
        };
        CentreSample {
            rgb: [rgb[0] as f32, rgb[1] as f32, rgb[2] as f32],
            depth: hit.t * dc.z,
            visible,
            surface: surface.class,
            lit,
            normal: [
                hit.normal.x as f32,
                hit.normal.y as f32,
                hit.normal.z as f32,
            ],
            t: hit.t as f32,
        }
    }

    /// Mean radiance of n × n stratified samples over pixel (x, y).
    fn supersample(&self, x: f64, y: f64, n: u32) -> [f64; 3] {
        let mut acc = [0.0; 3];
        for sy in 0..n {
            for sx in 0..n {
                let ox = (sx as f64 + 0.5) / n as f64 - 0.5;
                let oy = (sy as f64 + 0.5) / n as f64 - 0.5;
                let Some(ds) = ray(self.camera, x + ox, y + oy) else {
                    continue;
                };
                let d = self.table_T_camera.rotation * ds;
                if let Some(h) = self.scene.intersect(&self.origin, &d, f64::INFINITY) {
                    let (s, _, _) = self.shade(&d, &h);
                    for k in 0..3 {
                        acc[k] += s[k];
                    }
                }
            }
        }
        let m = 1.0 / (n * n) as f64;
        [acc[0] * m, acc[1] * m, acc[2] * m]
    }
}

/// The surface at a hit point: its appearance, its class for edge detection (see
/// [`CentreSample::surface`]) and its brushing direction.
struct Surface {
    appearance: Appearance,
    class: u32,
    tangent: Option<Vector3<f64>>,
}

/// Appearance of the surface at a hit point.
fn surface_at(scene: &RenderScene, hit: &Hit, p: &Point3<f64>) -> Surface {
    let (appearance, class, tangent) = match hit.kind {
        SurfaceKind::Part(i) => {
            let inst = &scene.instances[i];
            let appearance = match (hit.accent, inst.accent) {
                (true, Some(a)) => a,
                _ => inst.appearance,
            };
            let tangent = inst.table_T_part.rotation * Vector3::x();
            (
                appearance,
                FIRST_PART_CLASS + 2 * i as u32 + u32::from(hit.accent),
                Some(tangent),
            )
        }
        SurfaceKind::Board => match scene
            .board
            .as_ref()
            .map(|b| (b, b.top_face_at(p, &hit.normal)))
        {
            Some((_, Some((appearance, mark)))) => {
                let class = match mark {
                    BoardMark::White => 2,
                    BoardMark::Black => 3,
                    BoardMark::Dust => 4,
                    BoardMark::Scratch => 5,
                };
                (appearance, class, None)
            }
            Some((b, None)) => (b.white, 2, None),
            None => (
                Appearance::for_material(perception::part::Material::Aluminium),
                2,
                None,
            ),
        },
        SurfaceKind::Table => {
            let mut a = scene.table.map(|t| t.appearance).unwrap_or_else(|| {
                Appearance::for_material(perception::part::Material::DarkPlastic)
            });
            if let Some(texture) = &scene.table_texture {
                let f = texture.factor(p);
                a.base_color = a.base_color.map(|c| (c * f).clamp(0.0, 1.0));
            }
            (a, 1, None)
        }
    };
    Surface {
        appearance,
        class,
        tangent,
    }
}

impl Tracer<'_> {
    /// Radiance leaving the hit surface towards the camera, the lights that reach it (bit k for
    /// light k) and the surface.
    ///
    /// A light with a radius is sampled at one point of its sphere per shading point, chosen by a
    /// hash of the point's coordinates: penumbrae come out as deterministic noise that the edge
    /// supersampling averages.
    fn shade(&self, d: &Vector3<f64>, hit: &Hit) -> ([f64; 3], u32, Surface) {
        let scene = self.scene;
        let p = self.origin + hit.t * d;
        let surface = surface_at(scene, hit, &p);
        let a = surface.appearance;
        let mut lit = 0u32;
        let n = hit.normal;
        let v = -d;
        let mut c = match &scene.environment {
            Some(env) => env.shade(&a, &n, &v),
            None => ambient(&a, &n, &v, &scene.ambient),
        };
        if let (Some(glow), SurfaceKind::Board, Some(board)) =
            (scene.backlight, hit.kind, scene.board.as_ref())
            && board.top_face_at(&p, &n).is_some()
        {
            // Light from under the plate passes its print as the print's albedo passes it.
            for ch in 0..3 {
                let white = board.white.base_color[ch].max(1e-6);
                c[ch] += glow[ch] * (a.base_color[ch] / white).min(1.0);
            }
        }
        let start = p + n * SHADOW_BIAS;
        for (k, light) in scene.lights.iter().enumerate() {
            let to = light.position - start;
            let dist = to.norm();
            if dist <= 0.0 {
                continue;
            }
            let l = to / dist;
            if n.dot(&l) <= 0.0 {
                continue;
            }
            if let Some(grids) = &self.shadow_grids {
                let target = if light.radius > 0.0 {
                    light.position + sphere_point(&p, k) * light.radius
                } else {
                    light.position
                };
                let ts = target - start;
                let ds = ts.norm();
                if ds > 0.0 && scene.occluded_towards(grids[k].as_ref(), &start, &(ts / ds), ds) {
                    continue;
                }
            }
            let spread = light.radius / dist;
            let f = brdf_cos(&a, &n, &v, &l, surface.tangent.as_ref(), spread);
            let inv2 = 1.0 / (dist * dist);
            for ch in 0..3 {
                c[ch] += f[ch] * light.intensity[ch] * inv2;
            }
            lit |= 1 << (k % 32);
        }
        (c, lit, surface)
    }
}

/// A point in the unit ball chosen by a hash of a shading point and a light number.
fn sphere_point(p: &Point3<f64>, light: usize) -> Vector3<f64> {
    let mut z = p.x.to_bits() ^ p.y.to_bits().rotate_left(21) ^ p.z.to_bits().rotate_left(42);
    z ^= (light as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    let mut next = || {
        z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut x = z;
        x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        x ^= x >> 31;
        (x >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    loop {
        let q = Vector3::new(next(), next(), next());
        if q.norm_squared() <= 1.0 {
            return q;
        }
    }
}

/// The full (unoccluded) silhouette of instance `i` over the window of a render `out` made with
/// the same scene, camera and pose: pixels where the instance is visible are covered; elsewhere
/// within the projection of its bounding box (plus a margin for lens distortion) a pixel-centre
/// ray is cast against that instance alone.
#[allow(non_snake_case)]
pub fn instance_mask(
    scene: &RenderScene,
    i: usize,
    camera: &Camera,
    table_T_camera: &Isometry3<f64>,
    out: &RenderOutput,
) -> InstanceMask {
    let window = out.window;
    let (lo, hi) = scene.instance_bounds(i);
    let camera_T_table = table_T_camera.inverse();
    let (mut u0, mut v0, mut u1, mut v1) = (
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    );
    let mut whole = false;
    for c in box_corners(&lo, &hi) {
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
    let sub = if whole {
        window
    } else {
        window.around([u0, v0, u1, v1], 3.0)
    };
    let origin = Point3::from(table_T_camera.translation.vector);
    let mut bits = vec![false; sub.len()];
    let id = (i + 1) as u16;
    for (idx, b) in bits.iter_mut().enumerate() {
        let (px, py) = (
            sub.x0 + (idx % sub.width as usize) as u32,
            sub.y0 + (idx / sub.width as usize) as u32,
        );
        if let Some(k) = out.index(px, py) {
            if out.visible[k] == id {
                *b = true;
                continue;
            }
            // The centre ray hit nothing at all, so it misses this instance too.
            if out.visible[k] == 0 && out.depth[k] == 0.0 {
                continue;
            }
        }
        let (x, y) = (px as f64, py as f64);
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
