//! The report a person opens: small, images beside it, failures grouped by mechanism, each
//! failed episode listed with a link to its event log.

mod support;

use cell::report::plots::{rate_axis_floor, tick_decimals};
use support::{cell, text};

#[test]
fn ticks_0_05_apart_print_with_two_decimals() {
    // An axis to 0.5 with ten ticks: 0.05 apart.
    let d = tick_decimals(0.5, 10);
    let labels: Vec<String> = (0..=10)
        .map(|i| format!("{:.d$}", f64::from(i) * 0.05))
        .collect();
    let mut unique = labels.clone();
    unique.dedup();
    assert_eq!(unique.len(), labels.len(), "{labels:?}");
    assert_eq!(tick_decimals(100.0, 10), 0);
}

#[test]
fn the_rate_axis_starts_where_99_5_and_100_percent_differ() {
    // 99.5 % (interval down to 97.2 %) and 100 %: the axis starts well above 0.
    let floor = rate_axis_floor(&[97.2, 98.1, 100.0]);
    assert!((90.0..97.2).contains(&floor), "{floor}");
    // A rate far from 100 % keeps the axis at 0.
    assert_eq!(rate_axis_floor(&[40.2, 97.0]), 0.0);
}

#[test]
fn a_noisy_run_reports_mechanisms_and_links_every_failed_episode_to_its_events() {
    let tmp = tempfile::tempdir().unwrap();
    let scenario = support::NoisyScenario::new("report");
    let out = tmp.path().display().to_string();
    let o = cell(&[
        "run",
        &scenario.path().display().to_string(),
        "--episodes",
        "40",
        "--pictures",
        "2",
        "--out",
        &out,
        "--quiet",
    ]);
    assert!(
        text(&o).contains("pictures of 2 failed episodes"),
        "{}",
        text(&o)
    );
    assert!(o.status.success(), "{}", text(&o));
    let dir = tmp.path().join("usbc-nominal/all");
    let html = std::fs::read_to_string(dir.join("report.html")).unwrap();
    // Plots are files beside the page, not inlined.
    assert!(!html.contains("<svg"), "inline SVG");
    for src in html.split("src=\"").skip(1) {
        let path = &src[..src.find('"').unwrap()];
        assert!(dir.join(path).is_file(), "{path} missing");
    }
    assert!(html.contains("plots/pose_error_step1.svg"));
    let scatter = std::fs::read_to_string(dir.join("plots/pose_error_step1.svg")).unwrap();
    assert!(
        scatter.contains("capture band ±0.145 mm"),
        "no capture band"
    );
    // Numbers do not wrap between value and unit.
    assert!(html.contains("&nbsp;%"));
    // Legends lie beside the data, not over it.
    for (plot, labels) in [
        (
            "plots/pose_error_step1.svg",
            &["capture band ±0.145 mm", "seated", "missed"][..],
        ),
        ("plots/cycle_time.svg", &["succeeded", "failed"][..]),
        ("plots/cycle_timeline.svg", &["pick", "insert"][..]),
    ] {
        let svg = std::fs::read_to_string(dir.join(plot)).unwrap();
        assert_legend_beside_the_data(plot, &svg, labels);
    }
    // Where the time goes: a table of the states' mean seconds that add up to the mean cycle,
    // and the timelines of a typical and of the slowest successful episode.
    assert!(html.contains("Where the time goes"));
    assert!(html.contains("plots/cycle_timeline.svg"));
    let timeline = std::fs::read_to_string(dir.join("plots/cycle_timeline.svg")).unwrap();
    assert!(timeline.contains("typical: ") && timeline.contains("slowest: "));
    // Tables fit 800 px.
    assert_tables_fit_800_px("run report", &html, cell::report::html::STYLE);
    // The page opens with the first episode's first capture: keypoint-noise perception reads
    // no pixels, so the rendered feeder with what perception reported.
    let first_img = html.split("<img").nth(1).unwrap();
    assert!(
        first_img.contains("src=\"pictures/first-feeder.png\""),
        "{first_img}"
    );
    assert!(html.contains("reads no pixels"));
    let opening = image::open(dir.join("pictures/first-feeder.png"))
        .unwrap()
        .to_rgb8();
    assert!(opening.width() >= 600);
    // Outlines of the perceived parts are drawn, in the catalog colours.
    assert!(
        opening
            .pixels()
            .any(|p| p.0 == [255, 140, 30] || p.0 == [80, 230, 80]),
        "no detection outline"
    );
    // Failures grouped by mechanism, far fewer rows than failures.
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("summary.json")).unwrap()).unwrap();
    let failures = summary["failures"].as_u64().unwrap();
    let mechanisms = summary["failure_mechanisms"].as_array().unwrap();
    let phases = summary["cycle_phases"].as_array().unwrap();
    let phased: f64 = phases.iter().map(|p| p["mean_s"].as_f64().unwrap()).sum();
    let mean_cycle = summary["cycle_time_s"]["mean"].as_f64().unwrap();
    assert!(
        (phased - mean_cycle).abs() < 1e-9,
        "phases {phased} s against the mean cycle {mean_cycle} s"
    );
    assert!(failures >= 8, "only {failures} failures at 3 px");
    assert!(mechanisms.len() <= 6, "{mechanisms:?}");
    let grouped: u64 = mechanisms
        .iter()
        .map(|m| m["count"].as_u64().unwrap())
        .sum();
    assert_eq!(grouped, failures);
    assert!(html.contains("missed: lateral offset beyond the capture band"));
    // Every failed episode is listed, linked to an event log that exists.
    let records = std::fs::read_to_string(dir.join("episodes.jsonl")).unwrap();
    let failed: Vec<u64> = records
        .lines()
        .skip(1)
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .filter(|r| r["success"] == false)
        .map(|r| r["episode"].as_u64().unwrap())
        .collect();
    assert_eq!(failed.len() as u64, failures);
    for e in failed {
        let link = format!("events/episode-{e:06}.jsonl");
        assert!(
            html.contains(&format!("href=\"{link}\"")),
            "{link} not linked"
        );
        assert!(dir.join(&link).is_file());
    }
}

/// An axis-aligned box in SVG pixels: left, top, right, bottom.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Box2 {
    l: f64,
    t: f64,
    r: f64,
    b: f64,
}

impl Box2 {
    fn union(self, o: Box2) -> Box2 {
        Box2 {
            l: self.l.min(o.l),
            t: self.t.min(o.t),
            r: self.r.max(o.r),
            b: self.b.max(o.b),
        }
    }
    /// Whether the interiors overlap (touching edges do not).
    fn overlaps(&self, o: &Box2) -> bool {
        self.l < o.r && o.l < self.r && self.t < o.b && o.t < self.b
    }
    fn holds(&self, x: f64, y: f64) -> bool {
        (self.l - 0.5..=self.r + 0.5).contains(&x) && (self.t - 0.5..=self.b + 0.5).contains(&y)
    }
}

/// The elements `<name .../>` of an SVG, each as its attribute text.
fn svg_tags<'a>(svg: &'a str, name: &str) -> Vec<&'a str> {
    let open = format!("<{name} ");
    svg.split(open.as_str())
        .skip(1)
        .map(|t| &t[..t.find('>').unwrap_or(t.len())])
        .collect()
}

fn svg_attr<'a>(tag: &'a str, name: &str) -> Option<&'a str> {
    let key = format!(" {name}=\"");
    let at = format!(" {tag}").find(&key)?;
    let rest = &tag[at + key.len() - 1..];
    Some(&rest[..rest.find('"')?])
}

fn svg_num(tag: &str, name: &str) -> f64 {
    svg_attr(tag, name)
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no number {name} in <{tag}>"))
}

/// The legend boxes of a plotters SVG: its outlined, unfilled rectangles.
fn legend_boxes(svg: &str) -> Vec<Box2> {
    svg_tags(svg, "rect")
        .into_iter()
        .filter(|t| svg_attr(t, "fill") == Some("none") && svg_attr(t, "stroke") == Some("#000000"))
        .map(|t| {
            let (x, y) = (svg_num(t, "x"), svg_num(t, "y"));
            Box2 {
                l: x,
                t: y,
                r: x + svg_num(t, "width"),
                b: y + svg_num(t, "height"),
            }
        })
        .collect()
}

/// The plot's data region: the extent of its grid (the faint mesh lines span it edge to edge).
fn data_region(svg: &str) -> Option<Box2> {
    let mut region: Option<Box2> = None;
    let mut add = |b: Box2| region = Some(region.map_or(b, |r| r.union(b)));
    for t in svg_tags(svg, "line") {
        if svg_attr(t, "opacity").is_some_and(|o| o.parse::<f64>().unwrap() < 1.0) {
            let (x1, y1, x2, y2) = (
                svg_num(t, "x1"),
                svg_num(t, "y1"),
                svg_num(t, "x2"),
                svg_num(t, "y2"),
            );
            add(Box2 {
                l: x1.min(x2),
                t: y1.min(y2),
                r: x1.max(x2),
                b: y1.max(y2),
            });
        }
    }
    for t in svg_tags(svg, "polyline") {
        if svg_attr(t, "opacity").is_some_and(|o| o.parse::<f64>().unwrap() < 1.0) {
            let pts: Vec<(f64, f64)> = svg_attr(t, "points")
                .unwrap()
                .split_whitespace()
                .map(|p| {
                    let (x, y) = p.split_once(',').unwrap();
                    (x.parse().unwrap(), y.parse().unwrap())
                })
                .collect();
            for (x, y) in pts {
                add(Box2 {
                    l: x,
                    t: y,
                    r: x,
                    b: y,
                });
            }
        }
    }
    region
}

/// The texts of an SVG with their anchor points.
fn svg_texts(svg: &str) -> Vec<(String, f64, f64)> {
    svg.split("<text ")
        .skip(1)
        .filter_map(|t| {
            let (attrs, rest) = t.split_once('>')?;
            let body = &rest[..rest.find("</text>")?];
            Some((
                body.trim().to_string(),
                svg_num(attrs, "x"),
                svg_num(attrs, "y"),
            ))
        })
        .collect()
}

/// Asserts that the SVG has a legend holding each of `labels`, inside the picture, and that it
/// does not overlap the plot's data region; and that every data point (circle) outside the
/// legend lies in that region (so the region found is the real one).
fn assert_legend_beside_the_data(name: &str, svg: &str, labels: &[&str]) {
    let root = svg_tags(svg, "svg")[0];
    let (w, h) = (svg_num(root, "width"), svg_num(root, "height"));
    let region = data_region(svg).unwrap_or_else(|| panic!("{name}: no grid"));
    assert!(
        region.r - region.l > 100.0 && region.b - region.t > 100.0,
        "{name}: {region:?}"
    );
    let legends = legend_boxes(svg);
    assert!(!legends.is_empty(), "{name}: no legend");
    for legend in &legends {
        assert!(
            legend.r - legend.l > 40.0 && legend.b - legend.t > 15.0,
            "{name}: the legend {legend:?} is squashed"
        );
        assert!(
            !legend.overlaps(&region),
            "{name}: the legend {legend:?} covers the data region {region:?}"
        );
        assert!(
            legend.l >= 0.0 && legend.t >= 0.0 && legend.r <= w && legend.b <= h,
            "{name}: the legend {legend:?} sticks out of the {w} × {h} picture"
        );
    }
    let texts = svg_texts(svg);
    for label in labels {
        let (_, x, y) = texts
            .iter()
            .find(|t| t.0 == *label)
            .unwrap_or_else(|| panic!("{name}: no text {label:?}"));
        assert!(
            legends.iter().any(|l| l.holds(*x, *y)),
            "{name}: {label:?} at ({x}, {y}) is not in a legend {legends:?}"
        );
    }
    for c in svg_tags(svg, "circle") {
        let (x, y) = (svg_num(c, "cx"), svg_num(c, "cy"));
        assert!(
            region.holds(x, y) || legends.iter().any(|l| l.holds(x, y)),
            "{name}: a point at ({x}, {y}) outside {region:?}"
        );
    }
}

#[test]
fn the_legend_check_catches_a_legend_over_the_data() {
    // A grid from (100, 50) to (500, 350) with a legend box inside it, as plotters drew legends
    // before: the check must fail.
    let svg = r##"<svg width="700" height="400" viewBox="0 0 700 400">
<line opacity="0.1" stroke="#000000" stroke-width="1" x1="100" y1="50" x2="100" y2="350"/>
<line opacity="0.1" stroke="#000000" stroke-width="1" x1="100" y1="350" x2="500" y2="350"/>
<polyline fill="none" opacity="0.2" stroke="#000000" stroke-width="1" points="500,50 500,350 "/>
<rect x="380" y="60" width="110" height="60" opacity="1" fill="none" stroke="#000000"/>
</svg>"##;
    let caught = std::panic::catch_unwind(|| assert_legend_beside_the_data("inside", svg, &[]));
    assert!(caught.is_err(), "a legend over the data passed");
    // The same legend moved right of the grid passes.
    let beside = svg.replace("x=\"380\"", "x=\"520\"");
    assert_legend_beside_the_data("beside", &beside, &[]);
    // A legend squashed against the grid's edge (plotters clips a legend it is asked to draw
    // outside the plotting area) fails.
    let squashed = svg.replace(
        "x=\"380\" y=\"60\" width=\"110\"",
        "x=\"500\" y=\"60\" width=\"0\"",
    );
    let caught =
        std::panic::catch_unwind(|| assert_legend_beside_the_data("squashed", &squashed, &[]));
    assert!(caught.is_err(), "a squashed legend passed");
}

/// The widest row of each table of `html`, in columns (colspan counted).
fn table_columns(html: &str) -> Vec<usize> {
    html.split("<table")
        .skip(1)
        .map(|t| {
            let t = &t[..t.find("</table>").unwrap_or(t.len())];
            t.split("<tr")
                .skip(1)
                .map(|row| {
                    row.split('<')
                        .filter(|c| c.starts_with("td") || c.starts_with("th"))
                        .filter(|c| c.len() == 2 || c[2..].starts_with([' ', '>']))
                        .map(|c| {
                            c.split("colspan=").nth(1).map_or(1, |n| {
                                n.trim_start_matches('"')
                                    .chars()
                                    .take_while(char::is_ascii_digit)
                                    .collect::<String>()
                                    .parse()
                                    .unwrap()
                            })
                        })
                        .sum()
                })
                .max()
                .unwrap_or(0)
        })
        .collect()
}

/// Widest table that fits 800 px with the pages' CSS (wrapping headers, 15 px text).
const MAX_COLUMNS: usize = 9;

/// Asserts that `html`'s tables fit a page 800 px wide: no sideways scrolling box, at most
/// [`MAX_COLUMNS`] columns, and CSS that lets header and text cells wrap and keeps tables and
/// pictures within the page.
fn assert_tables_fit_800_px(name: &str, html: &str, style: &str) {
    assert!(
        html.contains(style),
        "{name}: the page does not use its STYLE"
    );
    assert!(
        !style.contains("overflow-x"),
        "{name}: a box scrolls sideways"
    );
    let rule = |selector: &str| {
        style
            .split('}')
            .find(|r| r.split('{').next() == Some(selector))
            .unwrap_or_else(|| panic!("{name}: no CSS rule for {selector}"))
            .to_string()
    };
    assert!(
        rule("th").contains("white-space:normal"),
        "{name}: headers do not wrap"
    );
    assert!(
        ["td.l", "td.w"]
            .iter()
            .any(|s| style.contains(&format!("{s}{{white-space:normal"))),
        "{name}: text cells do not wrap"
    );
    assert!(
        rule("table").contains("max-width:100%"),
        "{name}: tables may be wider than the page"
    );
    assert!(
        rule("img.plot").contains("max-width:100%"),
        "{name}: plots may be wider than the page"
    );
    let columns = table_columns(html);
    assert!(!columns.is_empty(), "{name}: no tables");
    for (i, n) in columns.iter().enumerate() {
        assert!(
            *n <= MAX_COLUMNS,
            "{name}: table {i} has {n} columns (at most {MAX_COLUMNS} fit 800 px)"
        );
    }
}

#[test]
fn the_table_check_catches_a_wide_table() {
    let style = cell::report::html::STYLE;
    let narrow = format!(
        "<style>{style}</style><table><tr><th>a</th><th colspan=2>b</th></tr><tr><td>1</td><td>2</td><td>3</td></tr></table>"
    );
    assert_eq!(table_columns(&narrow), vec![3]);
    assert_tables_fit_800_px("narrow", &narrow, style);
    // The steps table as it was: 14 columns.
    let wide = format!(
        "<style>{style}</style><table><tr>{}</tr></table>",
        "<th>x</th>".repeat(14)
    );
    let caught = std::panic::catch_unwind(|| assert_tables_fit_800_px("wide", &wide, style));
    assert!(caught.is_err(), "a 14-column table passed");
}

#[test]
fn the_eval_report_fits_800_px_and_its_legends_lie_beside_the_curves() {
    use cell::eval::report_html::{EvalMeta, STYLE, cdf_plot_svg, write_eval_report};
    use cell::eval::{EvalOptions, EvalRun};
    let options = EvalOptions::default();
    let parts: Vec<(String, f64)> = ["main_shell", "insert_mold", "top_shell"]
        .iter()
        .map(|p| (p.to_string(), 0.012))
        .collect();
    let summary = cell::eval::summary::summarise(&[], &parts, &options);
    let run = EvalRun {
        frames: vec![],
        gallery: vec![],
        misplaced: vec![],
        failures: vec![],
        missed: vec![],
        false_positives: vec![],
    };
    let meta = EvalMeta {
        dataset: "ds".into(),
        split: "test_feeder".into(),
        catalog: "scenarios/parts/usbc.toml".into(),
        models: "scenarios/models/usbc".into(),
        options,
    };
    let tmp = tempfile::tempdir().unwrap();
    let files = write_eval_report(tmp.path(), &meta, &summary, &run).unwrap();
    let html = std::fs::read_to_string(files.html).unwrap();
    assert_tables_fit_800_px("eval report", &html, STYLE);

    // The CDF plots' layout, drawn as SVG: six curves (three parts, PnP and refined), one of
    // them reaching the top left where a legend used to sit.
    let series: Vec<(String, [u8; 3], bool, Vec<f64>)> = parts
        .iter()
        .enumerate()
        .flat_map(|(i, (p, _))| {
            [false, true].map(|refined| {
                let label = format!("{p} {}", if refined { "refined" } else { "PnP" });
                let values = (0..50)
                    .map(|k| f64::from(k) * 0.1 * (i + 1) as f64)
                    .collect();
                (label, [40 * i as u8, 100, 200], !refined, values)
            })
        })
        .collect();
    let svg = cdf_plot_svg("Rotation error", "e_θ (deg)", 30.0, &series).unwrap();
    let labels: Vec<&str> = series.iter().map(|s| s.0.as_str()).collect();
    assert_legend_beside_the_data("angle CDF", &svg, &labels);
}
