//! The calibration tag board: an aluminium plate printed with an AprilTag-style grid.

use super::Appearance;

/// A square board lying on the table with its top face at z = 0 in the table frame, centred on
/// the origin, printed with a grid of square fiducial tags (black border, 6 × 6 data cells).
///
/// The default follows the seed's board: 21 × 21 cm, a 5 × 5 grid of 3 cm tags at 4 cm pitch with
/// the inner 3 × 3 removed. Tag bit patterns are a fixed hash of the tag number: the board looks
/// like a tag36h11 board to a camera but the codes are not decodable tag36h11 words.
#[derive(Debug, Clone, PartialEq)]
pub struct TagBoard {
    /// Side length of the plate, metres.
    pub size: f64,
    /// Plate thickness, metres (its bottom rests on the table).
    pub thickness: f64,
    /// Outer side of a tag's black border, metres.
    pub tag_size: f64,
    /// Distance between neighbouring tag centres, metres.
    pub pitch: f64,
    /// Tags per row and column.
    pub grid: u32,
    /// Size of the removed inner block (0 for a full grid).
    pub inner_removed: u32,
    /// Appearance of the white print.
    pub white: Appearance,
    /// Appearance of the black print.
    pub black: Appearance,
    /// Amplitude of the smooth albedo variation of the print (0 for a uniform print; 0.1 is
    /// ±10 % over a few millimetres).
    pub grain: f64,
    /// Dust specks (0.04–0.12 mm, light grey) per square centimetre.
    pub dust: f64,
    /// Scratches through the print (3–8 mm long, bare aluminium) per 100 cm².
    pub scratches: f64,
    /// Seed of the grain, dust and scratch pattern.
    pub texture_seed: u64,
}

/// What the board shows at a point of its top face.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BoardMark {
    /// The white print.
    White,
    /// The black print of a tag.
    Black,
    /// A dust speck.
    Dust,
    /// A scratch through the print.
    Scratch,
}

impl Default for TagBoard {
    fn default() -> Self {
        Self {
            size: 0.21,
            thickness: 0.003,
            tag_size: 0.03,
            pitch: 0.04,
            grid: 5,
            inner_removed: 3,
            white: Appearance::for_material(perception::part::Material::TagBoard),
            black: Appearance {
                base_color: [0.025, 0.025, 0.025],
                metallic: 0.0,
                roughness: 0.55,
                specular: 0.04,
                anisotropy: 0.0,
            },
            grain: 0.0,
            dust: 0.0,
            scratches: 0.0,
            texture_seed: 0,
        }
    }
}

impl TagBoard {
    /// Half the side length, metres.
    pub fn half_size(&self) -> f64 {
        self.size / 2.0
    }

    /// Whether the tag at grid cell (i, j) is printed.
    fn has_tag(&self, i: u32, j: u32) -> bool {
        let lo = (self.grid - self.inner_removed.min(self.grid)) / 2;
        let hi = lo + self.inner_removed;
        !(i >= lo && i < hi && j >= lo && j < hi)
    }

    /// Whether the board point (x, y) on its top face is printed black.
    pub fn is_black(&self, x: f64, y: f64) -> bool {
        let n = self.grid as f64;
        let first = -(n - 1.0) / 2.0 * self.pitch;
        let i = ((x - first) / self.pitch).round();
        let j = ((y - first) / self.pitch).round();
        if i < 0.0 || j < 0.0 || i >= n || j >= n {
            return false;
        }
        let (iu, ju) = (i as u32, j as u32);
        if !self.has_tag(iu, ju) {
            return false;
        }
        let cell = self.tag_size / 8.0;
        let lx = x - (first + i * self.pitch) + self.tag_size / 2.0;
        let ly = y - (first + j * self.pitch) + self.tag_size / 2.0;
        if lx < 0.0 || ly < 0.0 || lx >= self.tag_size || ly >= self.tag_size {
            return false;
        }
        let (cx, cy) = ((lx / cell) as u32, (ly / cell) as u32);
        if cx == 0 || cy == 0 || cx == 7 || cy == 7 {
            return true;
        }
        let bit = (cy - 1) * 6 + (cx - 1);
        tag_bit(ju * self.grid + iu, bit)
    }

    /// The appearance at board point (x, y) of the top face.
    pub fn appearance_at(&self, x: f64, y: f64) -> Appearance {
        self.surface_at(x, y).0
    }

    /// The appearance and the mark at board point (x, y) of the top face: print, grain, dust
    /// and scratches.
    pub fn surface_at(&self, x: f64, y: f64) -> (Appearance, BoardMark) {
        if self.scratches > 0.0 && self.on_scratch(x, y) {
            return (SCRATCH, BoardMark::Scratch);
        }
        if self.dust > 0.0 && self.on_dust(x, y) {
            return (DUST, BoardMark::Dust);
        }
        let (mut a, mark) = if self.is_black(x, y) {
            (self.black, BoardMark::Black)
        } else {
            (self.white, BoardMark::White)
        };
        if self.grain > 0.0 {
            let g =
                1.0 + self.grain * (2.0 * self.value_noise(x / GRAIN_CELL, y / GRAIN_CELL) - 1.0);
            a.base_color = a.base_color.map(|c| (c * g).clamp(0.0, 1.0));
        }
        (a, mark)
    }

    /// Smooth noise in [0, 1]: bilinear interpolation of hashed lattice values.
    fn value_noise(&self, x: f64, y: f64) -> f64 {
        let (fx, fy) = (x.floor(), y.floor());
        let (tx, ty) = (x - fx, y - fy);
        let (sx, sy) = (tx * tx * (3.0 - 2.0 * tx), ty * ty * (3.0 - 2.0 * ty));
        let at = |i: f64, j: f64| unit(hash3(self.texture_seed, i as i64, j as i64, 1));
        let top = at(fx, fy) * (1.0 - sx) + at(fx + 1.0, fy) * sx;
        let bottom = at(fx, fy + 1.0) * (1.0 - sx) + at(fx + 1.0, fy + 1.0) * sx;
        top * (1.0 - sy) + bottom * sy
    }

    /// Whether (x, y) lies on a dust speck: at most one per 1 mm cell, at a hashed place.
    fn on_dust(&self, x: f64, y: f64) -> bool {
        let (i, j) = ((x / DUST_CELL).floor(), (y / DUST_CELL).floor());
        let h = hash3(self.texture_seed, i as i64, j as i64, 2);
        // Specks per cell = specks per cm² × cell area in cm².
        if unit(h) >= self.dust * (DUST_CELL * 100.0).powi(2) {
            return false;
        }
        let cx = (i + unit(h.rotate_left(21))) * DUST_CELL;
        let cy = (j + unit(h.rotate_left(42))) * DUST_CELL;
        let r = 4e-5 + 8e-5 * unit(h.rotate_left(11));
        (x - cx).powi(2) + (y - cy).powi(2) < r * r
    }

    /// Whether (x, y) lies on a scratch: at most one per 1 cm cell (checked with its neighbours,
    /// as scratches cross cell borders), a hashed segment.
    fn on_scratch(&self, x: f64, y: f64) -> bool {
        let (i0, j0) = ((x / SCRATCH_CELL).floor(), (y / SCRATCH_CELL).floor());
        for dj in -1..=1 {
            for di in -1..=1 {
                let (i, j) = (i0 + di as f64, j0 + dj as f64);
                let h = hash3(self.texture_seed, i as i64, j as i64, 3);
                if unit(h) >= self.scratches / 100.0 * (SCRATCH_CELL * 100.0).powi(2) {
                    continue;
                }
                let cx = (i + unit(h.rotate_left(13))) * SCRATCH_CELL;
                let cy = (j + unit(h.rotate_left(26))) * SCRATCH_CELL;
                let angle = unit(h.rotate_left(39)) * std::f64::consts::PI;
                let half = (3e-3 + 5e-3 * unit(h.rotate_left(52))) / 2.0;
                let width = 2e-5 + 3e-5 * unit(h.rotate_left(7));
                let (dx, dy) = (x - cx, y - cy);
                let along = dx * angle.cos() + dy * angle.sin();
                let across = -dx * angle.sin() + dy * angle.cos();
                if along.abs() <= half && across.abs() <= width / 2.0 {
                    return true;
                }
            }
        }
        false
    }
}

/// Lattice spacing of the print's albedo grain, metres.
const GRAIN_CELL: f64 = 3e-3;
/// Cell of the dust pattern, metres.
const DUST_CELL: f64 = 1e-3;
/// Cell of the scratch pattern, metres.
const SCRATCH_CELL: f64 = 1e-2;

/// A dust speck: light grey, matte.
const DUST: Appearance = Appearance {
    base_color: [0.55, 0.54, 0.5],
    metallic: 0.0,
    roughness: 0.9,
    specular: 0.04,
    anisotropy: 0.0,
};

/// Bare aluminium where a scratch cut through the print.
const SCRATCH: Appearance = Appearance {
    base_color: [0.91, 0.92, 0.92],
    metallic: 1.0,
    roughness: 0.3,
    specular: 0.04,
    anisotropy: 0.0,
};

/// A splitmix64 hash of a seed, two lattice coordinates and a stream tag.
fn hash3(seed: u64, i: i64, j: i64, tag: u64) -> u64 {
    let mut z = seed ^ tag.wrapping_mul(0xD6E8_FEB8_6659_FD93);
    for v in [i as u64, j as u64] {
        z = z.wrapping_add(0x9E37_79B9_7F4A_7C15).wrapping_add(v);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
    }
    z
}

/// The top 53 bits of a hash as a number in [0, 1).
fn unit(h: u64) -> f64 {
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// Bit `bit` (0–35) of tag `id`'s data pattern: a fixed integer hash (splitmix64).
fn tag_bit(id: u32, bit: u32) -> bool {
    let mut z = (id as u64).wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> bit) & 1 == 1
}
