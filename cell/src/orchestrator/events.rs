//! The episode's event log: every state transition as one JSON line with simulated and wall time.

use std::io::Write;
use std::time::Instant;

use serde::{Deserialize, Serialize};

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
}

impl EventLog {
    /// An empty log for `episode`, its wall clock starting now.
    pub fn new(episode: u32) -> Self {
        Self {
            episode,
            start: Instant::now(),
            events: Vec::new(),
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

    /// Wall-clock seconds since the log was created.
    pub fn wall_time_s(&self) -> f64 {
        self.start.elapsed().as_secs_f64()
    }

    /// The events so far.
    pub fn events(&self) -> &[Event] {
        &self.events
    }

    /// Where the cycle's simulated time went: each state entered after the cycle started (the
    /// arm at home), in order, with the simulated seconds spent in it. The spans add up to the
    /// cycle time.
    pub fn phases(&self) -> Vec<PhaseSpan> {
        let mut spans = Vec::new();
        // (simulated time, step) at which the state being timed was entered.
        let mut entered: Option<(f64, Option<usize>)> = None;
        for e in &self.events {
            if let Some((start, step)) = entered {
                spans.push(PhaseSpan {
                    state: e.from,
                    step,
                    duration_s: e.sim_time_s - start,
                });
            }
            if entered.is_some() || (e.from == State::Home && e.to != State::Home) {
                entered = Some((e.sim_time_s, e.step));
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
