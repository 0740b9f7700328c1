//! The opt-in look of `cell dataset --environment`: a procedural room around the cell (walls,
//! ceiling light panels, floor, the table and the camera's own mount) that metals reflect through
//! prefiltered image-based lighting, rectangular area lights beside the randomisation's point
//! lights, and a backlit feeder plate, each drawn per image from its own random stream so that
//! the scene's other draws (parts, lights, camera, sensor) stay those of a run without it.

use std::sync::Arc;

use nalgebra::{Point3, Vector3};
use rand::{Rng, RngExt};

use crate::render::{AreaLight, CameraMount, CeilingPanel, Environment, PointLight, Room};
use crate::scene::{Randomisation, Range, SampledScene};

/// Options of the look, as a TOML file gives them (every key optional; a range is written
/// `key = { lo = 0.1, hi = 0.2 }`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LookOptions {
    /// The room the cell stands in.
    pub room: RoomRanges,
    /// Rectangular area lights, added to the randomisation's point lights.
    pub area_lights: AreaLightRanges,
    /// The backlit feeder plate.
    pub backlight: BacklightRanges,
    /// Whether the randomisation's point lights stay (false: only the room and the area lights
    /// light the scene; the point lights are still drawn, so the other draws are unchanged).
    pub point_lights: bool,
}

impl Default for LookOptions {
    fn default() -> Self {
        Self {
            room: RoomRanges::default(),
            area_lights: AreaLightRanges::default(),
            backlight: BacklightRanges::default(),
            point_lights: true,
        }
    }
}

/// Ranges of the procedural room. Lengths in metres, radiances in linear sensor units (1 is full
/// scale at exposure 1; the randomisation's ambient is 0.04–0.15).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RoomRanges {
    /// Whether to draw a room at all (without it the uniform ambient stays).
    pub enabled: bool,
    /// Half size of the room (walls at ± this along x and, drawn again, y).
    pub half_size: Range,
    /// Height of the table top above the floor.
    pub table_height: Range,
    /// Height of the ceiling above the table top.
    pub ceiling: Range,
    /// Grey radiance of each wall at ceiling height.
    pub wall: Range,
    /// Per-channel colour variation of a wall (multiplier).
    pub wall_tint: Range,
    /// Radiance of the ceiling between the panels.
    pub ceiling_radiance: Range,
    /// Radiance of the floor.
    pub floor: Range,
    /// Number of light panels on the ceiling (rounded draw).
    pub panels: Range,
    /// Side of a panel (each side drawn).
    pub panel_size: Range,
    /// Radiance of a panel (its brightness, drawn per panel).
    pub panel_radiance: Range,
    /// Colour temperature of a panel, drawn per panel: −1 warm (about 3 000 K) … 1 cool (about
    /// 8 000 K), as multipliers (1 − 0.25 w, 1, 1 + 0.25 w) of its radiance.
    pub panel_warmth: Range,
    /// Horizontal distance of a panel's centre from the cell, along x and along y.
    pub panel_offset: Range,
    /// Half size of the table top around the feeder plate.
    pub table_half: Range,
    /// Whether the camera's mount (its body and the beam holding it) is drawn.
    pub mount: bool,
    /// Half width of the camera body (its depth along the optical axis is 1.5 times this).
    pub mount_size: Range,
    /// Radiance of the mount (dark anodised to bare aluminium).
    pub mount_radiance: Range,
    /// Rooms baked once per dataset run and shared by its images, each image drawing one
    /// (their mounts where the randomisation puts cameras, seen from the board's centre); 0
    /// bakes a room for every image, seen from its parts with the mount at its own camera
    /// (about 30 ms of CPU an image). A backlit image always gets its own.
    pub pool: usize,
}

impl Default for RoomRanges {
    fn default() -> Self {
        Self {
            enabled: true,
            half_size: Range::new(1.5, 4.0),
            table_height: Range::new(0.75, 0.95),
            ceiling: Range::new(1.9, 3.0),
            wall: Range::new(0.03, 0.25),
            wall_tint: Range::new(0.9, 1.1),
            ceiling_radiance: Range::new(0.03, 0.2),
            floor: Range::new(0.02, 0.1),
            panels: Range::new(1.0, 6.0),
            panel_size: Range::new(0.3, 1.2),
            panel_radiance: Range::new(1.0, 5.0),
            panel_warmth: Range::new(-1.0, 0.6),
            panel_offset: Range::new(-2.0, 2.0),
            table_half: Range::new(0.3, 0.8),
            mount: true,
            mount_size: Range::new(0.03, 0.08),
            mount_radiance: Range::new(0.005, 0.06),
            pool: 32,
        }
    }
}

/// Ranges of the rectangular area lights (horizontal, emitting downwards).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AreaLightRanges {
    /// Number of area lights (rounded draw).
    pub count: Range,
    /// Side of a light (each side drawn).
    pub size: Range,
    /// Height above the table.
    pub height: Range,
    /// Horizontal distance from the parts.
    pub radius: Range,
    /// Radiance × area: the irradiance it gives 1 m below it, as a point light's intensity.
    pub intensity: Range,
    /// Per-channel colour variation (multiplier).
    pub tint: Range,
    /// Sphere lights per side the face is rendered with (samples² in all), 1–4; 1 renders it as
    /// one sphere light of half its side's radius (soft shadows, one shadow ray a point).
    pub samples: usize,
}

impl Default for AreaLightRanges {
    fn default() -> Self {
        Self {
            count: Range::new(0.0, 2.0),
            size: Range::new(0.2, 0.8),
            height: Range::new(0.8, 1.6),
            radius: Range::new(0.2, 0.9),
            intensity: Range::new(0.5, 1.5),
            tint: Range::new(0.92, 1.08),
            samples: 1,
        }
    }
}

/// The backlit feeder plate: the board's top face glows.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BacklightRanges {
    /// Share of the images whose plate is backlit, 0–1.
    pub probability: f64,
    /// Radiance the plate's white emits.
    pub radiance: Range,
}

impl Default for BacklightRanges {
    fn default() -> Self {
        Self {
            probability: 0.0,
            radiance: Range::new(0.4, 1.0),
        }
    }
}

/// A look option that cannot be used: its key path (`room.panels`) and why.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{key}: {message}")]
pub struct LookError {
    /// The option's key path in the TOML file.
    pub key: String,
    /// What is wrong.
    pub message: String,
}

impl LookOptions {
    /// Checks every range (finite, lo ≤ hi, inside its domain) and count; the error names the
    /// key.
    pub fn validate(&self) -> Result<(), LookError> {
        let inf = f64::INFINITY;
        let r = &self.room;
        let a = &self.area_lights;
        let ranges: [(&str, Range, f64, f64); 24] = [
            ("room.half_size", r.half_size, 0.3, 100.0),
            ("room.table_height", r.table_height, 0.0, 10.0),
            ("room.ceiling", r.ceiling, 0.2, 100.0),
            ("room.wall", r.wall, 0.0, inf),
            ("room.wall_tint", r.wall_tint, 0.0, inf),
            ("room.ceiling_radiance", r.ceiling_radiance, 0.0, inf),
            ("room.floor", r.floor, 0.0, inf),
            ("room.panels", r.panels, 0.0, 32.0),
            ("room.panel_size", r.panel_size, 0.0, 10.0),
            ("room.panel_radiance", r.panel_radiance, 0.0, inf),
            ("room.panel_warmth", r.panel_warmth, -2.0, 2.0),
            ("room.panel_offset", r.panel_offset, -100.0, 100.0),
            ("room.table_half", r.table_half, 0.0, 100.0),
            ("room.mount_size", r.mount_size, 0.0, 0.5),
            ("room.mount_radiance", r.mount_radiance, 0.0, inf),
            ("area_lights.count", a.count, 0.0, 8.0),
            ("area_lights.size", a.size, 0.0, 5.0),
            ("area_lights.height", a.height, 0.05, 100.0),
            ("area_lights.radius", a.radius, 0.0, 100.0),
            ("area_lights.intensity", a.intensity, 0.0, inf),
            ("area_lights.tint", a.tint, 0.0, inf),
            (
                "area_lights.samples",
                Range::new(a.samples as f64, a.samples as f64),
                1.0,
                4.0,
            ),
            (
                "backlight.probability",
                Range::new(self.backlight.probability, self.backlight.probability),
                0.0,
                1.0,
            ),
            ("backlight.radiance", self.backlight.radiance, 0.0, inf),
        ];
        for (key, range, min, max) in ranges {
            range.check(min, max).map_err(|e| LookError {
                key: key.to_string(),
                message: e.to_string(),
            })?;
        }
        if r.half_size.lo <= r.table_half.hi {
            return Err(LookError {
                key: "room.table_half".into(),
                message: format!(
                    "the table (half size up to {} m) must fit inside the room (walls from {} m)",
                    r.table_half.hi, r.half_size.lo
                ),
            });
        }
        Ok(())
    }

    /// Dresses `scene` in the look, drawing from `rng` (a stream of its own): the room as its
    /// environment (one of `pool` when given and the plate is not backlit, else one drawn for
    /// it, seen from the middle of its parts), the area lights appended to its lights, and the
    /// backlight. With `key_sky` (the lights family's hard key regime and the dim sky it drew),
    /// the room's lights are off: the room and the area lights are dimmed together so that the
    /// room's irradiance / π on the table is that sky (never brightened), as the room the key
    /// lights only by its spill; the draws are those of the undimmed look (a look without a
    /// room keeps its area lights as drawn).
    pub fn apply(
        &self,
        scene: &mut SampledScene,
        pool: Option<&[Arc<Environment>]>,
        key_sky: Option<f64>,
        rng: &mut impl Rng,
    ) {
        let eye = {
            let n = scene.parts.len().max(1) as f64;
            let sum = scene.parts.iter().fold(Vector3::zeros(), |s, p| {
                s + p.table_T_part.translation.vector
            });
            Point3::new(sum.x / n, sum.y / n, 0.005)
        };
        if !self.point_lights {
            scene.render.lights.clear();
        }
        let a = &self.area_lights;
        let first_area = scene.render.lights.len();
        let count = a.count.sample(rng).round().max(0.0) as usize;
        for _ in 0..count {
            let (su, sv) = (a.size.sample(rng), a.size.sample(rng));
            let phi = rng.random_range(0.0..std::f64::consts::TAU);
            let psi = rng.random_range(0.0..std::f64::consts::PI);
            let r = a.radius.sample(rng);
            let h = a.height.sample(rng);
            let i = a.intensity.sample(rng);
            let tint = [a.tint.sample(rng), a.tint.sample(rng), a.tint.sample(rng)];
            let area = (su * sv).max(1e-9);
            let light = AreaLight {
                centre: Point3::new(eye.x + r * phi.cos(), eye.y + r * phi.sin(), h),
                half_u: Vector3::new(psi.cos(), psi.sin(), 0.0) * (su / 2.0),
                half_v: Vector3::new(psi.sin(), -psi.cos(), 0.0) * (sv / 2.0),
                radiance: tint.map(|t| t * i / area),
            };
            scene
                .render
                .lights
                .extend(light.point_lights(a.samples, &eye));
        }
        let backlit = self.backlight.probability > 0.0
            && rng.random_range(0.0..1.0) < self.backlight.probability;
        let glow = backlit.then(|| self.backlight.radiance.sample(rng));
        scene.render.backlight = glow.map(|g| [g; 3]);
        if !self.room.enabled {
            return;
        }
        let dim_to = key_sky.filter(|s| s.is_finite() && *s >= 0.0);
        let pick = pool
            .filter(|p| !p.is_empty())
            .map(|p| p[rng.random_range(0..p.len())].clone());
        scene.render.environment = Some(match (pick, glow) {
            (Some(env), None) => env,
            _ => {
                let (board, table) = albedos(scene);
                let camera = Point3::from(scene.table_T_camera.translation.vector);
                let room = self.draw_room(
                    eye,
                    camera,
                    &scene.render.lights,
                    board,
                    table,
                    glow.unwrap_or(0.0),
                    rng,
                );
                Arc::new(Environment::from_room(&room))
            }
        });
        if let (Some(sky), Some(env)) = (dim_to, scene.render.environment.as_mut()) {
            let k = dimming(env, sky);
            *env = Arc::new(env.scaled([k; 3]));
            for light in &mut scene.render.lights[first_area..] {
                light.intensity = light.intensity.map(|i| i * k);
            }
        }
    }

    /// The run's shared rooms ([`RoomRanges::pool`] of them), baked from a stream of
    /// `seed`: seen from the board's centre, their mounts where `rand` puts cameras about
    /// `nominal_camera`, their plate and table lit by the middle of `rand`'s lights.
    pub fn bake_pool(
        &self,
        seed: u64,
        nominal_camera: &Point3<f64>,
        rand: &Randomisation,
    ) -> Vec<Arc<Environment>> {
        use rand::SeedableRng;
        if !self.room.enabled {
            return Vec::new();
        }
        let mid = |r: Range| (r.lo + r.hi) / 2.0;
        let lights = vec![PointLight {
            position: Point3::new(0.0, 0.0, mid(rand.light_height)),
            intensity: [mid(rand.lights).round().max(0.0) * mid(rand.light_intensity); 3],
            radius: 0.0,
        }];
        let board = (0.78 * mid(rand.material_tint), mid(rand.board_black));
        let table = [mid(rand.table_albedo); 3];
        // Serially: the caller holds a lock that a work-stealing thread pool could re-enter.
        (0..self.room.pool)
            .map(|k| {
                let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(
                    seed ^ (k as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
                );
                let camera = Point3::new(
                    nominal_camera.x + rand.camera_xy.sample(&mut rng),
                    nominal_camera.y + rand.camera_xy.sample(&mut rng),
                    rand.camera_height.sample(&mut rng),
                );
                let eye = Point3::new(0.0, 0.0, 0.005);
                let room = self.draw_room(eye, camera, &lights, board, table, 0.0, &mut rng);
                Arc::new(Environment::from_room(&room))
            })
            .collect()
    }

    /// Draws the room seen from `eye` with the mount at `camera`; the plate and table radiances
    /// are their albedos (`board`: white and black print) under `lights` and the room's upper
    /// half, plus the backlight's `glow` through the plate.
    #[allow(clippy::too_many_arguments)]
    fn draw_room(
        &self,
        eye: Point3<f64>,
        camera: Point3<f64>,
        lights: &[PointLight],
        board: (f64, f64),
        table: [f64; 3],
        glow: f64,
        rng: &mut impl Rng,
    ) -> Room {
        let r = &self.room;
        let half_size = [r.half_size.sample(rng), r.half_size.sample(rng)];
        let floor = -r.table_height.sample(rng);
        let ceiling = r.ceiling.sample(rng);
        let walls = [0; 4].map(|_| {
            let g = r.wall.sample(rng);
            [
                g * r.wall_tint.sample(rng),
                g * r.wall_tint.sample(rng),
                g * r.wall_tint.sample(rng),
            ]
        });
        let ceiling_radiance = [r.ceiling_radiance.sample(rng); 3];
        let floor_radiance = [r.floor.sample(rng); 3];
        let n_panels = r.panels.sample(rng).round().max(0.0) as usize;
        let mut panels: Vec<CeilingPanel> = (0..n_panels)
            .map(|_| {
                let l = r.panel_radiance.sample(rng);
                CeilingPanel {
                    centre: [
                        (eye.x + r.panel_offset.sample(rng)).clamp(-half_size[0], half_size[0]),
                        (eye.y + r.panel_offset.sample(rng)).clamp(-half_size[1], half_size[1]),
                    ],
                    size: [r.panel_size.sample(rng), r.panel_size.sample(rng)],
                    radiance: [l; 3],
                }
            })
            .collect();
        let mount = r.mount.then(|| {
            let s = r.mount_size.sample(rng);
            CameraMount {
                position: camera + Vector3::new(0.0, 0.0, 0.75 * s),
                half_extents: [s, s, 0.75 * s],
                beam_azimuth: rng.random_range(0.0..std::f64::consts::TAU),
                beam_half_width: s / 2.0,
                radiance: [r.mount_radiance.sample(rng); 3],
            }
        });
        let table_half = r.table_half.sample(rng);
        // The panels' colours last, so that the room's other draws stay those drawn before
        // panels had colours.
        for panel in &mut panels {
            let w = r.panel_warmth.sample(rng);
            let l = panel.radiance[1];
            panel.radiance = [l * (1.0 - 0.25 * w), l, l * (1.0 + 0.25 * w)];
        }
        let mut room = Room {
            eye,
            half_size,
            floor,
            ceiling,
            walls,
            ceiling_radiance,
            floor_radiance,
            table_half,
            table_radiance: [0.0; 3],
            plate_half: 0.105,
            plate_radiance: [0.0; 3],
            panels,
            mount,
        };
        // Irradiance / π at the eye from the room's upper half (cosine-weighted midpoint rule)
        // and from the lights, unshadowed.
        let mut sky = [0.0; 3];
        let (nt, np) = (24, 48);
        for i in 0..nt {
            let c = ((i as f64 + 0.5) / nt as f64).sqrt();
            let s = (1.0 - c * c).sqrt();
            for j in 0..np {
                let phi = (j as f64 + 0.5) / np as f64 * std::f64::consts::TAU;
                let l = room.radiance(&Vector3::new(s * phi.cos(), s * phi.sin(), c));
                for (s, l) in sky.iter_mut().zip(l) {
                    *s += l / (nt * np) as f64;
                }
            }
        }
        for light in lights {
            let d = light.position - eye;
            let dist2 = d.norm_squared().max(1e-9);
            let cos = (d.z / dist2.sqrt()).max(0.0);
            for (s, i) in sky.iter_mut().zip(light.intensity) {
                *s += i * cos / dist2 / std::f64::consts::PI;
            }
        }
        // The board is about half white print and half black.
        let (w, k) = board;
        let (board, passed) = ((w + k) / 2.0, (1.0 + k / w.max(1e-6)) / 2.0);
        room.plate_radiance = [0, 1, 2].map(|ch| board * sky[ch] + glow * passed);
        room.table_radiance = [0, 1, 2].map(|ch| table[ch] * sky[ch]);
        room
    }
}

/// The factor (at most 1) that brings `env`'s irradiance / π on the table (normal up, green) to
/// `sky`.
fn dimming(env: &Environment, sky: f64) -> f64 {
    let up = env.irradiance(&Vector3::z())[1];
    if up > sky && up > 0.0 { sky / up } else { 1.0 }
}

/// The green albedos of a scene's board print (white, black) and its table's colour.
fn albedos(scene: &SampledScene) -> ((f64, f64), [f64; 3]) {
    let board = scene.render.board.as_ref().map_or((0.78, 0.035), |b| {
        (b.white.base_color[1], b.black.base_color[1])
    });
    let table = scene
        .render
        .table
        .map_or([0.3; 3], |t| t.appearance.base_color);
    (board, table)
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;

    use super::*;

    fn inside(r: Range, x: f64) -> bool {
        (r.lo - 1e-9..=r.hi + 1e-9).contains(&x)
    }

    /// A scene of two parts lit by one point light, for the look to dress.
    fn two_parts() -> SampledScene {
        let part = |x: f64| crate::scene::PlacedPart {
            model: 0,
            table_T_part: nalgebra::Isometry3::translation(x, 0.01, 0.003),
        };
        let key = PointLight {
            position: Point3::new(0.8, 0.0, 0.9),
            intensity: [2.0; 3],
            radius: 0.01,
        };
        SampledScene {
            parts: vec![part(0.0), part(0.02)],
            render: crate::render::RenderScene::new(Vec::new(), None, None, vec![key], [0.02; 3]),
            table_T_camera: nalgebra::Isometry3::translation(0.0, 0.0, 1.6),
            sensor: crate::render::SensorModel::default(),
            overexposure: 1.0,
        }
    }

    #[test]
    fn under_the_key_regime_the_room_and_its_area_lights_are_dimmed_to_the_key_sky() {
        let mut look = LookOptions::default();
        look.area_lights.count = Range::new(2.0, 2.0);
        look.room.pool = 0;
        let dress = |sky: Option<f64>, seed: u64| {
            let mut scene = two_parts();
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            look.apply(&mut scene, None, sky, &mut rng);
            scene
        };
        let up = Vector3::z();
        let dirs = [
            Vector3::new(0.0, 0.0, 1.0),
            Vector3::new(0.6, 0.0, 0.8),
            Vector3::new(-0.3, 0.5, 0.81).normalize(),
            Vector3::new(0.9, 0.1, -0.42).normalize(),
        ];
        for seed in 0..6 {
            let (lit, dim) = (dress(None, seed), dress(Some(0.02), seed));
            let (e_lit, e_dim) = (
                lit.render.environment.as_ref().unwrap(),
                dim.render.environment.as_ref().unwrap(),
            );
            let room = e_lit.irradiance(&up)[1];
            assert!(room > 0.1, "the lit room's irradiance / π {room}");
            let k = 0.02 / room;
            assert!(
                (e_dim.irradiance(&up)[1] - 0.02).abs() < 1e-4,
                "seed {seed}"
            );
            for d in &dirs {
                for r in [0.0, 0.35, 0.7] {
                    let (a, b) = (e_lit.specular(d, r), e_dim.specular(d, r));
                    for c in 0..3 {
                        assert!(
                            (b[c] - k * a[c]).abs() <= 1e-5 * (1.0 + a[c]),
                            "{a:?} {b:?}"
                        );
                    }
                }
            }
            // The scene's own light is the key's: untouched. The area lights are the room's:
            // where they were, dimmed by the same factor.
            let (l, m) = (&lit.render.lights, &dim.render.lights);
            assert_eq!(l.len(), m.len());
            assert!(l.len() > 1, "area lights drawn");
            assert_eq!(l[0], m[0]);
            for (a, b) in l.iter().zip(m).skip(1) {
                assert_eq!(a.position, b.position);
                for c in 0..3 {
                    assert!((b.intensity[c] - k * a.intensity[c]).abs() < 1e-12 * a.intensity[c]);
                }
            }
            assert_eq!(lit.render.backlight, dim.render.backlight);
            // A sky brighter than the room leaves it as it is: never brightened.
            let bright = dress(Some(100.0), seed);
            assert_eq!(bright.render.lights, lit.render.lights);
            let e = bright.render.environment.as_ref().unwrap();
            assert_eq!(e.irradiance(&up), e_lit.irradiance(&up));
        }
    }

    #[test]
    fn panels_are_drawn_in_colour_and_brightness_within_their_ranges() {
        let look = LookOptions::default();
        let r = &look.room;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let (mut warm, mut cool, mut seen) = (0, 0, Vec::new());
        for _ in 0..40 {
            let room = look.draw_room(
                Point3::new(0.0, 0.0, 0.005),
                Point3::new(0.0, 0.0, 1.6),
                &[],
                (0.78, 0.035),
                [0.3; 3],
                0.0,
                &mut rng,
            );
            for p in &room.panels {
                let [red, green, blue] = p.radiance;
                assert!(inside(r.panel_radiance, green), "{green}");
                // Red and blue move against each other by the drawn warmth w:
                // red = (1 − w / 4) green, blue = (1 + w / 4) green.
                let w = 4.0 * (1.0 - red / green);
                assert!(inside(r.panel_warmth, w), "warmth {w}");
                assert!((blue / green - (1.0 + 0.25 * w)).abs() < 1e-12);
                warm += usize::from(w < -0.5);
                cool += usize::from(w > 0.3);
                seen.push(green);
            }
        }
        assert!(warm > 5 && cool > 5, "{warm} warm, {cool} cool panels");
        let (lo, hi) = seen
            .iter()
            .fold((f64::INFINITY, 0.0f64), |(l, h), g| (l.min(*g), h.max(*g)));
        assert!(lo < 1.5 && hi > 4.5, "panel radiance {lo}–{hi}");
    }
}
