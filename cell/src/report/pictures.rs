//! Pictures of a failed episode, rendered with the simulator's ray tracer: a close-up of the part
//! over its receiver with the true pose error recorded at insertion, from above and from the
//! side, with the step's capture band drawn; and the feeder as the episode found it, each part
//! marked with its true position.

#![allow(non_snake_case)]

use std::path::{Path, PathBuf};
use std::sync::Arc;

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use perception::camera::{Camera, Distortion};
use perception::part::Catalog;
use sim::render::{
    Appearance, Instance, PointLight, RenderMesh, RenderScene, RenderSettings, Table, Window,
    render,
};
use sim::scene::look_at;

use crate::episode::{EpisodeRecord, StepOutcome};
use crate::scenario::{Destination, Scenario};

/// Side of a close-up picture, pixels.
const CLOSE_UP_PX: u32 = 320;
/// Field of view of a close-up at the target, metres.
const CLOSE_UP_FIELD: f64 = 0.018;
/// Magnification of the inset around the target in the top view.
const INSET_ZOOM: u32 = 4;
/// Distance of the close-up camera from the target, metres.
const CLOSE_UP_DISTANCE: f64 = 0.15;
/// Width of the feeder picture, pixels.
const FEEDER_PX: u32 = 480;

/// Why a picture could not be made.
#[derive(Debug, thiserror::Error)]
pub enum PictureError {
    /// A part's mesh could not be loaded or has no triangles to render.
    #[error("part {part:?}: {reason}")]
    Part {
        /// The part.
        part: String,
        /// Why.
        reason: String,
    },
    /// A picture camera is invalid.
    #[error("picture camera: {0}")]
    Camera(String),
    /// The simulated cell of the episode could not be built.
    #[error("the episode's simulated cell: {0}")]
    Cell(String),
    /// Writing a picture failed.
    #[error("{}: {reason}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        reason: String,
    },
}

/// The render mesh and appearance of a catalog part.
fn part_instance(
    catalog: &Catalog,
    name: &str,
    table_T_part: Isometry3<f64>,
) -> Result<Instance, PictureError> {
    let err = |reason: String| PictureError::Part {
        part: name.into(),
        reason,
    };
    let spec = catalog
        .part(name)
        .ok_or_else(|| err("not in the catalog".into()))?;
    let mesh = catalog.load_mesh(spec).map_err(|e| err(e.to_string()))?;
    let mesh = RenderMesh::new(&mesh).ok_or_else(|| err("no triangles to render".into()))?;
    Ok(Instance::new(
        Arc::new(mesh),
        table_T_part,
        Appearance::for_material(spec.material),
    ))
}

/// The table-frame pose of step `i`'s destination, assuming the earlier steps seated.
#[allow(non_snake_case)]
fn table_T_destination(scenario: &Scenario, i: usize) -> Isometry3<f64> {
    let steps = &scenario.spec.assembly;
    match &steps[i].into {
        Destination::Fixture => scenario.spec.cell.fixture.table_T_fixture.isometry(),
        Destination::Part(p) => match steps[..i].iter().position(|s| &s.part == p) {
            Some(j) => table_T_destination(scenario, j) * steps[j].target.isometry(),
            None => scenario.spec.cell.fixture.table_T_fixture.isometry(),
        },
    }
}

fn lights(at: &Point3<f64>) -> Vec<PointLight> {
    vec![
        PointLight {
            position: at + Vector3::new(0.3, -0.4, 1.0),
            intensity: [0.9, 0.9, 0.85],
            radius: 0.0,
        },
        PointLight {
            position: at + Vector3::new(-0.5, 0.3, 0.8),
            intensity: [0.35, 0.35, 0.4],
            radius: 0.0,
        },
    ]
}

fn table() -> Table {
    Table {
        height: -1e-4,
        appearance: Appearance {
            base_color: [0.25, 0.27, 0.3],
            metallic: 0.0,
            roughness: 0.9,
            specular: 0.2,
            anisotropy: 0.0,
        },
    }
}

/// An RGB picture in sRGB bytes.
struct Picture {
    width: u32,
    height: u32,
    rgb: Vec<u8>,
}

impl Picture {
    fn from_render(scene: &RenderScene, camera: &Camera, table_T_camera: &Isometry3<f64>) -> Self {
        let settings = RenderSettings {
            supersampling: 1,
            shadows: true,
            full_masks: false,
        };
        let window = Window::full(camera.width, camera.height);
        let out = render(scene, camera, table_T_camera, window, &settings);
        let rgb = out
            .radiance
            .iter()
            .flat_map(|c| c.map(|v| (v.clamp(0.0, 1.0).powf(1.0 / 2.2) * 255.0).round() as u8))
            .collect();
        Self {
            width: camera.width,
            height: camera.height,
            rgb,
        }
    }

    /// Draws a line between two pixels (clipped to the picture).
    fn line(&mut self, a: (f64, f64), b: (f64, f64), colour: [u8; 3]) {
        let n = ((b.0 - a.0).abs().max((b.1 - a.1).abs()).ceil() as usize).clamp(1, 10_000);
        for k in 0..=n {
            let t = k as f64 / n as f64;
            let (x, y) = (a.0 + (b.0 - a.0) * t, a.1 + (b.1 - a.1) * t);
            for (dx, dy) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)] {
                let (px, py) = ((x + dx).round(), (y + dy).round());
                if px >= 0.0
                    && py >= 0.0
                    && px < f64::from(self.width)
                    && py < f64::from(self.height)
                {
                    let i = 3 * (py as usize * self.width as usize + px as usize);
                    self.rgb[i..i + 3].copy_from_slice(&colour);
                }
            }
        }
    }

    /// Draws the closed polygon of table-frame points seen by `camera` at `table_T_camera`.
    fn polygon(
        &mut self,
        camera: &Camera,
        table_T_camera: &Isometry3<f64>,
        points: &[Point3<f64>],
        colour: [u8; 3],
    ) {
        let camera_T_table = table_T_camera.inverse();
        let px: Vec<(f64, f64)> = points
            .iter()
            .filter_map(|p| camera.project(&(camera_T_table * p)).ok())
            .map(|p| (p.x, p.y))
            .collect();
        if px.len() != points.len() {
            return;
        }
        for k in 0..px.len() {
            self.line(px[k], px[(k + 1) % px.len()], colour);
        }
    }

    /// Copies the square of side `size / zoom` around pixel `centre`, magnified `zoom` times,
    /// into the top-left corner, framed.
    fn inset(&mut self, centre: (f64, f64), size: u32, zoom: u32) {
        let src = self.rgb.clone();
        let half = f64::from(size / zoom) / 2.0;
        for y in 0..size.min(self.height) {
            for x in 0..size.min(self.width) {
                let sx = (centre.0 - half + f64::from(x) / f64::from(zoom)).round();
                let sy = (centre.1 - half + f64::from(y) / f64::from(zoom)).round();
                if sx < 0.0
                    || sy < 0.0
                    || sx >= f64::from(self.width)
                    || sy >= f64::from(self.height)
                {
                    continue;
                }
                let from = 3 * (sy as usize * self.width as usize + sx as usize);
                let to = 3 * (y as usize * self.width as usize + x as usize);
                self.rgb[to..to + 3].copy_from_slice(&src[from..from + 3]);
            }
        }
        let s = f64::from(size);
        for (a, b) in [((0.0, s), (s, s)), ((s, 0.0), (s, s))] {
            self.line(a, b, [255, 255, 255]);
        }
    }

    fn save(&self, path: &Path) -> Result<(), PictureError> {
        let err = |reason: String| PictureError::Write {
            path: path.into(),
            reason,
        };
        let mut png = Vec::new();
        image::ImageEncoder::write_image(
            image::codecs::png::PngEncoder::new(&mut png),
            &self.rgb,
            self.width,
            self.height,
            image::ExtendedColorType::Rgb8,
        )
        .map_err(|e| err(e.to_string()))?;
        sim::fsutil::write_atomic(path, &png).map_err(|e| err(e.to_string()))
    }
}

fn close_up_camera() -> Result<Camera, PictureError> {
    let f = f64::from(CLOSE_UP_PX) * CLOSE_UP_DISTANCE / CLOSE_UP_FIELD;
    let c = f64::from(CLOSE_UP_PX - 1) / 2.0;
    Camera::new(f, f, c, c, CLOSE_UP_PX, CLOSE_UP_PX, Distortion::default())
        .map_err(|e| PictureError::Camera(e.to_string()))
}

/// Renders the pictures of a failed episode into `dir` as `episode-NNNNNN-*.png`: the failing
/// step's part over its receiver from above and from the side (when the step inserted), and
/// the feeder at the start of the episode (when `feeder` gives its parts). Returns the files.
#[allow(non_snake_case)]
pub fn failure_pictures(
    scenario: &Scenario,
    record: &EpisodeRecord,
    feeder: Option<&[sim::cell::feeder::FeederPart]>,
    dir: &Path,
) -> Result<Vec<PathBuf>, PictureError> {
    std::fs::create_dir_all(dir).map_err(|e| PictureError::Write {
        path: dir.into(),
        reason: e.to_string(),
    })?;
    let mut written = Vec::new();
    let name = |what: &str| dir.join(format!("episode-{:06}-{what}.png", record.episode));
    let failing = record
        .steps
        .iter()
        .enumerate()
        .find(|(_, s)| s.outcome != StepOutcome::Seated);
    if let Some((i, step)) = failing
        && let Some(e) = step.pose_error
        && i < scenario.spec.assembly.len()
    {
        let spec = &scenario.spec;
        let catalog = &scenario.catalog;
        let table_T_target = table_T_destination(scenario, i) * spec.assembly[i].target.isometry();
        // The held part where insertion left it: the recorded offsets in the target frame.
        let error = Isometry3::from_parts(
            Translation3::new(e.dx_mm * 1e-3, e.dy_mm * 1e-3, e.depth_mm.max(0.0) * 1e-3),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), e.tilt_deg.to_radians())
                * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), e.yaw_deg.to_radians()),
        );
        let mut instances = vec![part_instance(
            catalog,
            &spec.cell.fixture.part,
            spec.cell.fixture.table_T_fixture.isometry(),
        )?];
        for (j, s) in spec.assembly[..i].iter().enumerate() {
            let pose = table_T_destination(scenario, j) * s.target.isometry();
            instances.push(part_instance(catalog, &s.part, pose)?);
        }
        instances.push(part_instance(catalog, &step.part, table_T_target * error)?);
        let target = Point3::from(table_T_target.translation.vector);
        let scene = RenderScene::new(instances, None, Some(table()), lights(&target), [0.12; 3]);
        let camera = close_up_camera()?;
        let c = spec.assembly[i].clearance / 2.0 + spec.assembly[i].lead_in;
        let band: Vec<Point3<f64>> = [(-c, -c), (c, -c), (c, c), (-c, c)]
            .iter()
            .map(|(x, y)| table_T_target * Point3::new(*x, *y, 0.0))
            .collect();
        let views = [
            ("top", Vector3::new(0.0, -1e-3, 1.0)),
            ("side", Vector3::new(0.0, -0.87, 0.5)),
        ];
        // The held part's origin (a cross) against the band around the target (a square).
        let held = table_T_target * error * Point3::origin();
        let r = c.max(1e-4) * 0.3;
        let cross = [
            vec![
                held + Vector3::new(-r, -r, 0.0),
                held + Vector3::new(r, r, 0.0),
            ],
            vec![
                held + Vector3::new(-r, r, 0.0),
                held + Vector3::new(r, -r, 0.0),
            ],
        ];
        for (view, dir_to_eye) in views {
            let eye = target + dir_to_eye.normalize() * CLOSE_UP_DISTANCE;
            let table_T_camera = look_at(&eye, &target, &Vector3::x(), 0.0);
            let mut picture = Picture::from_render(&scene, &camera, &table_T_camera);
            picture.polygon(&camera, &table_T_camera, &band, [255, 220, 0]);
            for line in &cross {
                picture.polygon(&camera, &table_T_camera, line, [230, 40, 40]);
            }
            if view == "top" {
                let c = f64::from(CLOSE_UP_PX - 1) / 2.0;
                picture.inset((c, c), CLOSE_UP_PX / 2, INSET_ZOOM);
            }
            let path = name(&format!("step{i}-{view}"));
            picture.save(&path)?;
            written.push(path);
        }
    }
    if let Some(parts) = feeder {
        written.push(feeder_picture(scenario, parts, &name("feeder"))?);
    }
    Ok(written)
}

/// The feeder region rendered from above, `width` pixels wide, with `parts` at their true poses:
/// the picture, its camera and the camera's pose in the table frame.
#[allow(non_snake_case)]
pub fn feeder_view(
    scenario: &Scenario,
    parts: &[sim::cell::feeder::FeederPart],
    width: u32,
) -> Result<(image::RgbImage, Camera, Isometry3<f64>), PictureError> {
    let (picture, camera, table_T_camera) = feeder_render(scenario, parts, width)?;
    let img = image::RgbImage::from_raw(picture.width, picture.height, picture.rgb)
        .expect("a render has width × height × 3 bytes");
    Ok((img, camera, table_T_camera))
}

#[allow(non_snake_case)]
fn feeder_render(
    scenario: &Scenario,
    parts: &[sim::cell::feeder::FeederPart],
    width: u32,
) -> Result<(Picture, Camera, Isometry3<f64>), PictureError> {
    let spec = &scenario.spec;
    let f = &spec.cell.feeder;
    let instances = parts
        .iter()
        .map(|p| part_instance(&scenario.catalog, &p.part, p.table_T_part))
        .collect::<Result<Vec<_>, _>>()?;
    let centre = Point3::new(f.center[0], f.center[1], 0.0);
    let scene = RenderScene::new(instances, None, Some(table()), lights(&centre), [0.12; 3]);
    let aspect = f.size[1] / f.size[0];
    let width = width.max(16);
    let height = ((f64::from(width) * aspect).round() as u32).max(16);
    let distance = 0.4;
    let focal = f64::from(width) * distance / (f.size[0] * 1.1);
    let camera = Camera::new(
        focal,
        focal,
        f64::from(width - 1) / 2.0,
        f64::from(height - 1) / 2.0,
        width,
        height,
        Distortion::default(),
    )
    .map_err(|e| PictureError::Camera(e.to_string()))?;
    let eye = centre + Vector3::new(0.0, -1e-4, distance);
    let table_T_camera = look_at(&eye, &centre, &Vector3::x(), 0.0);
    let picture = Picture::from_render(&scene, &camera, &table_T_camera);
    Ok((picture, camera, table_T_camera))
}

/// The feeder region from above at the start of the episode, each part's true position ringed
/// (yellow: a part an assembly step needs; grey: others).
#[allow(non_snake_case)]
fn feeder_picture(
    scenario: &Scenario,
    parts: &[sim::cell::feeder::FeederPart],
    path: &Path,
) -> Result<PathBuf, PictureError> {
    let spec = &scenario.spec;
    let (mut picture, camera, table_T_camera) = feeder_render(scenario, parts, FEEDER_PX)?;
    let needed: Vec<&str> = spec.assembly.iter().map(|s| s.part.as_str()).collect();
    for p in parts {
        let o = p.table_T_part * Point3::origin();
        let r = 0.006;
        let ring: Vec<Point3<f64>> = (0..24)
            .map(|k| {
                let a = f64::from(k) * std::f64::consts::TAU / 24.0;
                Point3::new(o.x + r * a.cos(), o.y + r * a.sin(), o.z)
            })
            .collect();
        let colour = if needed.contains(&p.part.as_str()) {
            [255, 220, 0]
        } else {
            [160, 160, 160]
        };
        picture.polygon(&camera, &table_T_camera, &ring, colour);
    }
    picture.save(path)?;
    Ok(path.into())
}
