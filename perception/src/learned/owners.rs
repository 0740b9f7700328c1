//! Which detected part each pixel of a frame shows: contour alignment neither fits nor counts an
//! outline sample where another part lies, because the edge it would find belongs to the part on
//! top (or beside), and weighs competing stable poses by how well they cover the part's own
//! pixels.

use super::instances::Instance;
use super::net_view::NetView;
use crate::contour::Owner;

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

    /// Fills `row` with the owners, as instance `me` sees them, of the pixels of sensor row `y`
    /// from column `x` on.
    pub fn owner_row(&self, me: usize, y: i64, x: i64, row: &mut [Owner]) {
        row.fill(Owner::Nobody);
        let Some(view) = self.view else { return };
        let origin = view.region.map(i64::from);
        let i = view.cell_of(1, y - origin[1]);
        if !(0..self.height as i64).contains(&i) {
            return;
        }
        let owners = &self.owner[i as usize * self.width..][..self.width];
        for (k, owner) in row.iter_mut().enumerate() {
            let j = view.cell_of(0, x + k as i64 - origin[0]);
            if let Some(&o) = usize::try_from(j).ok().and_then(|j| owners.get(j)) {
                *owner = match o {
                    0 => Owner::Nobody,
                    o if o as usize == me + 1 => Owner::Me,
                    _ => Owner::Other,
                };
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_row_is_owned_by_the_instances_cells() {
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
            let mut out = vec![Owner::Me; n];
            owners.owner_row(me, y, x, &mut out);
            out
        };
        let (o, m, n) = (Owner::Other, Owner::Me, Owner::Nobody);
        // Cell (1, 3) covers sensor pixels 112..=115 × 54..=57; row 54 from column 110 on.
        let covered_by_1 = [n, n, o, o, o, o, n, n];
        assert_eq!(
            row(0, 54, 110, 8),
            covered_by_1,
            "past the map's right side: nobody's"
        );
        assert_eq!(row(0, 57, 110, 8), covered_by_1);
        assert_eq!(row(1, 54, 110, 8), [n, n, m, m, m, m, n, n], "its own cell");
        // Row 50 from column 98: instance 0's cells are 100..=107.
        let of_0 = |mine: Owner| -> Vec<Owner> {
            (98..110)
                .map(|x| if (100..108).contains(&x) { mine } else { n })
                .collect()
        };
        assert_eq!(row(1, 50, 98, 12), of_0(o));
        assert_eq!(row(1, 53, 98, 12), of_0(o));
        assert_eq!(row(0, 50, 98, 12), of_0(m));
        // Rows above and below the map are nobody's.
        assert_eq!(row(0, 49, 110, 8), [n; 8]);
        assert_eq!(row(0, 58, 110, 8), [n; 8]);
    }
}
