//! The evaluation's files: `eval.json` (settings, summary, every frame's records), the estimates
//! as a BOP results file ([`bop_results`]), `eval.html` (one page, inline CSS, nothing fetched),
//! PNG plots in `plots/` and the galleries in `gallery/`, each written atomically.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use image::ImageEncoder;
use image::codecs::png::PngEncoder;
use plotters::prelude::*;
use serde::Serialize;

use super::bop_results;
use super::causes::found_as_text;
use super::detection_gallery::{DetectionErrorCrop, DetectionErrorKind};
use super::gallery::{FailedCrop, GalleryItem};
use super::picks::Picks;
use super::stable_poses::StablePoseRow;
use super::summary::{EvalSummary, MSPD_PX, MSSD_FRACTIONS, PartSummary};
use super::table1::{Table1Row, seed_row};
use super::{EvalOptions, EvalRun, FrameRecord};
use crate::report::escape::escape;

/// Name of the JSON results.
pub const JSON_FILE: &str = "eval.json";
/// Name of the HTML page.
pub const HTML_FILE: &str = "eval.html";
/// Folder of the plots.
pub const PLOTS_DIR: &str = "plots";
/// Folder of the gallery pictures.
pub const GALLERY_DIR: &str = "gallery";

/// Why the report could not be written.
#[derive(Debug, thiserror::Error)]
pub enum EvalReportError {
    /// A file or folder could not be written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The path.
        path: PathBuf,
        /// The failure.
        source: std::io::Error,
    },
    /// A plot or picture could not be drawn or encoded.
    #[error("{name}: {message}")]
    Draw {
        /// The file.
        name: String,
        /// What failed.
        message: String,
    },
}

/// What was evaluated, for the record.
#[derive(Debug, Clone, Serialize)]
pub struct EvalMeta {
    /// Dataset folder.
    pub dataset: PathBuf,
    /// Split read.
    pub split: String,
    /// Part catalog.
    pub catalog: PathBuf,
    /// Model folder.
    pub models: PathBuf,
    /// Settings.
    pub options: EvalOptions,
}

#[derive(Serialize)]
struct JsonOut<'a> {
    meta: &'a EvalMeta,
    summary: &'a EvalSummary,
    frames: &'a [FrameRecord],
}

/// The main files a report wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EvalFiles {
    /// eval.json.
    pub json: PathBuf,
    /// The BOP Challenge results file.
    pub bop_results: PathBuf,
    /// eval.html.
    pub html: PathBuf,
}

/// Writes eval.json, the BOP results, eval.html, the plots and the galleries into `out`
/// (created).
pub fn write_eval_report(
    out: &Path,
    meta: &EvalMeta,
    summary: &EvalSummary,
    run: &EvalRun,
) -> Result<EvalFiles, EvalReportError> {
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source| EvalReportError::Io { path, source }
    };
    for dir in [
        out.to_path_buf(),
        out.join(PLOTS_DIR),
        out.join(GALLERY_DIR),
    ] {
        std::fs::create_dir_all(&dir).map_err(io(&dir))?;
    }
    let write = |rel: &str, bytes: &[u8]| {
        let path = out.join(rel);
        sim::fsutil::write_atomic(&path, bytes).map_err(io(&path))
    };
    let mut json = serde_json::to_string_pretty(&JsonOut {
        meta,
        summary,
        frames: &run.frames,
    })
    .map_err(|e| EvalReportError::Draw {
        name: JSON_FILE.into(),
        message: e.to_string(),
    })?;
    json.push('\n');
    write(JSON_FILE, json.as_bytes())?;
    let dataset_name = meta
        .dataset
        .file_name()
        .unwrap_or_default()
        .to_string_lossy();
    let bop_file = bop_results::file_name(&dataset_name, &meta.split);
    write(&bop_file, bop_results::results_csv(&run.frames).as_bytes())?;

    let mut plots = Vec::new();
    for (name, title, x_label, x_max, get) in [
        (
            "angle_cdf",
            "Rotation error: share of matched estimates below e_θ",
            "e_θ (deg)",
            30.0,
            (|e: &perception::metrics::PoseErrors| e.sym_angle_deg)
                as fn(&perception::metrics::PoseErrors) -> f64,
        ),
        (
            "depth_cdf",
            "Depth error: share of matched estimates below |e_z|",
            "|e_z| (mm)",
            100.0,
            |e| e.z_mm,
        ),
    ] {
        let rel = format!("{PLOTS_DIR}/{name}.png");
        let png = cdf_plot(&rel, title, x_label, x_max, &series(run, summary, get))?;
        write(&rel, &png)?;
        plots.push((rel, title));
    }
    // Each gallery picture as gallery/NAME, and its path for the page (a crop in two galleries
    // is the same picture).
    let save = |name: String, crop: &image::RgbImage| {
        let rel = format!("{GALLERY_DIR}/{name}");
        write(&rel, &encode_png(&rel, crop)?)?;
        Ok::<_, EvalReportError>(rel)
    };
    let worst = saved(&run.gallery, |i| save(i.file_name(), &i.crop))?;
    let misplaced = saved(&run.misplaced, |i| save(i.file_name(), &i.crop))?;
    let failed = saved(&run.failures, |i| save(i.file_name(), &i.crop))?;
    let missed = saved(&run.missed, |i| save(i.file_name(), &i.crop))?;
    let false_positives = saved(&run.false_positives, |i| save(i.file_name(), &i.crop))?;
    let html = render(
        meta,
        summary,
        &plots,
        [&worst, &misplaced],
        &failed,
        [&missed, &false_positives],
    );
    write(HTML_FILE, html.as_bytes())?;
    Ok(EvalFiles {
        json: out.join(JSON_FILE),
        bop_results: out.join(bop_file),
        html: out.join(HTML_FILE),
    })
}

/// Each of `items` with the path `save` wrote its picture to.
fn saved<T>(
    items: &[T],
    save: impl Fn(&T) -> Result<String, EvalReportError>,
) -> Result<Vec<(String, &T)>, EvalReportError> {
    items.iter().map(|i| Ok((save(i)?, i))).collect()
}

type Series = (String, RGBColor, bool, Vec<f64>);

/// Per part: raw (dashed) and refined (solid) values of one error, sorted.
fn series(
    run: &EvalRun,
    summary: &EvalSummary,
    get: fn(&perception::metrics::PoseErrors) -> f64,
) -> Vec<Series> {
    let colours = [
        RGBColor(31, 119, 180),
        RGBColor(255, 127, 14),
        RGBColor(44, 160, 44),
        RGBColor(214, 39, 40),
        RGBColor(148, 103, 189),
    ];
    let mut out = Vec::new();
    for (i, p) in summary.parts.iter().enumerate() {
        let c = colours[i % colours.len()];
        for refined in [false, true] {
            let mut v: Vec<f64> = run
                .frames
                .iter()
                .flat_map(|f| {
                    f.detections.iter().filter(|d| {
                        d.part == p.part && d.truth.is_some_and(|t| !f.truths[t].ignored)
                    })
                })
                .filter_map(|d| if refined { d.refined } else { d.raw })
                .map(|e| get(&e))
                .filter(|x| x.is_finite())
                .collect();
            v.sort_by(f64::total_cmp);
            let label = format!("{} {}", p.part, if refined { "refined" } else { "PnP" });
            out.push((label, c, !refined, v));
        }
    }
    out
}

fn draw_error(name: &str) -> impl Fn(String) -> EvalReportError + '_ {
    move |message| EvalReportError::Draw {
        name: name.into(),
        message,
    }
}

fn encode_png(name: &str, img: &image::RgbImage) -> Result<Vec<u8>, EvalReportError> {
    let mut buf = Vec::new();
    PngEncoder::new(&mut buf)
        .write_image(
            img.as_raw(),
            img.width(),
            img.height(),
            image::ExtendedColorType::Rgb8,
        )
        .map_err(|e| draw_error(name)(e.to_string()))?;
    Ok(buf)
}

/// Size of a CDF plot, pixels.
const CDF_SIZE: (u32, u32) = (1000, 560);
/// Legend text size of a CDF plot, pixels.
const CDF_LEGEND_PX: u32 = 15;

/// Draws the cumulative distribution of each series (share of values ≤ x) on `root`, the legend
/// beside the plotting area.
fn draw_cdf<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    title: &str,
    x_label: &str,
    x_max: f64,
    series: &[Series],
) -> Result<(), String> {
    use crate::report::plots::{Mark, legend_beside, legend_room};
    let e = |x: &dyn std::fmt::Display| x.to_string();
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let legend: Vec<(&str, Mark)> = series
        .iter()
        .filter(|s| !s.3.is_empty())
        .map(|(label, colour, dashed, _)| {
            let mark = if *dashed {
                Mark::Dashed(*colour)
            } else {
                Mark::Line(*colour)
            };
            (label.as_str(), mark)
        })
        .collect();
    let labels: Vec<&str> = legend.iter().map(|l| l.0).collect();
    let mut chart = ChartBuilder::on(root)
        .caption(title, ("sans-serif", 22))
        .margin(12)
        .margin_right(12 + legend_room(&labels, CDF_LEGEND_PX))
        .x_label_area_size(44)
        .y_label_area_size(56)
        .build_cartesian_2d(0.0..x_max, 0.0..100.0)
        .map_err(|x| e(&x))?;
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc("estimates (%)")
        .label_style(("sans-serif", 15))
        .draw()
        .map_err(|x| e(&x))?;
    for (_, colour, dashed, values) in series {
        if values.is_empty() {
            continue;
        }
        let n = values.len() as f64;
        let mut pts: Vec<(f64, f64)> = vec![(0.0, 0.0)];
        for (i, v) in values.iter().enumerate() {
            let x = v.min(x_max);
            pts.push((x, 100.0 * i as f64 / n));
            pts.push((x, 100.0 * (i + 1) as f64 / n));
        }
        let last_y = pts.last().map_or(0.0, |p| p.1);
        pts.push((x_max, last_y));
        let style = colour.stroke_width(2);
        let drawn = if *dashed {
            chart.draw_series(DashedLineSeries::new(pts, 6, 4, style))
        } else {
            chart.draw_series(LineSeries::new(pts, style))
        };
        drawn.map_err(|x| e(&x))?;
    }
    legend_beside(root, chart.plotting_area(), &legend, CDF_LEGEND_PX).map_err(|x| e(&x))?;
    root.present().map_err(|x| e(&x))
}

/// A cumulative-distribution plot of each series (share of values ≤ x), as PNG bytes.
fn cdf_plot(
    name: &str,
    title: &str,
    x_label: &str,
    x_max: f64,
    series: &[Series],
) -> Result<Vec<u8>, EvalReportError> {
    crate::report::plots::register_font();
    let (w, h) = CDF_SIZE;
    let mut rgb = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        draw_cdf(&root, title, x_label, x_max, series).map_err(draw_error(name))?;
    }
    let img = image::RgbImage::from_raw(w, h, rgb).expect("the buffer has w × h × 3 bytes");
    encode_png(name, &img)
}

/// The CDF plot of the eval report drawn as SVG text instead of PNG, the same layout: for
/// checking where its legend lies. Each series is (label, RGB colour, dashed, values).
pub fn cdf_plot_svg(
    title: &str,
    x_label: &str,
    x_max: f64,
    series: &[(String, [u8; 3], bool, Vec<f64>)],
) -> Result<String, String> {
    crate::report::plots::register_font();
    let series: Vec<Series> = series
        .iter()
        .map(|(l, [r, g, b], d, v)| {
            let mut v = v.clone();
            v.sort_by(f64::total_cmp);
            (l.clone(), RGBColor(*r, *g, *b), *d, v)
        })
        .collect();
    let mut out = String::new();
    {
        let root = SVGBackend::with_string(&mut out, CDF_SIZE).into_drawing_area();
        draw_cdf(&root, title, x_label, x_max, &series)?;
    }
    Ok(out)
}

/// The page's CSS. Every table fits a page 800 px wide without scrolling: at most 9 columns,
/// header text wraps, left-aligned text cells wrap, numbers do not.
pub const STYLE: &str = "body{font-family:sans-serif;max-width:1200px;margin:1em auto;padding:0 1em;color:#222}\
table{border-collapse:collapse;margin:1em 0;max-width:100%;font-size:15px}\
td,th{border:1px solid #ccc;padding:3px 6px;text-align:right;white-space:nowrap}\
th{background:#f3f3f3;white-space:normal;vertical-align:bottom}\
td.l,th.l{text-align:left}td.l{white-space:normal}tr.seed td{color:#777;font-style:italic}\
img.plot{max-width:100%;height:auto;display:block;margin:1em 0}\
figure{display:inline-block;margin:4px;width:256px;max-width:100%;vertical-align:top;font-size:12px}\
figure img{width:256px;height:256px;max-width:100%;image-rendering:pixelated;border:1px solid #ccc}\
code{background:#f3f3f3;padding:1px 4px;overflow-wrap:anywhere}";

/// Detection and posing by the stable pose the parts truly rest in.
fn stable_pose_table(h: &mut String, rows: &[StablePoseRow]) {
    if rows.is_empty() {
        return;
    }
    h.push_str(
        "<h2>By stable pose</h2><p>Counted instances resting on the table, by the stable pose \
         they truly rest in: how many were found, posed (a detection with a pose), and posed in \
         that stable pose, and what the others were taken for.</p><table><tr><th class=l>part</th>\
         <th class=l>stable pose</th><th>resting</th><th>found</th><th>posed</th>\
         <th>posed in it</th><th class=l>taken for</th></tr>",
    );
    for r in rows {
        let wrong: Vec<String> = r
            .taken_for
            .iter()
            .map(|(p, n)| format!("{n} × {}", escape(p)))
            .collect();
        let _ = write!(
            h,
            "<tr><td class=l>{}</td><td class=l>{}</td><td>{}</td><td>{}</td><td>{}</td>\
             <td>{}</td><td class=l>{}</td></tr>",
            escape(&r.part),
            escape(&r.stable_pose),
            r.resting,
            r.found,
            r.posed,
            r.right,
            wrong.join(", ")
        );
    }
    h.push_str("</table>");
}

fn num(x: f64, d: usize) -> String {
    if x.is_finite() {
        format!("{x:.d$}")
    } else {
        "–".into()
    }
}

fn pct(x: f64) -> String {
    if x.is_finite() {
        format!("{:.1}&nbsp;%", 100.0 * x)
    } else {
        "–".into()
    }
}

fn pm(v: [f64; 2]) -> String {
    if v[0].is_finite() {
        format!("{:.2} ± {:.2}", v[0], v[1])
    } else {
        "–".into()
    }
}

fn row_cells(r: &Table1Row) -> String {
    format!(
        "<td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td>",
        r.n,
        r.outliers,
        pm(r.x_mm),
        pm(r.y_mm),
        pm(r.z_mm),
        pm(r.angle_deg)
    )
}

fn render(
    meta: &EvalMeta,
    s: &EvalSummary,
    plots: &[(String, &str)],
    [worst, misplaced]: [&[(String, &GalleryItem)]; 2],
    failed: &[(String, &FailedCrop)],
    [missed, false_positives]: [&[(String, &DetectionErrorCrop)]; 2],
) -> String {
    let mut h = String::new();
    let _ = write!(
        h,
        "<!doctype html><html lang=en><meta charset=utf-8><title>Perception evaluation</title>\
         <style>{STYLE}</style><h1>Learned perception on <code>{}</code> / {}</h1>",
        escape(&meta.dataset.display().to_string()),
        escape(&meta.split)
    );
    let _ = write!(
        h,
        "<p>{} images ({} failed outright), {} ground-truth instances counted ({} ignored below \
         {:.0}&nbsp;% visible), {} detections; matching: same part, visible-mask IoU ≥ {}, greedy \
         by score. Pipeline: {} frames/s (mean total {} ms). Models: <code>{}</code>, catalog \
         <code>{}</code>.</p>",
        s.frames,
        s.frame_failures,
        s.pooled.truths,
        s.pooled.ignored,
        100.0 * meta.options.min_visib_fract,
        s.pooled.detections,
        meta.options.min_iou,
        num(s.frames_per_s, 1),
        num(s.stages.last().map_or(f64::NAN, |t| t.mean_ms), 1),
        escape(&meta.models.display().to_string()),
        escape(&meta.catalog.display().to_string())
    );
    for e in &s.failure_examples {
        let _ = write!(h, "<p>failed: {}</p>", escape(e));
    }

    // Table 1.
    let _ = write!(
        h,
        "<h2>Table 1: pose error in the camera frame</h2><p>Mean ± σ of the absolute error per \
         axis (z is depth) and of the geodesic angle θ to the nearest exact twin (a part with \
         symmetries is right in any of its twin poses; the seed's parts have none), over matched \
         estimates. The seed drops \
         estimates with θ &gt; {}° from every statistic (\"seed-style\"); we count them (\"out\") \
         and also give the statistics over all estimates. The average row is the seed's: the \
         mean of the parts' means and σs.</p><table><tr><th class=l>part</th>\
         <th class=l>estimate</th><th>n</th><th>out</th><th>x (mm)</th><th>y (mm)</th>\
         <th>z (mm)</th><th>θ (deg)</th></tr>",
        meta.options.outlier_deg
    );
    let mut parts: Vec<&str> = s.parts.iter().map(|p| p.part.as_str()).collect();
    parts.push("average");
    for part in parts {
        let seed = seed_row(part);
        if let Some(r) = seed {
            let _ = write!(
                h,
                "<tr class=seed><td class=l>{}</td><td class=l>seed paper, PnP, seed-style</td>\
                 <td>{}</td><td>?</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
                escape(part),
                if part == "average" { 6000 } else { 2000 },
                pm([r[0].0, r[0].1]),
                pm([r[1].0, r[1].1]),
                pm([r[2].0, r[2].1]),
                pm([r[3].0, r[3].1])
            );
        }
        for (method, dropped, label) in [
            ("pnp", true, "PnP, seed-style"),
            ("pnp", false, "PnP, all"),
            ("refined", true, "refined, seed-style"),
            ("refined", false, "refined, all"),
        ] {
            if let Some(e) = s
                .table1
                .iter()
                .find(|e| e.part == part && e.method == method && e.outliers_dropped == dropped)
            {
                let _ = write!(
                    h,
                    "<tr><td class=l>{}</td><td class=l>{label}</td>{}</tr>",
                    escape(part),
                    row_cells(&e.row)
                );
            }
        }
    }
    h.push_str("</table>");

    // Detection: counts and rates, then why instances were missed, then what the false
    // positives were.
    let _ = write!(
        h,
        "<h2>Detection</h2><p>Touching: the visible mask comes within {} px of another \
         instance's.</p><table><tr><th class=l>part</th><th>instances</th><th>ignored</th>\
         <th>touching</th><th>detections</th><th>true pos.</th><th>false pos.</th>\
         <th>precision</th><th>recall</th></tr>",
        meta.options.touch_gap_px
    );
    let all: Vec<&PartSummary> = s.parts.iter().chain(std::iter::once(&s.pooled)).collect();
    for p in &all {
        let _ = write!(
            h,
            "<tr><td class=l>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td>\
             <td>{}</td><td>{}</td><td>{}</td></tr>",
            escape(&p.part),
            p.truths,
            p.ignored,
            p.touching,
            p.detections,
            p.true_positives,
            p.false_positives,
            pct(p.precision),
            pct(p.recall),
        );
    }
    h.push_str(
        "</table><p>Recall of touching and isolated instances, and what became of the missed \
         ones.</p><table><tr><th class=l>part</th><th>recall touching</th>\
         <th>recall isolated</th><th>missed: wrong part</th><th class=l>found as</th>\
         <th>split or merged</th>\
         <th>under another</th><th>nothing</th></tr>",
    );
    for p in &all {
        let _ = write!(
            h,
            "<tr><td class=l>{}</td><td>{}</td><td>{}</td><td>{}</td><td class=l>{}</td>\
             <td>{}</td><td>{}</td><td>{}</td></tr>",
            escape(&p.part),
            pct(p.recall_touching),
            pct(p.recall_isolated),
            p.misses.wrong_part,
            escape(&found_as_text(&p.found_as)),
            p.misses.partial,
            p.misses.covered,
            p.misses.nothing,
        );
    }
    h.push_str(
        "</table><p>What the false positives were.</p><table><tr><th class=l>part</th>\
         <th>false pos.</th><th>wrong part</th><th>second instance</th><th>poor mask</th>\
         <th>over others</th><th>on the table</th></tr>",
    );
    for p in &all {
        let _ = write!(
            h,
            "<tr><td class=l>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td>\
             <td>{}</td></tr>",
            escape(&p.part),
            p.false_positives,
            p.false_positive_causes.wrong_part,
            p.false_positive_causes.duplicate,
            p.false_positive_causes.partial,
            p.false_positive_causes.straddling,
            p.false_positive_causes.nothing
        );
    }
    h.push_str("</table>");

    // Poses beyond Table 1.
    let _ = write!(
        h,
        "<h2>Poses</h2><p>Stable pose right: the class chosen equals the class the planar \
         refiner assigns to the true pose. Refined figures cover the parts resting on the table; \
         parts leaning on or lying on another one are in no stable pose and are counted apart \
         (off the table: instances / of them posed). Flips: outliers within {}° of a \
         near-symmetric equivalent of the truth. AR: BOP average recall over the counted \
         instances, MSSD at {}–{} × diameter, MSPD at {}–{} px.</p><table><tr><th class=l>part</th>\
         <th>matched</th><th>no pose</th><th>off the table</th><th>stable pose right</th>\
         <th>flips PnP / refined</th></tr>",
        meta.options.outlier_deg,
        MSSD_FRACTIONS[0],
        MSSD_FRACTIONS[MSSD_FRACTIONS.len() - 1],
        MSPD_PX[0],
        MSPD_PX[MSPD_PX.len() - 1]
    );
    for p in &all {
        let _ = write!(
            h,
            "<tr><td class=l>{}</td><td>{}</td><td>{}</td><td>{} / {}</td><td>{} ({})</td>\
             <td>{} / {}</td></tr>",
            escape(&p.part),
            p.true_positives,
            p.pose_failures,
            p.not_resting,
            p.not_resting_posed,
            pct(p.stable_pose_rate),
            p.stable_pose_right,
            p.raw.symmetry_flips,
            p.refined.symmetry_flips,
        );
    }
    h.push_str(
        "</table><table><tr><th class=l>part</th><th>θ p50 / p95 PnP</th>\
         <th>θ p50 / p95 refined</th><th>AR<sub>MSSD</sub> PnP / refined</th>\
         <th>AR<sub>MSPD</sub> PnP / refined</th></tr>",
    );
    for p in &all {
        let _ = write!(
            h,
            "<tr><td class=l>{}</td><td>{} / {}</td><td>{} / {}</td><td>{} / {}</td>\
             <td>{} / {}</td></tr>",
            escape(&p.part),
            num(p.raw.all.sym_angle_deg.p50, 2),
            num(p.raw.all.sym_angle_deg.p95, 2),
            num(p.refined.all.sym_angle_deg.p50, 2),
            num(p.refined.all.sym_angle_deg.p95, 2),
            pct(p.raw.ar_mssd),
            pct(p.refined.ar_mssd),
            pct(p.raw.ar_mspd),
            pct(p.refined.ar_mspd)
        );
    }
    h.push_str("</table>");
    let room = meta.options.finger_margin.map_or_else(
        || "; room for the fingers not checked".to_string(),
        |m| format!(", with {:.1} mm of room for the open fingers", m * 1e3),
    );
    let _ = write!(
        h,
        "<h2>Picks</h2><p>The poses the cell would pick (confidence ≥ {}, in a stable pose it \
         has a grasp for{room}), by what the picked part turned out to be; reach is not checked.\
         </p><table><tr>\
         <th class=l>part</th><th>picks</th><th>assembly-grade</th><th>further off</th>\
         <th>other stable pose</th><th>on or under another part</th><th>on no part</th>\
         <th>no room for the fingers</th></tr>",
        meta.options.pick_confidence
    );
    let row = |h: &mut String, part: &str, k: &Picks, crowded: bool| {
        let _ = write!(
            h,
            "<tr><td class=l>{}</td><td>{}</td><td>{} ({})</td><td>{}</td><td>{}</td><td>{}</td>\
             <td>{}</td>",
            escape(part),
            k.picks,
            k.assembly_grade,
            pct(k.assembly_grade as f64 / k.picks.max(1) as f64),
            k.off,
            k.wrong_stable_pose,
            k.not_resting,
            k.unmatched,
        );
        if crowded {
            let _ = write!(h, "<td>{}</td>", k.crowded);
        }
        h.push_str("</tr>");
    };
    for p in &all {
        row(&mut h, &p.part, &p.picks, true);
    }
    h.push_str(
        "</table><p>The cell's first pick: per frame and part, the most confident of those \
         picks.</p><table><tr><th class=l>part</th><th>first picks</th><th>assembly-grade</th>\
         <th>further off</th><th>other stable pose</th><th>on or under another part</th>\
         <th>on no part</th></tr>",
    );
    for p in &all {
        row(&mut h, &p.part, &p.first_picks, false);
    }
    h.push_str("</table>");
    for p in &s.parts {
        for (kind, n) in &p.pose_failure_kinds {
            let _ = write!(
                h,
                "<p>{}: {n} without a pose: {}</p>",
                escape(&p.part),
                escape(kind)
            );
        }
    }
    stable_pose_table(&mut h, &s.stable_poses);

    // Timing.
    h.push_str(
        "<h2>Time per stage</h2><table><tr><th class=l>stage</th><th>mean (ms)</th>\
         <th>median (ms)</th><th>p95 (ms)</th></tr>",
    );
    for t in &s.stages {
        let _ = write!(
            h,
            "<tr><td class=l>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            escape(&t.stage),
            num(t.mean_ms, 2),
            num(t.median_ms, 2),
            num(t.p95_ms, 2)
        );
    }
    h.push_str("</table>");

    h.push_str("<h2>Distributions</h2><p>Dashed: PnP; solid: after planar refinement.</p>");
    for (rel, alt) in plots {
        let _ = write!(
            h,
            "<img class=plot src=\"{}\" alt=\"{}\">",
            escape(rel),
            escape(alt)
        );
    }

    let _ = write!(
        h,
        "<h2>The {} worst estimates (by refined MSSD)</h2><p>The keypoint crop × 2: predicted mask \
         outline yellow, the part's true outline and keypoints (ground-truth pose projected) \
         green line and circles, the refined pose's outline magenta, voted keypoints red \
         crosses.</p>",
        worst.len()
    );
    gallery_figures(&mut h, worst);
    if !misplaced.is_empty() {
        let _ = write!(
            h,
            "<h2>The {} worst placed in the right stable pose (by in-plane error)</h2><p>Parts \
             resting on the table whose stable pose was found and whose angle error is within \
             the outlier angle: where contour alignment took the wrong edges.</p>",
            misplaced.len()
        );
    }
    gallery_figures(&mut h, misplaced);
    if !failed.is_empty() {
        let _ = write!(
            h,
            "<h2>Matched detections without a pose ({} of {}, highest score first)</h2>",
            failed.len(),
            s.pooled.pose_failures
        );
    }
    for (rel, item) in failed {
        let _ = write!(
            h,
            "<figure><img src=\"{}\" alt=\"{}\"><figcaption>{} — scene {} image {} det {}; score \
             {:.2}, IoU {:.2}<br>{}</figcaption></figure>",
            escape(rel),
            escape(&item.part),
            escape(&item.part),
            item.scene,
            item.image,
            item.detection,
            item.score,
            item.iou,
            escape(&item.reason)
        );
    }
    for (items, title, of) in [
        (
            missed,
            "Missed instances",
            s.pooled.truths - s.pooled.true_positives,
        ),
        (false_positives, "False positives", s.pooled.false_positives),
    ] {
        if items.is_empty() {
            continue;
        }
        let _ = write!(
            h,
            "<h2>{title} ({} of {of})</h2><p>The frame around each × 2: the true visible mask \
             outlined green, the detection in question yellow, every other detection cyan. \
             Missed instances the most visible first, false positives the highest score first.</p>",
            items.len()
        );
        for (rel, item) in items {
            let _ = write!(
                h,
                "<figure><img src=\"{}\" alt=\"{}\"><figcaption>{} — scene {} image {} {} {}<br>{}\
                 </figcaption></figure>",
                escape(rel),
                escape(&item.part),
                escape(&item.part),
                item.scene,
                item.image,
                match item.kind {
                    DetectionErrorKind::Missed => "truth",
                    DetectionErrorKind::FalsePositive => "det",
                },
                item.index,
                escape(&item.caption)
            );
        }
    }
    h.push_str("</html>\n");
    h
}

/// One figure per gallery item: the picture and its errors.
fn gallery_figures(h: &mut String, items: &[(String, &GalleryItem)]) {
    for (rel, item) in items {
        let _ = write!(
            h,
            "<figure><img src=\"{}\" alt=\"{}\"><figcaption>{} — scene {} image {} det {}; IoU \
             {:.2}<br>refined: MSSD {:.2} mm, θ {:.1}°, x/y/z {:.2}/{:.2}/{:.1} mm<br>PnP: θ \
             {:.1}°, x/y/z {:.2}/{:.2}/{:.1} mm<br>stable pose {} (true {})</figcaption></figure>",
            escape(rel),
            escape(&item.part),
            escape(&item.part),
            item.scene,
            item.image,
            item.detection,
            item.iou,
            item.refined.mssd_mm,
            item.refined.sym_angle_deg,
            item.refined.x_mm,
            item.refined.y_mm,
            item.refined.z_mm,
            item.raw.sym_angle_deg,
            item.raw.x_mm,
            item.raw.y_mm,
            item.raw.z_mm,
            escape(&item.stable_pose),
            escape(item.true_stable_pose.as_deref().unwrap_or("?"))
        );
    }
}
