//! The wrench trace of a force-guided insertion (`cell replay`): the force out of the hole
//! against the TCP's height above seated and against time, descent by descent, with the
//! thresholds its verdicts were read against.

use plotters::prelude::*;

use super::plots::{LABEL_PX, PlotError, svg};
use crate::orchestrator::{WrenchSample, WrenchTrace};

/// One colour per descent, cycled (tableau-like).
const PROBE_COLOURS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
    RGBColor(188, 189, 34),
    RGBColor(127, 127, 127),
];
const SEAT: RGBColor = RGBColor(44, 160, 44);
const RIM: RGBColor = RGBColor(214, 39, 40);
const STOP: RGBColor = RGBColor(60, 60, 60);

/// The descents of `trace`, each its samples in order.
fn descents(trace: &WrenchTrace) -> Vec<(u32, Vec<WrenchSample>)> {
    let mut out: Vec<(u32, Vec<WrenchSample>)> = Vec::new();
    for s in &trace.samples {
        match out.last_mut() {
            Some((p, v)) if *p == s.probe => v.push(*s),
            _ => out.push((s.probe, vec![*s])),
        }
    }
    out
}

fn range(values: impl Iterator<Item = f64>, with: &[f64]) -> (f64, f64) {
    let (lo, hi) = values
        .chain(with.iter().copied())
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.05).max(1e-3);
    (lo - pad, hi + pad)
}

/// The trace as an SVG: left, force out of the hole against the TCP's height above seated
/// (the seat band and the rim as vertical lines, the stopping force as a horizontal one);
/// right, force out of the hole (solid) and across the axis (thin) against time since each
/// descent began. `title` names the insertion.
pub fn wrench_trace_plot(title: &str, trace: &WrenchTrace) -> Result<String, PlotError> {
    let runs = descents(trace);
    let (h_lo, h_hi) = range(
        trace.samples.iter().map(|s| s.height_mm),
        &[0.0, trace.seat_band_mm, trace.rim_mm],
    );
    let (f_lo, f_hi) = range(
        trace.samples.iter().flat_map(|s| [s.force_n, s.lateral_n]),
        &[0.0, trace.contact_force_n],
    );
    let (t_lo, t_hi) = range(trace.samples.iter().map(|s| s.t_s), &[0.0]);
    let title = title.to_string();
    svg("wrench trace", (1000, 440), |root| {
        let root = root.titled(&title, ("sans-serif", 20))?;
        let (left, right) = root.split_horizontally(500);
        let mut chart = ChartBuilder::on(&left)
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(56)
            .build_cartesian_2d(h_lo..h_hi, f_lo..f_hi)?;
        chart
            .configure_mesh()
            .label_style(("sans-serif", LABEL_PX))
            .axis_desc_style(("sans-serif", LABEL_PX))
            .x_desc("TCP height above seated (mm)")
            .y_desc("force out of the hole (N)")
            .draw()?;
        let vline = |x: f64| vec![(x, f_lo), (x, f_hi)];
        chart
            .draw_series(LineSeries::new(
                vline(trace.seat_band_mm),
                SEAT.stroke_width(2),
            ))?
            .label(format!("seat band {:.3} mm", trace.seat_band_mm))
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], SEAT.stroke_width(2)));
        chart
            .draw_series(LineSeries::new(vline(trace.rim_mm), RIM.stroke_width(2)))?
            .label(format!("rim {:.3} mm", trace.rim_mm))
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], RIM.stroke_width(2)));
        chart
            .draw_series(LineSeries::new(
                vec![(h_lo, trace.contact_force_n), (h_hi, trace.contact_force_n)],
                STOP.stroke_width(1),
            ))?
            .label(format!("stop at {:.1} N", trace.contact_force_n))
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], STOP.stroke_width(1)));
        for (probe, samples) in &runs {
            let c = PROBE_COLOURS[*probe as usize % PROBE_COLOURS.len()];
            chart.draw_series(LineSeries::new(
                samples.iter().map(|s| (s.height_mm, s.force_n)),
                c.stroke_width(2),
            ))?;
            chart.draw_series(
                samples
                    .last()
                    .map(|s| Circle::new((s.height_mm, s.force_n), 4, c.filled())),
            )?;
        }
        chart
            .configure_series_labels()
            .label_font(("sans-serif", LABEL_PX))
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperLeft)
            .draw()?;
        let mut chart = ChartBuilder::on(&right)
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(56)
            .build_cartesian_2d(t_lo..t_hi, f_lo..f_hi)?;
        chart
            .configure_mesh()
            .label_style(("sans-serif", LABEL_PX))
            .axis_desc_style(("sans-serif", LABEL_PX))
            .x_desc("time since the descent began (s)")
            .y_desc("force (N)")
            .draw()?;
        chart.draw_series(LineSeries::new(
            vec![(t_lo, trace.contact_force_n), (t_hi, trace.contact_force_n)],
            STOP.stroke_width(1),
        ))?;
        for (probe, samples) in &runs {
            let c = PROBE_COLOURS[*probe as usize % PROBE_COLOURS.len()];
            let name = if *probe == 0 {
                "planned descent".to_string()
            } else {
                format!("spiral probe {probe}")
            };
            chart
                .draw_series(LineSeries::new(
                    samples.iter().map(|s| (s.t_s, s.force_n)),
                    c.stroke_width(2),
                ))?
                .label(name)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], c.stroke_width(2))
                });
            chart.draw_series(LineSeries::new(
                samples.iter().map(|s| (s.t_s, s.lateral_n)),
                c.stroke_width(1),
            ))?;
        }
        chart
            .configure_series_labels()
            .label_font(("sans-serif", LABEL_PX))
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperLeft)
            .draw()?;
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(probe: u32, t_s: f64, height_mm: f64, force_n: f64) -> WrenchSample {
        WrenchSample {
            probe,
            t_s,
            height_mm,
            force_n,
            lateral_n: 0.5,
        }
    }

    #[test]
    fn the_plot_draws_every_descent_and_the_thresholds() {
        let trace = WrenchTrace {
            contact_force_n: 10.0,
            contact_stiffness_n_per_m: 2e5,
            seat_band_mm: 0.05,
            rim_mm: 1.95,
            landings_mm: vec![],
            samples: vec![
                sample(0, 0.0, 3.0, 0.0),
                sample(0, 0.05, 2.0, 0.0),
                sample(0, 0.06, 1.95, 10.2),
                sample(1, 0.0, 2.2, 0.0),
                sample(1, 0.1, 0.0, 0.0),
                sample(1, 0.11, -0.05, 10.1),
            ],
        };
        assert_eq!(descents(&trace).len(), 2);
        let svg = wrench_trace_plot("step 0", &trace).unwrap();
        assert!(svg.starts_with("<svg"), "{}", &svg[..60.min(svg.len())]);
        for text in [
            "seat band 0.050 mm",
            "rim 1.950 mm",
            "stop at 10.0 N",
            "spiral probe 1",
        ] {
            assert!(svg.contains(text), "{text} missing");
        }
    }
}
