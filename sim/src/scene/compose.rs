//! Sampling one randomised scene: parts dropped on the board, lights, materials, camera, sensor.

use nalgebra::{Isometry3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, RngExt};

use super::{
    DropError, PartModel, PlacedPart, Randomisation, RandomisationError, Range, drop_parts,
};
use crate::render::{
    Appearance, Instance, PointLight, RenderOutput, RenderScene, SensorModel, Table, TagBoard,
};

/// Why a scene could not be sampled.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SceneError {
    /// A randomisation range is unusable.
    #[error(transparent)]
    Randomisation(#[from] RandomisationError),
    /// The physics drop failed.
    #[error(transparent)]
    Drop(#[from] DropError),
    /// The part counts ask for no parts at all.
    #[error("the scene has no parts: every part count is zero")]
    NoParts,
    /// The counts list does not match the models.
    #[error("{counts} part counts given for {models} part models")]
    CountMismatch {
        /// Counts given.
        counts: usize,
        /// Models given.
        models: usize,
    },
}

/// What to drop and where to look.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneRequest {
    /// Copies of each model to drop.
    pub counts: Vec<usize>,
    /// Centre of the drop region on the board, metres.
    pub drop_centre: (f64, f64),
    /// Half-size of the square drop region, metres.
    pub drop_half: f64,
    /// Aim the camera at this placed part (by index); the board centre when `None`.
    pub aim_at_part: Option<usize>,
    /// Nominal camera pose; its x, y are offset and its height replaced by the randomisation.
    #[allow(non_snake_case)]
    pub nominal_table_T_camera: Isometry3<f64>,
}

/// A sampled scene, ready to render.
#[derive(Debug, Clone)]
pub struct SampledScene {
    /// The parts at rest.
    pub parts: Vec<PlacedPart>,
    /// The renderer's view of it.
    pub render: RenderScene,
    /// Camera pose in the table frame.
    #[allow(non_snake_case)]
    pub table_T_camera: Isometry3<f64>,
    /// Sensor settings (before metering; see [`SampledScene::metered_sensor`]).
    pub sensor: SensorModel,
    /// Exposure multiplier applied after metering: 1, or the randomised over-exposure.
    pub overexposure: f64,
}

/// Metering target: the parts' pixels stay below this share of full scale ...
pub const METER_TARGET: f64 = 0.9;
/// ... in all but this share of them (specular glints of a small light on a mirror-like facet
/// may clip: metering on every glint would leave the rest of the image black) ...
pub const METER_SHARE: f64 = 0.005;
/// ... and metering lowers the drawn exposure by at most this factor.
pub const METER_FLOOR: f64 = 0.15;

impl SampledScene {
    /// The sensor for a render of this scene: highlight-priority metering on the parts
    /// ([`SensorModel::metered`]), then the randomised over-exposure, if drawn.
    pub fn metered_sensor(&self, out: &RenderOutput) -> SensorModel {
        let mut s = self.sensor.metered(out, METER_TARGET, METER_SHARE);
        s.exposure = s.exposure.max(self.sensor.exposure * METER_FLOOR) * self.overexposure;
        s
    }

    /// The table-frame box (low and high corners) holding every part's footprint: its centre ±
    /// half its diagonal plus `margin`, up to the highest such top. What a window covering the
    /// parts must show.
    pub fn footprint(&self, models: &[PartModel], margin: f64) -> (Point3<f64>, Point3<f64>) {
        let mut lo = Point3::new(f64::INFINITY, f64::INFINITY, 0.0);
        let mut hi = Point3::new(f64::NEG_INFINITY, f64::NEG_INFINITY, 0.0);
        for p in &self.parts {
            let r = models[p.model].mesh.extents().norm() / 2.0 + margin;
            let c = p.table_T_part.translation.vector;
            lo.x = lo.x.min(c.x - r);
            lo.y = lo.y.min(c.y - r);
            hi.x = hi.x.max(c.x + r);
            hi.y = hi.y.max(c.y + r);
            hi.z = hi.z.max(c.z + r);
        }
        (lo, hi)
    }
}

/// Samples a scene: drops the parts, then draws lights, materials, camera and sensor.
pub fn sample_scene(
    models: &[PartModel],
    request: &SceneRequest,
    rand: &Randomisation,
    rng: &mut impl Rng,
) -> Result<SampledScene, SceneError> {
    rand.validate()?;
    if request.counts.len() != models.len() {
        return Err(SceneError::CountMismatch {
            counts: request.counts.len(),
            models: models.len(),
        });
    }
    if request.counts.iter().all(|c| *c == 0) {
        return Err(SceneError::NoParts);
    }
    let parts = drop_parts(
        models,
        &request.counts,
        request.drop_centre,
        request.drop_half,
        rng,
    )?;
    dress_scene(models, parts, request, rand, rng)
}

/// Draws lights, materials, camera and sensor around parts already at rest.
pub fn dress_scene(
    models: &[PartModel],
    parts: Vec<PlacedPart>,
    request: &SceneRequest,
    rand: &Randomisation,
    rng: &mut impl Rng,
) -> Result<SampledScene, SceneError> {
    rand.validate()?;

    let looks: Vec<(Appearance, Option<Appearance>)> = models
        .iter()
        .map(|m| {
            let main = randomised(m.appearance(), rand, rng);
            let accent = m.accent_appearance().map(|a| randomised(a, rand, rng));
            (main, accent)
        })
        .collect();
    let instances = parts
        .iter()
        .map(|p| Instance {
            mesh: models[p.model].render_mesh.clone(),
            table_T_part: p.table_T_part,
            appearance: looks[p.model].0,
            accent: looks[p.model].1,
        })
        .collect();
    let mut board = TagBoard::default();
    let board_tint = rand.material_tint.sample(rng);
    board.white = board.white.tinted([board_tint; 3], board.white.roughness);
    board.black.base_color = [rand.board_black.sample(rng); 3];
    board.grain = rand.board_grain.sample(rng);
    board.dust = rand.dust.sample(rng);
    board.scratches = rand.scratches.sample(rng);
    board.texture_seed = rng.random();
    let grey = rand.table_albedo.sample(rng);
    let table = Table {
        height: -board.thickness(),
        appearance: Appearance {
            base_color: [grey, grey * 0.95, grey * 0.9],
            metallic: 0.0,
            roughness: 0.7,
            specular: 0.04,
            anisotropy: 0.0,
        },
    };
    let n_lights = rand.lights.sample(rng).round().max(0.0) as usize;
    let lights = (0..n_lights)
        .map(|_| {
            let r = rand.light_radius.sample(rng);
            let phi = rng.random_range(0.0..std::f64::consts::TAU);
            let h = rand.light_height.sample(rng);
            let i = rand.light_intensity.sample(rng);
            PointLight {
                position: Point3::new(r * phi.cos(), r * phi.sin(), h),
                intensity: [
                    i * rand.light_tint.sample(rng),
                    i * rand.light_tint.sample(rng),
                    i * rand.light_tint.sample(rng),
                ],
                radius: rand.light_size.sample(rng),
            }
        })
        .collect();
    let sky = rand.ambient.sample(rng);
    let render = RenderScene::new(instances, Some(board), Some(table), lights, [sky; 3]);

    let target = request
        .aim_at_part
        .and_then(|i| parts.get(i))
        .map(|p| Point3::from(p.table_T_part.translation.vector))
        .unwrap_or_else(Point3::origin);
    let nominal = request.nominal_table_T_camera;
    let eye = Point3::new(
        nominal.translation.x + rand.camera_xy.sample(rng),
        nominal.translation.y + rand.camera_xy.sample(rng),
        rand.camera_height.sample(rng),
    );
    let aim = target
        + Vector3::new(
            rand.camera_aim.sample(rng),
            rand.camera_aim.sample(rng),
            0.0,
        );
    let roll = rand.camera_roll.sample(rng);
    let table_T_camera = look_at(&eye, &aim, &(nominal.rotation * Vector3::x()), roll);
    let overexposure = if rng.random_range(0.0..1.0) < rand.overexposure_probability {
        rand.overexposure.sample(rng)
    } else {
        1.0
    };
    let sensor = SensorModel {
        exposure: rand.exposure.sample(rng),
        blur_sigma: rand.blur_sigma.sample(rng),
        read_noise: rand.read_noise.sample(rng),
        shot_noise: rand.shot_noise.sample(rng),
        gain: rand.gain.sample(rng),
        defocus_radius: rand.defocus_radius.sample(rng),
        motion_length: rand.motion_length.sample(rng),
        motion_angle: rng.random_range(0.0..std::f64::consts::PI),
        jpeg_quality: if rng.random_range(0.0..1.0) < rand.jpeg_probability {
            rand.jpeg_quality.sample(rng).round()
        } else {
            0.0
        },
    };
    Ok(SampledScene {
        parts,
        render,
        table_T_camera,
        sensor,
        overexposure,
    })
}

/// A material with randomised tint and roughness, and brushing when it is a metal.
fn randomised(a: Appearance, rand: &Randomisation, rng: &mut impl Rng) -> Appearance {
    // Brightness from the range, and a hue shift of at most a fifth of its spread: colour casts
    // of plated metal and moulded plastic are subtle.
    let brightness = rand.material_tint.sample(rng);
    let hue = Range::new(
        1.0 - (rand.material_tint.hi - rand.material_tint.lo) / 10.0,
        1.0 + (rand.material_tint.hi - rand.material_tint.lo) / 10.0,
    );
    let tint = [
        brightness * hue.sample(rng),
        brightness * hue.sample(rng),
        brightness * hue.sample(rng),
    ];
    let mut a = a.tinted(tint, a.roughness * rand.roughness_scale.sample(rng));
    if a.metallic > 0.5 {
        a.anisotropy = rand.metal_anisotropy.sample(rng);
    }
    a
}

/// The renderer's view of parts at rest in the cell under its fixed, nominal conditions: nominal
/// materials, the default (seed's) tag board, a mid-grey table, two point lights (hard shadows)
/// above the board and a dim ambient (see [`nominal_scene_on`]).
pub fn nominal_scene(models: &[PartModel], parts: &[PlacedPart]) -> RenderScene {
    nominal_scene_on(models, parts, TagBoard::default())
}

/// [`nominal_scene`] with `board` on the table (a scenario's `[cell] board`, printed with the
/// default print): the table sits under that board's thickness. Simulated runs render their
/// captures of this (see [`crate::render::capture`]).
pub fn nominal_scene_on(
    models: &[PartModel],
    parts: &[PlacedPart],
    board: TagBoard,
) -> RenderScene {
    let instances = parts
        .iter()
        .map(|p| Instance {
            mesh: models[p.model].render_mesh.clone(),
            table_T_part: p.table_T_part,
            appearance: models[p.model].appearance(),
            accent: models[p.model].accent_appearance(),
        })
        .collect();
    let table = Table {
        height: -board.thickness(),
        appearance: Appearance {
            base_color: [0.3, 0.29, 0.27],
            metallic: 0.0,
            roughness: 0.7,
            specular: 0.04,
            anisotropy: 0.0,
        },
    };
    let lights = vec![
        PointLight {
            position: Point3::new(0.45, 0.3, 1.2),
            intensity: [1.1; 3],
            radius: 0.0,
        },
        PointLight {
            position: Point3::new(-0.4, -0.25, 1.0),
            intensity: [0.8; 3],
            radius: 0.0,
        },
    ];
    RenderScene::new(instances, Some(board), Some(table), lights, [0.08; 3])
}

/// The OpenCV camera pose at `eye` looking at `target`, its x axis as close as possible to
/// `x_hint`, then turned by `roll` about the optical axis.
pub fn look_at(
    eye: &Point3<f64>,
    target: &Point3<f64>,
    x_hint: &Vector3<f64>,
    roll: f64,
) -> Isometry3<f64> {
    let z = (target - eye)
        .try_normalize(1e-12)
        .unwrap_or_else(|| -Vector3::z());
    let mut x = x_hint - z * z.dot(x_hint);
    if x.norm() < 1e-9 {
        x = Vector3::x() - z * z.x;
    }
    let x = x.normalize();
    let y = z.cross(&x);
    let r = Rotation3::from_basis_unchecked(&[x, y, z]);
    let q = UnitQuaternion::from_rotation_matrix(&r)
        * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), roll);
    Isometry3::from_parts(Translation3::from(eye.coords), q)
}

#[cfg(test)]
mod tests {
    use nalgebra::{Isometry3, Point2, Point3, Translation3, UnitQuaternion, Vector3};
    use perception::calibration::{Board, BoardSpec};
    use perception::camera::Camera;

    use super::*;
    use crate::render::{RenderSettings, render, window_covering};

    /// The simulated cell's capture scene prints the board it is given (a scenario's `[cell]
    /// board`), not the seed's: rendered from 1.5 m overhead, every data cell of the first tag
    /// where the two boards' codes differ is dark exactly where the given board prints black.
    #[test]
    fn the_capture_scene_prints_the_board_it_is_given() {
        let other = Board::new(BoardSpec {
            first_id: 100,
            thickness: 0.005,
            ..BoardSpec::seed()
        })
        .unwrap();
        let seed = nominal_scene(&[], &[]);
        let given = nominal_scene_on(&[], &[], TagBoard::new(other.clone()));
        assert_eq!(given.table.map(|t| t.height), Some(-0.005));
        let camera = Camera::basler_seed();
        let overhead = Isometry3::from_parts(
            Translation3::new(-0.08, 0.08, 1.5),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
        );
        let corners = other.corners(100).unwrap();
        let window = window_covering(&camera, &overhead, &corners[0], &corners[2]).unwrap();
        let settings = RenderSettings::default();
        let renders = [seed, given].map(|s| render(&s, &camera, &overhead, window, &settings));
        let luminance = |i: usize, p: Point2<f64>| {
            let out = &renders[i];
            let k = out.index(p.x.round() as u32, p.y.round() as u32).unwrap();
            let [r, g, b] = out.radiance[k];
            0.2126 * r + 0.7152 * g + 0.0722 * b
        };
        let seed_board = Board::seed();
        let cell = 0.03 / 8.0;
        let mut differing = 0;
        for cy in 2..8 {
            for cx in 2..8 {
                let x = -0.08 - 5.0 * cell + (cx as f64 + 0.5) * cell;
                let y = 0.08 + 5.0 * cell - (cy as f64 + 0.5) * cell;
                let (a, b) = (seed_board.is_black(x, y), other.is_black(x, y));
                if a == b {
                    continue;
                }
                differing += 1;
                let at = camera
                    .project(&(overhead.inverse() * Point3::new(x, y, 0.0)))
                    .unwrap();
                let (la, lb) = (luminance(0, at), luminance(1, at));
                assert_eq!(la < lb, a, "cell ({cx}, {cy}): seed {la}, given {lb}");
                assert!(la.max(lb) > 4.0 * la.min(lb), "black and white apart");
            }
        }
        assert!(
            differing >= 10,
            "tags 0 and 100 differ in {differing} cells"
        );
    }
}
