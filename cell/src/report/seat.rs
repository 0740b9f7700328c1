//! The report's table of seat checks by camera (`[seat_check]`), beside the force-guided
//! verdicts: per step, how many placed parts the camera passed, failed, could not see, or could
//! not check with the arm in view, and the offsets it measured. Built from the step records
//! alone, so a production run's report shows the same columns as a simulated one's; a simulated
//! run also shows the check's error against the placed part's true offset.

use std::fmt::Write as _;

use crate::episode::{EpisodeRecord, SeatCheckVerdict};
use crate::run::distribution::Distribution;

use super::escape::escape;

/// One step's seat checks.
#[derive(Debug, Clone, PartialEq)]
pub struct SeatRow {
    /// Step index.
    pub index: usize,
    /// Its part.
    pub part: String,
    /// Checks run.
    pub checked: u32,
    /// Passed.
    pub passed: u32,
    /// Failed (found beyond the tolerances).
    pub failed: u32,
    /// Not visible.
    pub not_visible: u32,
    /// Refused (the arm in view, or no capture).
    pub refused: u32,
    /// Measured lateral offsets, mm.
    pub offset_mm: Option<Distribution>,
    /// Own-outline supports.
    pub support: Option<Distribution>,
    /// Measured against true lateral offset (simulation only), µm.
    pub error_um: Option<Distribution>,
}

/// The rows of `records`' seat checks, by step index (empty when no step was checked).
pub fn seat_rows(records: &[&EpisodeRecord]) -> Vec<SeatRow> {
    let mut rows: Vec<SeatRow> = Vec::new();
    let mut values: Vec<[Vec<f64>; 3]> = Vec::new();
    for r in records {
        for (i, s) in r.steps.iter().enumerate() {
            let Some(c) = s.seat_check else { continue };
            while rows.len() <= i {
                rows.push(SeatRow {
                    index: rows.len(),
                    part: String::new(),
                    checked: 0,
                    passed: 0,
                    failed: 0,
                    not_visible: 0,
                    refused: 0,
                    offset_mm: None,
                    support: None,
                    error_um: None,
                });
                values.push(Default::default());
            }
            let row = &mut rows[i];
            row.part.clone_from(&s.part);
            row.checked += 1;
            match c.verdict {
                SeatCheckVerdict::Passed => row.passed += 1,
                SeatCheckVerdict::Failed => row.failed += 1,
                SeatCheckVerdict::NotVisible => row.not_visible += 1,
                SeatCheckVerdict::Refused => row.refused += 1,
            }
            if let Some([x, y]) = c.offset_mm {
                values[i][0].push(x.hypot(y));
                if let Some([tx, ty]) = c.true_offset_mm {
                    values[i][2].push((x - tx).hypot(y - ty) * 1e3);
                }
            }
            if let Some(support) = c.support {
                values[i][1].push(support);
            }
        }
    }
    for (row, [offset, support, error]) in rows.iter_mut().zip(values) {
        row.offset_mm = Distribution::of(&offset);
        row.support = Distribution::of(&support);
        row.error_um = Distribution::of(&error);
    }
    rows.retain(|r| r.checked > 0);
    rows
}

/// The report's section for `records`' seat checks (nothing when no step was checked).
pub fn seat_section(records: &[&EpisodeRecord]) -> String {
    let rows = seat_rows(records);
    if rows.is_empty() {
        return String::new();
    }
    let mut h = String::from(
        "<h2>Seat checks by camera</h2>\n<p>After a seated verdict, the release and the retreat, \
         a capture of the fixture with the arm out of the camera's view; the placed part's \
         outline aligned from its target pose (in simulation and production alike). <i>not \
         visible</i>: too few of the part's own edges (those off the nest's and the receiving \
         part's edges) were found; a part its receiver hides by construction is recorded so and \
         keeps its seat. <i>error</i>: measured against the true offset (simulation \
         only).</p>\n<table><tr><th class=l>step</th><th>checked</th><th>passed</th>\
         <th>failed</th><th>not visible</th><th>refused</th><th>offset p50 / max (mm)</th>\
         <th>support p50 / min</th><th>error mean / max (µm)</th></tr>\n",
    );
    let dash = || "–".to_string();
    for r in &rows {
        let offset = r
            .offset_mm
            .map_or_else(dash, |d| format!("{:.3} / {:.3}", d.p50, d.max));
        let support = r
            .support
            .map_or_else(dash, |d| format!("{:.2} / {:.2}", d.p50, d.min));
        let error = r
            .error_um
            .map_or_else(dash, |d| format!("{:.1} / {:.1}", d.mean, d.max));
        let _ = writeln!(
            h,
            "<tr><td class=l>{}: {}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td>\
             <td>{offset}</td><td>{support}</td><td>{error}</td></tr>",
            r.index,
            escape(&r.part),
            r.checked,
            r.passed,
            r.failed,
            r.not_visible,
            r.refused
        );
    }
    h.push_str("</table>\n");
    h
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::episode::{SeatCheckRecord, StepOutcome, StepRecord};

    fn step(part: &str, check: Option<SeatCheckRecord>) -> StepRecord {
        StepRecord {
            part: part.into(),
            outcome: StepOutcome::Seated,
            attempts: 1,
            insertion_attempts: 1,
            shakes: 0,
            cause: None,
            sources: vec![],
            pose_error: None,
            perception_error: None,
            perception_verdict: None,
            confidence: None,
            sim_time_s: 1.0,
            force: None,
            seat_check: check,
        }
    }

    fn check(verdict: SeatCheckVerdict, offset: Option<[f64; 2]>) -> SeatCheckRecord {
        SeatCheckRecord {
            verdict,
            offset_mm: offset,
            yaw_mrad: offset.map(|_| 1.0),
            support: offset.map(|_| 0.9),
            samples: 100,
            tolerance: [0.16, 35.0],
            true_offset_mm: offset.map(|_| [0.0, 0.0]),
        }
    }

    #[test]
    fn the_section_counts_each_verdict_per_step_and_shows_the_measured_offsets() {
        let record = |steps| EpisodeRecord {
            version: crate::episode::RECORD_VERSION,
            scenario: "s".into(),
            seed: 1,
            episode: 0,
            success: true,
            steps,
            cycle_time_s: 1.0,
            wall_time_s: 1.0,
            abort: None,
            phases: vec![],
        };
        let a = record(vec![
            step(
                "main_shell",
                Some(check(SeatCheckVerdict::Passed, Some([0.03, 0.04]))),
            ),
            step(
                "insert_mold",
                Some(check(SeatCheckVerdict::NotVisible, None)),
            ),
        ]);
        let b = record(vec![step(
            "main_shell",
            Some(check(SeatCheckVerdict::Failed, Some([0.3, 0.0]))),
        )]);
        let rows = seat_rows(&[&a, &b]);
        assert_eq!(rows.len(), 2);
        assert_eq!((rows[0].checked, rows[0].passed, rows[0].failed), (2, 1, 1));
        assert_eq!((rows[1].checked, rows[1].not_visible), (1, 1));
        let offset = rows[0].offset_mm.unwrap();
        assert!((offset.max - 0.3).abs() < 1e-12 && (offset.min - 0.05).abs() < 1e-12);
        assert!((rows[0].error_um.unwrap().max - 300.0).abs() < 1e-9);
        let html = seat_section(&[&a, &b]);
        assert!(html.contains("Seat checks by camera") && html.contains("0: main_shell"));
        // No check, no section.
        assert!(seat_section(&[&record(vec![step("main_shell", None)])]).is_empty());
    }
}
