//! AprilTag families as the reference library defines them: codes and bit layout, so that a board
//! we print is one that the reference detector (and OpenCV's) decodes.

use super::BoardError;

/// Families this project prints and detects (the reference library's names).
pub const FAMILIES: [&str; 5] = [
    "tag36h11",
    "tag25h9",
    "tag16h5",
    "tagStandard41h12",
    "tagStandard52h13",
];

/// One AprilTag family: its codes and where each code bit is printed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TagFamily {
    /// The family's name, e.g. `tag36h11`.
    pub name: String,
    /// The code words, by tag id.
    pub codes: Vec<u64>,
    /// Code bits per tag.
    pub nbits: u32,
    /// Column of each code bit (most significant first), relative to the border's outer edge.
    pub bit_x: Vec<i32>,
    /// Row of each code bit, relative to the border's outer edge.
    pub bit_y: Vec<i32>,
    /// Cells across the border's outer edge: what the detector's corners span.
    pub width_at_border: u32,
    /// Cells across the whole tag image, quiet zone included.
    pub total_width: u32,
    /// Whether the border ring is white inside black (the `tagStandard` families).
    pub reversed_border: bool,
    /// Minimum Hamming distance between codes.
    pub min_hamming: u32,
}

impl TagFamily {
    /// The named family, read from the linked reference library (`apriltag-sys`).
    pub fn named(name: &str) -> Result<Self, BoardError> {
        let create = match name {
            "tag36h11" => apriltag_sys::tag36h11_create,
            "tag25h9" => apriltag_sys::tag25h9_create,
            "tag16h5" => apriltag_sys::tag16h5_create,
            "tagStandard41h12" => apriltag_sys::tagStandard41h12_create,
            "tagStandard52h13" => apriltag_sys::tagStandard52h13_create,
            _ => return Err(BoardError::UnknownFamily(name.to_string())),
        };
        Ok(read_family(name, create))
    }

    /// The printed cells of tag `index` (not the id: the index into [`TagFamily::codes`]):
    /// `total_width`² flags, row by row from the top, `true` where the print is white.
    ///
    /// This follows the reference library's `apriltag_to_image`: a black field, a white ring
    /// outside the border (inside it for reversed borders), and a white cell for each set bit.
    pub fn cells(&self, index: usize) -> Vec<bool> {
        let w = self.total_width as usize;
        let mut white = vec![false; w * w];
        let ring = self.width_at_border as usize + if self.reversed_border { 0 } else { 2 };
        let start = (w - ring) / 2;
        for i in 0..ring.saturating_sub(1) {
            white[start * w + start + i] = true;
            white[(start + i) * w + w - 1 - start] = true;
            white[(w - 1 - start) * w + start + i + 1] = true;
            white[(start + 1 + i) * w + start] = true;
        }
        let border = (w - self.width_at_border as usize) as i32 / 2;
        let code = self.codes[index];
        for i in 0..self.nbits as usize {
            if code & (1u64 << (self.nbits as usize - i - 1)) != 0 {
                let (x, y) = (self.bit_x[i] + border, self.bit_y[i] + border);
                if (0..w as i32).contains(&x) && (0..w as i32).contains(&y) {
                    white[y as usize * w + x as usize] = true;
                }
            }
        }
        white
    }
}

/// Copies a family out of the reference library and frees the library's copy.
#[allow(unsafe_code)]
fn read_family(
    name: &str,
    create: unsafe extern "C" fn() -> *mut apriltag_sys::apriltag_family_t,
) -> TagFamily {
    // SAFETY: the `*_create` functions return a fully initialised, heap-allocated family whose
    // `codes` holds `ncodes` words and whose `bit_x`/`bit_y` hold `nbits` entries each; we copy
    // them out before handing the same pointer back to the family's own destroy function.
    unsafe {
        let raw = create();
        let f = &*raw;
        let codes = std::slice::from_raw_parts(f.codes, f.ncodes as usize).to_vec();
        let bit_x = std::slice::from_raw_parts(f.bit_x, f.nbits as usize);
        let bit_y = std::slice::from_raw_parts(f.bit_y, f.nbits as usize);
        let family = TagFamily {
            name: name.to_string(),
            codes,
            nbits: f.nbits,
            // Negative offsets (bits outside the border of the `tagStandard` families) are stored
            // as wrapped unsigned integers.
            bit_x: bit_x.iter().map(|&v| v as i32).collect(),
            bit_y: bit_y.iter().map(|&v| v as i32).collect(),
            width_at_border: f.width_at_border as u32,
            total_width: f.total_width as u32,
            reversed_border: f.reversed_border,
            min_hamming: f.h,
        };
        destroy(name, raw);
        family
    }
}

/// Frees a family made by the matching `*_create`.
#[allow(unsafe_code)]
unsafe fn destroy(name: &str, raw: *mut apriltag_sys::apriltag_family_t) {
    // SAFETY: `raw` came from the `*_create` of the same family name and is freed once.
    unsafe {
        match name {
            "tag36h11" => apriltag_sys::tag36h11_destroy(raw),
            "tag25h9" => apriltag_sys::tag25h9_destroy(raw),
            "tag16h5" => apriltag_sys::tag16h5_destroy(raw),
            "tagStandard41h12" => apriltag_sys::tagStandard41h12_destroy(raw),
            _ => apriltag_sys::tagStandard52h13_destroy(raw),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tag36h11_is_the_reference_family() {
        let f = TagFamily::named("tag36h11").unwrap();
        assert_eq!(f.codes.len(), 587);
        assert_eq!(f.nbits, 36);
        assert_eq!(f.min_hamming, 11);
        assert_eq!((f.width_at_border, f.total_width), (8, 10));
        // The first code word of tag36h11 in every implementation (OpenCV's, Kalibr's).
        assert_eq!(f.codes[0], 0x0000_000d_7e00_984b);
    }

    #[test]
    fn tag_cells_have_a_black_border_inside_a_white_quiet_zone() {
        let f = TagFamily::named("tag36h11").unwrap();
        let cells = f.cells(0);
        let w = f.total_width as usize;
        for i in 0..w {
            assert!(cells[i] && cells[(w - 1) * w + i], "quiet zone row");
            assert!(cells[i * w] && cells[i * w + w - 1], "quiet zone column");
        }
        for i in 1..w - 1 {
            assert!(!cells[w + i] && !cells[(w - 2) * w + i], "border row");
        }
        let data_white = cells.iter().filter(|&&c| c).count() - (4 * w - 4);
        assert_eq!(data_white as u32, f.codes[0].count_ones());
    }

    #[test]
    fn every_listed_family_loads_and_an_unknown_one_is_named() {
        for name in FAMILIES {
            let f = TagFamily::named(name).unwrap();
            assert!(
                !f.codes.is_empty() && f.bit_x.len() == f.nbits as usize,
                "{name}"
            );
        }
        let e = TagFamily::named("tag99h1").unwrap_err().to_string();
        assert!(e.contains("tag99h1") && e.contains("tag36h11"), "{e}");
    }
}
