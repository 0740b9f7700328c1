//! The report's table of force-guided verdicts (`[force_insertion]`): per step, what the wrist's
//! force and the arm's depth decided before the fingers opened, and the first contact and force
//! that decided it. Built from the step records alone, so a production run's report shows the
//! same columns as a simulated one's; a simulated run also counts how often the force verdict
//! was the simulation's own.

use std::fmt::Write as _;

use crate::episode::{EpisodeRecord, StepOutcome};
use crate::run::distribution::Distribution;

use super::escape::escape;

/// One step's force-guided verdicts.
#[derive(Debug, Clone, PartialEq)]
pub struct ForceRow {
    /// Step index.
    pub index: usize,
    /// Its part.
    pub part: String,
    /// Steps that inserted by feel.
    pub inserted: u32,
    /// Force verdicts: seated (confirmed), jammed, missed.
    pub seated: u32,
    /// Jammed by force.
    pub jammed: u32,
    /// Missed by force.
    pub missed: u32,
    /// Force verdicts equal to the step's recorded outcome (in simulation, the simulated cell's
    /// own verdict).
    pub agree: u32,
    /// First contact above seated of the confirmed seats, mm.
    pub seated_contact_mm: Option<Distribution>,
    /// Force out of the hole of the confirmed seats, N.
    pub seated_force_n: Option<Distribution>,
    /// First contact above seated of the rest, mm.
    pub unseated_contact_mm: Option<Distribution>,
}

/// The rows of `records`' force-guided steps, by step index (empty when no step inserted by
/// feel).
pub fn force_rows(records: &[&EpisodeRecord]) -> Vec<ForceRow> {
    let mut rows: Vec<ForceRow> = Vec::new();
    let mut values: Vec<[Vec<f64>; 3]> = Vec::new();
    for r in records {
        for (i, s) in r.steps.iter().enumerate() {
            let Some(f) = s.force else { continue };
            while rows.len() <= i {
                rows.push(ForceRow {
                    index: rows.len(),
                    part: String::new(),
                    inserted: 0,
                    seated: 0,
                    jammed: 0,
                    missed: 0,
                    agree: 0,
                    seated_contact_mm: None,
                    seated_force_n: None,
                    unseated_contact_mm: None,
                });
                values.push(Default::default());
            }
            let row = &mut rows[i];
            row.part.clone_from(&s.part);
            row.inserted += 1;
            match f.verdict {
                StepOutcome::Seated => {
                    row.seated += 1;
                    values[i][0].push(f.contact_mm);
                    values[i][1].push(f.force_n);
                }
                StepOutcome::Jammed => row.jammed += 1,
                StepOutcome::Missed | StepOutcome::Aborted => row.missed += 1,
            }
            if f.verdict != StepOutcome::Seated {
                values[i][2].push(f.contact_mm);
            }
            row.agree += u32::from(f.verdict == s.outcome);
        }
    }
    for (row, [contact, force, unseated]) in rows.iter_mut().zip(values) {
        row.seated_contact_mm = Distribution::of(&contact);
        row.seated_force_n = Distribution::of(&force);
        row.unseated_contact_mm = Distribution::of(&unseated);
    }
    rows.retain(|r| r.inserted > 0);
    rows
}

/// The report's section for `records`' force-guided steps (nothing when none inserted by feel).
pub fn force_section(records: &[&EpisodeRecord]) -> String {
    let rows = force_rows(records);
    if rows.is_empty() {
        return String::new();
    }
    let mut h = String::from(
        "<h2>Force-guided verdicts</h2>\n<p>What the wrist's force and the arm's depth decided \
         before the fingers opened (the step's last insertion), in simulation and production \
         alike; first contact is the stop less the press's compliance, above seated. \
         <i>as recorded</i>: force verdicts equal to the step's recorded outcome (in \
         simulation, the simulated cell's own verdict; in production, the force verdict is the \
         record's).</p>\n<table><tr><th class=l>step</th><th>by feel</th><th>seated</th>\
         <th>jammed</th><th>missed</th><th>as recorded</th><th>seat: first contact p50 / max \
         (mm)</th><th>seat: force p50 (N)</th><th>unseated: first contact min / p50 (mm)</th>\
         </tr>\n",
    );
    let dash = || "–".to_string();
    for r in &rows {
        let seat = r
            .seated_contact_mm
            .map_or_else(dash, |d| format!("{:.3} / {:.3}", d.p50, d.max));
        let force = r
            .seated_force_n
            .map_or_else(dash, |d| format!("{:.1}", d.p50));
        let unseated = r
            .unseated_contact_mm
            .map_or_else(dash, |d| format!("{:.3} / {:.3}", d.min, d.p50));
        let _ = writeln!(
            h,
            "<tr><td class=l>{}: {}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td>\
             <td>{seat}</td><td>{force}</td><td>{unseated}</td></tr>",
            r.index,
            escape(&r.part),
            r.inserted,
            r.seated,
            r.jammed,
            r.missed,
            r.agree
        );
    }
    h.push_str("</table>\n");
    h
}
