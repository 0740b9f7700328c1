//! The report's plots as SVG text (plotters' SVG backend), ready to inline into HTML.

use plotters::prelude::*;
use plotters::style::FontStyle;

use crate::episode::{EpisodeRecord, StepOutcome};
use crate::run::Summary;
use crate::run::summary::outcome_name;

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
fn svg<F>(plot: &'static str, size: (u32, u32), draw: F) -> Result<String, PlotError>
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

/// Episode success and each step's seated rate with 95 % Wilson intervals.
pub fn success_rates(s: &Summary) -> Result<String, PlotError> {
    let mut bars = vec![("episode".to_string(), s.success_rate, s.success_ci95)];
    bars.extend(
        s.steps
            .iter()
            .map(|t| (format!("{}: {}", t.index, t.part), t.rate, t.ci95)),
    );
    let labels: Vec<String> = bars.iter().map(|b| b.0.clone()).collect();
    let n = bars.len();
    svg("success rate", (900, 480), |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(
                "Success rate with 95 % Wilson intervals",
                ("sans-serif", 22),
            )
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(-0.5f64..n as f64 - 0.5, 0.0f64..100.0)?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(n)
            .x_label_formatter(&|x| category_label(&labels, *x))
            .y_desc("% of episodes reaching it")
            .draw()?;
        chart.draw_series(bars.iter().enumerate().map(|(i, (_, r, _))| {
            let x = i as f64;
            let c = if i == 0 { BLUE } else { GREEN };
            Rectangle::new([(x - 0.3, 0.0), (x + 0.3, 100.0 * r)], c.mix(0.7).filled())
        }))?;
        chart.draw_series(bars.iter().enumerate().map(|(i, (_, r, ci))| {
            ErrorBar::new_vertical(
                i as f64,
                100.0 * ci.lo,
                100.0 * r,
                100.0 * ci.hi,
                BLACK.stroke_width(2),
                16,
            )
        }))?;
        Ok(())
    })
}

/// Horizontal bars of `(label, value)` with a value axis named `x_desc`.
fn horizontal_bars(
    plot: &'static str,
    caption: &str,
    x_desc: &str,
    items: &[(String, f64)],
    colour: RGBColor,
) -> Result<String, PlotError> {
    let labels: Vec<String> = items.iter().map(|(l, _)| shorten(l, 48)).collect();
    let n = items.len().max(1);
    let max = items.iter().map(|i| i.1).fold(0.0, f64::max).max(1e-9) * 1.1;
    svg(plot, (900, 120 + 32 * n as u32), |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(caption, ("sans-serif", 22))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(360)
            .build_cartesian_2d(0.0f64..max, -0.5f64..n as f64 - 0.5)?;
        chart
            .configure_mesh()
            .disable_y_mesh()
            .y_labels(n)
            .y_label_formatter(&|y| category_label(&labels, *y))
            .x_desc(x_desc)
            .draw()?;
        chart.draw_series(items.iter().enumerate().map(|(i, (_, v))| {
            let y = i as f64;
            Rectangle::new([(0.0, y - 0.35), (*v, y + 0.35)], colour.mix(0.75).filled())
        }))?;
        Ok(())
    })
}

/// Failed episodes per cause (the `top` most frequent).
pub fn failure_causes(s: &Summary, top: usize) -> Result<String, PlotError> {
    let items: Vec<(String, f64)> = s
        .failure_causes
        .iter()
        .take(top)
        .map(|c| {
            let head = match (&c.part, c.outcome) {
                (Some(p), Some(o)) => format!("{p} {}: ", outcome_name(o)),
                _ => "episode: ".into(),
            };
            (format!("{head}{}", c.cause), f64::from(c.count))
        })
        .collect();
    horizontal_bars(
        "failure causes",
        "Failure causes",
        "failed episodes",
        &items,
        RED,
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
    svg("cycle time", (900, 420), |root| {
        let mut chart = ChartBuilder::on(root)
            .caption("Simulated cycle time", ("sans-serif", 22))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(lo..lo + width * bins as f64, 0.0..f64::from(top) * 1.1)?;
        chart
            .configure_mesh()
            .x_desc("cycle time (s)")
            .y_desc("episodes")
            .draw()?;
        let x = |b: usize| lo + width * b as f64;
        chart
            .draw_series((0..bins).map(|b| {
                Rectangle::new(
                    [(x(b), 0.0), (x(b + 1), f64::from(ok[b]))],
                    GREEN.mix(0.7).filled(),
                )
            }))?
            .label("succeeded")
            .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 12, y + 5)], GREEN.filled()));
        chart
            .draw_series((0..bins).map(|b| {
                let base = f64::from(ok[b]);
                Rectangle::new(
                    [(x(b), base), (x(b + 1), base + f64::from(failed[b]))],
                    RED.mix(0.7).filled(),
                )
            }))?
            .label("failed")
            .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 12, y + 5)], RED.filled()));
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()?;
        Ok(())
    })
}

fn outcome_colour(o: StepOutcome) -> RGBColor {
    match o {
        StepOutcome::Seated => GREEN,
        StepOutcome::Jammed => ORANGE,
        StepOutcome::Missed => RED,
        StepOutcome::Aborted => GREY,
    }
}

/// Lateral pose error at insertion (dx, dy in mm), one panel per step, coloured by outcome.
pub fn pose_error_scatter(s: &Summary, records: &[&EpisodeRecord]) -> Result<String, PlotError> {
    let steps: Vec<(usize, String)> = s.steps.iter().map(|t| (t.index, t.part.clone())).collect();
    let panels = steps.len().max(1);
    svg("pose error", (440 * panels as u32, 460), |root| {
        for ((index, part), area) in steps.iter().zip(root.split_evenly((1, panels))) {
            let points: Vec<(f64, f64, StepOutcome)> = records
                .iter()
                .filter_map(|r| r.steps.get(*index).filter(|t| &t.part == part))
                .filter_map(|t| t.pose_error.map(|e| (e.dx_mm, e.dy_mm, t.outcome)))
                .collect();
            let r = points
                .iter()
                .map(|p| p.0.abs().max(p.1.abs()))
                .fold(0.0, f64::max)
                .max(0.01)
                * 1.1;
            let mut chart = ChartBuilder::on(&area)
                .caption(format!("{index}: {part}"), ("sans-serif", 18))
                .margin(10)
                .x_label_area_size(36)
                .y_label_area_size(56)
                .build_cartesian_2d(-r..r, -r..r)?;
            chart
                .configure_mesh()
                .x_desc("dx (mm)")
                .y_desc("dy (mm)")
                .draw()?;
            for o in [
                StepOutcome::Seated,
                StepOutcome::Jammed,
                StepOutcome::Missed,
                StepOutcome::Aborted,
            ] {
                let c = outcome_colour(o);
                let pts: Vec<(f64, f64)> = points
                    .iter()
                    .filter(|p| p.2 == o)
                    .map(|p| (p.0, p.1))
                    .collect();
                if pts.is_empty() {
                    continue;
                }
                chart
                    .draw_series(pts.iter().map(|p| Circle::new(*p, 3, c.mix(0.8).filled())))?
                    .label(outcome_name(o))
                    .legend(move |(x, y)| Circle::new((x + 6, y), 4, c.filled()));
            }
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()?;
        }
        Ok(())
    })
}
