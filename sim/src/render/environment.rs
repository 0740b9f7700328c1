//! The room the cell stands in, as image-based lighting: a procedural room (walls, ceiling with
//! light panels, floor, the table around the feeder plate and the camera's own mount) baked into
//! a latitude–longitude radiance map seen from the feeder, prefiltered once per roughness level
//! for the GGX lobe (filtered importance sampling over a mip chain) and once for the cosine lobe
//! (diffuse irradiance). Shading reads the prefiltered radiance along the mirror direction and
//! weighs it by the split-sum factors of a precomputed BRDF table (Karis 2013), so a metal
//! reflects its room at the cost of a few texel reads per shading point.

use std::f64::consts::PI;
use std::sync::OnceLock;

use nalgebra::{Point3, Vector3};

use super::Appearance;

/// An emitting rectangle on the ceiling (a light panel), axis-aligned in the table frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CeilingPanel {
    /// Centre (x, y) in the table frame, metres.
    pub centre: [f64; 2],
    /// Side lengths along table x and y, metres.
    pub size: [f64; 2],
    /// Emitted radiance per linear RGB channel.
    pub radiance: [f64; 3],
}

/// The camera's own mount: a box around the camera body and a horizontal beam from it to the
/// wall (the gantry or profile that holds it), both of one dull radiance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraMount {
    /// Centre of the camera body in the table frame, metres.
    pub position: Point3<f64>,
    /// Half extents of the body box along table x, y, z, metres.
    pub half_extents: [f64; 3],
    /// Azimuth of the beam from the body to the wall, radians from table +x.
    pub beam_azimuth: f64,
    /// Half width (and half height) of the beam's square section, metres.
    pub beam_half_width: f64,
    /// Radiance of body and beam per channel.
    pub radiance: [f64; 3],
}

/// A procedural room in the table frame (z up, the feeder plate's top at z = 0), seen from a
/// point just above the plate. Radiances are linear sensor units (1 = full scale at exposure 1).
#[derive(Debug, Clone, PartialEq)]
pub struct Room {
    /// The point the room is seen from (the middle of the parts), metres.
    pub eye: Point3<f64>,
    /// Half size of the room along table x and y (walls at ± these), metres.
    pub half_size: [f64; 2],
    /// Height of the floor (negative: below the table top), metres.
    pub floor: f64,
    /// Height of the ceiling above the table top, metres.
    pub ceiling: f64,
    /// Radiance of the +x, −x, +y and −y walls at ceiling height (they darken to 60 % at the
    /// floor: the panels light them from above).
    pub walls: [[f64; 3]; 4],
    /// Radiance of the ceiling between the panels.
    pub ceiling_radiance: [f64; 3],
    /// Radiance of the floor.
    pub floor_radiance: [f64; 3],
    /// Half size of the table top around the feeder plate, metres.
    pub table_half: f64,
    /// Radiance of the table top.
    pub table_radiance: [f64; 3],
    /// Half size of the feeder plate (the board) at the table's centre, metres.
    pub plate_half: f64,
    /// Radiance of the feeder plate (lit from above, or glowing when backlit).
    pub plate_radiance: [f64; 3],
    /// Light panels on the ceiling.
    pub panels: Vec<CeilingPanel>,
    /// The camera's mount, if drawn.
    pub mount: Option<CameraMount>,
}

impl Room {
    /// Radiance arriving at [`Room::eye`] from unit direction `d`.
    pub fn radiance(&self, d: &Vector3<f64>) -> [f64; 3] {
        self.radiance_with(self.beam_frame(), d)
    }

    /// The sine and cosine of the mount's beam azimuth (0 and 1 without a mount) and the beam's
    /// length, which [`Room::radiance_with`] takes so that a bake computes them once, not per
    /// direction.
    fn beam_frame(&self) -> (f64, f64, f64) {
        let (s, c) = self
            .mount
            .as_ref()
            .map_or((0.0, 1.0), |m| m.beam_azimuth.sin_cos());
        (s, c, self.half_size[0].hypot(self.half_size[1]) * 2.0)
    }

    /// [`Room::radiance`] with the beam's [`Room::beam_frame`] given.
    fn radiance_with(&self, beam: (f64, f64, f64), d: &Vector3<f64>) -> [f64; 3] {
        let o = self.eye;
        if let Some(m) = &self.mount
            && mount_hit(m, &o, d, beam)
        {
            return m.radiance;
        }
        if d.z < 0.0 {
            let t = -o.z / d.z;
            let p = o + d * t;
            if p.x.abs() <= self.plate_half && p.y.abs() <= self.plate_half {
                return self.plate_radiance;
            }
            if p.x.abs() <= self.table_half && p.y.abs() <= self.table_half {
                return self.table_radiance;
            }
        }
        // The room's shell: the nearest of ceiling or floor and the four walls.
        let mut best = (f64::INFINITY, 0usize);
        if d.z > 1e-12 {
            best = ((self.ceiling - o.z) / d.z, 4);
        } else if d.z < -1e-12 {
            best = ((self.floor - o.z) / d.z, 5);
        }
        for (axis, sides) in [(0usize, [0usize, 1]), (1, [2, 3])] {
            let (dc, oc) = (d[axis], o[axis]);
            if dc.abs() > 1e-12 {
                let (wall, side) = if dc > 0.0 {
                    (self.half_size[axis], sides[0])
                } else {
                    (-self.half_size[axis], sides[1])
                };
                let t = (wall - oc) / dc;
                if t < best.0 {
                    best = (t, side);
                }
            }
        }
        let p = o + d * best.0;
        match best.1 {
            4 => {
                for panel in &self.panels {
                    if (p.x - panel.centre[0]).abs() <= panel.size[0] / 2.0
                        && (p.y - panel.centre[1]).abs() <= panel.size[1] / 2.0
                    {
                        return panel.radiance;
                    }
                }
                self.ceiling_radiance
            }
            5 => self.floor_radiance,
            side => {
                let h = ((p.z - self.floor) / (self.ceiling - self.floor)).clamp(0.0, 1.0);
                let k = 0.6 + 0.4 * h;
                self.walls[side].map(|c| c * k)
            }
        }
    }
}

/// Whether the ray from `o` along `d` hits the camera body or its beam (`beam`: the sine and
/// cosine of its azimuth and its length).
fn mount_hit(m: &CameraMount, o: &Point3<f64>, d: &Vector3<f64>, beam: (f64, f64, f64)) -> bool {
    let c = m.position;
    let e = m.half_extents;
    if ray_box(
        o,
        d,
        [c.x - e[0], c.y - e[1], c.z - e[2]],
        [c.x + e[0], c.y + e[1], c.z + e[2]],
    ) {
        return true;
    }
    // The beam: a square bar from the body to the wall along its azimuth, tested in the bar's
    // own frame (rotated about z).
    let (s, co, length) = beam;
    let rot = |v: Vector3<f64>| Vector3::new(co * v.x + s * v.y, -s * v.x + co * v.y, v.z);
    let ol = rot(o - c);
    let dl = rot(*d);
    let w = m.beam_half_width;
    ray_box(
        &Point3::from(ol),
        &dl,
        [0.0, -w, e[2] - w],
        [length, w, e[2] + w],
    )
}

/// Whether a ray (from outside the box) enters the axis-aligned box [lo, hi] ahead of `o`.
fn ray_box(o: &Point3<f64>, d: &Vector3<f64>, lo: [f64; 3], hi: [f64; 3]) -> bool {
    let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
    for k in 0..3 {
        if d[k].abs() < 1e-15 {
            if o[k] < lo[k] || o[k] > hi[k] {
                return false;
            }
            continue;
        }
        let (a, b) = ((lo[k] - o[k]) / d[k], (hi[k] - o[k]) / d[k]);
        t0 = t0.max(a.min(b));
        t1 = t1.min(a.max(b));
    }
    t0 <= t1
}

/// A latitude–longitude map: texel (i, j) holds the radiance around polar angle
/// θ = (j + ½) π / h from table +z and azimuth φ = (i + ½) 2π / w from +x.
#[derive(Debug, Clone)]
struct LatLong {
    w: usize,
    h: usize,
    texels: Vec<[f32; 3]>,
}

impl LatLong {
    /// The map of `f` at `w` × `h`, each texel the mean of `ss` × `ss` directions over it.
    fn bake(w: usize, h: usize, ss: usize, f: &(dyn Fn(&Vector3<f64>) -> [f64; 3] + Sync)) -> Self {
        let mut texels = vec![[0f32; 3]; w * h];
        // The sub-sample directions' azimuths and polar angles, once per column and row (the
        // values `direction` computes).
        let columns: Vec<(f64, f64)> = (0..w * ss)
            .map(|c| {
                let (i, sx) = (c / ss, c % ss);
                let phi = (i as f64 + (sx as f64 + 0.5) / ss as f64) / w as f64 * 2.0 * PI;
                (phi.cos(), phi.sin())
            })
            .collect();
        let rows: Vec<(f64, f64)> = (0..h * ss)
            .map(|r| {
                let (j, sy) = (r / ss, r % ss);
                let theta = (j as f64 + (sy as f64 + 0.5) / ss as f64) / h as f64 * PI;
                (theta.sin(), theta.cos())
            })
            .collect();
        for (k, t) in texels.iter_mut().enumerate() {
            let (i, j) = (k % w, k / w);
            let mut acc = [0.0; 3];
            for sy in 0..ss {
                let (s, z) = rows[j * ss + sy];
                for sx in 0..ss {
                    let (cp, sp) = columns[i * ss + sx];
                    let c = f(&Vector3::new(s * cp, s * sp, z));
                    for ch in 0..3 {
                        acc[ch] += c[ch];
                    }
                }
            }
            let m = 1.0 / (ss * ss) as f64;
            *t = [
                (acc[0] * m) as f32,
                (acc[1] * m) as f32,
                (acc[2] * m) as f32,
            ];
        }
        Self { w, h, texels }
    }

    /// The map at half resolution (2 × 2 boxes, weighted by their rows' solid angle).
    fn half(&self) -> Self {
        let (w, h) = ((self.w / 2).max(1), (self.h / 2).max(1));
        let mut texels = vec![[0f32; 3]; w * h];
        for j in 0..h {
            for i in 0..w {
                let mut acc = [0f64; 3];
                let mut wsum = 0.0;
                for dj in 0..2 {
                    let sj = (2 * j + dj).min(self.h - 1);
                    let weight = ((sj as f64 + 0.5) * PI / self.h as f64).sin().max(1e-6);
                    for di in 0..2 {
                        let si = (2 * i + di) % self.w;
                        let t = self.texels[sj * self.w + si];
                        for ch in 0..3 {
                            acc[ch] += weight * t[ch] as f64;
                        }
                        wsum += weight;
                    }
                }
                texels[j * w + i] = [
                    (acc[0] / wsum) as f32,
                    (acc[1] / wsum) as f32,
                    (acc[2] / wsum) as f32,
                ];
            }
        }
        Self { w, h, texels }
    }

    /// Bilinear lookup along unit direction `d` (wrapping in azimuth, clamped at the poles).
    fn lookup(&self, d: &Vector3<f64>) -> [f64; 3] {
        let (u, v) = lat_long(d);
        self.lookup_uv(u, v)
    }

    /// Bilinear lookup at map coordinates (u, v); u wraps (any u ≥ 0 is taken modulo 1).
    fn lookup_uv(&self, u: f64, v: f64) -> [f64; 3] {
        let (i0, i1, j0, j1, fx, fy) = self.corners(u, v);
        let (r0, r1) = (j0 * self.w, j1 * self.w);
        let (t00, t10) = (self.texels[r0 + i0], self.texels[r0 + i1]);
        let (t01, t11) = (self.texels[r1 + i0], self.texels[r1 + i1]);
        let mut out = [0.0; 3];
        for (ch, o) in out.iter_mut().enumerate() {
            let a = t00[ch] as f64 * (1.0 - fx) + t10[ch] as f64 * fx;
            let b = t01[ch] as f64 * (1.0 - fx) + t11[ch] as f64 * fx;
            *o = a * (1.0 - fy) + b * fy;
        }
        out
    }

    /// The texels a bilinear lookup at (u, v) reads, as (column, next column, row, next row) and
    /// the fractions (fx, fy) of the next ones.
    fn corners(&self, u: f64, v: f64) -> (usize, usize, usize, usize, f64, f64) {
        let x = u * self.w as f64 - 0.5;
        let y = (v * self.h as f64 - 0.5).clamp(0.0, (self.h - 1) as f64);
        let (xi, yi) = (floor(x), floor(y));
        let (fx, fy) = (x - xi as f64, y - yi as f64);
        let w = self.w as i64;
        // u is within [0, 2) here (a direction's, or one shifted by less than a turn).
        let i0 = if (0..w).contains(&xi) {
            xi
        } else if (-w..0).contains(&xi) {
            xi + w
        } else if (w..2 * w).contains(&xi) {
            xi - w
        } else {
            xi.rem_euclid(w)
        } as usize;
        let i1 = if i0 + 1 == self.w { 0 } else { i0 + 1 };
        let j0 = yi as usize;
        let j1 = (j0 + 1).min(self.h - 1);
        (i0, i1, j0, j1, fx, fy)
    }
}

/// ⌊x⌋ as an integer, for |x| well within i64 (NaN gives 0): without SSE4.1 `f64::floor` is a
/// library call, and the lookups take two each.
fn floor(x: f64) -> i64 {
    let i = x as i64;
    if (i as f64) > x { i - 1 } else { i }
}

/// The unit direction at map coordinates (u, v) in [0, 1]².
fn direction(u: f64, v: f64) -> Vector3<f64> {
    let (phi, theta) = (u * 2.0 * PI, v * PI);
    let s = theta.sin();
    Vector3::new(s * phi.cos(), s * phi.sin(), theta.cos())
}

/// Map coordinates (u, v) of a unit direction.
fn lat_long(d: &Vector3<f64>) -> (f64, f64) {
    // atan2 is within [-π, π], so this is `rem_euclid(2π)` without its library `fmod` call.
    let phi = d.y.atan2(d.x);
    let phi = if phi < 0.0 { phi + 2.0 * PI } else { phi };
    let theta = d.z.clamp(-1.0, 1.0).acos();
    (phi / (2.0 * PI), theta / PI)
}

/// Roughness of each prefiltered level (the last is the roughest the shading model takes).
const LEVEL_ROUGHNESS: [f64; 7] = [0.0, 0.1, 0.2, 0.3, 0.45, 0.65, 1.0];
/// Width of the base map (height is half); level k > 0 is stored at `LEVEL_WIDTH[k]`.
const LEVEL_WIDTH: [usize; 7] = [256, 128, 64, 64, 32, 32, 16];
/// GGX samples per texel when prefiltering.
const PREFILTER_SAMPLES: usize = 48;

/// A baked, prefiltered environment: what [`Room`] (or any radiance function) sends to a point
/// of the feeder from every direction, ready for shading.
#[derive(Debug, Clone)]
pub struct Environment {
    /// Prefiltered radiance per level of [`LEVEL_ROUGHNESS`].
    levels: Vec<LatLong>,
    /// Cosine-weighted mean radiance around each normal (irradiance / π).
    irradiance: LatLong,
    /// The irradiance map's value straight up (the table's and the plate's normal), read once.
    irradiance_up: [f64; 3],
}

impl Environment {
    /// Bakes a room.
    pub fn from_room(room: &Room) -> Self {
        let beam = room.beam_frame();
        Self::bake(&|d| room.radiance_with(beam, d))
    }

    /// A uniform environment of radiance `l` (the analytic case: every level and the irradiance
    /// are `l` exactly).
    pub fn uniform(l: [f64; 3]) -> Self {
        Self::bake(&move |_| l)
    }

    /// Bakes any radiance function of direction (table frame).
    pub fn bake(f: &(dyn Fn(&Vector3<f64>) -> [f64; 3] + Sync)) -> Self {
        let mips = mip_chain(LatLong::bake(LEVEL_WIDTH[0], LEVEL_WIDTH[0] / 2, 2, f));
        let mut levels = vec![mips[0].clone()];
        for k in 1..LEVEL_ROUGHNESS.len() {
            levels.push(prefilter(&mips, LEVEL_ROUGHNESS[k], LEVEL_WIDTH[k]));
        }
        Self::new(levels, cosine_filter(&mips, 16))
    }

    /// The environment of these levels and irradiance map.
    fn new(levels: Vec<LatLong>, irradiance: LatLong) -> Self {
        let irradiance_up = irradiance.lookup(&Vector3::z());
        Self {
            levels,
            irradiance,
            irradiance_up,
        }
    }

    /// This environment with every radiance times `k` per channel (the room with its lights
    /// dimmed): prefiltering is linear, so it is the bake of the scaled radiance function.
    pub fn scaled(&self, k: [f64; 3]) -> Self {
        let scale = |m: &LatLong| LatLong {
            w: m.w,
            h: m.h,
            texels: m
                .texels
                .iter()
                .map(|t| [0, 1, 2].map(|c| (t[c] as f64 * k[c]) as f32))
                .collect(),
        };
        Self::new(
            self.levels.iter().map(scale).collect(),
            scale(&self.irradiance),
        )
    }

    /// Prefiltered radiance along unit direction `r` for a lobe of `roughness` (linear between
    /// the two nearest levels).
    pub fn specular(&self, r: &Vector3<f64>, roughness: f64) -> [f64; 3] {
        let rough = roughness.clamp(0.0, 1.0);
        let k = LEVEL_ROUGHNESS
            .iter()
            .rposition(|x| *x <= rough)
            .unwrap_or(0)
            .min(LEVEL_ROUGHNESS.len() - 2);
        let f = ((rough - LEVEL_ROUGHNESS[k]) / (LEVEL_ROUGHNESS[k + 1] - LEVEL_ROUGHNESS[k]))
            .clamp(0.0, 1.0);
        // One direction for both levels: its map coordinates once.
        let (u, v) = lat_long(r);
        let a = self.levels[k].lookup_uv(u, v);
        if f <= 0.0 {
            return a;
        }
        let b = self.levels[k + 1].lookup_uv(u, v);
        [0, 1, 2].map(|c| a[c] * (1.0 - f) + b[c] * f)
    }

    /// Cosine-weighted mean radiance over the hemisphere around unit normal `n` (irradiance / π).
    pub fn irradiance(&self, n: &Vector3<f64>) -> [f64; 3] {
        if n.x == 0.0 && n.y == 0.0 && n.z == 1.0 {
            return self.irradiance_up;
        }
        self.irradiance.lookup(n)
    }

    /// Radiance reflected towards `v` by a surface of appearance `a` with unit normal `n`: the
    /// diffuse lobe under the irradiance, and the specular lobe as prefiltered radiance along the
    /// mirror direction times the split-sum directional albedo; the diffuse share is what the
    /// specular lobe leaves, so a white surface under a uniform environment returns it.
    pub fn shade(&self, a: &Appearance, n: &Vector3<f64>, v: &Vector3<f64>) -> [f64; 3] {
        let nv = n.dot(v).clamp(1e-4, 1.0);
        let r = n * (2.0 * nv) - v;
        let (scale, bias) = brdf_lut(a.roughness, nv);
        let spec = self.specular(&r, a.roughness);
        let irr = self.irradiance(n);
        [0, 1, 2].map(|c| {
            let f0 = a.specular * (1.0 - a.metallic) + a.base_color[c] * a.metallic;
            let albedo = f0 * scale + bias;
            let diffuse = (1.0 - a.metallic) * a.base_color[c] * (1.0 - albedo);
            diffuse * irr[c] + albedo * spec[c]
        })
    }
}

/// One sample of a prefiltered lobe: map coordinates (u, v), mip level and cosine weight.
type Tap = (f64, f64, (usize, f64), f64);

/// `base` and its halvings down to one row: the mip levels the prefilter reads.
fn mip_chain(base: LatLong) -> Vec<LatLong> {
    let mut mips = vec![base];
    while let Some(next) = mips.last().filter(|m| m.h > 1).map(LatLong::half) {
        mips.push(next);
    }
    mips
}

/// One level of GGX-prefiltered radiance at `w` × `w/2`, each texel the lobe around its direction
/// (n = v = r), sampled by filtered importance sampling over `mips`.
fn prefilter(mips: &[LatLong], roughness: f64, w: usize) -> LatLong {
    let alpha = (roughness * roughness).max(1e-4);
    let a2 = alpha * alpha;
    let base_texel = 4.0 * PI / (mips[0].w * mips[0].h) as f64;
    // Sample half vectors about +z once; each texel rotates them onto its direction.
    let samples: Vec<(Vector3<f64>, f64)> = (0..PREFILTER_SAMPLES)
        .map(|i| {
            let (u1, u2) = hammersley(i, PREFILTER_SAMPLES);
            let cos_t = ((1.0 - u1) / (1.0 + (a2 - 1.0) * u1)).sqrt();
            let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
            let phi = 2.0 * PI * u2;
            let h = Vector3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t);
            let dd = cos_t * cos_t * (a2 - 1.0) + 1.0;
            let d = a2 / (PI * dd * dd);
            // pdf of l = pdf of h / (4 v·h); with n = v, v·h = n·h: D n·h / (4 n·h) = D / 4.
            let pdf = d / 4.0;
            let lod = (0.5 * (1.0 / (PREFILTER_SAMPLES as f64 * pdf) / base_texel).log2() + 1.0)
                .clamp(0.0, (mips.len() - 1) as f64);
            (h, lod)
        })
        .collect();
    // The lobe's taps around `n`: map coordinates, mip level and cosine weight of each sample.
    let taps = |n: &Vector3<f64>| -> Vec<Tap> {
        let (t, b) = frame(n);
        samples
            .iter()
            .filter_map(|(h, lod)| {
                let hw = t * h.x + b * h.y + n * h.z;
                let l = hw * (2.0 * n.dot(&hw)) - n;
                let nl = n.dot(&l);
                (nl > 0.0).then(|| {
                    let (u, v) = lat_long(&l);
                    (u, v, mip_level(mips, *lod), nl)
                })
            })
            .collect()
    };
    let filter = |taps: &[Tap], du: f64| {
        let mut acc = [0.0; 3];
        let mut wsum = 0.0;
        for &(u, v, lod, nl) in taps {
            let c = mip_lookup(mips, u + du, v, lod);
            for ch in 0..3 {
                acc[ch] += c[ch] * nl;
            }
            wsum += nl;
        }
        let m = 1.0 / wsum.max(1e-12);
        acc.map(|x| (x * m) as f32)
    };
    let h = w / 2;
    let mut texels = Vec::with_capacity(w * h);
    for j in 0..h {
        let v = (j as f64 + 0.5) / h as f64;
        let first = direction(0.5 / w as f64, v);
        if first.z.abs() < 0.9 {
            // Away from the poles `frame` turns with the azimuth, so every texel of the row sees
            // the first one's lobe turned about z: the same taps, shifted in u by i / w.
            let row = taps(&first);
            match RowKernel::new(mips, &row, w) {
                Some(kernel) => texels.extend(kernel.apply(mips)),
                None => texels.extend((0..w).map(|i| filter(&row, i as f64 / w as f64))),
            }
        } else {
            texels.extend(
                (0..w).map(|i| filter(&taps(&direction((i as f64 + 0.5) / w as f64, v)), 0.0)),
            );
        }
    }
    LatLong { w, h, texels }
}

/// The most kernels a [`RowKernel`] builds for a row (each costs a sort of the lobe's taps).
const MAX_PHASES: usize = 4;

/// The mip texels one row of a prefiltered level reads, with their weights: the lobe's taps
/// merged (a narrow lobe's 48 samples fall on a few texels). Texel i of the row reads what
/// texel i mod `period` reads, turned by whole texels of each mip: its taps are shifted by
/// i / w in u, a whole number of texels of every mip at least `w / period` wide. Taps on mips
/// coarser than `w / MAX_PHASES` (a lobe's far tail) are read for each texel instead.
struct RowKernel {
    /// Texels of the row.
    w: usize,
    /// Texels after which the kernels repeat, turned.
    period: usize,
    /// Per phase (texel i mod `period`): (mip, row start, column, weight), merged.
    phases: Vec<Vec<(usize, usize, usize, f64)>>,
    /// Taps on coarse mips, their weights normalised.
    coarse: Vec<Tap>,
}

impl RowKernel {
    /// The kernels of a row of `w` texels whose first texel's lobe has taps `taps`; `None` for
    /// widths that are not powers of two.
    fn new(mips: &[LatLong], taps: &[Tap], w: usize) -> Option<Self> {
        if !w.is_power_of_two() || mips.iter().any(|m| !m.w.is_power_of_two()) {
            return None;
        }
        let wsum: f64 = taps.iter().map(|t| t.3).sum();
        let norm = 1.0 / wsum.max(1e-12);
        // The narrowest mip a tap reads (the next level's when it blends in).
        let narrowest = |&(_, _, (k, f), _): &Tap| {
            let k = if f > 0.0 { k + 1 } else { k };
            mips[k.min(mips.len() - 1)].w
        };
        let least = (w / MAX_PHASES).max(1);
        let (fine, coarse): (Vec<Tap>, Vec<Tap>) = taps.iter().partition(|t| narrowest(t) >= least);
        let period = fine
            .iter()
            .map(|t| w / narrowest(t).min(w))
            .max()
            .unwrap_or(1);
        let phases = (0..period)
            .map(|p| {
                let du = p as f64 / w as f64;
                // (mip << 40 | texel index, weight): one integer key to sort on.
                let mut e: Vec<(u64, f64)> = Vec::with_capacity(fine.len() * 8);
                for &(u, v, (k, f), nl) in &fine {
                    let levels: &[(usize, f64)] = if f <= 0.0 || k + 1 >= mips.len() {
                        &[(k, 1.0)]
                    } else {
                        &[(k, 1.0 - f), (k + 1, f)]
                    };
                    for &(m, lw) in levels {
                        let map = &mips[m];
                        let (i0, i1, j0, j1, fx, fy) = map.corners(u + du, v);
                        let wt = nl * norm * lw;
                        for (j, wy) in [(j0, 1.0 - fy), (j1, fy)] {
                            for (i, wx) in [(i0, 1.0 - fx), (i1, fx)] {
                                e.push((((m as u64) << 40) | (j * map.w + i) as u64, wt * wx * wy));
                            }
                        }
                    }
                }
                e.sort_unstable_by_key(|x| x.0);
                let mut merged: Vec<(u64, f64)> = Vec::with_capacity(e.len());
                for x in e {
                    match merged.last_mut() {
                        Some(last) if last.0 == x.0 => last.1 += x.1,
                        _ => merged.push(x),
                    }
                }
                merged
                    .into_iter()
                    .map(|(key, wt)| {
                        let (m, k) = ((key >> 40) as usize, (key & ((1 << 40) - 1)) as usize);
                        let w = mips[m].w;
                        (m, k - k % w, k % w, wt)
                    })
                    .collect()
            })
            .collect();
        let coarse = coarse
            .into_iter()
            .map(|(u, v, lod, nl)| (u, v, lod, nl * norm))
            .collect();
        Some(Self {
            w,
            period,
            phases,
            coarse,
        })
    }

    /// The row's texels.
    fn apply<'a>(&'a self, mips: &'a [LatLong]) -> impl Iterator<Item = [f32; 3]> + 'a {
        (0..self.w).map(move |i| {
            let (q, p) = (i / self.period, i % self.period);
            let mut acc = [0.0; 3];
            for &(m, row, col, wt) in &self.phases[p] {
                let map = &mips[m];
                // A turn of q periods is q · period · (mip width / w) whole texels.
                let shift = q * self.period * map.w / self.w;
                let t = map.texels[row + (col + shift) % map.w];
                for ch in 0..3 {
                    acc[ch] += t[ch] as f64 * wt;
                }
            }
            let du = i as f64 / self.w as f64;
            for &(u, v, lod, wt) in &self.coarse {
                let c = mip_lookup(mips, u + du, v, lod);
                for ch in 0..3 {
                    acc[ch] += c[ch] * wt;
                }
            }
            acc.map(|x| x as f32)
        })
    }
}

/// Cosine-weighted mean radiance around each direction at `w` × `w/2`, summed over a coarse mip
/// level's texels with their solid angles.
fn cosine_filter(mips: &[LatLong], w: usize) -> LatLong {
    let src = mips
        .iter()
        .find(|m| m.w <= 32)
        .unwrap_or(&mips[mips.len() - 1]);
    let texels: Vec<(Vector3<f64>, f64, [f32; 3])> = (0..src.w * src.h)
        .map(|k| {
            let (i, j) = (k % src.w, k / src.w);
            let d = direction(
                (i as f64 + 0.5) / src.w as f64,
                (j as f64 + 0.5) / src.h as f64,
            );
            let solid = (2.0 * PI / src.w as f64)
                * (((j as f64) * PI / src.h as f64).cos()
                    - ((j as f64 + 1.0) * PI / src.h as f64).cos());
            (d, solid, src.texels[k])
        })
        .collect();
    LatLong::bake(w, w / 2, 1, &|n| {
        let mut acc = [0.0; 3];
        let mut wsum = 0.0;
        for (d, solid, c) in &texels {
            let cos = n.dot(d);
            if cos <= 0.0 {
                continue;
            }
            let wgt = cos * solid;
            for ch in 0..3 {
                acc[ch] += c[ch] as f64 * wgt;
            }
            wsum += wgt;
        }
        acc.map(|x| x / wsum.max(1e-12))
    })
}

/// A fractional mip level as (level, weight of the next level).
fn mip_level(mips: &[LatLong], lod: f64) -> (usize, f64) {
    let k = (floor(lod).max(0) as usize).min(mips.len() - 1);
    (k, lod - k as f64)
}

/// Trilinear lookup in a mip chain at a fractional level ([`mip_level`]), at map coordinates
/// (u, v).
fn mip_lookup(mips: &[LatLong], u: f64, v: f64, (k, f): (usize, f64)) -> [f64; 3] {
    let a = mips[k].lookup_uv(u, v);
    if f <= 0.0 || k + 1 >= mips.len() {
        return a;
    }
    let b = mips[k + 1].lookup_uv(u, v);
    [0, 1, 2].map(|c| a[c] * (1.0 - f) + b[c] * f)
}

/// Two unit vectors completing unit `n` to an orthonormal frame.
fn frame(n: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let up = if n.z.abs() < 0.9 {
        Vector3::z()
    } else {
        Vector3::x()
    };
    let t = up.cross(n).normalize();
    (t, n.cross(&t))
}

/// The i-th of n points of the Hammersley set in [0, 1)².
fn hammersley(i: usize, n: usize) -> (f64, f64) {
    let bits = (i as u32).reverse_bits();
    ((i as f64 + 0.5) / n as f64, bits as f64 / 4_294_967_296.0)
}

/// Sides of the split-sum table (roughness × n·v).
const LUT_SIZE: usize = 32;
/// GGX samples per entry of the split-sum table.
const LUT_SAMPLES: usize = 1024;

/// The split-sum directional albedo of the specular lobe as (scale, bias) with
/// albedo = F0 · scale + bias, for `roughness` and n·v: the GGX lobe with Smith height-correlated
/// masking and Schlick's Fresnel (the model `shading::brdf_cos` evaluates), integrated once by
/// importance sampling and read bilinearly.
pub(crate) fn brdf_lut(roughness: f64, nv: f64) -> (f64, f64) {
    static LUT: OnceLock<Vec<(f64, f64)>> = OnceLock::new();
    let lut = LUT.get_or_init(|| {
        let mut t = Vec::with_capacity(LUT_SIZE * LUT_SIZE);
        for j in 0..LUT_SIZE {
            for i in 0..LUT_SIZE {
                let r = j as f64 / (LUT_SIZE - 1) as f64;
                let nv = (i as f64 / (LUT_SIZE - 1) as f64).max(1e-3);
                t.push(integrate_brdf(r, nv, LUT_SAMPLES));
            }
        }
        t
    });
    let x = (nv.clamp(0.0, 1.0) * (LUT_SIZE - 1) as f64).min((LUT_SIZE - 1) as f64 - 1e-9);
    let y = (roughness.clamp(0.0, 1.0) * (LUT_SIZE - 1) as f64).min((LUT_SIZE - 1) as f64 - 1e-9);
    let (i, j) = (x.floor() as usize, y.floor() as usize);
    let (fx, fy) = (x - i as f64, y - j as f64);
    let e = |i: usize, j: usize| lut[j * LUT_SIZE + i];
    let mix = |a: (f64, f64), b: (f64, f64), f: f64| (a.0 + (b.0 - a.0) * f, a.1 + (b.1 - a.1) * f);
    mix(
        mix(e(i, j), e(i + 1, j), fx),
        mix(e(i, j + 1), e(i + 1, j + 1), fx),
        fy,
    )
}

/// (scale, bias) of the specular directional albedo at (roughness, n·v), `n` GGX samples.
pub(crate) fn integrate_brdf(roughness: f64, nv: f64, n: usize) -> (f64, f64) {
    let alpha = (roughness * roughness).max(1e-4);
    let a2 = alpha * alpha;
    let v = Vector3::new((1.0 - nv * nv).max(0.0).sqrt(), 0.0, nv);
    let (mut scale, mut bias) = (0.0, 0.0);
    for i in 0..n {
        let (u1, u2) = hammersley(i, n);
        let cos_t = ((1.0 - u1) / (1.0 + (a2 - 1.0) * u1)).sqrt();
        let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
        let phi = 2.0 * PI * u2;
        let h = Vector3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t);
        let vh = v.dot(&h);
        let l = h * (2.0 * vh) - v;
        let (nl, nh) = (l.z, h.z);
        if nl <= 0.0 || vh <= 0.0 {
            continue;
        }
        // brdf · cos / pdf with pdf = D n·h / (4 v·h): 4 · Vis · n·l · v·h / n·h.
        let lambda_v = nl * (nv * nv * (1.0 - a2) + a2).sqrt();
        let lambda_l = nv * (nl * nl * (1.0 - a2) + a2).sqrt();
        let vis = 0.5 / (lambda_v + lambda_l).max(1e-12);
        let g = 4.0 * vis * nl * vh / nh;
        let fc = (1.0 - vh).powi(5);
        scale += (1.0 - fc) * g;
        bias += fc * g;
    }
    (scale / n as f64, bias / n as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mirror(f0: f64, roughness: f64) -> Appearance {
        Appearance {
            base_color: [f0; 3],
            metallic: 1.0,
            roughness,
            specular: 0.04,
            anisotropy: 0.0,
        }
    }

    /// The prefilter's shortcuts (a row's taps shared and merged into kernels) give what
    /// filtering every texel on its own gives, in a room with sharp panels and a mount.
    #[test]
    fn the_row_kernels_filter_as_each_texel_alone() {
        let room = Room {
            eye: Point3::new(0.01, -0.02, 0.005),
            half_size: [2.0, 3.0],
            floor: -0.9,
            ceiling: 2.5,
            walls: [[0.2; 3], [0.3, 0.2, 0.1], [0.4; 3], [0.5; 3]],
            ceiling_radiance: [0.1; 3],
            floor_radiance: [0.05; 3],
            table_half: 0.5,
            table_radiance: [0.07; 3],
            plate_half: 0.1,
            plate_radiance: [0.6; 3],
            panels: vec![
                CeilingPanel {
                    centre: [0.3, 0.1],
                    size: [0.6, 0.3],
                    radiance: [5.0, 4.0, 3.0],
                },
                CeilingPanel {
                    centre: [-1.0, 1.5],
                    size: [0.2, 1.2],
                    radiance: [2.0; 3],
                },
            ],
            mount: Some(CameraMount {
                position: Point3::new(0.1, 0.0, 1.5),
                half_extents: [0.04, 0.04, 0.06],
                beam_azimuth: 1.0,
                beam_half_width: 0.02,
                radiance: [0.01; 3],
            }),
        };
        let mips = mip_chain(LatLong::bake(LEVEL_WIDTH[0], LEVEL_WIDTH[0] / 2, 2, &|d| {
            room.radiance(d)
        }));
        let base_texel = 4.0 * PI / (mips[0].w * mips[0].h) as f64;
        for k in 1..LEVEL_ROUGHNESS.len() {
            let (r, w) = (LEVEL_ROUGHNESS[k], LEVEL_WIDTH[k]);
            let fast = prefilter(&mips, r, w);
            let a2 = (r * r).max(1e-4).powi(2);
            // Every texel alone: its own frame, its own 48 directions.
            let slow = LatLong::bake(w, w / 2, 1, &|n| {
                let (t, b) = frame(n);
                let (mut acc, mut wsum) = ([0.0; 3], 0.0);
                for i in 0..PREFILTER_SAMPLES {
                    let (u1, u2) = hammersley(i, PREFILTER_SAMPLES);
                    let cos_t = ((1.0 - u1) / (1.0 + (a2 - 1.0) * u1)).sqrt();
                    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
                    let phi = 2.0 * PI * u2;
                    let h = Vector3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t);
                    let dd = cos_t * cos_t * (a2 - 1.0) + 1.0;
                    let pdf = a2 / (PI * dd * dd) / 4.0;
                    let lod = (0.5 * (1.0 / (PREFILTER_SAMPLES as f64 * pdf) / base_texel).log2()
                        + 1.0)
                        .clamp(0.0, (mips.len() - 1) as f64);
                    let hw = t * h.x + b * h.y + n * h.z;
                    let l = hw * (2.0 * n.dot(&hw)) - n;
                    let nl = n.dot(&l);
                    if nl <= 0.0 {
                        continue;
                    }
                    let (u, v) = lat_long(&l);
                    let c = mip_lookup(&mips, u, v, mip_level(&mips, lod));
                    for ch in 0..3 {
                        acc[ch] += c[ch] * nl;
                    }
                    wsum += nl;
                }
                acc.map(|x| x / wsum)
            });
            for (i, (a, b)) in fast.texels.iter().zip(&slow.texels).enumerate() {
                for c in 0..3 {
                    assert!(
                        (a[c] - b[c]).abs() <= 1e-5 * (1.0 + b[c].abs()),
                        "level {k}, texel {i}: {a:?} against {b:?}"
                    );
                }
            }
        }
    }

    /// A uniform environment stays uniform through every prefiltered level and the irradiance.
    #[test]
    fn a_uniform_environment_is_uniform_at_every_level() {
        let env = Environment::uniform([0.3, 0.5, 0.7]);
        for k in 0..30 {
            let d = direction((k as f64 * 0.37).fract(), (k as f64 * 0.61).fract()).normalize();
            for r in [0.0, 0.05, 0.2, 0.35, 0.7, 1.0] {
                let s = env.specular(&d, r);
                for (c, want) in [0.3, 0.5, 0.7].iter().enumerate() {
                    assert!((s[c] - want).abs() < 1e-5, "level {r}: {s:?}");
                }
            }
            let e = env.irradiance(&d);
            assert!((e[1] - 0.5).abs() < 1e-5, "irradiance {e:?}");
        }
    }

    /// A scaled environment is the bake of the scaled radiance: every level and the irradiance,
    /// per channel, in a room that is not uniform (a bright patch over a dim sky).
    #[test]
    fn a_scaled_environment_is_the_scaled_room_baked() {
        let f = |d: &Vector3<f64>| {
            if d.z > 0.8 {
                [4.0, 3.0, 2.0]
            } else if d.z > 0.0 {
                [0.2, 0.25, 0.3]
            } else {
                [0.05; 3]
            }
        };
        let k = [0.03, 0.05, 0.5];
        let dim = Environment::bake(&f).scaled(k);
        let baked = Environment::bake(&move |d| {
            let l = f(d);
            [0, 1, 2].map(|c| l[c] * k[c])
        });
        for i in 0..40 {
            let d = direction((i as f64 * 0.37).fract(), (i as f64 * 0.61).fract()).normalize();
            for r in [0.0, 0.15, 0.35, 0.7, 1.0] {
                let (a, b) = (dim.specular(&d, r), baked.specular(&d, r));
                for c in 0..3 {
                    assert!(
                        (a[c] - b[c]).abs() <= 1e-5 * (1.0 + b[c]),
                        "{r}: {a:?} {b:?}"
                    );
                }
            }
            let (a, b) = (dim.irradiance(&d), baked.irradiance(&d));
            for c in 0..3 {
                assert!((a[c] - b[c]).abs() <= 1e-5 * (1.0 + b[c]), "{a:?} {b:?}");
            }
        }
        let up = dim.irradiance(&Vector3::z());
        assert!(up[0] > 0.01 && up[2] > 5.0 * up[1], "{up:?}");
    }

    /// White furnace: under a uniform environment of radiance 1, a white Lambertian surface, a
    /// white dielectric and a white (F0 = 1) metal reflect at most 1 at every roughness and
    /// angle; the diffuse ones exactly 1, a mirror-smooth white metal 1, and a rough one loses
    /// only what single scattering loses.
    #[test]
    fn white_furnace() {
        let env = Environment::uniform([1.0; 3]);
        let n = Vector3::z();
        for r in [0.02, 0.1, 0.3, 0.5, 0.8, 1.0] {
            for nv in [0.05, 0.3, 0.6, 0.9, 1.0] {
                let v = Vector3::new((1.0f64 - nv * nv).sqrt(), 0.0, nv);
                let metal = env.shade(&mirror(1.0, r), &n, &v)[0];
                assert!(metal <= 1.0 + 1e-3, "metal r {r}, n·v {nv}: {metal}");
                // Single scattering loses up to about two thirds at roughness 1 (no multiple
                // scattering is modelled; Kulla & Conty 2017).
                let floor = if r <= 0.1 { 0.97 } else { 0.3 };
                assert!(metal >= floor, "metal r {r}, n·v {nv}: {metal}");
                if nv >= 0.3 {
                    let smoother = env.shade(&mirror(1.0, r * 0.8), &n, &v)[0];
                    assert!(
                        smoother >= metal - 1e-3,
                        "r {r}, n·v {nv}: {smoother} < {metal}"
                    );
                }
                let white = Appearance {
                    base_color: [1.0; 3],
                    metallic: 0.0,
                    ..mirror(1.0, r)
                };
                let d = env.shade(&white, &n, &v)[0];
                assert!(
                    (d - 1.0).abs() < 1e-9,
                    "white dielectric r {r}, n·v {nv}: {d}"
                );
            }
        }
    }

    /// The split-sum table agrees with a brute-force integral of the direct-light BRDF
    /// (`shading::brdf_cos`) over the hemisphere, which itself never reflects more than it gets.
    #[test]
    fn the_split_sum_table_integrates_the_direct_brdf() {
        let n = Vector3::z();
        for r in [0.25, 0.35, 0.5, 0.8, 1.0] {
            for nv in [0.2, 0.5, 0.9] {
                let v = Vector3::new((1.0f64 - nv * nv).sqrt(), 0.0, nv);
                let a = mirror(1.0, r);
                // Midpoint rule over (cos θ, φ): dω = d(cos θ) dφ.
                let (nt, np) = (400, 400);
                let mut sum = 0.0;
                for i in 0..nt {
                    let c = (i as f64 + 0.5) / nt as f64;
                    let s = (1.0 - c * c).sqrt();
                    for j in 0..np {
                        let phi = (j as f64 + 0.5) / np as f64 * 2.0 * PI;
                        let l = Vector3::new(s * phi.cos(), s * phi.sin(), c);
                        sum += super::super::shading::brdf_cos(&a, &n, &v, &l, None, 0.0)[0];
                    }
                }
                let direct = sum * (1.0 / nt as f64) * (2.0 * PI / np as f64);
                let (scale, bias) = brdf_lut(r, nv);
                assert!(direct <= 1.0 + 1e-3, "r {r} n·v {nv}: {direct}");
                assert!(
                    (direct - (scale + bias)).abs() < 0.02,
                    "r {r} n·v {nv}: integral {direct}, table {}",
                    scale + bias
                );
            }
        }
    }

    /// A sharp environment (bright above the horizon, dark below) reaches a smooth level
    /// unblurred and a rough level blurred across the horizon.
    #[test]
    fn prefiltering_blurs_with_roughness() {
        let env = Environment::bake(&|d| if d.z > 0.0 { [1.0; 3] } else { [0.0; 3] });
        let above = Vector3::new(1.0, 0.0, 0.2).normalize();
        let below = Vector3::new(1.0, 0.0, -0.2).normalize();
        assert!(env.specular(&above, 0.0)[0] > 0.99);
        assert!(env.specular(&below, 0.0)[0] < 0.01);
        let (a, b) = (env.specular(&above, 0.8)[0], env.specular(&below, 0.8)[0]);
        assert!(a < 0.9 && b > 0.1 && a > b, "rough: {a} above, {b} below");
        // Straight up, a lobe that ends well above the horizon sees sky: within the 1–2 % the
        // coarse mip levels of the lobe's tail samples let through.
        let up = env.specular(&Vector3::z(), 0.3)[0];
        assert!(up > 0.98, "straight up at roughness 0.3: {up}");
    }

    /// The room: up sees the panel over the eye, straight down the plate, sideways a wall, and
    /// the mount where the camera is.
    #[test]
    fn the_room_is_where_it_is_drawn() {
        let room = Room {
            eye: Point3::new(0.0, 0.0, 0.005),
            half_size: [2.0, 3.0],
            floor: -0.9,
            ceiling: 2.5,
            walls: [[0.2; 3], [0.3; 3], [0.4; 3], [0.5; 3]],
            ceiling_radiance: [0.1; 3],
            floor_radiance: [0.05; 3],
            table_half: 0.5,
            table_radiance: [0.07; 3],
            plate_half: 0.1,
            plate_radiance: [0.6; 3],
            panels: vec![CeilingPanel {
                centre: [0.5, 0.0],
                size: [0.6, 0.6],
                radiance: [5.0; 3],
            }],
            mount: Some(CameraMount {
                position: Point3::new(0.0, 0.0, 1.5),
                half_extents: [0.04, 0.04, 0.06],
                beam_azimuth: PI / 2.0,
                beam_half_width: 0.02,
                radiance: [0.01; 3],
            }),
        };
        assert_eq!(room.radiance(&Vector3::z()), [0.01; 3]);
        let to_panel = (Point3::new(0.5, 0.0, 2.5) - room.eye).normalize();
        assert_eq!(room.radiance(&to_panel), [5.0; 3]);
        let to_ceiling = (Point3::new(-0.5, -0.5, 2.5) - room.eye).normalize();
        assert_eq!(room.radiance(&to_ceiling), [0.1; 3]);
        assert_eq!(room.radiance(&-Vector3::z()), [0.6; 3]);
        let wall = room.radiance(&Vector3::new(1.0, 0.0, 0.3).normalize());
        assert!(wall[0] > 0.12 && wall[0] < 0.2, "{wall:?}");
        // The beam runs along +y at the body's top: seen above the body, not beside it.
        let beam = (Point3::new(0.0, 1.0, 1.55) - room.eye).normalize();
        assert_eq!(room.radiance(&beam), [0.01; 3]);
        let off_beam = (Point3::new(0.0, -1.0, 1.55) - room.eye).normalize();
        assert_ne!(room.radiance(&off_beam), [0.01; 3]);
    }
}
