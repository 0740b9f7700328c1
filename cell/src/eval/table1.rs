//! The seed's Table 1: mean ± σ of |e_x|, |e_y|, |e_z| in mm and e_θ in degrees, raw PnP and
//! after planar refinement, with outliers (θ > 10°, θ to the nearest exact twin of a symmetric
//! part) counted and reported; statistics both over
//! all estimates and seed-style without the outliers. The compact text table with the seed's
//! numbers beside ours is in `table1_text`.

use perception::metrics::{ErrorSummary, Summary};
use serde::{Deserialize, Serialize};

/// The seed's Table 1 (raw PnP, θ > 10° dropped): part, then (mean, σ) of x, y, z (mm), θ (deg).
pub const SEED_TABLE1: [(&str, [(f64, f64); 4]); 3] = [
    (
        "insert_mold",
        [(0.60, 0.45), (0.59, 0.42), (63.80, 17.24), (2.74, 1.60)],
    ),
    (
        "main_shell",
        [(0.46, 0.37), (0.47, 0.38), (51.74, 19.38), (6.19, 2.52)],
    ),
    (
        "top_shell",
        [(0.74, 0.54), (0.71, 0.54), (75.90, 23.13), (3.31, 2.09)],
    ),
];
/// The seed's average row.
pub const SEED_AVERAGE: [(f64, f64); 4] =
    [(0.60, 0.45), (0.59, 0.45), (63.81, 19.92), (4.08, 2.07)];

/// The seed's Table 1 row for `part` ("average" for its average row), if it has one.
pub fn seed_row(part: &str) -> Option<[(f64, f64); 4]> {
    if part == "average" {
        return Some(SEED_AVERAGE);
    }
    SEED_TABLE1
        .iter()
        .find(|(n, _)| *n == part)
        .map(|(_, r)| *r)
}

/// One row of Table 1: mean and σ of each error, sample count and outliers.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Table1Row {
    /// Estimates summarised (after dropping outliers, seed-style).
    pub n: usize,
    /// Estimates with θ above the outlier angle (whether dropped or not).
    pub outliers: usize,
    /// |e_x| mean, σ (mm).
    pub x_mm: [f64; 2],
    /// |e_y| mean, σ (mm).
    pub y_mm: [f64; 2],
    /// |e_z| mean, σ (mm).
    pub z_mm: [f64; 2],
    /// e_θ mean, σ (deg), to the nearest exact twin (the geodesic angle for the seed's parts).
    pub angle_deg: [f64; 2],
}

impl Table1Row {
    /// The row of a summary.
    pub fn of(s: &ErrorSummary) -> Self {
        let ms = |x: &Summary| [x.mean, x.std];
        Self {
            n: s.sym_angle_deg.count,
            outliers: s.outliers,
            x_mm: ms(&s.x_mm),
            y_mm: ms(&s.y_mm),
            z_mm: ms(&s.z_mm),
            angle_deg: ms(&s.sym_angle_deg),
        }
    }

    /// The seed's way of averaging parts: the mean of their means and of their σs (parts
    /// without estimates left out); counts add up.
    pub fn average(rows: &[Table1Row]) -> Self {
        let with: Vec<&Table1Row> = rows.iter().filter(|r| r.n > 0).collect();
        let avg = |f: fn(&Table1Row) -> [f64; 2]| {
            if with.is_empty() {
                return [f64::NAN; 2];
            }
            let n = with.len() as f64;
            [
                with.iter().map(|r| f(r)[0]).sum::<f64>() / n,
                with.iter().map(|r| f(r)[1]).sum::<f64>() / n,
            ]
        };
        Self {
            n: rows.iter().map(|r| r.n).sum(),
            outliers: rows.iter().map(|r| r.outliers).sum(),
            x_mm: avg(|r| r.x_mm),
            y_mm: avg(|r| r.y_mm),
            z_mm: avg(|r| r.z_mm),
            angle_deg: avg(|r| r.angle_deg),
        }
    }
}

/// One row of Table 1 with its label.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Table1Entry {
    /// Part name or "average" (the seed's mean of part means and σs).
    pub part: String,
    /// "pnp" or "refined".
    pub method: String,
    /// Outliers dropped (seed-style) or kept.
    pub outliers_dropped: bool,
    /// The numbers.
    pub row: Table1Row,
}
