//! The calibration tag board as the renderer sees it: an aluminium plate printed with AprilTags,
//! with grain, dust and scratches.

use std::sync::Arc;

use nalgebra::{Isometry3, Point3, Vector3};
use perception::calibration::Board;

use super::Appearance;

/// A tag board printed with real AprilTags ([`Board`]: the seed's board by default), so that the
/// reference detector decodes what we render. By default it lies on the table with its top face
/// at z = 0 in the table frame, centred on the origin; [`TagBoard::with_pose`] places it anywhere
/// (a board held by the robot for hand-eye calibration).
#[derive(Debug, Clone, PartialEq)]
#[allow(non_snake_case)]
pub struct TagBoard {
    /// The board's layout and tag family.
    pub layout: Arc<Board>,
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
    /// The board frame (origin at the top face's centre, z out of the print) in the table frame.
    table_T_board: Isometry3<f64>,
    /// Its inverse, kept so rays are not inverted per query.
    board_T_table: Isometry3<f64>,
    /// Whether the pose is not the identity: an unposed board skips every transform, so it
    /// renders bit for bit as before poses existed.
    posed: bool,
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
        Self::new(Board::seed())
    }
}

impl TagBoard {
    /// A board of this layout with the default print: white aluminium, black ink, no wear.
    pub fn new(layout: Board) -> Self {
        Self {
            layout: Arc::new(layout),
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
            table_T_board: Isometry3::identity(),
            board_T_table: Isometry3::identity(),
            posed: false,
        }
    }

    /// The same board placed at `table_T_board` (the identity lays it on the table at the origin).
    #[allow(non_snake_case)]
    pub fn with_pose(mut self, table_T_board: Isometry3<f64>) -> Self {
        self.table_T_board = table_T_board;
        self.board_T_table = table_T_board.inverse();
        self.posed = table_T_board != Isometry3::identity();
        self
    }

    /// The board's pose in the table frame.
    #[allow(non_snake_case)]
    pub fn pose(&self) -> Isometry3<f64> {
        self.table_T_board
    }

    /// A table-frame ray in the board frame (unchanged for an unposed board).
    pub(crate) fn ray_to_board(
        &self,
        o: &Point3<f64>,
        d: &Vector3<f64>,
    ) -> (Point3<f64>, Vector3<f64>) {
        if self.posed {
            (self.board_T_table * o, self.board_T_table * d)
        } else {
            (*o, *d)
        }
    }

    /// A board-frame normal in the table frame (unchanged for an unposed board).
    pub(crate) fn normal_to_table(&self, n: Vector3<f64>) -> Vector3<f64> {
        if self.posed {
            self.table_T_board * n
        } else {
            n
        }
    }

    /// The lowest table-frame height the plate reaches (its bottom face, −thickness, unposed).
    pub fn lowest_z(&self) -> f64 {
        if !self.posed {
            return -self.thickness();
        }
        let [hx, hy] = self.half_extents();
        let mut z = f64::INFINITY;
        for x in [-hx, hx] {
            for y in [-hy, hy] {
                for h in [-self.thickness(), 0.0] {
                    z = z.min((self.table_T_board * Point3::new(x, y, h)).z);
                }
            }
        }
        z
    }

    /// What a hit at table point `p` with table-frame normal `normal` shows: the print, grain,
    /// dust or scratch of the top face ([`Self::surface_at`]), or `None` on the plate's sides
    /// and bottom.
    pub fn top_face_at(
        &self,
        p: &Point3<f64>,
        normal: &Vector3<f64>,
    ) -> Option<(Appearance, BoardMark)> {
        let (p, normal) = if self.posed {
            (self.board_T_table * p, self.board_T_table.rotation * normal)
        } else {
            (*p, *normal)
        };
        (normal.z > 0.5).then(|| self.surface_at(p.x, p.y))
    }

    /// Half the plate's size along x and y, metres.
    pub fn half_extents(&self) -> [f64; 2] {
        let [x, y] = self.layout.spec().plate;
        [x / 2.0, y / 2.0]
    }

    /// Plate thickness, metres (its bottom rests on the table).
    pub fn thickness(&self) -> f64 {
        self.layout.spec().thickness
    }

    /// Whether the board point (x, y) on its top face is printed black.
    pub fn is_black(&self, x: f64, y: f64) -> bool {
        self.layout.is_black(x, y)
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

#[cfg(test)]
mod tests {
    use nalgebra::{Translation3, UnitQuaternion};

    use super::*;

    #[test]
    fn a_posed_board_reads_its_print_and_its_lowest_corner_in_the_table_frame() {
        let unposed = TagBoard::default();
        assert_eq!(unposed.lowest_z(), -0.003);
        let pose = Isometry3::from_parts(
            Translation3::new(0.1, -0.2, 0.3),
            UnitQuaternion::from_euler_angles(0.2, 0.0, 0.5),
        );
        let posed = TagBoard::default().with_pose(pose);
        assert_eq!(posed.pose(), pose);
        // Tipped 0.2 rad about its x axis (then turned about z): the −y edge of the bottom face
        // is lowest.
        let want = 0.3 - 0.105 * 0.2f64.sin() - 0.003 * 0.2f64.cos();
        assert!(
            (posed.lowest_z() - want).abs() < 1e-15,
            "{}",
            posed.lowest_z()
        );
        // A black border point of tag 0 and a white quiet-zone point, seen on the posed top face.
        for (x, y, black) in [(-0.094, 0.094, true), (-0.0955, 0.0955, false)] {
            let p = pose * Point3::new(x, y, 0.0);
            let up = pose.rotation * Vector3::z();
            let (_, mark) = posed.top_face_at(&p, &up).unwrap();
            assert_eq!(mark == BoardMark::Black, black, "({x}, {y})");
            // The same table point on the unposed board is elsewhere on the print.
            assert_eq!(
                unposed.top_face_at(&p, &Vector3::z()).map(|s| s.1),
                Some(BoardMark::White)
            );
            // A side face shows no print.
            assert!(
                posed
                    .top_face_at(&p, &(pose.rotation * Vector3::x()))
                    .is_none()
            );
        }
    }
}
