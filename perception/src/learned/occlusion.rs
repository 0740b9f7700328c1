//! Where the other detected parts lie in a frame: contour alignment neither fits nor counts an
//! outline sample there, because the edge it would find belongs to the part on top (or beside).

use super::instances::Instance;
use super::net_view::NetView;

/// The instance that owns each segmenter cell of a frame (its buffer reused from frame to
/// frame).
#[derive(Debug, Clone, Default)]
pub struct CellOwners {
    width: usize,
    height: usize,
    /// How the map's region lies on the sensor.
    view: Option<NetView>,
    /// Instance index + 1 per cell, row-major (0: no instance).
    owner: Vec<u32>,
}

impl CellOwners {
    /// Sets the owners of the `width` × `height` cells of a segment map of the region that
    /// `view` shows the nets from the frame's `instances`.
    pub fn set(&mut self, instances: &[Instance], width: usize, height: usize, view: NetView) {
        self.owner.clear();
        self.owner.resize(width * height, 0);
        for (k, inst) in instances.iter().enumerate() {
            for &c in &inst.cells {
                if let Some(o) = self.owner.get_mut(c as usize) {
                    *o = k as u32 + 1;
                }
            }
        }
        (self.width, self.height) = (width, height);
        self.view = Some(view);
    }

    /// Marks in `row` the pixels of sensor row `y` from column `x` on that lie in a cell of an
    /// instance other than instance `me` (and clears the others).
    pub fn cover_row(&self, me: usize, y: i64, x: i64, row: &mut [bool]) {
        row.fill(false);
        let Some(view) = self.view else { return };
        let origin = view.region.map(i64::from);
        let i = view.cell_of(1, y - origin[1]);
        if !(0..self.height as i64).contains(&i) {
            return;
        }
        let owners = &self.owner[i as usize * self.width..][..self.width];
        for (k, covered) in row.iter_mut().enumerate() {
            let j = view.cell_of(0, x + k as i64 - origin[0]);
            if let Some(&o) = usize::try_from(j).ok().and_then(|j| owners.get(j)) {
                *covered = o != 0 && o as usize != me + 1;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_row_is_covered_by_the_other_instances_cells_only() {
        // A 4 × 2 cell map at sensor pixel (100, 50): instance 0 owns cells (0, 0) and (0, 1),
        // instance 1 owns cell (1, 3).
        let inst = |cells: Vec<u32>| Instance {
            part: 0,
            score: 1.0,
            centre: [0.0; 2],
            cells,
        };
        let mut owners = CellOwners::default();
        // A frame before, of another size and owners, leaves nothing behind.
        let at = |region| NetView::new(region, [24, 8], 7.0, None);
        owners.set(&[inst((0..12).collect())], 6, 2, at([0, 0]));
        owners.set(&[inst(vec![0, 1]), inst(vec![7])], 4, 2, at([100, 50]));
        let row = |me: usize, y: i64, x: i64, n: usize| {
            let mut out = vec![true; n];
            owners.cover_row(me, y, x, &mut out);
            out
        };
        // Cell (1, 3) covers sensor pixels 112..=115 × 54..=57; row 54 from column 110 on.
        let covered_by_1 = [false, false, true, true, true, true, false, false];
        assert_eq!(
            row(0, 54, 110, 8),
            covered_by_1,
            "past the map's right side: uncovered"
        );
        assert_eq!(row(0, 57, 110, 8), covered_by_1);
        assert_eq!(row(1, 54, 110, 8), [false; 8], "its own cell");
        // Row 50 from column 98: instance 0's cells are 100..=107.
        let covered_by_0: Vec<bool> = (98..110).map(|x| (100..108).contains(&x)).collect();
        assert_eq!(row(1, 50, 98, 12), covered_by_0);
        assert_eq!(row(1, 53, 98, 12), covered_by_0);
        assert_eq!(row(0, 50, 98, 12), [false; 12]);
        // Rows above and below the map are uncovered.
        assert_eq!(row(0, 49, 110, 8), [false; 8]);
        assert_eq!(row(0, 58, 110, 8), [false; 8]);
    }
}
