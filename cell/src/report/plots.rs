//! The report's plots as SVG text (plotters' SVG backend), ready to inline into HTML.

use plotters::prelude::*;
use plotters::style::FontStyle;

use crate::episode::{EpisodeRecord, StepOutcome};
use crate::run::Summary;
use crate::run::outcomes::outcome_name;

/// A plot that could not be drawn.
#[derive(Debug, thiserror::Error)]
#[error("drawing the {plot} plot: {message}")]
pub struct PlotError {
    /// Which plot.
    pub plot: &'static str,
    /// The drawing error.
    pub message: String,
}

const BLUE: RGBColor = RGBColor(31, 119, 180);
const ORANGE: RGBColor = RGBColor(255, 127, 14);
const GREEN: RGBColor = RGBColor(44, 160, 44);
const RED: RGBColor = RGBColor(214, 39, 40);
const PURPLE: RGBColor = RGBColor(148, 103, 189);
const GREY: RGBColor = RGBColor(127, 127, 127);

/// Registers the committed DejaVu Sans (cell/assets/fonts) as plotters' sans-serif font: with
/// the `ab_glyph` feature plotters needs it to lay out text, even for SVG.
pub fn register_font() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let bytes: &'static [u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");
        if plotters::style::register_font("sans-serif", FontStyle::Normal, bytes).is_err() {
            tracing::warn!("the bundled font could not be loaded; plot text will be missing");
        }
    });
}

type DrawResult = Result<(), Box<dyn std::error::Error>>;

/// Draws into an SVG string of `size` pixels.
pub(crate) fn svg<F>(plot: &'static str, size: (u32, u32), draw: F) -> Result<String, PlotError>
where
    F: FnOnce(&DrawingArea<SVGBackend<'_>, plotters::coord::Shift>) -> DrawResult,
{
    register_font();
    let mut out = String::new();
    {
        let root = SVGBackend::with_string(&mut out, size).into_drawing_area();
        let drawn = root
            .fill(&WHITE)
            .map_err(|e| e.into())
            .and_then(|()| draw(&root))
            .and_then(|()| root.present().map_err(|e| e.into()));
        drawn.map_err(|e| PlotError {
            plot,
            message: e.to_string(),
        })?;
    }
    Ok(out)
}

fn shorten(s: &str, n: usize) -> String {
    if s.chars().count() <= n {
        s.into()
    } else {
        let mut t: String = s.chars().take(n - 1).collect();
        t.push('…');
        t
    }
}

fn category_label(labels: &[String], x: f64) -> String {
    let i = x.round();
    if (x - i).abs() < 1e-6 && i >= 0.0 && (i as usize) < labels.len() {
        labels[i as usize].clone()
    } else {
        String::new()
    }
}

/// Decimals that tell apart ticks of an axis spanning `span` with about `ticks` labels (so
/// ticks 0.05 apart print as 0.05, 0.10, 0.15, not 0.1, 0.1, 0.2).
pub fn tick_decimals(span: f64, ticks: usize) -> usize {
    let step = (span / ticks.max(1) as f64).abs();
    if !(step.is_finite() && step > 0.0) {
        return 1;
    }
    // plotters steps are 1, 2 or 5 times a power of ten: one more decimal covers a 2.5 step.
    (-(step.log10().floor()) as i64 + 1).clamp(0, 6) as usize
}

/// Font size of tick labels and axis descriptions, pixels (the SVGs are shown at about their
/// own width, so this stays readable at 800 px).
pub(crate) const LABEL_PX: u32 = 16;
/// Font size of legend text, pixels.
pub(crate) const LEGEND_PX: u32 = 15;

/// Gap between the plotting area and the legend beside it, pixels.
const LEGEND_GAP: i32 = 16;
/// The legend box: width of the marker column and margin around the entries, pixels.
const LEGEND_MARKER_PX: u32 = 30;
const LEGEND_MARGIN_PX: u32 = 8;

/// The marker of a legend entry.
#[derive(Debug, Clone, Copy)]
pub enum Mark {
    /// A filled square (bars).
    Square(RGBColor),
    /// A filled circle (points).
    Dot(RGBColor),
    /// A solid line.
    Line(RGBColor),
    /// A dashed line.
    Dashed(RGBColor),
}

fn text_width(label: &str, font_px: u32) -> u32 {
    ("sans-serif", font_px)
        .into_font()
        .box_size(label)
        .map_or(label.chars().count() as u32 * font_px * 6 / 10, |(w, _)| w)
}

/// Room to leave right of the plotting area for a legend of `labels` in `font_px` text, pixels
/// (pass it to `ChartBuilder::margin_right`): legends go beside the plot, never over its data.
pub fn legend_room(labels: &[&str], font_px: u32) -> u32 {
    register_font();
    let text = labels
        .iter()
        .map(|l| text_width(l, font_px))
        .max()
        .unwrap_or(0);
    text + LEGEND_MARKER_PX + 2 * LEGEND_MARGIN_PX + LEGEND_GAP as u32 + 4
}

/// Draws a legend of `items` on `root` (the whole picture) as a box right of `plot` (the
/// chart's plotting area), top-aligned with it, in the room that [`legend_room`] left there.
pub fn legend_beside<DB, CT>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    plot: &DrawingArea<DB, CT>,
    items: &[(&str, Mark)],
    font_px: u32,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>>
where
    DB: DrawingBackend,
    CT: plotters::coord::CoordTranslate,
{
    if items.is_empty() {
        return Ok(());
    }
    register_font();
    let (px, py) = plot.get_base_pixel();
    let left = px + plot.dim_in_pixel().0 as i32 + LEGEND_GAP;
    let top = py;
    let line = (font_px * 3 / 2) as i32;
    let margin = LEGEND_MARGIN_PX as i32;
    let text = items
        .iter()
        .map(|(l, _)| text_width(l, font_px))
        .max()
        .unwrap_or(0) as i32;
    let right = left + 2 * margin + LEGEND_MARKER_PX as i32 + text;
    let bottom = top + 2 * margin + line * items.len() as i32;
    root.draw(&Rectangle::new(
        [(left, top), (right, bottom)],
        WHITE.filled(),
    ))?;
    root.draw(&Rectangle::new([(left, top), (right, bottom)], BLACK))?;
    let font = ("sans-serif", font_px).into_font();
    for (i, (label, mark)) in items.iter().enumerate() {
        let y = top + margin + line * i as i32 + line / 2;
        let x = left + margin;
        match *mark {
            Mark::Square(c) => root.draw(&Rectangle::new(
                [(x + 4, y - 6), (x + 16, y + 6)],
                c.filled(),
            ))?,
            Mark::Dot(c) => root.draw(&Circle::new((x + 10, y), 5, c.filled()))?,
            Mark::Line(c) => root.draw(&PathElement::new(
                vec![(x, y), (x + 22, y)],
                c.stroke_width(2),
            ))?,
            Mark::Dashed(c) => {
                for k in [0, 9, 18] {
                    root.draw(&PathElement::new(
                        vec![(x + k, y), (x + k + 5, y)],
                        c.stroke_width(2),
                    ))?;
                }
            }
        }
        root.draw(&Text::new(
            label.to_string(),
            (x + LEGEND_MARKER_PX as i32, y),
            font.clone()
                .into_text_style(root)
                .pos(plotters::style::text_anchor::Pos::new(
                    plotters::style::text_anchor::HPos::Left,
                    plotters::style::text_anchor::VPos::Center,
                )),
        ))?;
    }
    Ok(())
}

/// The lower end of a percentage axis that shows the differences between `lows` (the lowest
/// interval ends): 0 when something is far from 100 %, otherwise a round number below them,
/// so that 99.5 % and 100 % do not look the same.
pub fn rate_axis_floor(lows: &[f64]) -> f64 {
    let lo = lows.iter().copied().fold(100.0, f64::min);
    let span = (100.0 - lo).max(0.5) * 1.25;
    let floor = 100.0 - span;
    if floor < 40.0 {
        return 0.0;
    }
    let step = if span > 20.0 {
        10.0
    } else if span > 5.0 {
        1.0
    } else {
        0.5
    };
    (floor / step).floor() * step
}

/// Vertical 95 % interval markers: a line from `lo` to `hi` with caps.
fn interval_marker(x: f64, lo: f64, hi: f64) -> Vec<PathElement<(f64, f64)>> {
    let style = BLACK.stroke_width(2);
    vec![
        PathElement::new(vec![(x, lo), (x, hi)], style),
        PathElement::new(vec![(x - 0.1, lo), (x + 0.1, lo)], style),
        PathElement::new(vec![(x - 0.1, hi), (x + 0.1, hi)], style),
    ]
}

/// Episode success and each step's seated rate with 95 % Wilson intervals; the rate axis starts
/// where the differences show (its lower end is printed in the caption when it is not 0).
pub fn success_rates(s: &Summary) -> Result<String, PlotError> {
    let mut bars = vec![("episode".to_string(), s.success_rate, s.success_ci95)];
    bars.extend(
        s.steps
            .iter()
            .map(|t| (format!("{}: {}", t.index, t.part), t.rate, t.ci95)),
    );
    let labels: Vec<String> = bars.iter().map(|b| b.0.clone()).collect();
    let n = bars.len();
    let lows: Vec<f64> = bars.iter().map(|b| 100.0 * b.2.lo).collect();
    let floor = rate_axis_floor(&lows);
    let caption = if floor > 0.0 {
        format!("Success rate, 95 % Wilson intervals (axis from {floor} %)")
    } else {
        "Success rate, 95 % Wilson intervals".to_string()
    };
    let decimals = if 100.0 - floor <= 5.0 { 1 } else { 0 };
    svg("success rate", (800, 420), |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(caption, ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(-0.5f64..n as f64 - 0.5, floor..100.0)?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(n)
            .x_label_formatter(&|x| category_label(&labels, *x))
            .y_label_formatter(&|y| format!("{y:.decimals$} %"))
            .label_style(("sans-serif", LABEL_PX))
            .axis_desc_style(("sans-serif", LABEL_PX))
            .y_desc("seated / reached")
            .draw()?;
        chart.draw_series(bars.iter().enumerate().map(|(i, (_, r, _))| {
            let x = i as f64;
            let c = if i == 0 { BLUE } else { GREEN };
            Rectangle::new(
                [(x - 0.3, floor), (x + 0.3, (100.0 * r).max(floor))],
                c.mix(0.7).filled(),
            )
        }))?;
        for (i, (_, r, ci)) in bars.iter().enumerate() {
            let x = i as f64;
            chart.draw_series(interval_marker(
                x,
                (100.0 * ci.lo).max(floor),
                100.0 * ci.hi,
            ))?;
            chart.draw_series(std::iter::once(Text::new(
                format!("{:.1} %", 100.0 * r),
                (x + 0.12, (100.0 * r).max(floor)),
                ("sans-serif", LABEL_PX).into_font(),
            )))?;
        }
        Ok(())
    })
}

/// Horizontal bars of `(label, value)` with a value axis named `x_desc`; `counts` prints the
/// value axis as whole numbers. The label area fits the longest label.
fn horizontal_bars(
    plot: &'static str,
    caption: &str,
    x_desc: &str,
    items: &[(String, f64)],
    colour: RGBColor,
    counts: bool,
) -> Result<String, PlotError> {
    let labels: Vec<String> = items.iter().map(|(l, _)| shorten(l, 64)).collect();
    let n = items.len().max(1);
    let max = items.iter().map(|i| i.1).fold(0.0, f64::max).max(1e-9) * 1.1;
    let longest = labels.iter().map(|l| l.chars().count()).max().unwrap_or(8) as u32;
    let label_area = (longest * 9 + 16).clamp(120, 560);
    let width = (label_area + 360).max(800);
    let ticks = if counts {
        (max.ceil() as usize).clamp(1, 10)
    } else {
        10
    };
    svg(plot, (width, 110 + 34 * n as u32), |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(caption, ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(44)
            .y_label_area_size(label_area)
            .build_cartesian_2d(0.0f64..max, -0.5f64..n as f64 - 0.5)?;
        chart
            .configure_mesh()
            .disable_y_mesh()
            .y_labels(n)
            .y_label_formatter(&|y| category_label(&labels, *y))
            .x_labels(ticks)
            .x_label_formatter(&|x| {
                if counts {
                    format!("{x:.0}")
                } else {
                    format!("{x}")
                }
            })
            .label_style(("sans-serif", LABEL_PX))
            .axis_desc_style(("sans-serif", LABEL_PX))
            .x_desc(x_desc)
            .draw()?;
        chart.draw_series(items.iter().enumerate().map(|(i, (_, v))| {
            let y = i as f64;
            Rectangle::new([(0.0, y - 0.35), (*v, y + 0.35)], colour.mix(0.75).filled())
        }))?;
        Ok(())
    })
}

/// Failed episodes per failure mechanism (the `top` most frequent).
pub fn failure_mechanisms(s: &Summary, top: usize) -> Result<String, PlotError> {
    let items: Vec<(String, f64)> = s
        .failure_mechanisms
        .iter()
        .take(top)
        .map(|m| {
            let part = m.part.as_deref().unwrap_or("episode");
            (format!("{part} {}", m.mechanism), f64::from(m.count))
        })
        .collect();
    horizontal_bars(
        "failure mechanisms",
        "Failure mechanisms",
        "failed episodes",
        &items,
        RED,
        true,
    )
}

/// Share of failed episodes blaming each error source.
pub fn error_budget(s: &Summary) -> Result<String, PlotError> {
    let items: Vec<(String, f64)> = s
        .error_budget
        .iter()
        .map(|e| (e.source.clone(), 100.0 * e.share))
        .collect();
    horizontal_bars(
        "error budget",
        "Error budget: failures blamed on each error source",
        "% of failed episodes",
        &items,
        PURPLE,
        false,
    )
}

/// Histogram of the simulated cycle time, successful and failed episodes stacked.
pub fn cycle_time_histogram(records: &[&EpisodeRecord]) -> Result<String, PlotError> {
    let times: Vec<f64> = records.iter().map(|r| r.cycle_time_s).collect();
    let lo = times.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = times.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let bins = ((times.len() as f64).sqrt().ceil() as usize).clamp(1, 40);
    let (lo, width) = if hi > lo {
        (lo, (hi - lo) / bins as f64)
    } else {
        (lo - 0.5, 1.0 / bins as f64)
    };
    let bin = |t: f64| (((t - lo) / width) as usize).min(bins - 1);
    let mut ok = vec![0u32; bins];
    let mut failed = vec![0u32; bins];
    for r in records {
        let b = bin(r.cycle_time_s);
        if r.success {
            ok[b] += 1
        } else {
            failed[b] += 1
        }
    }
    let top = ok
        .iter()
        .zip(&failed)
        .map(|(a, b)| a + b)
        .max()
        .unwrap_or(1)
        .max(1);
    let room = legend_room(&["succeeded", "failed"], LEGEND_PX);
    svg("cycle time", (800, 400), |root| {
        let mut chart = ChartBuilder::on(root)
            .caption("Simulated cycle time", ("sans-serif", 22))
            .margin(12)
            .margin_right(12 + room)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(lo..lo + width * bins as f64, 0.0..f64::from(top) * 1.1)?;
        chart
            .configure_mesh()
            .y_labels((top as usize + 1).min(10))
            .y_label_formatter(&|y| format!("{y:.0}"))
            .label_style(("sans-serif", LABEL_PX))
            .axis_desc_style(("sans-serif", LABEL_PX))
            .x_desc("cycle time (s)")
            .y_desc("episodes")
            .draw()?;
        let x = |b: usize| lo + width * b as f64;
        chart.draw_series((0..bins).map(|b| {
            Rectangle::new(
                [(x(b), 0.0), (x(b + 1), f64::from(ok[b]))],
                GREEN.mix(0.7).filled(),
            )
        }))?;
        chart.draw_series((0..bins).map(|b| {
            let base = f64::from(ok[b]);
            Rectangle::new(
                [(x(b), base), (x(b + 1), base + f64::from(failed[b]))],
                RED.mix(0.7).filled(),
            )
        }))?;
        legend_beside(
            root,
            chart.plotting_area(),
            &[
                ("succeeded", Mark::Square(GREEN)),
                ("failed", Mark::Square(RED)),
            ],
            LEGEND_PX,
        )?;
        Ok(())
    })
}

const OUTCOMES: [StepOutcome; 4] = [
    StepOutcome::Seated,
    StepOutcome::Jammed,
    StepOutcome::Missed,
    StepOutcome::Aborted,
];

fn outcome_colour(o: StepOutcome) -> RGBColor {
    match o {
        StepOutcome::Seated => GREEN,
        StepOutcome::Jammed => ORANGE,
        StepOutcome::Missed => RED,
        StepOutcome::Aborted => GREY,
    }
}

/// Lateral pose error at insertion (dx, dy in mm) of step `index`, coloured by outcome, with
/// the step's capture band (|dx|, |dy| ≤ clearance / 2 + lead-in) drawn as a dashed square
/// when known: points outside it missed, points inside that failed jammed or were yawed.
pub fn pose_error_scatter(
    s: &Summary,
    index: usize,
    records: &[&EpisodeRecord],
) -> Result<String, PlotError> {
    let Some(step) = s.steps.iter().find(|t| t.index == index) else {
        return Err(PlotError {
            plot: "pose error",
            message: format!("no step {index}"),
        });
    };
    let part = &step.part;
    let points: Vec<(f64, f64, StepOutcome)> = records
        .iter()
        .filter_map(|r| r.steps.get(index).filter(|t| &t.part == part))
        .filter_map(|t| t.pose_error.map(|e| (e.dx_mm, e.dy_mm, t.outcome)))
        .collect();
    let band = step.capture_mm;
    let r = points
        .iter()
        .map(|p| p.0.abs().max(p.1.abs()))
        .fold(band.unwrap_or(0.0), f64::max)
        .max(0.01)
        * 1.15;
    let band_label = band.map(|c| format!("capture band ±{c:.3} mm"));
    let mut labels: Vec<&str> = band_label.iter().map(String::as_str).collect();
    labels.extend(OUTCOMES.iter().map(|o| outcome_name(*o)));
    let room = legend_room(&labels, LEGEND_PX);
    svg("pose error", (520 + room, 520), |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(format!("{index}: {part}"), ("sans-serif", 20))
            .margin(12)
            .margin_right(12 + room)
            .x_label_area_size(44)
            .y_label_area_size(70)
            .build_cartesian_2d(-r..r, -r..r)?;
        chart
            .configure_mesh()
            .x_labels(6)
            .y_labels(6)
            .label_style(("sans-serif", LABEL_PX))
            .axis_desc_style(("sans-serif", LABEL_PX))
            .x_desc("dx (mm)")
            .y_desc("dy (mm)")
            .draw()?;
        let mut legend: Vec<(&str, Mark)> = Vec::new();
        if let (Some(c), Some(label)) = (band, band_label.as_deref()) {
            let corners = [(-c, -c), (c, -c), (c, c), (-c, c), (-c, -c)];
            let dashes: Vec<PathElement<(f64, f64)>> = corners
                .windows(2)
                .flat_map(|w| {
                    let (a, b) = (w[0], w[1]);
                    (0..20).step_by(2).map(move |k| {
                        let t0 = f64::from(k) / 20.0;
                        let t1 = f64::from(k + 1) / 20.0;
                        PathElement::new(
                            vec![
                                (a.0 + (b.0 - a.0) * t0, a.1 + (b.1 - a.1) * t0),
                                (a.0 + (b.0 - a.0) * t1, a.1 + (b.1 - a.1) * t1),
                            ],
                            BLACK.stroke_width(2),
                        )
                    })
                })
                .collect();
            chart.draw_series(dashes)?;
            legend.push((label, Mark::Dashed(BLACK)));
        }
        for o in OUTCOMES {
            let c = outcome_colour(o);
            let pts: Vec<(f64, f64)> = points
                .iter()
                .filter(|p| p.2 == o)
                .map(|p| (p.0, p.1))
                .collect();
            if pts.is_empty() {
                continue;
            }
            chart.draw_series(pts.iter().map(|p| Circle::new(*p, 3, c.mix(0.8).filled())))?;
            legend.push((outcome_name(o), Mark::Dot(c)));
        }
        legend_beside(root, chart.plotting_area(), &legend, LEGEND_PX)?;
        Ok(())
    })
}
