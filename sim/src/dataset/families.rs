//! Randomisation families (`cell dataset --families`): six opt-in widenings of the dataset
//! randomisation, after BlenderProc's practice (random lights in number, strength, position and
//! colour; random materials; random textures; distractor objects; camera effects), so that the
//! training images span both our renderer and Blender Cycles. Each family is switched on alone
//! and draws from a random stream of its own, so an ablation can turn any one off and the other
//! families' draws stay the same; with every family off (the default) images are unchanged, byte
//! for byte.

use std::borrow::Cow;
use std::sync::Arc;

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use perception::part::TriMesh;
use rand::{Rng, RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::render::{
    Appearance, Instance, PointLight, RenderMesh, RenderOutput, RenderScene, TableTexture,
    TexturePattern,
};
use crate::scene::{PartModel, Range, SampledScene};

/// The family names, in the order their streams are numbered.
pub const FAMILY_NAMES: [&str; 6] = [
    "lights",
    "plating",
    "plastic",
    "textures",
    "distractors",
    "sensor",
];

/// The families' switches and ranges, as a TOML file gives them (every key optional; a range is
/// written `key = { lo = 0.1, hi = 0.2 }`; a family is on when its `enabled` is true).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Families {
    /// Point lights redrawn in number, size, position, strength and colour, and a coloured sky.
    pub lights: LightFamily,
    /// Metal platings (nickel, tin, chromium, silver, iron) from matte to mirror.
    pub plating: PlatingFamily,
    /// Plastic gloss, brightness and specular level.
    pub plastic: PlasticFamily,
    /// Table textures and feeder plate colour, gloss and wear.
    pub textures: TextureFamily,
    /// Simple non-catalog shapes on the table beside the parts (never labelled).
    pub distractors: DistractorFamily,
    /// Sensor gain, blur, noise and white balance.
    pub sensor: SensorFamily,
}

/// Lights: the randomisation's point lights and sky are replaced.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LightFamily {
    /// Whether the family is on.
    pub enabled: bool,
    /// Number of point lights (rounded draw).
    pub count: Range,
    /// Height above the table, m.
    pub height: Range,
    /// Horizontal distance from the parts, m.
    pub radius: Range,
    /// Irradiance a light gives the parts facing it (its intensity is this times its distance
    /// squared, so near and far lights are equally usable), split over the lights drawn.
    pub irradiance: Range,
    /// Radius of a light's sphere, m (hard to soft shadows).
    pub size: Range,
    /// Colour temperature shift: −1 warm (about 3 000 K) … 1 cool (about 8 000 K), as
    /// multipliers (1 − 0.25 w, 1, 1 + 0.25 w).
    pub warmth: Range,
    /// Sky (ambient) radiance.
    pub ambient: Range,
    /// Share of the images (0–1) lit instead by one hard key light well off the vertical in a
    /// dim room (a spot lamp or a window): flat metal tops mirror the dim room and come out dark,
    /// shadows are long and sharp, and the parts' glints meter the exposure down.
    pub key_probability: f64,
    /// The key light's angle from the vertical through the parts, degrees.
    pub key_angle: Range,
    /// The key light's distance from the parts, m.
    pub key_distance: Range,
    /// Irradiance the key gives the parts facing it (its intensity is this times its distance
    /// squared).
    pub key_irradiance: Range,
    /// Radius of the key light's sphere, m.
    pub key_size: Range,
    /// The dim room under the key: sky radiance as a share of the key's irradiance.
    pub key_ambient: Range,
}

impl Default for LightFamily {
    fn default() -> Self {
        Self {
            enabled: false,
            count: Range::new(1.0, 3.0),
            height: Range::new(0.8, 1.8),
            radius: Range::new(0.0, 0.9),
            irradiance: Range::new(0.2, 5.0),
            size: Range::new(0.0, 0.2),
            warmth: Range::new(-1.0, 1.0),
            ambient: Range::new(0.03, 0.15),
            key_probability: 0.25,
            key_angle: Range::new(35.0, 65.0),
            key_distance: Range::new(0.8, 2.5),
            key_irradiance: Range::new(1.5, 3.5),
            key_size: Range::new(0.0, 0.03),
            key_ambient: Range::new(0.004, 0.02),
        }
    }
}

/// Plating: the metal parts' finish, drawn per part kind and image.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlatingFamily {
    /// Whether the family is on.
    pub enabled: bool,
    /// Brightness multiplier of the drawn plating's reflectance.
    pub brightness: Range,
    /// GGX roughness (0.03 mirror … 0.7 matte).
    pub roughness: Range,
    /// Brushing, 0–1.
    pub anisotropy: Range,
}

impl Default for PlatingFamily {
    fn default() -> Self {
        Self {
            enabled: false,
            brightness: Range::new(0.85, 1.1),
            roughness: Range::new(0.03, 0.7),
            anisotropy: Range::new(0.0, 0.8),
        }
    }
}

/// The platings a metal part is drawn from: linear F0 reflectances (nickel, chromium, silver and
/// iron from Real-Time Rendering's table as Unity's Metal Reflectance node gives it; tin a
/// neutral 0.75, an assumption: no measured value at hand).
pub const PLATINGS: [(&str, [f64; 3]); 5] = [
    ("nickel", [0.660, 0.609, 0.526]),
    ("tin", [0.75, 0.75, 0.75]),
    ("chromium", [0.550, 0.556, 0.554]),
    ("silver", [0.972, 0.960, 0.915]),
    ("iron", [0.560, 0.570, 0.580]),
];

/// Plastic: the dielectric parts' gloss and colour, drawn per part kind and image.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PlasticFamily {
    /// Whether the family is on.
    pub enabled: bool,
    /// GGX roughness (0.08 glossy … 0.9 matte).
    pub roughness: Range,
    /// Specular reflectance at normal incidence.
    pub specular: Range,
    /// Multiplier of the nominal albedo (black plastics range from deep black to dark grey).
    pub brightness: Range,
}

impl Default for PlasticFamily {
    fn default() -> Self {
        Self {
            enabled: false,
            roughness: Range::new(0.08, 0.9),
            specular: Range::new(0.03, 0.06),
            brightness: Range::new(0.5, 2.5),
        }
    }
}

/// Textures: the table's pattern and colour, the feeder plate's colour, gloss and wear.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TextureFamily {
    /// Whether the family is on.
    pub enabled: bool,
    /// Table albedo (grey level before its colour).
    pub table_albedo: Range,
    /// Per-channel colour of the table (multiplier).
    pub table_tint: Range,
    /// Table roughness.
    pub table_roughness: Range,
    /// Feature size of the table's pattern, m.
    pub table_scale: Range,
    /// Amplitude of the table's pattern, 0–1.
    pub table_contrast: Range,
    /// Per-channel colour of the plate's white (multiplier of its albedo).
    pub plate_tint: Range,
    /// Roughness of the plate's white.
    pub plate_roughness: Range,
    /// Amplitude of the plate print's smooth albedo variation.
    pub plate_grain: Range,
    /// Dust specks on the plate per cm².
    pub plate_dust: Range,
    /// Scratches through the plate's print per 100 cm².
    pub plate_scratches: Range,
}

impl Default for TextureFamily {
    fn default() -> Self {
        Self {
            enabled: false,
            table_albedo: Range::new(0.03, 0.8),
            table_tint: Range::new(0.85, 1.15),
            table_roughness: Range::new(0.3, 0.95),
            table_scale: Range::new(0.002, 0.05),
            table_contrast: Range::new(0.0, 0.6),
            plate_tint: Range::new(0.9, 1.05),
            plate_roughness: Range::new(0.2, 0.9),
            plate_grain: Range::new(0.0, 0.2),
            plate_dust: Range::new(0.0, 2.0),
            plate_scratches: Range::new(0.0, 12.0),
        }
    }
}

/// Distractors: boxes and cylinders of random size and material lying on the table beside the
/// parts, never touching them. They are rendered (they shadow, reflect and hide parts behind
/// them, so the visible masks stay right) but are not parts: not in the BOP ground truth or the
/// crops' labels.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DistractorFamily {
    /// Whether the family is on.
    pub enabled: bool,
    /// Number of distractors (rounded draw).
    pub count: Range,
    /// Side (box) or diameter (cylinder) of a distractor, m.
    pub size: Range,
    /// Height of a distractor, m.
    pub height: Range,
    /// Distance of a distractor's centre from the parts' centre (a crop's target), m.
    pub radius: Range,
    /// Share of the distractors that are metal, 0–1.
    pub metal_probability: f64,
    /// Albedo (or a metal's reflectance) of a distractor's colour channels.
    pub albedo: Range,
    /// Roughness of a distractor.
    pub roughness: Range,
}

impl Default for DistractorFamily {
    fn default() -> Self {
        Self {
            enabled: false,
            count: Range::new(1.0, 6.0),
            size: Range::new(0.003, 0.02),
            height: Range::new(0.001, 0.012),
            radius: Range::new(0.006, 0.05),
            metal_probability: 0.3,
            albedo: Range::new(0.02, 0.9),
            roughness: Range::new(0.05, 0.9),
        }
    }
}

/// Sensor: wider gain, blur and noise than the randomisation's, and a white balance error. Per
/// image one of two regimes: a clean one (`clean_probability` of the images: a camera at its
/// base gain, whose noise is below 8-bit quantisation) and a noisy one (the other images:
/// raised gain, read and shot noise up to several codes).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SensorFamily {
    /// Whether the family is on.
    pub enabled: bool,
    /// Analogue gain (noisy regime).
    pub gain: Range,
    /// Gaussian blur sigma, px (both regimes: optics, not the sensor).
    pub blur_sigma: Range,
    /// Read noise standard deviation (full scale 1; noisy regime).
    pub read_noise: Range,
    /// Shot noise variance per unit signal (noisy regime).
    pub shot_noise: Range,
    /// White balance multipliers of red and of blue relative to green (both regimes).
    pub white_balance: Range,
    /// Share of the images (0–1) taken in the clean regime.
    pub clean_probability: f64,
    /// Analogue gain of the clean regime (about base gain).
    pub clean_gain: Range,
    /// Read noise of the clean regime (full scale 1).
    pub clean_read_noise: Range,
    /// Shot noise variance per unit signal of the clean regime (1 / full-well electrons).
    pub clean_shot_noise: Range,
}

impl Default for SensorFamily {
    fn default() -> Self {
        Self {
            enabled: false,
            gain: Range::new(1.0, 2.5),
            blur_sigma: Range::new(0.0, 1.5),
            read_noise: Range::new(0.0, 0.02),
            shot_noise: Range::new(0.0, 0.005),
            white_balance: Range::new(0.88, 1.12),
            clean_probability: 0.3,
            clean_gain: Range::new(1.0, 1.2),
            clean_read_noise: Range::new(0.0, 0.001),
            clean_shot_noise: Range::new(0.0, 0.0002),
        }
    }
}

/// A family option that cannot be used: its key path (`lights.count`) and why.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{key}: {message}")]
pub struct FamilyError {
    /// The option's key path in the TOML file.
    pub key: String,
    /// What is wrong.
    pub message: String,
}

/// What the families drew for an image beyond its scene: the white balance its sensor applies,
/// and the sky a look's room is dimmed to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FamilyDraw {
    /// Per-channel white balance (red, green, blue); `[1, 1, 1]` without the sensor family.
    pub white_balance: [f64; 3],
    /// When the lights family drew its hard key regime: the dim sky's radiance (green) it drew,
    /// which a look's room is dimmed to (the room's own lights off, lit only by the key's
    /// spill); `None` otherwise.
    pub key_sky: Option<f64>,
}

impl Default for FamilyDraw {
    fn default() -> Self {
        Self {
            white_balance: [1.0; 3],
            key_sky: None,
        }
    }
}

impl Families {
    /// Every family on, at its default ranges.
    pub fn all() -> Self {
        let mut f = Self::default();
        for name in FAMILY_NAMES {
            f.set(name, true).expect("a known family");
        }
        f
    }

    /// Turns the family `name` on or off; an unknown name is an error listing the known ones.
    pub fn set(&mut self, name: &str, on: bool) -> Result<(), FamilyError> {
        let flag = match name {
            "lights" => &mut self.lights.enabled,
            "plating" => &mut self.plating.enabled,
            "plastic" => &mut self.plastic.enabled,
            "textures" => &mut self.textures.enabled,
            "distractors" => &mut self.distractors.enabled,
            "sensor" => &mut self.sensor.enabled,
            _ => {
                return Err(FamilyError {
                    key: name.to_string(),
                    message: format!(
                        "no randomisation family of that name (known: {}, or all, none)",
                        FAMILY_NAMES.join(", ")
                    ),
                });
            }
        };
        *flag = on;
        Ok(())
    }

    /// The names of the families that are on.
    pub fn enabled(&self) -> Vec<&'static str> {
        let on = [
            self.lights.enabled,
            self.plating.enabled,
            self.plastic.enabled,
            self.textures.enabled,
            self.distractors.enabled,
            self.sensor.enabled,
        ];
        FAMILY_NAMES
            .iter()
            .zip(on)
            .filter(|(_, on)| *on)
            .map(|(n, _)| *n)
            .collect()
    }

    /// Families from a comma-separated list of names (`all`, `none`, or family names; `all`
    /// followed by `-name` turns one off), at their default ranges.
    pub fn from_list(list: &str) -> Result<Self, FamilyError> {
        let mut f = Self::default();
        for name in list.split(',').map(str::trim).filter(|n| !n.is_empty()) {
            match name {
                "all" => f = Self::all(),
                "none" => f = Self::default(),
                _ => match name.strip_prefix('-') {
                    Some(off) => f.set(off, false)?,
                    None => f.set(name, true)?,
                },
            }
        }
        Ok(f)
    }

    /// Checks every range (finite, lo ≤ hi, inside its domain); the error names the key.
    pub fn validate(&self) -> Result<(), FamilyError> {
        let inf = f64::INFINITY;
        let (l, p, q, t, d, s) = (
            &self.lights,
            &self.plating,
            &self.plastic,
            &self.textures,
            &self.distractors,
            &self.sensor,
        );
        let ranges: [(&str, Range, f64, f64); 44] = [
            ("lights.count", l.count, 0.0, 8.0),
            ("lights.height", l.height, 0.05, 100.0),
            ("lights.radius", l.radius, 0.0, 100.0),
            ("lights.irradiance", l.irradiance, 0.0, inf),
            ("lights.size", l.size, 0.0, 1.0),
            ("lights.warmth", l.warmth, -2.0, 2.0),
            ("lights.ambient", l.ambient, 0.0, inf),
            (
                "lights.key_probability",
                Range::new(l.key_probability, l.key_probability),
                0.0,
                1.0,
            ),
            ("lights.key_angle", l.key_angle, 0.0, 89.0),
            ("lights.key_distance", l.key_distance, 0.05, 100.0),
            ("lights.key_irradiance", l.key_irradiance, 0.0, inf),
            ("lights.key_size", l.key_size, 0.0, 1.0),
            ("lights.key_ambient", l.key_ambient, 0.0, inf),
            ("plating.brightness", p.brightness, 0.0, inf),
            ("plating.roughness", p.roughness, 0.02, 1.0),
            ("plating.anisotropy", p.anisotropy, 0.0, 1.0),
            ("plastic.roughness", q.roughness, 0.02, 1.0),
            ("plastic.specular", q.specular, 0.0, 1.0),
            ("plastic.brightness", q.brightness, 0.0, inf),
            ("textures.table_albedo", t.table_albedo, 0.0, 1.0),
            ("textures.table_tint", t.table_tint, 0.0, inf),
            ("textures.table_roughness", t.table_roughness, 0.02, 1.0),
            ("textures.table_scale", t.table_scale, 1e-4, 10.0),
            ("textures.table_contrast", t.table_contrast, 0.0, 1.0),
            ("textures.plate_tint", t.plate_tint, 0.0, inf),
            ("textures.plate_roughness", t.plate_roughness, 0.02, 1.0),
            ("textures.plate_grain", t.plate_grain, 0.0, 1.0),
            ("textures.plate_dust", t.plate_dust, 0.0, 100.0),
            ("textures.plate_scratches", t.plate_scratches, 0.0, 100.0),
            ("distractors.count", d.count, 0.0, 32.0),
            ("distractors.size", d.size, 1e-4, 0.2),
            ("distractors.height", d.height, 1e-4, 0.2),
            ("distractors.radius", d.radius, 0.0, 1.0),
            (
                "distractors.metal_probability",
                Range::new(d.metal_probability, d.metal_probability),
                0.0,
                1.0,
            ),
            ("distractors.albedo", d.albedo, 0.0, 1.0),
            ("distractors.roughness", d.roughness, 0.02, 1.0),
            ("sensor.gain", s.gain, 1e-6, inf),
            ("sensor.blur_sigma", s.blur_sigma, 0.0, 10.0),
            ("sensor.read_noise", s.read_noise, 0.0, 1.0),
            ("sensor.shot_noise", s.shot_noise, 0.0, 1.0),
            (
                "sensor.clean_probability",
                Range::new(s.clean_probability, s.clean_probability),
                0.0,
                1.0,
            ),
            ("sensor.clean_gain", s.clean_gain, 1e-6, inf),
            ("sensor.clean_read_noise", s.clean_read_noise, 0.0, 1.0),
            ("sensor.clean_shot_noise", s.clean_shot_noise, 0.0, 1.0),
        ];
        let extra = [("sensor.white_balance", s.white_balance, 1e-3, 1e3)];
        for (key, range, min, max) in ranges.into_iter().chain(extra) {
            range.check(min, max).map_err(|e| FamilyError {
                key: key.to_string(),
                message: e.to_string(),
            })?;
        }
        Ok(())
    }

    /// Applies the families that are on to `scene` (drawn for its `models`), each from its own
    /// stream: `seed_of(k)` seeds family k of [`FAMILY_NAMES`]. Distractors and lights are
    /// placed about part `focus` (a crop's target), else about the middle of the parts.
    /// Returns what the sensor must apply.
    pub fn apply(
        &self,
        scene: &mut SampledScene,
        models: &[PartModel],
        focus: Option<usize>,
        seed_of: impl Fn(u64) -> u64,
    ) -> FamilyDraw {
        let mut draw = FamilyDraw::default();
        let rng = |k: u64| ChaCha8Rng::seed_from_u64(seed_of(k));
        if self.lights.enabled {
            draw.key_sky = self.lights.apply(scene, focus, &mut rng(0));
        }
        if self.plating.enabled {
            self.plating.apply(scene, models, &mut rng(1));
        }
        if self.plastic.enabled {
            self.plastic.apply(scene, models, &mut rng(2));
        }
        if self.textures.enabled {
            self.textures.apply(scene, &mut rng(3));
        }
        if self.distractors.enabled {
            self.distractors.apply(scene, models, focus, &mut rng(4));
        }
        if self.sensor.enabled {
            draw.white_balance = self.sensor.apply(scene, &mut rng(5));
        }
        draw
    }
}

/// What the sensor meters on: `out` itself, or, when distractors are in the scene (instances
/// beyond its `parts`), a copy whose distractor pixels count as background, so that a bright
/// distractor does not darken the parts (metering keeps the parts' highlights below full scale).
pub(crate) fn metering_view(out: &RenderOutput, parts: usize) -> Cow<'_, RenderOutput> {
    let last = parts as u16;
    if out.visible.iter().all(|v| *v <= last) {
        return Cow::Borrowed(out);
    }
    Cow::Owned(RenderOutput {
        window: out.window,
        radiance: out.radiance.clone(),
        depth: Vec::new(),
        visible: out
            .visible
            .iter()
            .map(|v| if *v > last { 0 } else { *v })
            .collect(),
        full_masks: Vec::new(),
    })
}

/// Where part `focus` lies on the table, else the middle of the scene's parts.
fn parts_centre(scene: &SampledScene, focus: Option<usize>) -> Point3<f64> {
    if let Some(p) = focus.and_then(|i| scene.parts.get(i)) {
        let c = p.table_T_part.translation.vector;
        return Point3::new(c.x, c.y, 0.0);
    }
    let n = scene.parts.len().max(1) as f64;
    let sum = scene.parts.iter().fold(Vector3::zeros(), |s, p| {
        s + p.table_T_part.translation.vector
    });
    Point3::new(sum.x / n, sum.y / n, 0.0)
}

/// A colour temperature shift `w` (−1 warm … 1 cool) applied to a grey level.
fn warmed(level: f64, w: f64) -> [f64; 3] {
    [level * (1.0 - 0.25 * w), level, level * (1.0 + 0.25 * w)]
}

impl LightFamily {
    /// Draws the lights; returns the dim sky's radiance (green) when the key regime was drawn.
    fn apply(
        &self,
        scene: &mut SampledScene,
        focus: Option<usize>,
        rng: &mut impl Rng,
    ) -> Option<f64> {
        let centre = parts_centre(scene, focus);
        if self.key_probability > 0.0 && rng.random_bool(self.key_probability.min(1.0)) {
            return Some(self.apply_key(scene, centre, rng));
        }
        let n = self.count.sample(rng).round().max(0.0) as usize;
        let share = 1.0 / n.max(1) as f64;
        scene.render.lights = (0..n)
            .map(|_| {
                let r = self.radius.sample(rng);
                let phi = rng.random_range(0.0..std::f64::consts::TAU);
                let h = self.height.sample(rng);
                let position = Point3::new(centre.x + r * phi.cos(), centre.y + r * phi.sin(), h);
                let e = self.irradiance.sample(rng) * share;
                let w = self.warmth.sample(rng);
                let i = e * (position - centre).norm_squared();
                PointLight {
                    position,
                    intensity: warmed(i, w),
                    radius: self.size.sample(rng),
                }
            })
            .collect();
        let sky = self.ambient.sample(rng);
        let w = self.warmth.sample(rng);
        scene.render.ambient = warmed(sky, w);
        None
    }

    /// The hard regime: one small key light `key_angle` off the vertical through `centre`,
    /// `key_distance` away, and a dim sky (its green radiance is returned).
    fn apply_key(&self, scene: &mut SampledScene, centre: Point3<f64>, rng: &mut impl Rng) -> f64 {
        let theta = self.key_angle.sample(rng).to_radians();
        let d = self.key_distance.sample(rng);
        let phi = rng.random_range(0.0..std::f64::consts::TAU);
        let position = centre
            + Vector3::new(
                d * theta.sin() * phi.cos(),
                d * theta.sin() * phi.sin(),
                d * theta.cos(),
            );
        let e = self.key_irradiance.sample(rng);
        let w = self.warmth.sample(rng);
        scene.render.lights = vec![PointLight {
            position,
            intensity: warmed(e * d * d, w),
            radius: self.key_size.sample(rng),
        }];
        let sky = e * self.key_ambient.sample(rng);
        scene.render.ambient = warmed(sky, self.warmth.sample(rng));
        sky
    }
}

impl PlatingFamily {
    fn apply(&self, scene: &mut SampledScene, models: &[PartModel], rng: &mut impl Rng) {
        let finishes: Vec<Appearance> = models
            .iter()
            .map(|m| {
                let (_, f0) = PLATINGS[rng.random_range(0..PLATINGS.len())];
                let b = self.brightness.sample(rng);
                Appearance {
                    base_color: f0.map(|c| (c * b).clamp(0.0, 1.0)),
                    metallic: 1.0,
                    roughness: self.roughness.sample(rng),
                    specular: m.appearance().specular,
                    anisotropy: self.anisotropy.sample(rng),
                }
            })
            .collect();
        for (inst, part) in scene.render.instances.iter_mut().zip(&scene.parts) {
            if inst.appearance.metallic >= 0.5 {
                inst.appearance = finishes[part.model];
            }
        }
    }
}

impl PlasticFamily {
    fn apply(&self, scene: &mut SampledScene, models: &[PartModel], rng: &mut impl Rng) {
        let draws: Vec<(f64, f64, f64)> = models
            .iter()
            .map(|_| {
                (
                    self.roughness.sample(rng),
                    self.specular.sample(rng),
                    self.brightness.sample(rng),
                )
            })
            .collect();
        for (inst, part) in scene.render.instances.iter_mut().zip(&scene.parts) {
            if inst.appearance.metallic < 0.5 {
                let (roughness, specular, b) = draws[part.model];
                let a = &mut inst.appearance;
                a.roughness = roughness;
                a.specular = specular;
                a.base_color = a.base_color.map(|c| (c * b).clamp(0.0, 1.0));
            }
        }
    }
}

impl TextureFamily {
    fn apply(&self, scene: &mut SampledScene, rng: &mut impl Rng) {
        let grey = self.table_albedo.sample(rng);
        let tint = [0; 3].map(|_| self.table_tint.sample(rng));
        let roughness = self.table_roughness.sample(rng);
        if let Some(table) = scene.render.table.as_mut() {
            table.appearance.base_color = tint.map(|t| (grey * t).clamp(0.0, 1.0));
            table.appearance.roughness = roughness;
        }
        let pattern = if rng.random_bool(0.5) {
            TexturePattern::Noise
        } else {
            TexturePattern::Stripes
        };
        scene.render.table_texture = Some(TableTexture {
            pattern,
            scale: self.table_scale.sample(rng),
            contrast: self.table_contrast.sample(rng),
            angle: rng.random_range(0.0..std::f64::consts::PI),
            seed: rng.random(),
        });
        let tint = [0; 3].map(|_| self.plate_tint.sample(rng));
        let roughness = self.plate_roughness.sample(rng);
        let (grain, dust, scratches) = (
            self.plate_grain.sample(rng),
            self.plate_dust.sample(rng),
            self.plate_scratches.sample(rng),
        );
        if let Some(board) = scene.render.board.as_mut() {
            board.white = board.white.tinted(tint, roughness);
            board.grain = grain;
            board.dust = dust;
            board.scratches = scratches;
        }
    }
}

impl DistractorFamily {
    fn apply(
        &self,
        scene: &mut SampledScene,
        models: &[PartModel],
        focus: Option<usize>,
        rng: &mut impl Rng,
    ) {
        let centre = parts_centre(scene, focus);
        // Footprint circles of the parts (and of the distractors placed so far): a distractor
        // never overlaps one, so no body interpenetrates another.
        let mut taken: Vec<(Point3<f64>, f64)> = scene
            .parts
            .iter()
            .map(|p| {
                let c = p.table_T_part.translation.vector;
                (
                    Point3::new(c.x, c.y, 0.0),
                    models[p.model].mesh.extents().norm() / 2.0,
                )
            })
            .collect();
        let n = self.count.sample(rng).round().max(0.0) as usize;
        let mut extra = Vec::with_capacity(n);
        for _ in 0..n {
            let (size, height) = (self.size.sample(rng), self.height.sample(rng));
            let cylinder = rng.random_bool(0.5);
            let aspect = if cylinder {
                1.0
            } else {
                rng.random_range(0.3..=1.0)
            };
            let mesh = if cylinder {
                TriMesh::prism(16, size, height)
            } else {
                let mut m = TriMesh::cuboid(Vector3::new(size, size * aspect, height));
                for v in &mut m.vertices {
                    v.z += height / 2.0;
                }
                m
            };
            let reach = (size * (1.0 + aspect * aspect).sqrt()) / 2.0;
            let metal = rng.random_bool(self.metal_probability);
            let grey = self.albedo.sample(rng);
            let hue = [0; 3].map(|_| rng.random_range(0.6..=1.0));
            let appearance = Appearance {
                base_color: hue.map(|h| (grey * h).clamp(0.0, 1.0)),
                metallic: if metal { 1.0 } else { 0.0 },
                roughness: self.roughness.sample(rng),
                specular: 0.04,
                anisotropy: 0.0,
            };
            let yaw = rng.random_range(0.0..std::f64::consts::TAU);
            // A free spot: up to 20 tries, else the distractor is left out.
            let spot = (0..20).find_map(|_| {
                let r = self.radius.sample(rng);
                let phi = rng.random_range(0.0..std::f64::consts::TAU);
                let p = Point3::new(centre.x + r * phi.cos(), centre.y + r * phi.sin(), 0.0);
                taken
                    .iter()
                    .all(|(q, rq)| (p - q).norm() > reach + rq + 0.001)
                    .then_some(p)
            });
            let (Some(p), Some(render_mesh)) = (spot, RenderMesh::new(&mesh)) else {
                continue;
            };
            taken.push((p, reach));
            extra.push(Instance::new(
                Arc::new(render_mesh),
                Isometry3::from_parts(
                    Translation3::new(p.x, p.y, 0.0),
                    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw),
                ),
                appearance,
            ));
        }
        if extra.is_empty() {
            return;
        }
        // The parts keep their instance numbers (their mask ids); the distractors come after.
        let r = &scene.render;
        let mut instances = r.instances.clone();
        instances.extend(extra);
        let mut render = RenderScene::new(
            instances,
            r.board.clone(),
            r.table,
            r.lights.clone(),
            r.ambient,
        );
        render.environment = r.environment.clone();
        render.backlight = r.backlight;
        render.table_texture = r.table_texture;
        scene.render = render;
    }
}

impl SensorFamily {
    fn apply(&self, scene: &mut SampledScene, rng: &mut impl Rng) -> [f64; 3] {
        let clean =
            self.clean_probability > 0.0 && rng.random_bool(self.clean_probability.min(1.0));
        let (gain, read, shot) = if clean {
            (
                self.clean_gain,
                self.clean_read_noise,
                self.clean_shot_noise,
            )
        } else {
            (self.gain, self.read_noise, self.shot_noise)
        };
        let s = &mut scene.sensor;
        s.gain = gain.sample(rng);
        s.blur_sigma = self.blur_sigma.sample(rng);
        s.read_noise = read.sample(rng);
        s.shot_noise = shot.sample(rng);
        [
            self.white_balance.sample(rng),
            1.0,
            self.white_balance.sample(rng),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lists_name_families_and_unknown_names_are_refused() {
        assert!(Families::from_list("").unwrap().enabled().is_empty());
        assert_eq!(Families::from_list("all").unwrap().enabled(), FAMILY_NAMES);
        assert_eq!(
            Families::from_list("all,-sensor").unwrap().enabled(),
            FAMILY_NAMES[..5]
        );
        assert_eq!(
            Families::from_list("plating, textures").unwrap().enabled(),
            ["plating", "textures"]
        );
        let e = Families::from_list("lights,glare").unwrap_err().to_string();
        assert!(e.starts_with("glare: no randomisation family"), "{e}");
        assert!(Families::all().validate().is_ok());
    }

    /// A scene of one part at (10, 20) mm and nothing to render: what the light family draws
    /// around.
    fn one_part() -> SampledScene {
        SampledScene {
            parts: vec![crate::scene::PlacedPart {
                model: 0,
                table_T_part: Isometry3::translation(0.01, 0.02, 0.003),
            }],
            render: RenderScene::new(Vec::new(), None, None, Vec::new(), [0.1; 3]),
            table_T_camera: Isometry3::identity(),
            sensor: crate::render::SensorModel::default(),
            overexposure: 1.0,
        }
    }

    #[test]
    fn the_key_light_is_one_hard_light_off_the_vertical_in_a_dim_room() {
        let family = LightFamily {
            enabled: true,
            key_probability: 1.0,
            ..LightFamily::default()
        };
        let centre = Point3::new(0.01, 0.02, 0.0);
        let inside = |r: Range, x: f64| (r.lo - 1e-9..=r.hi + 1e-9).contains(&x);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for _ in 0..200 {
            let mut scene = one_part();
            family.apply(&mut scene, None, &mut rng);
            let [light] = scene.render.lights[..] else {
                panic!("{} lights", scene.render.lights.len());
            };
            let d = light.position - centre;
            let angle = (d.z / d.norm()).acos().to_degrees();
            assert!(inside(family.key_angle, angle), "{angle}°");
            assert!(inside(family.key_distance, d.norm()), "{} m", d.norm());
            assert!(inside(family.key_size, light.radius), "{}", light.radius);
            let e = light.intensity[1] / d.norm_squared();
            assert!(inside(family.key_irradiance, e), "irradiance {e}");
            let dim = scene.render.ambient[1] / e;
            assert!(inside(family.key_ambient, dim), "sky / key {dim}");
        }
    }

    #[test]
    fn the_key_light_lights_its_share_of_the_images_and_the_soft_lights_the_rest() {
        // A key of a size no soft light has, to tell the two apart.
        let family = LightFamily {
            enabled: true,
            key_size: Range::new(0.5, 0.5),
            ..LightFamily::default()
        };
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let (mut keys, mut several) = (0, 0);
        for _ in 0..400 {
            let mut scene = one_part();
            family.apply(&mut scene, None, &mut rng);
            let lights = &scene.render.lights;
            if lights.iter().any(|l| l.radius == 0.5) {
                assert_eq!(lights.len(), 1);
                keys += 1;
            } else {
                assert!(lights.iter().all(|l| l.radius <= family.size.hi));
                several += usize::from(lights.len() > 1);
            }
        }
        let share = keys as f64 / 400.0;
        assert!((share - family.key_probability).abs() < 0.06, "{share}");
        assert!(several > 100, "{several} soft draws with several lights");
    }

    #[test]
    fn key_light_options_out_of_their_domain_are_refused_by_name() {
        let mut f = Families::all();
        f.lights.key_probability = 1.5;
        let e = f.validate().unwrap_err();
        assert_eq!(e.key, "lights.key_probability");
        f.lights.key_probability = 0.3;
        f.lights.key_angle = Range::new(40.0, 95.0);
        assert_eq!(f.validate().unwrap_err().key, "lights.key_angle");
    }

    #[test]
    fn the_sensor_draws_its_clean_regime_in_its_share_of_the_images_and_the_noisy_one_else() {
        // Clean ranges no noisy draw reaches, to tell the two regimes apart.
        let family = SensorFamily {
            enabled: true,
            clean_gain: Range::new(0.5, 0.6),
            ..SensorFamily::default()
        };
        let inside = |r: Range, x: f64| (r.lo..=r.hi).contains(&x);
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let (mut clean, mut loud) = (0, 0);
        for _ in 0..1000 {
            let mut scene = one_part();
            let wb = family.apply(&mut scene, &mut rng);
            let s = scene.sensor;
            assert!(inside(family.blur_sigma, s.blur_sigma), "{s:?}");
            assert!(inside(family.white_balance, wb[0]) && inside(family.white_balance, wb[2]));
            assert_eq!(wb[1], 1.0);
            if s.gain < 1.0 {
                clean += 1;
                assert!(inside(family.clean_gain, s.gain), "{s:?}");
                assert!(inside(family.clean_read_noise, s.read_noise), "{s:?}");
                assert!(inside(family.clean_shot_noise, s.shot_noise), "{s:?}");
            } else {
                assert!(inside(family.gain, s.gain), "{s:?}");
                assert!(inside(family.read_noise, s.read_noise), "{s:?}");
                assert!(inside(family.shot_noise, s.shot_noise), "{s:?}");
                loud += usize::from(s.read_noise > 0.01);
            }
        }
        let share = clean as f64 / 1000.0;
        assert!((share - family.clean_probability).abs() < 0.045, "{share}");
        // The noisy regime keeps its whole range: half its draws above 0.01 read noise.
        assert!(
            loud > 250,
            "{loud} of {} noisy draws above 0.01",
            1000 - clean
        );
    }

    #[test]
    fn the_clean_regime_is_a_few_codes_of_noise_at_most_and_the_noisy_one_many() {
        // At the defaults and mid grey (linear 0.2, sRGB code about 124, where one code is
        // about 0.0035 linear), the clean regime's worst noise (a camera at base gain, full well
        // of 5 000 electrons or more) is under 3 codes and it reaches none at all; the noisy
        // regime's worst is over 20 codes.
        let f = SensorFamily::default();
        let sd = |gain: f64, read: f64, shot: f64| gain * (read * read + shot * 0.2).sqrt();
        let code = 0.0035;
        let clean = sd(
            f.clean_gain.hi,
            f.clean_read_noise.hi,
            f.clean_shot_noise.hi,
        );
        let noisy = sd(f.gain.hi, f.read_noise.hi, f.shot_noise.hi);
        assert!(clean < 3.0 * code, "clean regime: σ {clean}");
        assert_eq!(
            sd(
                f.clean_gain.lo,
                f.clean_read_noise.lo,
                f.clean_shot_noise.lo
            ),
            0.0
        );
        assert!(noisy > 20.0 * code, "noisy regime: σ {noisy}");
        assert!(f.clean_probability > 0.0 && f.clean_probability < 0.5);
        let mut bad = Families::all();
        bad.sensor.clean_probability = -0.1;
        assert_eq!(bad.validate().unwrap_err().key, "sensor.clean_probability");
        bad.sensor.clean_probability = 0.3;
        bad.sensor.clean_read_noise = Range::new(0.002, 0.001);
        assert_eq!(bad.validate().unwrap_err().key, "sensor.clean_read_noise");
    }

    #[test]
    fn the_key_regime_reports_its_dim_sky_and_the_soft_one_nothing() {
        let mut family = LightFamily {
            enabled: true,
            key_probability: 1.0,
            ..LightFamily::default()
        };
        let mut rng = ChaCha8Rng::seed_from_u64(6);
        for _ in 0..50 {
            let mut scene = one_part();
            let sky = family
                .apply(&mut scene, None, &mut rng)
                .expect("a key draw");
            assert_eq!(sky, scene.render.ambient[1]);
        }
        family.key_probability = 0.0;
        let mut scene = one_part();
        assert_eq!(family.apply(&mut scene, None, &mut rng), None);
    }

    #[test]
    fn a_prism_is_closed_and_stands_on_the_table() {
        let m = TriMesh::prism(16, 0.01, 0.004);
        m.check_closed().unwrap();
        let (lo, hi) = m.aabb();
        assert!(lo.z.abs() < 1e-15 && (hi.z - 0.004).abs() < 1e-15);
        assert!(m.volume() > 0.0, "outward triangles");
    }
}
