//! The timeline of an episode's cycle: one bar per episode, coloured by the orchestrator state
//! the simulated time went to, so a reader sees where a typical cycle and the slowest one spend
//! their seconds.

use plotters::prelude::*;

use super::plots::{LABEL_PX, LEGEND_PX, Mark, PlotError, legend_beside, legend_room, svg};
use crate::episode::EpisodeRecord;
use crate::orchestrator::State;

/// Every state a cycle can spend time in, in the order a step passes through them, each with
/// the colour of its time (tableau-like, one per state).
const STATE_COLOURS: [(State, RGBColor); 12] = [
    (State::Home, RGBColor(199, 199, 199)),
    (State::Capture, RGBColor(23, 190, 207)),
    (State::Perceive, RGBColor(158, 218, 229)),
    (State::Select, RGBColor(188, 189, 34)),
    (State::PlanPick, RGBColor(219, 219, 141)),
    (State::Pick, RGBColor(31, 119, 180)),
    (State::VerifyGrasp, RGBColor(174, 199, 232)),
    (State::PlanInsert, RGBColor(255, 187, 120)),
    (State::Insert, RGBColor(255, 127, 14)),
    (State::Verify, RGBColor(44, 160, 44)),
    (State::Shake, RGBColor(214, 39, 40)),
    (State::Retract, RGBColor(148, 103, 189)),
];

/// The colour of a state's time.
fn colour(state: State) -> RGBColor {
    STATE_COLOURS
        .iter()
        .find(|(s, _)| *s == state)
        .map_or(STATE_COLOURS[0].1, |(_, c)| *c)
}

/// The timelines of `episodes` (a label and a record each, records with phases), one bar per
/// episode, with a legend of the states that appear, beside the bars.
pub fn cycle_timeline(episodes: &[(String, &EpisodeRecord)]) -> Result<String, PlotError> {
    let longest = episodes
        .iter()
        .map(|(_, r)| r.phases.iter().map(|p| p.duration_s).sum::<f64>())
        .fold(0.0, f64::max)
        .max(1e-3);
    let present: Vec<State> = STATE_COLOURS
        .iter()
        .map(|(s, _)| *s)
        .filter(|s| {
            episodes
                .iter()
                .any(|(_, r)| r.phases.iter().any(|p| p.state == *s && p.duration_s > 0.0))
        })
        .collect();
    let names: Vec<&str> = present.iter().map(|s| s.name()).collect();
    let room = legend_room(&names, LEGEND_PX);
    let rows = episodes.len().max(1);
    let height = (110 + 60 * rows as u32).max(24 * names.len() as u32 + 90);
    svg("cycle timeline", (800, height), |root| {
        let mut chart = ChartBuilder::on(root)
            .caption("Where the cycle time goes", ("sans-serif", 22))
            .margin(12)
            .margin_right(12 + room)
            .x_label_area_size(40)
            .y_label_area_size(150)
            .build_cartesian_2d(0.0..longest * 1.02, 0.0..rows as f64)?;
        let labels: Vec<String> = episodes.iter().map(|(l, _)| l.clone()).collect();
        chart
            .configure_mesh()
            .disable_y_mesh()
            .y_labels(rows * 2 + 1)
            .y_label_formatter(&|y| {
                let i = (y - 0.5).round();
                if (y - 0.5 - i).abs() < 1e-6 && i >= 0.0 && (i as usize) < labels.len() {
                    labels[labels.len() - 1 - i as usize].clone()
                } else {
                    String::new()
                }
            })
            .label_style(("sans-serif", LABEL_PX))
            .axis_desc_style(("sans-serif", LABEL_PX))
            .x_desc("simulated time since the arm left home (s)")
            .draw()?;
        for (row, (_, r)) in episodes.iter().enumerate() {
            let y = (rows - 1 - row) as f64;
            let mut t = 0.0;
            let mut bars = Vec::new();
            for p in &r.phases {
                bars.push(Rectangle::new(
                    [(t, y + 0.2), (t + p.duration_s, y + 0.8)],
                    colour(p.state).filled(),
                ));
                t += p.duration_s;
            }
            chart.draw_series(bars)?;
        }
        let items: Vec<(&str, Mark)> = present
            .iter()
            .map(|s| (s.name(), Mark::Square(colour(*s))))
            .collect();
        legend_beside(root, chart.plotting_area(), &items, LEGEND_PX)?;
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::episode::{PhaseSpan, RECORD_VERSION};

    #[test]
    fn every_state_has_its_own_colour() {
        let mut seen: Vec<RGBColor> = STATE_COLOURS.iter().map(|(s, _)| colour(*s)).collect();
        seen.sort_by_key(|c| (c.0, c.1, c.2));
        seen.dedup();
        assert_eq!(seen.len(), STATE_COLOURS.len());
    }

    #[test]
    fn a_timeline_draws_one_bar_per_phase_and_a_legend_of_the_states_present() {
        let r = EpisodeRecord {
            version: RECORD_VERSION,
            scenario: "s".into(),
            seed: 1,
            episode: 0,
            success: true,
            steps: vec![],
            cycle_time_s: 3.0,
            wall_time_s: 0.0,
            abort: None,
            phases: [
                (State::Pick, 1.0),
                (State::Insert, 1.5),
                (State::Verify, 0.5),
            ]
            .into_iter()
            .map(|(state, duration_s)| PhaseSpan {
                state,
                activity: None,
                step: Some(0),
                duration_s,
            })
            .collect(),
        };
        let svg = cycle_timeline(&[("typical".into(), &r)]).unwrap();
        for name in ["pick", "insert", "verify", "typical"] {
            assert!(svg.contains(name), "{name} missing");
        }
        assert!(!svg.contains(">shake<"));
        let (r0, g0, b0) = (
            colour(State::Insert).0,
            colour(State::Insert).1,
            colour(State::Insert).2,
        );
        assert!(
            svg.contains(&format!("#{r0:02X}{g0:02X}{b0:02X}")),
            "no insert-coloured bar"
        );
    }
}
