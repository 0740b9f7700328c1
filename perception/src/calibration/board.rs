//! The calibration board: a plate printed with a grid of AprilTags, described by a small TOML
//! file, with the board-frame position of every tag corner the detector reports.
//!
//! Board frame: origin at the plate's centre on its top face, z up out of the print, x along the
//! grid's columns, y along its rows. Viewed from above with y pointing up, tag ids run in reading
//! order (left to right, then top row to bottom row) over the printed tags, and every tag reads
//! upright.

use std::path::Path;

use nalgebra::{Point2, Point3};
use serde::Deserialize;

use super::{BoardError, TagFamily};
use crate::part::line_column;

/// A board as its TOML file describes it.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoardSpec {
    /// Tag family, by the reference library's name (`tag36h11`).
    pub family: String,
    /// Outer side of a tag's border (what the detector's corners span), metres.
    pub tag_size: f64,
    /// Distance between neighbouring tag centres, metres.
    pub pitch: f64,
    /// Tags per row and per column: `[columns, rows]`.
    pub grid: [u32; 2],
    /// A block of grid cells left unprinted (the seed's board leaves its inner 3 × 3 empty).
    #[serde(default)]
    pub removed: Option<RemovedBlock>,
    /// Id of the first printed tag; the others follow in reading order.
    #[serde(default)]
    pub first_id: u32,
    /// Plate size `[x, y]`, metres.
    pub plate: [f64; 2],
    /// Plate thickness, metres.
    #[serde(default = "default_thickness")]
    pub thickness: f64,
}

/// A rectangular block of unprinted grid cells.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RemovedBlock {
    /// Its first `[column, row]` (row 0 is the top row).
    pub first: [u32; 2],
    /// Its size in cells, `[columns, rows]`.
    pub size: [u32; 2],
}

fn default_thickness() -> f64 {
    0.003
}

impl BoardSpec {
    /// The seed's board: 21 × 21 cm aluminium, a 5 × 5 grid of 3 cm tag36h11 tags at 4 cm pitch,
    /// the inner 3 × 3 removed, ids from 0.
    pub fn seed() -> Self {
        Self {
            family: "tag36h11".into(),
            tag_size: 0.03,
            pitch: 0.04,
            grid: [5, 5],
            removed: Some(RemovedBlock {
                first: [1, 1],
                size: [3, 3],
            }),
            first_id: 0,
            plate: [0.21, 0.21],
            thickness: default_thickness(),
        }
    }

    /// Whether grid cell (column, row) carries a tag.
    fn is_printed(&self, column: u32, row: u32) -> bool {
        self.removed.is_none_or(|b| {
            !(column >= b.first[0]
                && column < b.first[0] + b.size[0]
                && row >= b.first[1]
                && row < b.first[1] + b.size[1])
        })
    }
}

/// One printed tag.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoardTag {
    /// Its id in the family.
    pub id: u32,
    /// Grid column (0 at −x).
    pub column: u32,
    /// Grid row (0 at +y, the top row seen from above).
    pub row: u32,
    /// Centre on the board's top face, metres.
    pub center: Point2<f64>,
}

/// A validated board: its description, its family and its printed tags.
#[derive(Debug, Clone, PartialEq)]
pub struct Board {
    spec: BoardSpec,
    family: TagFamily,
    tags: Vec<BoardTag>,
    /// Index into `tags` of each grid cell's tag, row by row.
    at_cell: Vec<Option<usize>>,
    /// Each tag's printed cells ([`TagFamily::cells`]), by index into `tags`.
    prints: Vec<Vec<bool>>,
}

impl Board {
    /// The seed's board ([`BoardSpec::seed`]).
    pub fn seed() -> Self {
        Self::new(BoardSpec::seed()).expect("the seed's board is valid")
    }

    /// Reads and validates a board file; errors name the file, line and column.
    pub fn load(path: &Path) -> Result<Self, BoardError> {
        let text = std::fs::read_to_string(path).map_err(|source| BoardError::Io {
            path: path.into(),
            source,
        })?;
        Self::parse(&text, path)
    }

    /// Parses board text read from `path` (named in errors).
    pub fn parse(text: &str, path: &Path) -> Result<Self, BoardError> {
        let at = |offset: Option<usize>, message: String| {
            let (line, column) = offset.map_or((1, 1), |o| line_column(text, o));
            BoardError::File {
                path: path.into(),
                line,
                column,
                message,
            }
        };
        let spec: BoardSpec = toml::from_str(text)
            .map_err(|e| at(e.span().map(|s| s.start), e.message().trim().to_string()))?;
        Self::new(spec).map_err(|e| {
            let key = e.key();
            let offset = key.and_then(|k| key_offset(text, k));
            at(offset, e.to_string())
        })
    }

    /// Validates a description: a known family, enough ids, tags that fit the plate without
    /// overlapping, and a removed block inside the grid.
    pub fn new(spec: BoardSpec) -> Result<Self, BoardError> {
        let invalid = |key: &'static str, message: String| BoardError::Invalid { key, message };
        let family = TagFamily::named(&spec.family).map_err(|e| match e {
            BoardError::UnknownFamily(_) => invalid("family", e.to_string()),
            other => other,
        })?;
        for (key, v) in [
            ("tag_size", spec.tag_size),
            ("pitch", spec.pitch),
            ("plate", spec.plate[0].min(spec.plate[1])),
            ("thickness", spec.thickness),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(invalid(
                    key,
                    format!("must be positive and finite, not {v}"),
                ));
            }
        }
        let [columns, rows] = spec.grid;
        if columns == 0 || rows == 0 {
            return Err(invalid(
                "grid",
                "needs at least one column and one row".into(),
            ));
        }
        // Each tag's quiet zone (the white ring outside its border) must fit within the pitch.
        let image = spec.tag_size * family.total_width as f64 / family.width_at_border as f64;
        if image > spec.pitch + 1e-12 {
            return Err(invalid(
                "pitch",
                format!(
                    "{:.4} m is less than a {} tag with its quiet zone ({image:.4} m for a {:.4} m \
                     tag): neighbours would touch and no detector could separate them",
                    spec.pitch, family.name, spec.tag_size
                ),
            ));
        }
        let extent = [
            (columns - 1) as f64 * spec.pitch + image,
            (rows - 1) as f64 * spec.pitch + image,
        ];
        if extent[0] > spec.plate[0] + 1e-12 || extent[1] > spec.plate[1] + 1e-12 {
            return Err(invalid(
                "plate",
                format!(
                    "{:.4} × {:.4} m is smaller than the printed grid ({:.4} × {:.4} m)",
                    spec.plate[0], spec.plate[1], extent[0], extent[1]
                ),
            ));
        }
        if let Some(b) = spec.removed
            && (b.first[0] + b.size[0] > columns || b.first[1] + b.size[1] > rows)
        {
            return Err(invalid(
                "removed",
                format!(
                    "block at column {}, row {} of {} × {} cells runs off the {columns} × {rows} grid",
                    b.first[0], b.first[1], b.size[0], b.size[1]
                ),
            ));
        }
        let mut tags = Vec::new();
        for row in 0..rows {
            for column in 0..columns {
                if !spec.is_printed(column, row) {
                    continue;
                }
                let id = spec.first_id + tags.len() as u32;
                let center = Point2::new(
                    (column as f64 - (columns - 1) as f64 / 2.0) * spec.pitch,
                    ((rows - 1) as f64 / 2.0 - row as f64) * spec.pitch,
                );
                tags.push(BoardTag {
                    id,
                    column,
                    row,
                    center,
                });
            }
        }
        if tags.is_empty() {
            return Err(invalid("removed", "leaves no tag on the board".into()));
        }
        let last = spec.first_id as u64 + tags.len() as u64;
        if last > family.codes.len() as u64 {
            return Err(invalid(
                "first_id",
                format!(
                    "{} tags from id {} need ids up to {}, but {} has {} codes",
                    tags.len(),
                    spec.first_id,
                    last - 1,
                    family.name,
                    family.codes.len()
                ),
            ));
        }
        let mut at_cell = vec![None; (columns * rows) as usize];
        for (i, t) in tags.iter().enumerate() {
            at_cell[(t.row * columns + t.column) as usize] = Some(i);
        }
        let prints = tags.iter().map(|t| family.cells(t.id as usize)).collect();
        Ok(Self {
            spec,
            family,
            tags,
            at_cell,
            prints,
        })
    }

    /// The description.
    pub fn spec(&self) -> &BoardSpec {
        &self.spec
    }

    /// The tag family.
    pub fn family(&self) -> &TagFamily {
        &self.family
    }

    /// The printed tags in id order.
    pub fn tags(&self) -> &[BoardTag] {
        &self.tags
    }

    /// The printed tag with this id.
    pub fn tag(&self, id: u32) -> Option<&BoardTag> {
        id.checked_sub(self.spec.first_id)
            .and_then(|i| self.tags.get(i as usize))
    }

    /// A tag's four border corners on the board's top face, in the order the reference detector
    /// reports them: (−1, +1), (+1, +1), (+1, −1), (−1, −1) in the tag's image frame (x right,
    /// y down), which is bottom-left, bottom-right, top-right, top-left seen upright.
    pub fn corners(&self, id: u32) -> Option<[Point3<f64>; 4]> {
        let c = self.tag(id)?.center;
        let h = self.spec.tag_size / 2.0;
        Some(
            [(-h, -h), (h, -h), (h, h), (-h, h)]
                .map(|(dx, dy)| Point3::new(c.x + dx, c.y + dy, 0.0)),
        )
    }

    /// Whether the print is black at board point (x, y) of the top face.
    pub fn is_black(&self, x: f64, y: f64) -> bool {
        let [columns, rows] = self.spec.grid;
        let pitch = self.spec.pitch;
        let column = (x / pitch + (columns - 1) as f64 / 2.0).round();
        let row = ((rows - 1) as f64 / 2.0 - y / pitch).round();
        if column < 0.0 || row < 0.0 || column >= columns as f64 || row >= rows as f64 {
            return false;
        }
        let Some(index) = self.at_cell[row as usize * columns as usize + column as usize] else {
            return false;
        };
        let tag = &self.tags[index];
        let w = self.family.total_width as usize;
        let cell = self.spec.tag_size / self.family.width_at_border as f64;
        let half = cell * w as f64 / 2.0;
        let (lx, ly) = (x - tag.center.x + half, tag.center.y + half - y);
        if lx < 0.0 || ly < 0.0 {
            return false;
        }
        let (cx, cy) = ((lx / cell) as usize, (ly / cell) as usize);
        if cx >= w || cy >= w {
            return false;
        }
        !self.prints[index][cy * w + cx]
    }
}

/// Byte offset of a top-level `key = ` in board text, for error locations.
fn key_offset(text: &str, key: &str) -> Option<usize> {
    let mut offset = 0;
    for line in text.split_inclusive('\n') {
        let trimmed = line.trim_start();
        if let Some(rest) = trimmed.strip_prefix(key)
            && rest.trim_start().starts_with('=')
        {
            return Some(offset + line.len() - trimmed.len());
        }
        offset += line.len();
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_seed_board_has_sixteen_tags_in_reading_order() {
        let b = Board::seed();
        assert_eq!(b.tags().len(), 16);
        let first = b.tags()[0];
        assert_eq!((first.id, first.column, first.row), (0, 0, 0));
        assert!((first.center - Point2::new(-0.08, 0.08)).norm() < 1e-12);
        let last = b.tags()[15];
        assert_eq!((last.id, last.column, last.row), (15, 4, 4));
        assert!((last.center - Point2::new(0.08, -0.08)).norm() < 1e-12);
        // Row 1 has only its two outer tags.
        assert_eq!(b.tag(5).map(|t| (t.column, t.row)), Some((0, 1)));
        assert_eq!(b.tag(6).map(|t| (t.column, t.row)), Some((4, 1)));
        assert!(b.tag(16).is_none());
    }

    #[test]
    fn corners_span_the_border_and_the_print_follows_the_family() {
        let b = Board::seed();
        let c = b.corners(0).unwrap();
        assert!((c[0] - Point3::new(-0.095, 0.065, 0.0)).norm() < 1e-12);
        assert!((c[2] - Point3::new(-0.065, 0.095, 0.0)).norm() < 1e-12);
        // Just inside each corner is the black border; just outside is the white quiet zone.
        for p in c {
            let inward = Point2::new(-0.08, 0.08)
                + (Point2::new(p.x, p.y) - Point2::new(-0.08, 0.08)) * 0.98;
            let outward = Point2::new(-0.08, 0.08)
                + (Point2::new(p.x, p.y) - Point2::new(-0.08, 0.08)) * 1.02;
            assert!(b.is_black(inward.x, inward.y));
            assert!(!b.is_black(outward.x, outward.y));
        }
        // The data cells print the code: count black data cells of tag 0 on the board.
        let cell = 0.03 / 8.0;
        let mut white = 0;
        for cy in 1..7 {
            for cx in 1..7 {
                let x = -0.095 + (cx as f64 + 0.5) * cell;
                let y = 0.095 - (cy as f64 + 0.5) * cell;
                white += usize::from(!b.is_black(x, y));
            }
        }
        assert_eq!(white as u32, b.family().codes[0].count_ones());
        assert!(!b.is_black(0.0, 0.0), "the removed block is blank");
    }

    #[test]
    fn bad_boards_are_refused_at_the_key() {
        let path = Path::new("board.toml");
        let text = "family = \"tag36h11\"\ntag_size = 0.03\npitch = 0.035\ngrid = [5, 5]\nplate = [0.21, 0.21]\n";
        let e = Board::parse(text, path).unwrap_err().to_string();
        assert!(
            e.starts_with("board.toml:3:1:") && e.contains("quiet zone"),
            "{e}"
        );
        let text = "family = \"tag36h11\"\ntag_size = 0.03\npitch = 0.04\ngrid = [5, 5]\nplate = [0.15, 0.21]\n";
        let e = Board::parse(text, path).unwrap_err().to_string();
        assert!(
            e.starts_with("board.toml:5:1:") && e.contains("smaller"),
            "{e}"
        );
        let text = "family = \"tag36h10\"\ntag_size = 0.03\npitch = 0.04\ngrid = [5, 5]\nplate = [0.21, 0.21]\n";
        let e = Board::parse(text, path).unwrap_err().to_string();
        assert!(
            e.starts_with("board.toml:1:1:") && e.contains("tag36h10"),
            "{e}"
        );
        let text = "family = \"tag16h5\"\ntag_size = 0.02\npitch = 0.04\ngrid = [8, 8]\nfirst_id = 0\nplate = [0.4, 0.4]\n";
        let e = Board::parse(text, path).unwrap_err().to_string();
        assert!(
            e.starts_with("board.toml:5:1:") && e.contains("30 codes"),
            "{e}"
        );
        let e = Board::parse("family = \"tag36h11\"\ntag_sise = 1\n", path)
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("board.toml:2:1:") && e.contains("tag_sise"),
            "{e}"
        );
    }

    #[test]
    fn the_seed_board_file_is_the_seed_board() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/boards/seed.toml");
        assert_eq!(Board::load(&path).unwrap(), Board::seed());
    }
}
