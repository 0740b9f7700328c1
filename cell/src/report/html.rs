//! The HTML report: one small page (inline CSS, no scripts, nothing fetched from elsewhere)
//! with the headline rate, tables, the failed episodes with links to their event logs and
//! pictures, and plots as separate SVG files beside it.

use std::collections::BTreeMap;
use std::fmt::Write as _;

use super::plots;
use crate::episode::EpisodeRecord;
use crate::episode::StepOutcome;
use crate::run::Summary;
use crate::run::distribution::Distribution;
use crate::run::outcomes::outcome_name;

use super::escape::escape;

fn pct(x: f64) -> String {
    format!("{:.1}&nbsp;%", 100.0 * x)
}

/// A duration in seconds for people: milliseconds below a second, so a fast episode does not
/// read "0.00 s".
pub fn seconds_text(s: f64) -> String {
    if s >= 1.0 {
        format!("{s:.2} s")
    } else if s >= 1e-3 {
        format!("{:.1} ms", s * 1e3)
    } else {
        format!("{:.0} µs", s * 1e6)
    }
}

/// What the report's opening picture shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Opening {
    /// The first capture's pixels with the detections drawn (perception that reads pixels).
    Capture,
    /// The feeder rendered from above as the first capture found it, with what perception
    /// reported drawn (keypoint-noise perception, which reads no pixels).
    Feeder,
}

/// Where a report links for each episode: its event log and its pictures, and its opening
/// picture, as paths relative to the report.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct EpisodeLinks {
    /// Event log (JSON lines) by episode.
    pub events: BTreeMap<u32, String>,
    /// Pictures by episode.
    pub pictures: BTreeMap<u32, Vec<String>>,
    /// The opening picture (see [`crate::report::capture_picture::first_capture_picture`]).
    pub opening: Option<(String, Opening)>,
}

/// A rendered report: the page and the image files it refers to (relative path, bytes).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Page {
    /// The HTML text.
    pub html: String,
    /// Files to write beside it.
    pub files: Vec<(String, Vec<u8>)>,
}

/// Failed episodes listed in the report at most.
pub const MAX_LISTED_FAILURES: usize = 500;

/// Folder of the plots, relative to the report.
pub const PLOTS_DIR: &str = "plots";

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

/// The page's CSS. Every table fits a page 800 px wide without scrolling: at most 8 columns,
/// header text wraps, long text cells (`w`) wrap, numbers and names do not, pictures of a failed
/// episode get a row of their own.
pub const STYLE: &str = "body{font-family:sans-serif;max-width:1100px;margin:1em auto;padding:0 1em;color:#222}\
table{border-collapse:collapse;margin:1em 0;max-width:100%;font-size:15px}\
td,th{border:1px solid #ccc;padding:3px 6px;text-align:right;white-space:nowrap}\
th{background:#f3f3f3;white-space:normal;vertical-align:bottom}\
td.l,th.l{text-align:left}td.w{white-space:normal;overflow-wrap:anywhere}\
.big{font-size:1.6em}img.plot{max-width:100%;height:auto;display:block;margin:1em 0}\
td.pics{white-space:normal;text-align:left;border-top:none}\
img.pic{width:240px;max-width:31%;margin:2px;border:1px solid #ccc}\
figure.opening{margin:1em 0}figure.opening img{max-width:100%;height:auto;display:block}\
figcaption{font-size:14px;color:#555;margin-top:4px}\
code{background:#f3f3f3;padding:1px 4px;overflow-wrap:anywhere}";

/// Adds a plot file to `files` and an image of it to the page.
fn plot(h: &mut String, files: &mut Vec<(String, Vec<u8>)>, name: &str, alt: &str, svg: String) {
    let path = format!("{PLOTS_DIR}/{name}.svg");
    let _ = writeln!(
        h,
        "<img class=plot src=\"{}\" alt=\"{}\">",
        escape(&path),
        escape(alt)
    );
    files.push((path, svg.into_bytes()));
}

/// Renders the report of `summary` and its `records`, linking each failed episode to what
/// `links` holds for it.
pub fn render_html(
    s: &Summary,
    records: &BTreeMap<u32, EpisodeRecord>,
    links: &EpisodeLinks,
) -> Result<Page, plots::PlotError> {
    let recs: Vec<&EpisodeRecord> = records.values().collect();
    let mut files: Vec<(String, Vec<u8>)> = Vec::new();
    let mut h = String::new();
    let name = escape(&s.scenario);
    let _ = write!(
        h,
        "<!DOCTYPE html>\n<html lang=en><head><meta charset=utf-8><title>cell run: {name}</title>\
         <style>{STYLE}</style></head><body>\n<h1>Scenario <code>{name}</code></h1>\n"
    );
    let _ = writeln!(
        h,
        "<p class=big>{} of {} episodes assembled: <b>{}</b> (95&nbsp;% Wilson interval {} – {})</p>",
        s.successes,
        s.episodes,
        pct(s.success_rate),
        pct(s.success_ci95.lo),
        pct(s.success_ci95.hi)
    );
    let wall: f64 = recs.iter().map(|r| r.wall_time_s).sum();
    let _ = writeln!(
        h,
        "<p>seed {} · scenario file SHA-256 <code>{}</code> · record version {} · {} of \
         compute ({} per episode)</p>",
        s.seed,
        escape(&s.scenario_sha256),
        s.record_version,
        seconds_text(wall),
        seconds_text(wall / f64::from(s.episodes.max(1)))
    );

    opening(&mut h, links);

    h.push_str("<h2>Steps</h2>\n<table><tr><th class=l>step</th><th>reached</th><th>seated</th><th>jammed</th><th>missed</th><th>aborted</th><th>seated rate</th><th>95 % interval</th></tr>\n");
    for t in &s.steps {
        let _ = writeln!(
            h,
            "<tr><td class=l>{}: {}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{} – {}</td></tr>",
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
        );
    }
    h.push_str("</table>\n<table><tr><th class=l>step</th><th>attempts per episode</th><th>insertions per inserted episode</th><th>seated after a retry</th><th>shakes</th><th>lateral error p50 / p95 (mm)</th><th>tilt p95 (°)</th></tr>\n");
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
            "<tr><td class=l>{}: {}</td><td>{:.2}</td><td>{insertions}</td><td>{retried}</td><td>{}</td><td>{lat}</td><td>{tilt}</td></tr>",
            t.index,
            escape(&t.part),
            t.mean_attempts,
            t.shakes
        );
    }
    h.push_str("</table>\n");
    h.push_str(&super::force::force_section(&recs));
    h.push_str(&super::seat::seat_section(&recs));
    plot(
        &mut h,
        &mut files,
        "success_rate",
        "success rate per step with 95 % intervals",
        plots::success_rates(s)?,
    );

    h.push_str("<h2>Failures</h2>\n");
    if s.failures == 0 {
        h.push_str("<p>No episode failed.</p>\n");
    } else {
        h.push_str("<p>Failures grouped by mechanism; the numbers each cause carried are given as their range, and the first one (the offset, tilt, … that failed) as median and 95th percentile.</p>\n<table><tr><th class=l>step</th><th class=l>mechanism</th><th>episodes</th><th>share</th><th>median</th><th>p95</th><th class=l>causes</th></tr>\n");
        for m in &s.failure_mechanisms {
            let (p50, p95) = match &m.value {
                Some(v) => (format!("{:.3}", v.p50), format!("{:.3}", v.p95)),
                None => ("–".into(), "–".into()),
            };
            let _ = writeln!(
                h,
                "<tr><td class=l>{}</td><td class=\"l w\">{}</td><td>{}</td><td>{}</td><td>{p50}</td><td>{p95}</td><td class=\"l w\">{}</td></tr>",
                escape(m.part.as_deref().unwrap_or("episode")),
                escape(&m.mechanism),
                m.count,
                pct(f64::from(m.count) / f64::from(s.failures)),
                escape(&m.detail)
            );
        }
        h.push_str("</table>\n");
        plot(
            &mut h,
            &mut files,
            "failure_mechanisms",
            "failed episodes per failure mechanism",
            plots::failure_mechanisms(s, 12)?,
        );
        failed_episodes(&mut h, &recs, links);
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
        plot(
            &mut h,
            &mut files,
            "error_budget",
            "share of failures blamed on each error source",
            plots::error_budget(s)?,
        );
    }

    h.push_str("<h2>Cycle time</h2>\n<table><tr><th class=l></th><th>mean</th><th>median</th><th>p95</th><th>max</th></tr>\n");
    let _ = writeln!(
        h,
        "<tr><td class=l>successful episodes (s)</td>{}</tr></table>",
        dist_cells(&s.cycle_time_s, 1.0)
    );
    if !recs.is_empty() {
        plot(
            &mut h,
            &mut files,
            "cycle_time",
            "histogram of simulated cycle times",
            plots::cycle_time_histogram(&recs)?,
        );
    }
    cycle_phases(&mut h, &mut files, s, &recs)?;
    h.push_str("<h2>Pose error at insertion</h2>\n<p>True offset of the held part from its target in the target frame when insertion started. The dashed square is the step's capture band (clearance / 2 + lead-in): outside it a part misses; inside it, a failure is a tilt or yaw.</p>\n");
    for t in &s.steps {
        plot(
            &mut h,
            &mut files,
            &format!("pose_error_step{}", t.index),
            &format!("pose error at insertion of step {}", t.index),
            plots::pose_error_scatter(s, t.index, &recs)?,
        );
    }
    h.push_str("</body></html>\n");
    Ok(Page { html: h, files })
}

/// A table of (name, mean seconds, share) rows headed `what`.
fn mean_table<'a>(h: &mut String, what: &str, rows: impl Iterator<Item = (&'a str, f64, f64)>) {
    let _ = writeln!(
        h,
        "<table><tr><th class=l>{what}</th><th>mean (s)</th><th>share</th></tr>"
    );
    for (name, mean, share) in rows {
        let _ = writeln!(
            h,
            "<tr><td class=l>{name}</td><td>{mean:.3}</td><td>{}</td></tr>",
            pct(share)
        );
    }
    h.push_str("</table>\n");
}

/// Where the cycle time goes: the mean seconds per state, and the timelines of a typical and
/// of the slowest successful episode.
fn cycle_phases(
    h: &mut String,
    files: &mut Vec<(String, Vec<u8>)>,
    s: &Summary,
    recs: &[&EpisodeRecord],
) -> Result<(), plots::PlotError> {
    if s.cycle_phases.is_empty() {
        return Ok(());
    }
    h.push_str("<h3>Where the time goes</h3>\n<p>Mean simulated seconds per successful assembly in each state of the orchestrator, on the cycle's critical path: work overlapped with a move (a shake started during an insertion) counts in the move, and <code>capture</code> includes waiting for the feeder to settle after a shake.</p>\n");
    mean_table(
        h,
        "state",
        s.cycle_phases
            .iter()
            .map(|m| (m.state.name(), m.mean_s, m.share)),
    );
    if !s.cycle_activities.is_empty() {
        h.push_str("<p>The same time by activity: each state's time split at the end of its motions.</p>\n");
        mean_table(
            h,
            "activity",
            s.cycle_activities
                .iter()
                .map(|m| (m.activity.name(), m.mean_s, m.share)),
        );
    }
    if let Some((typical, slowest)) = crate::run::phases::typical_and_slowest(recs.iter().copied())
    {
        let mut rows = vec![(
            format!(
                "typical: {} ({:.1} s)",
                typical.episode, typical.cycle_time_s
            ),
            typical,
        )];
        if slowest.episode != typical.episode {
            rows.push((
                format!(
                    "slowest: {} ({:.1} s)",
                    slowest.episode, slowest.cycle_time_s
                ),
                slowest,
            ));
        }
        plot(
            h,
            files,
            "cycle_timeline",
            "timelines of a typical and of the slowest successful episode, coloured by state",
            super::timeline::cycle_timeline(&rows)?,
        );
    }
    Ok(())
}

/// The opening picture, where there is one: a capture with what perception found in it.
fn opening(h: &mut String, links: &EpisodeLinks) {
    let Some((path, kind)) = &links.opening else {
        return;
    };
    let caption = match kind {
        Opening::Capture => {
            "The first episode's first capture (the camera's feeder window) with what perception \
             found in it: each posed part outlined at its estimated pose (its mesh projected) \
             and labelled with its confidence, keypoints yellow crosses, centre a magenta square; \
             parts found but not posed outlined cyan where they meet the table."
        }
        Opening::Feeder => {
            "The feeder as the first episode's first capture found it. This scenario's \
             perception (keypoint noise) reads no pixels: it perturbs the parts' true keypoints. \
             So the feeder is rendered from above with the parts at their true poses, and each \
             part perception reported is outlined at its estimated pose and labelled with its \
             confidence, keypoints yellow crosses, centre a magenta square."
        }
    };
    let _ = writeln!(
        h,
        "<figure class=opening><a href=\"{0}\"><img src=\"{0}\" alt=\"first capture with detections\"></a><figcaption>{1}</figcaption></figure>",
        escape(path),
        escape(caption)
    );
}

/// The failed episodes: failing step, outcome, cause, and links to the event log and pictures.
fn failed_episodes(h: &mut String, recs: &[&EpisodeRecord], links: &EpisodeLinks) {
    let failed: Vec<&&EpisodeRecord> = recs.iter().filter(|r| !r.success).collect();
    let _ = writeln!(
        h,
        "<h2>Failed episodes</h2>\n<p>{} failed{}. Replay one with <code>cell replay RESULTS --episode N</code>. An episode's pictures, where drawn, are in the row below it.</p>\n<table><tr><th>episode</th><th class=l>step</th><th class=l>outcome</th><th class=l>cause</th><th class=l>events</th></tr>",
        failed.len(),
        if failed.len() > MAX_LISTED_FAILURES {
            format!(" (the first {MAX_LISTED_FAILURES} listed)")
        } else {
            String::new()
        }
    );
    for r in failed.iter().take(MAX_LISTED_FAILURES) {
        let step = r.steps.iter().find(|s| s.outcome != StepOutcome::Seated);
        let (part, outcome, cause) = match step {
            Some(s) => (
                s.part.as_str(),
                outcome_name(s.outcome),
                s.cause.as_deref().unwrap_or(""),
            ),
            None => ("episode", "stopped", r.abort.as_deref().unwrap_or("")),
        };
        let events = links.events.get(&r.episode).map_or("–".to_string(), |p| {
            format!("<a href=\"{}\">events</a>", escape(p))
        });
        let _ = writeln!(
            h,
            "<tr id=\"episode-{0}\"><td>{0}</td><td class=l>{1}</td><td class=l>{2}</td><td class=\"l w\">{3}</td><td class=l>{events}</td></tr>",
            r.episode,
            escape(part),
            outcome,
            escape(cause)
        );
        if let Some(ps) = links.pictures.get(&r.episode) {
            let pictures: String = ps
                .iter()
                .map(|p| {
                    format!(
                        "<a href=\"{0}\"><img class=pic src=\"{0}\" alt=\"episode {1}\"></a>",
                        escape(p),
                        r.episode
                    )
                })
                .collect();
            let _ = writeln!(h, "<tr><td class=pics colspan=5>{pictures}</td></tr>");
        }
    }
    h.push_str("</table>\n");
}
