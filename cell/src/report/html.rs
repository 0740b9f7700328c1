//! The HTML report: one self-contained file (inline CSS and SVG, no scripts, no external
//! resources) with the headline rate, tables and plots.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use super::plots;
use crate::episode::EpisodeRecord;
use crate::run::Summary;
use crate::run::summary::{Distribution, outcome_name};

/// Escapes text for HTML element content and attribute values.
pub fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

fn pct(x: f64) -> String {
    format!("{:.1} %", 100.0 * x)
}

fn dist_cells(d: &Option<Distribution>, scale: f64) -> String {
    match d {
        Some(d) => format!(
            "<td>{:.3}</td><td>{:.3}</td><td>{:.3}</td><td>{:.3}</td>",
            d.mean * scale,
            d.p50 * scale,
            d.p95 * scale,
            d.max * scale
        ),
        None => "<td colspan=4>–</td>".into(),
    }
}

const STYLE: &str = "body{font-family:sans-serif;max-width:1400px;margin:2em auto;padding:0 1em;color:#222}\
table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;padding:4px 8px;text-align:right}\
th{background:#f3f3f3}td.l,th.l{text-align:left}.big{font-size:1.6em}svg{max-width:100%;height:auto;display:block;margin:1em 0}\
code{background:#f3f3f3;padding:1px 4px}";

/// Renders the report of `summary` and its `records`.
pub fn render_html(
    s: &Summary,
    records: &BTreeMap<u32, EpisodeRecord>,
) -> Result<String, plots::PlotError> {
    let recs: Vec<&EpisodeRecord> = records.values().collect();
    let mut h = String::new();
    let name = escape(&s.scenario);
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=en><head><meta charset=utf-8><title>cell run: {name}</title>\
         <style>{STYLE}</style></head><body>\n<h1>Scenario <code>{name}</code></h1>\n"
    );
    let _ = writeln!(
        h,
        "<p class=big>{} of {} episodes assembled: <b>{}</b> (95 % Wilson interval {} – {})</p>",
        s.successes,
        s.episodes,
        pct(s.success_rate),
        pct(s.success_ci95.lo),
        pct(s.success_ci95.hi)
    );
    let wall: f64 = recs.iter().map(|r| r.wall_time_s).sum();
    let _ = writeln!(
        h,
        "<p>seed {} · scenario file SHA-256 <code>{}</code> · record version {} · {:.1} s of \
         compute ({:.2} s per episode)</p>",
        s.seed,
        escape(&s.scenario_sha256),
        s.record_version,
        wall,
        wall / f64::from(s.episodes.max(1))
    );

    h.push_str("<h2>Steps</h2>\n<table><tr><th class=l>step</th><th>reached</th><th>seated</th><th>jammed</th><th>missed</th><th>aborted</th><th>seated rate</th><th>95 % interval</th><th>attempts / episode</th><th>insertions / inserted episode</th><th>seated after a retry</th><th>shakes</th><th>lateral error p50 / p95 (mm)</th><th>tilt p95 (°)</th></tr>\n");
    for t in &s.steps {
        let (lat, tilt) = match &t.pose_error {
            Some(e) => (
                format!("{:.3} / {:.3}", e.lateral_mm.p50, e.lateral_mm.p95),
                format!("{:.2}", e.tilt_deg.p95),
            ),
            None => ("–".into(), "–".into()),
        };
        // No insertion counted (none reached insertion, or records from before insertions were
        // counted): dashes, not zeros.
        let (insertions, retried) = match t.mean_insertion_attempts {
            Some(m) => (format!("{m:.2}"), t.seated_after_retry.to_string()),
            None => ("–".into(), "–".into()),
        };
        let _ = writeln!(
            h,
            "<tr><td class=l>{}: {}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{} – {}</td><td>{:.2}</td><td>{insertions}</td><td>{retried}</td><td>{}</td><td>{lat}</td><td>{tilt}</td></tr>",
            t.index,
            escape(&t.part),
            t.reached,
            t.seated,
            t.jammed,
            t.missed,
            t.aborted,
            pct(t.rate),
            pct(t.ci95.lo),
            pct(t.ci95.hi),
            t.mean_attempts,
            t.shakes
        );
    }
    h.push_str("</table>\n");
    h.push_str(&plots::success_rates(s)?);

    h.push_str("<h2>Failures</h2>\n");
    if s.failures == 0 {
        h.push_str("<p>No episode failed.</p>\n");
    } else {
        h.push_str("<table><tr><th class=l>step</th><th class=l>outcome</th><th class=l>cause</th><th>episodes</th><th>share</th></tr>\n");
        for c in &s.failure_causes {
            let _ = writeln!(
                h,
                "<tr><td class=l>{}</td><td class=l>{}</td><td class=l>{}</td><td>{}</td><td>{}</td></tr>",
                escape(c.part.as_deref().unwrap_or("episode")),
                c.outcome.map_or("stopped", outcome_name),
                escape(&c.cause),
                c.count,
                pct(f64::from(c.count) / f64::from(s.failures))
            );
        }
        h.push_str("</table>\n");
        h.push_str(&plots::failure_causes(s, 12)?);
        h.push_str("<h2>Error budget</h2>\n<p>Each failed episode is charged to the error sources its failing step blamed (an episode may blame several, so shares can add up to more than 100 %).</p>\n<table><tr><th class=l>error source</th><th>failed episodes</th><th>share</th></tr>\n");
        for e in &s.error_budget {
            let _ = writeln!(
                h,
                "<tr><td class=l>{}</td><td>{}</td><td>{}</td></tr>",
                escape(&e.source),
                e.failures,
                pct(e.share)
            );
        }
        h.push_str("</table>\n");
        h.push_str(&plots::error_budget(s)?);
    }

    h.push_str("<h2>Cycle time</h2>\n<table><tr><th class=l></th><th>mean</th><th>median</th><th>p95</th><th>max</th></tr>\n");
    let _ = writeln!(
        h,
        "<tr><td class=l>successful episodes (s)</td>{}</tr></table>",
        dist_cells(&s.cycle_time_s, 1.0)
    );
    if !recs.is_empty() {
        h.push_str(&plots::cycle_time_histogram(&recs)?);
    }
    h.push_str("<h2>Pose error at insertion</h2>\n<p>True offset of the held part from its target in the target frame when insertion started.</p>\n");
    h.push_str(&plots::pose_error_scatter(s, &recs)?);
    h.push_str("</body></html>\n");
    Ok(h)
}
