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
    /// A force-guided insertion's wrist readings, on the transition into Verify (absent
    /// otherwise, and in event files from before traces were kept).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wrench_trace: Option<WrenchTrace>,
    /// The feeder shakes started in the state this transition leaves (absent when none, and
    /// in event files from before shakes were recorded).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub shakes: Vec<ShakeStart>,
}

/// A feeder shake as the engine started it: when, where the arm was, and why it waited. A
/// shake starts only with the arm and any held part away from the feeder
/// (`orchestrator::view::arm_near_feeder`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShakeStart {
    /// The step whose parts it shakes up (this one after no usable instance was found, or the
    /// next one when decided right after a pick).
    pub for_step: usize,
    /// Cell clock when the shake started, s.
    pub t_s: f64,
    /// The arm's joints then (rad): the planned trajectory's sample at that instant in the
    /// simulated cell, the arm's reported joints on a controller.
    pub joints: [f64; 6],
    /// Radius of the held part's bounding sphere about the TCP the check counted, m (absent:
    /// empty fingers).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_radius_m: Option<f64>,
    /// The motion it started during (or after), by its waypoint name.
    pub motion: String,
    /// Seconds into that motion: mid-motion from the motion's sampled trajectory, or the
    /// motion's whole duration when it started after it.
    pub into_motion_s: f64,
    /// Seconds from the decision to shake to its start.
    pub held_back_s: f64,
    /// What was near the feeder when the shake was decided (absent: nothing, it started at
    /// once).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub waited_for: Option<String>,
}

impl ShakeStart {
    /// The shake in words, for the log.
    pub fn describe(&self) -> String {
        let wait = match &self.waited_for {
            Some(what) => format!(
                ", held back {:.3} s while the {what} was near the feeder",
                self.held_back_s
            ),
            None => String::new(),
        };
        format!(
            "shake for step {} started at {:.3} s, {:.3} s into the {}{wait}",
            self.for_step, self.t_s, self.into_motion_s, self.motion
        )
    }
}

/// A force-guided insertion's wrist readings along its guarded descents, in the insertion frame,
/// decimated, with the thresholds its verdicts were read against.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WrenchTrace {
    /// Force against the motion at which a guarded descent stops, N.
    pub contact_force_n: f64,
    /// Stiffness the verdicts assume for the press, N/m (first contact is the stop's height
    /// plus force / stiffness).
    pub contact_stiffness_n_per_m: f64,
    /// First contact at most this high above seated reads as seated, mm.
    pub seat_band_mm: f64,
    /// First contact at least this high above seated reads as missed on the rim, mm (jammed
    /// between the two, but within [`Self::landings_mm`]).
    pub rim_mm: f64,
    /// Bands (low, high) of heights above seated, mm, where a part beyond the capture band
    /// lands on what is in place: first contact within one reads as missed too. Empty in
    /// events from before them.
    #[serde(default)]
    pub landings_mm: Vec<[f64; 2]>,
    /// The readings, descent by descent, each in time order.
    pub samples: Vec<WrenchSample>,
}

/// One wrist reading of a [`WrenchTrace`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WrenchSample {
    /// Which guarded descent (0: the planned one, then the spiral probes).
    pub probe: u32,
    /// Seconds since that descent began.
    pub t_s: f64,
    /// TCP height above seated along the insertion axis, mm.
    pub height_mm: f64,
    /// Force out of the hole (against the descent), N.
    pub force_n: f64,
    /// Force across the insertion axis, N.
    pub lateral_n: f64,
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
    /// Shakes started since the last transition, for the next one.
    shakes: Vec<ShakeStart>,
}

impl EventLog {
    /// An empty log for `episode`, its wall clock starting now.
    pub fn new(episode: u32) -> Self {
        Self {
            episode,
            start: Instant::now(),
            events: Vec::new(),
            motions: Vec::new(),
            shakes: Vec::new(),
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
            wrench_trace: None,
            shakes: std::mem::take(&mut self.shakes),
        });
    }

    /// Records a feeder shake started in the state now running (kept on the transition that
    /// leaves it).
    pub fn shake_started(&mut self, shake: ShakeStart) {
        tracing::debug!(episode = self.episode, "{}", shake.describe());
        self.shakes.push(shake);
    }

    /// Attaches a force-guided insertion's wrench trace to the last event recorded.
    pub fn attach_trace(&mut self, trace: WrenchTrace) {
        if let Some(e) = self.events.last_mut() {
            e.wrench_trace = Some(trace);
        }
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
