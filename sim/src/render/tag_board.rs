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
            },
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
        if self.is_black(x, y) {
            self.black
        } else {
            self.white
        }
    }
}

/// Bit `bit` (0–35) of tag `id`'s data pattern: a fixed integer hash (splitmix64).
fn tag_bit(id: u32, bit: u32) -> bool {
    let mut z = (id as u64).wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> bit) & 1 == 1
}
