//! Table 1 as compact text from an evaluation summary: per part the seed's row, then ours (PnP
//! and refined, seed-style and with every estimate), with sample and outlier counts.

use std::fmt::Write as _;

use super::summary::EvalSummary;
use super::table1::seed_row;

fn ms(v: [f64; 2], decimals: usize) -> String {
    if v[0].is_nan() {
        "–".into()
    } else {
        format!("{:.d$} ± {:.d$}", v[0], v[1], d = decimals)
    }
}

/// Table 1 as compact text: per part the seed's row, then ours (PnP and refined, seed-style
/// and with every estimate), with sample and outlier counts.
pub fn text_table(summary: &EvalSummary) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Table 1: |error| in the camera frame, mean ± σ, θ to the nearest exact twin; \"seed-style\" drops θ > 10° (counted in \"out\")"
    );
    let _ = writeln!(
        s,
        "{:<12} {:<22} {:>6} {:>5}  {:>14} {:>14} {:>16} {:>14}",
        "part", "estimate", "n", "out", "x (mm)", "y (mm)", "z (mm)", "θ (deg)"
    );
    let mut parts: Vec<&str> = summary.parts.iter().map(|p| p.part.as_str()).collect();
    parts.push("average");
    for part in parts {
        let seed = seed_row(part);
        if let Some(r) = seed {
            let _ = writeln!(
                s,
                "{:<12} {:<22} {:>6} {:>5}  {:>14} {:>14} {:>16} {:>14}",
                part,
                "seed paper, PnP",
                if part == "average" { 6000 } else { 2000 },
                "?",
                ms([r[0].0, r[0].1], 2),
                ms([r[1].0, r[1].1], 2),
                ms([r[2].0, r[2].1], 2),
                ms([r[3].0, r[3].1], 2)
            );
        }
        for (method, dropped, label) in [
            ("pnp", true, "ours PnP, seed-style"),
            ("pnp", false, "ours PnP, all"),
            ("refined", true, "ours refined, seed-st."),
            ("refined", false, "ours refined, all"),
        ] {
            let Some(e) = summary
                .table1
                .iter()
                .find(|e| e.part == part && e.method == method && e.outliers_dropped == dropped)
            else {
                continue;
            };
            let r = &e.row;
            let _ = writeln!(
                s,
                "{:<12} {:<22} {:>6} {:>5}  {:>14} {:>14} {:>16} {:>14}",
                if seed.is_some() { "" } else { part },
                label,
                r.n,
                r.outliers,
                ms(r.x_mm, 2),
                ms(r.y_mm, 2),
                ms(r.z_mm, 2),
                ms(r.angle_deg, 2)
            );
        }
    }
    s
}
