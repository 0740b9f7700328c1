//! Where the other detected parts lie in a frame: contour alignment neither fits nor counts an
//! outline sample there, because the edge it would find belongs to the part on top (or beside).

use nalgebra::Point2;

use super::instances::Instance;
use super::models::SEGMENTER_STRIDE;

/// The instance that owns each segmenter cell of a frame.
#[derive(Debug, Clone, Default)]
pub struct CellOwners {
    width: usize,
    height: usize,
    /// Sensor pixel of cell (0, 0)'s first pixel.
    origin: [f64; 2],
    /// Instance index + 1 per cell, row-major (0: no instance).
    owner: Vec<u32>,
}

impl CellOwners {
    /// The owners of the `width` × `height` cells of a segment map whose first pixel is sensor
    /// pixel `origin`, from the frame's `instances`.
    pub fn new(instances: &[Instance], width: usize, height: usize, origin: [u32; 2]) -> Self {
        let mut owner = vec![0; width * height];
        for (k, inst) in instances.iter().enumerate() {
            for &c in &inst.cells {
                if let Some(o) = owner.get_mut(c as usize) {
                    *o = k as u32 + 1;
                }
            }
        }
        Self {
            width,
            height,
            origin: origin.map(f64::from),
            owner,
        }
    }

    /// Whether sensor pixel `p` (pixel centres at integers) lies in a cell of an instance other
    /// than instance `me`.
    pub fn other_than(&self, me: usize, p: Point2<f64>) -> bool {
        let s = SEGMENTER_STRIDE as f64;
        let (u, v) = (
            (p.x - self.origin[0] + 0.5) / s,
            (p.y - self.origin[1] + 0.5) / s,
        );
        if !(u >= 0.0 && v >= 0.0) {
            return false;
        }
        let (j, i) = (u as usize, v as usize);
        if j >= self.width || i >= self.height {
            return false;
        }
        let o = self.owner[i * self.width + j];
        o != 0 && o as usize != me + 1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pixel_is_hidden_by_the_other_instances_cells_only() {
        // A 4 × 2 cell map at sensor pixel (100, 50): instance 0 owns cells (0, 0) and (0, 1),
        // instance 1 owns cell (1, 3).
        let inst = |cells: Vec<u32>| Instance {
            part: 0,
            score: 1.0,
            centre: [0.0; 2],
            cells,
        };
        let owners = CellOwners::new(&[inst(vec![0, 1]), inst(vec![7])], 4, 2, [100, 50]);
        let p = |x: f64, y: f64| Point2::new(x, y);
        // Cell (1, 3) covers sensor pixels 112..=115 × 54..=57 (centres), edges at ±0.5.
        assert!(owners.other_than(0, p(112.0, 54.0)));
        assert!(owners.other_than(0, p(115.4, 57.4)));
        assert!(
            !owners.other_than(0, p(111.4, 54.0)),
            "cell (1, 2) has no owner"
        );
        assert!(!owners.other_than(1, p(113.0, 55.0)), "its own cell");
        assert!(owners.other_than(1, p(100.0, 50.0)) && owners.other_than(1, p(107.0, 53.0)));
        assert!(!owners.other_than(0, p(100.0, 50.0)));
        // Outside the map nothing is hidden.
        for q in [
            p(99.0, 50.0),
            p(100.0, 49.0),
            p(116.0, 57.0),
            p(115.0, 58.0),
        ] {
            assert!(!owners.other_than(0, q) && !owners.other_than(1, q), "{q}");
        }
    }
}
