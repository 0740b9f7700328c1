//! The wrench trace of a force-guided insertion (`cell replay`): the force out of the hole
//! against the TCP's height above seated and against time, descent by descent, with the
//! thresholds its verdicts were read against.

use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
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

type DrawResult = Result<(), Box<dyn std::error::Error>>;

/// One of the two charts of the trace.
type Chart<'a, 'b> = ChartContext<'a, SVGBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// A chart on `area` over `x` × `y` with its mesh drawn and its axes described (`desc`: x, y).
fn new_chart<'a, 'b>(
    area: &'a DrawingArea<SVGBackend<'b>, Shift>,
    (x, y): ((f64, f64), (f64, f64)),
    desc: (&str, &str),
) -> Result<Chart<'a, 'b>, Box<dyn std::error::Error>> {
    let mut chart = ChartBuilder::on(area)
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(56)
        .build_cartesian_2d(x.0..x.1, y.0..y.1)?;
    chart
        .configure_mesh()
        .label_style(("sans-serif", LABEL_PX))
        .axis_desc_style(("sans-serif", LABEL_PX))
        .x_desc(desc.0)
        .y_desc(desc.1)
        .draw()?;
    Ok(chart)
}

/// Draws the labelled series' legend in the chart's upper left corner.
fn legend<'a, 'b: 'a>(chart: &mut Chart<'a, 'b>) -> DrawResult {
    chart
        .configure_series_labels()
        .label_font(("sans-serif", LABEL_PX))
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperLeft)
        .draw()?;
    Ok(())
}

/// The legend's text for the landing bands: "miss lands here" and their heights.
fn landings_label(bands: &[[f64; 2]]) -> String {
    let each: Vec<String> = bands
        .iter()
        .map(|b| format!("{:.3}–{:.3}", b[0], b[1]))
        .collect();
    format!("miss lands here {} mm", each.join(", "))
}

/// The trace as an SVG: left, force out of the hole against the TCP's height above seated
/// (the seat band and the receiver's top as vertical lines, the heights where a part beyond
/// the capture band lands on what is in place as shaded bands, the stopping force as a
/// horizontal line); right, force out of the hole (solid) and across the axis (thin) against
/// time since each descent began. `title` names the insertion. A trace from before the
/// landing bands were kept draws without them.
pub fn wrench_trace_plot(title: &str, trace: &WrenchTrace) -> Result<String, PlotError> {
    let runs = descents(trace);
    let mut marks = vec![0.0, trace.seat_band_mm, trace.rim_mm];
    marks.extend(trace.landings_mm.iter().flatten().copied());
    let (h_lo, h_hi) = range(trace.samples.iter().map(|s| s.height_mm), &marks);
    let (f_lo, f_hi) = range(
        trace.samples.iter().flat_map(|s| [s.force_n, s.lateral_n]),
        &[0.0, trace.contact_force_n],
    );
    let (t_lo, t_hi) = range(trace.samples.iter().map(|s| s.t_s), &[0.0]);
    let title = title.to_string();
    svg("wrench trace", (1000, 440), |root| {
        let root = root.titled(&title, ("sans-serif", 20))?;
        let (left, right) = root.split_horizontally(500);
        let mut chart = new_chart(
            &left,
            ((h_lo, h_hi), (f_lo, f_hi)),
            ("TCP height above seated (mm)", "force out of the hole (N)"),
        )?;
        if !trace.landings_mm.is_empty() {
            let shade = RIM.mix(0.15).filled();
            chart
                .draw_series(
                    trace
                        .landings_mm
                        .iter()
                        .map(|b| Rectangle::new([(b[0], f_lo), (b[1], f_hi)], shade)),
                )?
                .label(landings_label(&trace.landings_mm))
                .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 18, y + 5)], shade));
        }
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
            .label(format!("top of the receiver from {:.3} mm", trace.rim_mm))
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
        legend(&mut chart)?;
        let mut chart = new_chart(
            &right,
            ((t_lo, t_hi), (f_lo, f_hi)),
            ("time since the descent began (s)", "force (N)"),
        )?;
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
        legend(&mut chart)
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

    fn trace(landings_mm: Vec<[f64; 2]>) -> WrenchTrace {
        WrenchTrace {
            contact_force_n: 10.0,
            contact_stiffness_n_per_m: 2e5,
            seat_band_mm: 0.05,
            rim_mm: 1.95,
            landings_mm,
            samples: vec![
                sample(0, 0.0, 3.0, 0.0),
                sample(0, 0.05, 2.0, 0.0),
                sample(0, 0.06, 1.95, 10.2),
                sample(1, 0.0, 2.2, 0.0),
                sample(1, 0.1, 0.0, 0.0),
                sample(1, 0.11, -0.05, 10.1),
            ],
        }
    }

    /// The shaded rectangles of an SVG (the landing bands are the only ones drawn at 15 %).
    fn shaded(svg: &str) -> Vec<(f64, f64)> {
        let attr = |r: &str, name: &str| -> f64 {
            let at = r.find(&format!(" {name}=\"")).expect(name) + name.len() + 3;
            r[at..].split('"').next().unwrap().parse().unwrap()
        };
        svg.split("<rect")
            .skip(1)
            .filter_map(|r| r.split('>').next())
            .filter(|r| r.contains("opacity=\"0.15\""))
            .map(|r| (attr(r, "x"), attr(r, "x") + attr(r, "width")))
            .collect()
    }

    #[test]
    fn the_plot_draws_every_descent_and_the_thresholds() {
        let trace = trace(vec![]);
        assert_eq!(descents(&trace).len(), 2);
        let svg = wrench_trace_plot("step 0", &trace).unwrap();
        assert!(svg.starts_with("<svg"), "{}", &svg[..60.min(svg.len())]);
        for text in [
            "seat band 0.050 mm",
            "top of the receiver from 1.950 mm",
            "stop at 10.0 N",
            "spiral probe 1",
        ] {
            assert!(svg.contains(text), "{text} missing");
        }
        assert!(!svg.contains("miss lands here"));
        assert!(shaded(&svg).is_empty());
    }

    #[test]
    fn the_plot_shades_where_a_miss_lands_and_reaches_bands_beyond_the_descents() {
        // A top shell's bands: onto what the main shell holds, onto its rim, and one above
        // every reading.
        let trace = trace(vec![[1.296, 1.4], [2.248, 2.54], [3.642, 3.94]]);
        let svg = wrench_trace_plot("step 2", &trace).unwrap();
        assert!(
            svg.contains("miss lands here 1.296–1.400, 2.248–2.540, 3.642–3.940 mm"),
            "the bands' legend missing"
        );
        // One shaded band per landing, and the legend's swatch, all within the left chart (its
        // height axis reaches the band above every reading).
        let bands = shaded(&svg);
        assert_eq!(bands.len(), 4, "{bands:?}");
        assert!(
            bands
                .iter()
                .all(|b| b.0 >= 56.0 && b.1 <= 500.0 && b.1 > b.0),
            "{bands:?}"
        );
        for text in ["seat band 0.050 mm", "top of the receiver from 1.950 mm"] {
            assert!(svg.contains(text), "{text} missing");
        }
    }

    #[test]
    fn a_trace_from_an_event_file_without_bands_still_plots() {
        // As the Insert → Verify event stored it before the landing bands were kept.
        let old: WrenchTrace = serde_json::from_str(
            r#"{"contact_force_n":10.0,"contact_stiffness_n_per_m":200000.0,
                "seat_band_mm":0.2,"rim_mm":2.69,
                "samples":[{"probe":0,"t_s":0.0,"height_mm":3.0,"force_n":0.0,"lateral_n":0.1},
                           {"probe":0,"t_s":0.1,"height_mm":1.35,"force_n":10.4,"lateral_n":0.3}]}"#,
        )
        .unwrap();
        assert!(old.landings_mm.is_empty());
        let svg = wrench_trace_plot("step 2", &old).unwrap();
        assert!(svg.contains("top of the receiver from 2.690 mm"));
        assert!(svg.contains("planned descent"));
        assert!(!svg.contains("miss lands here"));
        assert!(shaded(&svg).is_empty());
    }
}
