//! The episode's event log: every state transition as one JSON line with simulated and wall time.

use std::io::Write;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use super::activity::Activity;
use super::state::State;
use crate::episode::PhaseSpan;

/// One transition of the state machine.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Event {
    /// Episode index.
    pub episode: u32,
    /// Assembly step index, when inside a step.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub step: Option<usize>,
    /// State left.
    pub from: State,
    /// State entered.
    pub to: State,
    /// Simulated (or controller) seconds since the episode started.
    pub sim_time_s: f64,
    /// Wall-clock seconds since the episode started.
    pub wall_time_s: f64,
    /// What happened, in words.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub detail: String,
}

/// The events of one episode, in order.
#[derive(Debug, Clone)]
pub struct EventLog {
    episode: u32,
    start: Instant,
    events: Vec<Event>,
    /// (index of the event that will close the state it ran in, simulated time, activity) at
    /// the end of each motion, in order.
    motions: Vec<(usize, f64, Activity)>,
}

impl EventLog {
    /// An empty log for `episode`, its wall clock starting now.
    pub fn new(episode: u32) -> Self {
        Self {
            episode,
            start: Instant::now(),
            events: Vec::new(),
            motions: Vec::new(),
        }
    }

    /// Records a transition.
    pub fn push(
        &mut self,
        step: Option<usize>,
        from: State,
        to: State,
        sim_time_s: f64,
        detail: impl Into<String>,
    ) {
        let detail = detail.into();
        tracing::debug!(episode = self.episode, ?step, ?from, ?to, sim_time_s, %detail, "transition");
        self.events.push(Event {
            episode: self.episode,
            step,
            from,
            to,
            sim_time_s,
            wall_time_s: self.start.elapsed().as_secs_f64(),
            detail,
        });
    }

    /// Records that a motion named `waypoint` ended at `sim_time_s`: the time since the state's
    /// previous mark is that motion's activity ([`Activity::of_motion`]; names it does not know
    /// leave the time to their state's).
    pub fn motion_done(&mut self, waypoint: &str, sim_time_s: f64) {
        if let Some(a) = Activity::of_motion(waypoint) {
            self.motions.push((self.events.len(), sim_time_s, a));
        }
    }

    /// Wall-clock seconds since the log was created.
    pub fn wall_time_s(&self) -> f64 {
        self.start.elapsed().as_secs_f64()
    }

    /// The events so far.
    pub fn events(&self) -> &[Event] {
        &self.events
    }

    /// Where the cycle's simulated time went: each state entered after the cycle started (the
    /// arm at home), in order, split at the end of each of its motions, with the simulated
    /// seconds and the activity of each part. The spans add up to the cycle time.
    pub fn phases(&self) -> Vec<PhaseSpan> {
        let mut spans = Vec::new();
        // (simulated time, step, state before) at which the state being timed was entered.
        let mut entered: Option<(f64, Option<usize>, Option<State>)> = None;
        let mut motions = self.motions.iter().peekable();
        for (i, e) in self.events.iter().enumerate() {
            // The motions that ran in the state this event leaves.
            let mut ran = Vec::new();
            while let Some(&(_, t, activity)) = motions.next_if(|m| m.0 == i) {
                ran.push((t, activity));
            }
            if let Some((start, step, before)) = entered {
                let span = |activity, from: f64, to: f64| PhaseSpan {
                    state: e.from,
                    activity: Some(activity),
                    step,
                    duration_s: to - from,
                };
                let mut at = start;
                for (t, activity) in ran {
                    if t >= at {
                        spans.push(span(activity, at, t));
                        at = t;
                    }
                }
                if e.sim_time_s > at || at == start {
                    spans.push(span(Activity::of_state(e.from, before), at, e.sim_time_s));
                }
            }
            if entered.is_some() || (e.from == State::Home && e.to != State::Home) {
                entered = Some((e.sim_time_s, e.step, Some(e.from)));
            }
        }
        spans
    }

    /// Writes the events as JSON lines.
    pub fn write_jsonl(&self, out: &mut dyn Write) -> std::io::Result<()> {
        for e in &self.events {
            serde_json::to_writer(&mut *out, e)?;
            out.write_all(b"\n")?;
        }
        Ok(())
    }
}
