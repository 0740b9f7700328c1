//! Force-guided insertion (`[force_insertion]`), one strategy for the simulated cell and a
//! production arm alike: both are a `robots::Robot` with a wrist sensor
//! ([`Robot::move_until_contact`], [`Robot::wrench`]).
//!
//! 1. The planner's moves bring the held part to the lead-in (transfer, pre-insert).
//! 2. A guarded descent towards the seat, [`ForceInsertionSpec::overtravel`] beyond it, stops
//!    where the wrist feels [`ForceInsertionSpec::contact_force`] against the motion.
//! 3. [`classify`] tells the outcome from force and depth: no contact at all is a miss with
//!    nothing under the tool; first contact (the stop, less the press's compliance) within
//!    [`ForceInsertionSpec::seat_band`] of seated is a seat; where a part beyond the capture
//!    band lands on what is in place ([`RimLandings`], swept from the parts' shapes: the
//!    receiver's rim, or a lower face where the receiver is narrower than the held part), or at
//!    the receiver's top (within half the lead-in of the engagement depth), a miss on the rim;
//!    anywhere else in between a jam.
//! 4. A miss on the rim or a jam starts a bounded spiral search within the capture band: lift
//!    clear, step sideways to the next point (rings of radius k × capture band, 8k points each),
//!    descend again; a seat, or a descent that meets nothing, ends it.
//! 5. A seat is confirmed before the fingers open ([`confirm_seat`]): the wrist must still feel
//!    the part pressed, and the arm must still be at seated depth.
//!
//! The engine retries what this returns unseated (a jam with a yaw search, a miss with a wider
//! lateral offset) within `policy.max_insertion_attempts`, and never releases a part that was
//! not confirmed seated.

use std::collections::HashMap;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use nalgebra::{Isometry3, Translation3, Vector3};
use robots::robot::{ContactOutcome, ContactSample, LinearMotion, Robot, RobotError};
use sim::cell::geometry::PartGeometry;
pub use sim::cell::insertion::landing::RimLandings;
use sim::cell::insertion::landing::Sweep;

use super::events::{WrenchSample, WrenchTrace};
use crate::episode::StepOutcome;
use crate::scenario::ForceInsertionSpec;

/// Height above the receiver's top to which a spiral probe lifts the part off the rim, as a
/// multiple of the step's lead-in (at least [`MIN_PROBE_LIFT`]).
const PROBE_LIFT_LEAD_INS: f64 = 2.0;
/// Smallest lift off the rim between spiral probes, metres.
const MIN_PROBE_LIFT: f64 = 1e-4;
/// Share of the contact force the wrist must still feel for a seat to be confirmed.
const CONFIRM_FORCE_SHARE: f64 = 0.5;
/// Most wrist readings one insertion keeps in its wrench trace, over all its descents.
pub const TRACE_BUDGET: usize = 360;
/// Fewest readings kept of each descent, whatever the number of probes.
const TRACE_PER_PROBE_MIN: usize = 8;

/// The geometry of one insertion, in the base frame.
#[derive(Debug, Clone)]
#[allow(non_snake_case)]
pub struct InsertionGeometry {
    /// The planned TCP pose with the part seated.
    pub seated: Isometry3<f64>,
    /// The insertion frame (z out of the hole).
    pub base_T_ins: Isometry3<f64>,
    /// How far above seated the part first meets its receiver, metres.
    pub engagement: f64,
    /// The capture band: clearance/2 + lead-in, metres.
    pub capture: f64,
    /// The receiver's lead-in, metres.
    pub lead_in: f64,
    /// Speed and acceleration of the lifts and side steps between probes.
    pub slow: LinearMotion,
    /// Where first contact reads as a miss on a rim ([`rim_landings`]): at the top of what the
    /// part goes into, or where a part beyond the capture band lands.
    pub rims: RimLandings,
}

/// Where the held part `held`, seated at `base_T_part`, lands when it comes down beyond the
/// capture band (`capture`) onto the parts in place (`placed`, each at its pose, what it goes
/// into first; base frame), and the top of what it goes into (its engagement depth):
/// the held part swept rigid and level down beside its target in every direction, just beyond
/// the band to twice it, against the convex pieces of what is in place
/// ([`sim::cell::insertion::landing`]). Landings at or below `seat_band` above seated are not
/// rims; each landing is widened by half the lead-in either side (the rim's own tolerance:
/// tilt, the sensor's ±4 N, the chamfer's height).
#[allow(non_snake_case)]
pub fn rim_landings(
    held: &PartGeometry,
    base_T_part: &Isometry3<f64>,
    base_T_ins: &Isometry3<f64>,
    placed: &[(&PartGeometry, Isometry3<f64>)],
    (capture, lead_in): (f64, f64),
    seat_band: f64,
) -> RimLandings {
    let ins_T_base = base_T_ins.inverse();
    let receivers: Vec<(&PartGeometry, Isometry3<f64>)> =
        placed.iter().map(|(g, t)| (*g, ins_T_base * t)).collect();
    let sweep = Sweep::new(held, &(ins_T_base * base_T_part), &receivers);
    RimLandings::of(&sweep, capture, seat_band, rim_tolerance(lead_in))
}

/// [`rim_landings`] computed once per step and receiver state and reused: by the step's
/// insertion attempts (each with its spiral probes), and by every episode of a scenario that
/// reaches the same step with the same parts in place (they are placed at their nominal poses,
/// so every episode that gets there sees the same state). One sweep costs 5–25 ms in release;
/// a lookup costs the key's comparison.
///
/// The key is everything the sweep reads, exactly (names, the bits of every pose and length),
/// so a reused value is the value the sweep would return.
#[derive(Debug, Default)]
pub struct RimCache {
    entries: Mutex<HashMap<RimKey, RimLandings>>,
    lookups: AtomicUsize,
}

/// What [`rim_landings`] reads: the part names (held first, then the parts in place in order),
/// and the bits of the poses and lengths.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
struct RimKey {
    names: Vec<String>,
    bits: Vec<u64>,
}

impl RimKey {
    #[allow(non_snake_case)]
    fn new(
        held: &PartGeometry,
        base_T_part: &Isometry3<f64>,
        base_T_ins: &Isometry3<f64>,
        placed: &[(&PartGeometry, Isometry3<f64>)],
        (capture, lead_in): (f64, f64),
        seat_band: f64,
    ) -> Self {
        fn pose(bits: &mut Vec<u64>, t: &Isometry3<f64>) {
            let q = t.rotation.coords;
            bits.extend(
                t.translation
                    .vector
                    .iter()
                    .chain(q.iter())
                    .map(|v| v.to_bits()),
            );
        }
        let mut bits = Vec::with_capacity(7 * (2 + placed.len()) + 3);
        pose(&mut bits, base_T_part);
        pose(&mut bits, base_T_ins);
        for (_, t) in placed {
            pose(&mut bits, t);
        }
        bits.extend([capture, lead_in, seat_band].map(f64::to_bits));
        let names = std::iter::once(&held.name)
            .chain(placed.iter().map(|(g, _)| &g.name))
            .cloned()
            .collect();
        Self { names, bits }
    }
}

impl RimCache {
    /// [`rim_landings`] of these arguments: swept the first time they are asked for, the
    /// same value again after that.
    #[allow(non_snake_case)]
    pub fn landings(
        &self,
        held: &PartGeometry,
        base_T_part: &Isometry3<f64>,
        base_T_ins: &Isometry3<f64>,
        placed: &[(&PartGeometry, Isometry3<f64>)],
        capture_lead_in: (f64, f64),
        seat_band: f64,
    ) -> RimLandings {
        self.lookups.fetch_add(1, Ordering::Relaxed);
        let key = RimKey::new(
            held,
            base_T_part,
            base_T_ins,
            placed,
            capture_lead_in,
            seat_band,
        );
        if let Some(r) = self.lock().get(&key) {
            return r.clone();
        }
        // Swept outside the lock: episodes on other threads looking up other steps do not
        // wait; two that miss the same key at once both sweep it, to the same value.
        let start = std::time::Instant::now();
        let rims = rim_landings(
            held,
            base_T_part,
            base_T_ins,
            placed,
            capture_lead_in,
            seat_band,
        );
        tracing::debug!(
            part = %held.name,
            in_place = placed.len(),
            "rim landings swept in {:.1} ms",
            start.elapsed().as_secs_f64() * 1e3
        );
        self.lock().entry(key).or_insert(rims).clone()
    }

    /// How many distinct steps and receiver states have been swept.
    pub fn swept(&self) -> usize {
        self.lock().len()
    }

    /// How many times rim landings have been asked for.
    pub fn lookups(&self) -> usize {
        self.lookups.load(Ordering::Relaxed)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<RimKey, RimLandings>> {
        // A sweep never panics while holding the lock (it runs outside it), so a poisoned map
        // is still whole.
        self.entries
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }
}

/// How far a first contact may lie from where a rim was swept and still read as that rim, metres:
/// half the lead-in.
pub fn rim_tolerance(lead_in: f64) -> f64 {
    lead_in / 2.0
}

impl InsertionGeometry {
    /// Unit vector out of the hole (base frame).
    pub fn out(&self) -> Vector3<f64> {
        self.base_T_ins.rotation * Vector3::z()
    }

    /// The seated TCP pose moved sideways by `offset` (insertion frame x, y) and up by `height`.
    fn at(&self, offset: [f64; 2], height: f64) -> Isometry3<f64> {
        let shift = self.base_T_ins.rotation * Vector3::new(offset[0], offset[1], height);
        Translation3::from(shift) * self.seated
    }
}

/// One guarded descent as the strategy read it.
#[derive(Debug, Clone, PartialEq)]
pub struct Probe {
    /// Side offset of the probe in the insertion frame (x, y), metres.
    pub offset: [f64; 2],
    /// Whether the descent stopped on contact.
    pub contact: bool,
    /// Height of first contact above seated, metres (the stop less the press's compliance).
    pub height: f64,
    /// The wrist's reading at the stop (base frame, at the TCP).
    pub wrench: [f64; 6],
    /// The outcome read from it.
    pub outcome: StepOutcome,
    /// The wrist's readings along the descent, in the insertion frame, decimated.
    pub samples: Vec<WrenchSample>,
}

impl Probe {
    /// The force of its reading out of the hole (along `out`, base frame), newtons.
    pub fn force_along(&self, out: &Vector3<f64>) -> f64 {
        Vector3::new(self.wrench[0], self.wrench[1], self.wrench[2]).dot(out)
    }

    /// One line for the event log: offset, stop height, force and wrench.
    pub fn describe(&self) -> String {
        let w = &self.wrench;
        format!(
            "probe ({:+.3}, {:+.3}) mm: {} at {:.3} mm above seated, wrench [{:.1} {:.1} {:.1} N, \
             {:.2} {:.2} {:.2} N·m] → {}",
            self.offset[0] * 1e3,
            self.offset[1] * 1e3,
            if self.contact {
                "contact"
            } else {
                "no contact"
            },
            self.height * 1e3,
            w[0],
            w[1],
            w[2],
            w[3],
            w[4],
            w[5],
            outcome_word(self.outcome)
        )
    }
}

fn outcome_word(o: StepOutcome) -> &'static str {
    match o {
        StepOutcome::Seated => "seated",
        StepOutcome::Jammed => "jammed",
        StepOutcome::Missed => "missed",
        StepOutcome::Aborted => "aborted",
    }
}

/// What a force-guided insertion found before the fingers open.
#[derive(Debug, Clone, PartialEq)]
pub struct ForceVerdict {
    /// Seated (and confirmed), jammed or missed.
    pub outcome: StepOutcome,
    /// Why it is not seated, or how the seat was confirmed.
    pub cause: String,
    /// Every guarded descent, in order (the first is the planned one, the rest spiral probes).
    pub probes: Vec<Probe>,
    /// The wrist readings of every descent with the thresholds they were read against, for
    /// the episode events.
    pub trace: WrenchTrace,
    /// First contact above seated of the reading that decided (the confirming one for a
    /// seat), metres.
    pub height: f64,
    /// Force out of the hole in that reading, newtons.
    pub force_n: f64,
}

/// A guarded move's readings in the insertion frame, at most `keep` of them (evenly spread,
/// the first and the last, the stop, always kept).
pub fn trace_samples(
    trace: &[ContactSample],
    geometry: &InsertionGeometry,
    probe: u32,
    keep: usize,
) -> Vec<WrenchSample> {
    let out = geometry.out();
    let n = trace.len();
    let picked: Vec<usize> = if n <= keep.max(2) {
        (0..n).collect()
    } else {
        let mut v: Vec<usize> = (0..keep)
            .map(|i| (i * (n - 1) + (keep - 1) / 2) / (keep - 1))
            .collect();
        v.dedup();
        v
    };
    picked
        .into_iter()
        .map(|i| {
            let s = &trace[i];
            let f = Vector3::new(s.wrench[0], s.wrench[1], s.wrench[2]);
            let along = f.dot(&out);
            let tcp = Vector3::from(s.tcp);
            WrenchSample {
                probe,
                t_s: s.t,
                height_mm: (tcp - geometry.seated.translation.vector).dot(&out) * 1e3,
                force_n: along,
                lateral_n: (f - out * along).norm(),
            }
        })
        .collect()
}

impl ForceVerdict {
    /// The step record's account: the verdict and the depth and force that decided it.
    pub fn record(&self) -> crate::episode::ForceRecord {
        crate::episode::ForceRecord {
            verdict: self.outcome,
            contact_mm: self.height * 1e3,
            force_n: self.force_n,
            probes: u32::try_from(self.probes.len()).unwrap_or(u32::MAX),
        }
    }

    /// The event log's account: each probe's reading and the verdict.
    pub fn describe(&self) -> String {
        let probes: Vec<String> = self.probes.iter().map(Probe::describe).collect();
        format!(
            "force-guided: {}; {}",
            probes.join("; "),
            match self.outcome {
                StepOutcome::Seated => format!("seated ({})", self.cause),
                o => format!("{} ({})", outcome_word(o), self.cause),
            }
        )
    }
}

/// Reads a guarded descent: no contact is a miss with nothing under the tool; otherwise the
/// height of first contact above seated (the stop's height less `force / contact_stiffness`)
/// says seated (within `seat_band`), missed on the rim (where a part beyond the capture band
/// lands, or within half the lead-in of the engagement depth, or above it) or jammed (anywhere
/// else). Returns the outcome and the height.
pub fn classify(
    outcome: &ContactOutcome,
    geometry: &InsertionGeometry,
    spec: &ForceInsertionSpec,
) -> (StepOutcome, f64) {
    let out = geometry.out();
    let stop =
        (outcome.stopped_at.translation.vector - geometry.seated.translation.vector).dot(&out);
    if !outcome.contact {
        return (StepOutcome::Missed, stop);
    }
    let height = stop + outcome.force_along(&out).max(0.0) / spec.contact_stiffness;
    (verdict_at(height, &geometry.rims, spec), height)
}

/// The verdict of a first contact `height` above seated (metres): seated within
/// [`ForceInsertionSpec::seat_band`]; missed on a rim ([`RimLandings::contains`]: at or above
/// the receiver's top less half the lead-in, or where a part beyond the capture band lands);
/// jammed anywhere else (stopped inside the receiver, short of its seat).
pub fn verdict_at(height: f64, rims: &RimLandings, spec: &ForceInsertionSpec) -> StepOutcome {
    if height <= spec.seat_band {
        StepOutcome::Seated
    } else if rims.contains(height) {
        StepOutcome::Missed
    } else {
        StepOutcome::Jammed
    }
}

/// Confirms a seat before release from a fresh reading with the arm still pressing: the wrist
/// must feel at least half the contact force out of the hole (a seat does not give way), and
/// first contact must still be within the seat band. `Err` says why the seat is refused.
pub fn confirm_seat(
    force_out: f64,
    height: f64,
    spec: &ForceInsertionSpec,
) -> Result<String, String> {
    let least = CONFIRM_FORCE_SHARE * spec.contact_force;
    if force_out < least {
        return Err(format!(
            "seat not confirmed: the wrist feels {force_out:.1} N out of the hole, under the \
             {least:.1} N a seated part pressed on its seat gives"
        ));
    }
    if height > spec.seat_band {
        return Err(format!(
            "seat not confirmed: first contact now {:.3} mm above seated, beyond the {:.3} mm \
             seat band",
            height * 1e3,
            spec.seat_band * 1e3
        ));
    }
    Ok(format!(
        "confirmed at {force_out:.1} N, {:.3} mm from seated",
        height * 1e3
    ))
}

/// The side offsets of the spiral search within the capture band, in order: rings of radius
/// k × `capture` with 8k points each, the first `points` of them.
pub fn spiral(capture: f64, points: u32) -> Vec<[f64; 2]> {
    let mut out = Vec::with_capacity(points as usize);
    let mut ring = 1u32;
    while out.len() < points as usize {
        let n = 8 * ring;
        let r = capture * f64::from(ring);
        // Even rings start half a step round, so the rings' points do not line up.
        let phase = if ring.is_multiple_of(2) { 0.5 } else { 0.0 };
        for k in 0..n {
            if out.len() == points as usize {
                break;
            }
            let a = std::f64::consts::TAU * (f64::from(k) + phase) / f64::from(n);
            out.push([r * a.cos(), r * a.sin()]);
        }
        ring += 1;
    }
    out
}

/// One guarded descent from where the arm is to `offset` beside the seat and `overtravel` below.
async fn descend(
    robot: &mut dyn Robot,
    geometry: &InsertionGeometry,
    spec: &ForceInsertionSpec,
    offset: [f64; 2],
    probe: u32,
) -> Result<Probe, RobotError> {
    let motion = LinearMotion {
        speed: spec.contact_speed,
        acceleration: geometry.slow.acceleration,
    };
    let target = geometry.at(offset, -spec.overtravel);
    let outcome = robot
        .move_until_contact(target, motion, spec.contact_force)
        .await?;
    let (verdict, height) = classify(&outcome, geometry, spec);
    let keep = (TRACE_BUDGET / (1 + spec.search_points as usize)).max(TRACE_PER_PROBE_MIN);
    Ok(Probe {
        offset,
        contact: outcome.contact,
        height,
        wrench: outcome.wrench,
        outcome: verdict,
        samples: trace_samples(&outcome.trace, geometry, probe, keep),
    })
}

/// Runs the force-guided insertion from the pre-insert pose: the guarded descent, the spiral
/// search after a miss on the rim or a jam, and the seat confirmation. The part stays in the fingers:
/// the caller releases it only on a confirmed seat.
pub async fn force_insert(
    robot: &mut dyn Robot,
    geometry: &InsertionGeometry,
    spec: &ForceInsertionSpec,
) -> Result<ForceVerdict, RobotError> {
    let first = planned_descent(robot, geometry, spec).await?;
    search_and_confirm(robot, geometry, spec, first).await
}

/// The planned guarded descent straight down onto the seat, the first of [`force_insert`]
/// (a caller that wants to look at the cell between the two runs them apart).
pub async fn planned_descent(
    robot: &mut dyn Robot,
    geometry: &InsertionGeometry,
    spec: &ForceInsertionSpec,
) -> Result<Probe, RobotError> {
    descend(robot, geometry, spec, [0.0, 0.0], 0).await
}

/// The rest of [`force_insert`] after its planned descent `first`: the spiral search after a
/// miss on the rim or a jam, and the seat confirmation.
pub async fn search_and_confirm(
    robot: &mut dyn Robot,
    geometry: &InsertionGeometry,
    spec: &ForceInsertionSpec,
    first: Probe,
) -> Result<ForceVerdict, RobotError> {
    let mut probes = vec![first];
    let lift = geometry.engagement + (PROBE_LIFT_LEAD_INS * geometry.lead_in).max(MIN_PROBE_LIFT);
    let mut search = spiral(geometry.capture, spec.search_points).into_iter();
    loop {
        let last = probes.last().expect("one probe at least");
        if !last.contact || last.outcome == StepOutcome::Seated {
            break;
        }
        let Some(offset) = search.next() else { break };
        // Off the rim, then sideways above it, then down again.
        let here = robot.tcp_pose().await?;
        let out = geometry.out();
        let up = (geometry.at(last.offset, lift).translation.vector - here.translation.vector)
            .dot(&out)
            .max(0.0);
        robot
            .move_l(Translation3::from(out * up) * here, geometry.slow)
            .await?;
        robot
            .move_l(geometry.at(offset, lift), geometry.slow)
            .await?;
        let probe = u32::try_from(probes.len()).unwrap_or(u32::MAX);
        probes.push(descend(robot, geometry, spec, offset, probe).await?);
    }
    // A seat found by the search is the verdict; otherwise the planned descent's reading says
    // what went wrong (the retries search by it: yaw after a jam, sideways after a miss).
    let last = match probes.last() {
        Some(p) if p.outcome == StepOutcome::Seated => p.clone(),
        _ => probes[0].clone(),
    };
    let searched = probes.len() - 1;
    let tried = if searched == 0 {
        String::new()
    } else {
        format!(" after {searched} spiral probes")
    };
    // The reading that decides: the confirming one for a seat, else the probe's stop.
    let mut decided = (last.height, last.force_along(&geometry.out()));
    let (outcome, cause) = match last.outcome {
        StepOutcome::Seated => {
            let reading = robot.wrench().await?;
            let force_out = Vector3::new(reading[0], reading[1], reading[2]).dot(&geometry.out());
            let pose = robot.tcp_pose().await?;
            let stop =
                (pose.translation.vector - geometry.seated.translation.vector).dot(&geometry.out());
            let height = stop + force_out.max(0.0) / spec.contact_stiffness;
            decided = (height, force_out);
            match confirm_seat(force_out, height, spec) {
                Ok(how) => (StepOutcome::Seated, format!("{how}{tried}")),
                Err(why) => (StepOutcome::Jammed, format!("{why}{tried}")),
            }
        }
        StepOutcome::Missed if !last.contact => (
            StepOutcome::Missed,
            format!(
                "no contact down to {:.3} mm below seated: nothing under the tool{tried}",
                spec.overtravel * 1e3
            ),
        ),
        StepOutcome::Missed => (
            StepOutcome::Missed,
            format!(
                "stopped on the receiver's rim, {:.3} mm above seated{tried}",
                last.height * 1e3
            ),
        ),
        o => (
            o,
            format!(
                "stopped {:.3} mm above seated, below the receiver's top{tried}",
                last.height * 1e3
            ),
        ),
    };
    let trace = WrenchTrace {
        contact_force_n: spec.contact_force,
        contact_stiffness_n_per_m: spec.contact_stiffness,
        seat_band_mm: spec.seat_band * 1e3,
        rim_mm: geometry.rims.rim * 1e3,
        landings_mm: geometry
            .rims
            .bands
            .iter()
            .map(|b| [b[0] * 1e3, b[1] * 1e3])
            .collect(),
        samples: probes.iter().flat_map(|p| p.samples.clone()).collect(),
    };
    Ok(ForceVerdict {
        outcome,
        cause,
        probes,
        trace,
        height: decided.0,
        force_n: decided.1,
    })
}

/// How well the force-guided verdicts tell seated, jammed and missed apart near the capture
/// boundary, against a contact engine's truth (`cell scorers --force-verdicts`).
pub mod agreement {
    use std::sync::Arc;

    use rayon::prelude::*;
    use robots::virtual_ur::force::FtNoise;
    use serde::Serialize;
    use sim::cell::insertion::agreement::{StepGeometry, boundary_case};
    use sim::cell::insertion::{InsertionScorer, PoseError, ScorerError, Verdict};

    use nalgebra::{Isometry3, Translation3};

    use super::{RimLandings, rim_landings, verdict_at};
    use crate::episode::StepOutcome;
    use crate::scenario::ForceInsertionSpec;

    /// One boundary insertion: the truth and what the guarded descent reads.
    #[derive(Debug, Clone, Serialize)]
    pub struct ForceCase {
        /// Assembly step index.
        pub step: usize,
        /// Sample index (with the seed it redraws the misalignment).
        pub sample: usize,
        /// The held part's misalignment at the start.
        pub start: PoseError,
        /// The contact engine's verdict (the truth).
        pub truth: StepOutcome,
        /// Where the contact engine stopped the part, metres above seated.
        pub truth_stop: f64,
        /// The force-guided verdict from the contact engine's stop.
        pub engine: StepOutcome,
        /// Where the simulated cell's contact model stops it (its scorer's stop:
        /// `sim::cell::SimCell::felt_stop`).
        pub cell_stop: f64,
        /// The force-guided verdict from the simulated cell's stop.
        pub cell: StepOutcome,
        /// The sensor's error along the insertion axis in this reading, N.
        pub noise_n: f64,
    }

    /// Counts of one step, or of all.
    #[derive(Debug, Clone, Default, Serialize)]
    pub struct ForceCounts {
        /// Insertions scored.
        pub samples: usize,
        /// The truth seated.
        pub truth_seated: usize,
        /// Seated-or-not agrees, verdicts from the contact engine's stop.
        pub engine_seating: usize,
        /// Seated / jammed / missed agree, from the contact engine's stop.
        pub engine_outcome: usize,
        /// Seated-or-not agrees, verdicts from the simulated cell's stop.
        pub cell_seating: usize,
        /// Seated / jammed / missed agree, from the simulated cell's stop.
        pub cell_outcome: usize,
        /// The highest stop above seated of a part the truth seated, metres (the seated
        /// signature: the seat band must lie above it).
        pub seated_stop_max: Option<f64>,
        /// The lowest stop above seated of a part the truth did not seat, metres (the seat
        /// band must lie below it).
        pub unseated_stop_min: Option<f64>,
        /// Verdicts from the contact engine's stop against the truth: `[truth][read]`, each
        /// indexed seated, jammed, missed.
        pub confusion: [[usize; 3]; 3],
    }

    /// The index of a verdict in [`ForceCounts::confusion`] (seated, jammed, missed; aborted
    /// never occurs here and counts as missed).
    pub fn confusion_index(o: StepOutcome) -> usize {
        match o {
            StepOutcome::Seated => 0,
            StepOutcome::Jammed => 1,
            StepOutcome::Missed | StepOutcome::Aborted => 2,
        }
    }

    impl ForceCounts {
        fn add(&mut self, c: &ForceCase) {
            let seated = |o: StepOutcome| o == StepOutcome::Seated;
            self.samples += 1;
            self.truth_seated += usize::from(seated(c.truth));
            self.engine_seating += usize::from(seated(c.engine) == seated(c.truth));
            self.engine_outcome += usize::from(c.engine == c.truth);
            self.cell_seating += usize::from(seated(c.cell) == seated(c.truth));
            self.cell_outcome += usize::from(c.cell == c.truth);
            self.confusion[confusion_index(c.truth)][confusion_index(c.engine)] += 1;
            if seated(c.truth) {
                self.seated_stop_max = Some(
                    self.seated_stop_max
                        .map_or(c.truth_stop, |m| m.max(c.truth_stop)),
                );
            } else {
                self.unseated_stop_min = Some(
                    self.unseated_stop_min
                        .map_or(c.truth_stop, |m| m.min(c.truth_stop)),
                );
            }
        }

        /// `count` as a fraction of the samples.
        pub fn rate(&self, count: usize) -> f64 {
            count as f64 / self.samples.max(1) as f64
        }
    }

    /// The measurement: counts per step and overall, and every case where a verdict differs
    /// from the truth.
    #[derive(Debug, Clone, Serialize)]
    pub struct ForceAgreement {
        /// The truth's engine.
        pub truth: String,
        /// The scorer whose stop the simulated cell's guarded move feels (the scenario's).
        pub cell: String,
        /// Per step: its part and counts.
        pub steps: Vec<(String, ForceCounts)>,
        /// Per step: where first contact reads as a miss ([`step_rims`]).
        pub rims: Vec<RimLandings>,
        /// All steps together.
        pub all: ForceCounts,
        /// The cases where either force verdict differs from the truth.
        pub disagreements: Vec<ForceCase>,
    }

    fn outcome(v: Verdict) -> StepOutcome {
        match v {
            Verdict::Seated => StepOutcome::Seated,
            Verdict::Jammed => StepOutcome::Jammed,
            Verdict::Missed => StepOutcome::Missed,
        }
    }

    /// A step's rims as production reads them ([`rim_landings`] for the parts in place, seated
    /// nominally, as planned): first contact at or above the receiver's top less half the
    /// lead-in is a miss, and so is first contact within the bands where a part beyond the
    /// capture band lands.
    pub fn step_rims(step: &StepGeometry<'_>, spec: &ForceInsertionSpec) -> RimLandings {
        let m = &step.mating;
        let ins_T_d = m.destination_T_insertion.inverse();
        let placed: Vec<_> = step
            .receivers
            .iter()
            .map(|r| (r.geometry, ins_T_d * r.destination_T_part))
            .collect();
        let seated = Isometry3::from_parts(Translation3::identity(), m.ins_R_seat);
        rim_landings(
            step.held,
            &seated,
            &Isometry3::identity(),
            &placed,
            (m.capture(), m.lead_in),
            spec.seat_band,
        )
    }

    /// Draws `samples` misalignments around the capture boundary (as `cell scorers` does, the
    /// same seed the same draws), scores each with `truth`, and reads each as the force-guided
    /// strategy does: first contact where the part stops (the contact engine's stop, and the
    /// simulated cell's, which is where `cell`, the scenario's scorer, stops it: the analytic
    /// capture model's end height, or a contact engine's push, the same call as `truth`'s when
    /// they are one engine), read back through the UR5e sensor's noise at the contact
    /// stiffness, against the seat band and the rims ([`step_rims`]).
    pub fn force_agreement(
        steps: &[StepGeometry<'_>],
        samples: usize,
        seed: u64,
        truth: &Arc<dyn InsertionScorer>,
        cell: &Arc<dyn InsertionScorer>,
        spec: &ForceInsertionSpec,
    ) -> Result<ForceAgreement, ScorerError> {
        let samples = if steps.is_empty() { 0 } else { samples };
        let rims: Vec<RimLandings> = steps.par_iter().map(|s| step_rims(s, spec)).collect();
        let cases: Vec<ForceCase> = (0..samples)
            .into_par_iter()
            .map(|k| {
                let (i, case) = boundary_case(steps, seed, k);
                let scored = truth.score(&case)?.result;
                let cell_stop = if cell.name() == truth.name() {
                    scored.end.height
                } else {
                    cell.score(&case)?.result.end.height
                };
                // The reading's error along the axis, in N: a fresh bias and noise per case.
                let noise_n = FtNoise::ur5e(seed ^ (k as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15))
                    .sample()[2];
                let read =
                    |stop: f64| verdict_at(stop + noise_n / spec.contact_stiffness, &rims[i], spec);
                Ok(ForceCase {
                    step: i,
                    sample: k,
                    start: scored.start,
                    truth: outcome(scored.verdict),
                    truth_stop: scored.end.height,
                    engine: read(scored.end.height),
                    cell_stop,
                    cell: read(cell_stop),
                    noise_n,
                })
            })
            .collect::<Result<_, ScorerError>>()?;
        let mut out = ForceAgreement {
            truth: truth.name().to_string(),
            cell: cell.name().to_string(),
            steps: steps
                .iter()
                .map(|s| (s.mating.part.clone(), ForceCounts::default()))
                .collect(),
            rims,
            all: ForceCounts::default(),
            disagreements: Vec::new(),
        };
        for c in cases {
            out.steps[c.step].1.add(&c);
            out.all.add(&c);
            if c.engine != c.truth || c.cell != c.truth {
                out.disagreements.push(c);
            }
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn geometry() -> InsertionGeometry {
        InsertionGeometry {
            seated: Isometry3::translation(0.1, -0.4, 0.02),
            base_T_ins: Isometry3::identity(),
            engagement: 0.002,
            capture: 0.000145,
            lead_in: 0.0001,
            slow: LinearMotion {
                speed: 0.02,
                acceleration: 1.2,
            },
            rims: RimLandings::at_engagement(0.002, 0.00005),
        }
    }

    fn stop(height: f64, force: f64, contact: bool) -> ContactOutcome {
        ContactOutcome {
            stopped_at: Isometry3::translation(0.1, -0.4, 0.02 + height),
            wrench: [0.0, 0.0, force, 0.0, 0.0, 0.0],
            contact,
            trace: vec![],
        }
    }

    #[test]
    fn force_and_depth_tell_seated_jammed_missed_and_nothing_apart() {
        let spec = ForceInsertionSpec::default();
        let g = geometry();
        let k = spec.contact_stiffness;
        // Pressed 10 N onto the seat: the stop is 10/k below first contact, at seated.
        let (o, h) = classify(&stop(-10.0 / k, 10.0, true), &g, &spec);
        assert_eq!(o, StepOutcome::Seated);
        assert!(h.abs() < 1e-12);
        // Stuck 1.2 mm up, inside the lead-in: a jam.
        assert_eq!(
            classify(&stop(0.0012 - 10.0 / k, 10.0, true), &g, &spec).0,
            StepOutcome::Jammed
        );
        // On the rim, at the engagement depth: a miss.
        assert_eq!(
            classify(&stop(0.002 - 10.0 / k, 10.0, true), &g, &spec).0,
            StepOutcome::Missed
        );
        // Down past seated with nothing felt: a miss with nothing under the tool, not a jam.
        let (o, h) = classify(&stop(-spec.overtravel, 0.5, false), &g, &spec);
        assert_eq!(o, StepOutcome::Missed);
        assert!(h < 0.0);
    }

    #[test]
    fn a_rim_miss_below_the_engagement_depth_is_missed_and_a_stop_between_rims_jammed() {
        // A top shell: 2.74 mm of engagement, and beyond its capture band it lands on the main
        // shell's rim 2.25–2.54 mm up or, across its open sides, on what the shell holds
        // 1.30–1.40 mm up (the bands `cell scorers --force-verdicts` prints for it).
        let spec = ForceInsertionSpec::default();
        let mut g = geometry();
        g.engagement = 0.00274;
        g.rims = RimLandings {
            rim: 0.00269,
            bands: vec![[0.0013, 0.0014], [0.00225, 0.00254]],
        };
        let k = spec.contact_stiffness;
        let read =
            |h: f64, g: &InsertionGeometry| classify(&stop(h - 10.0 / k, 10.0, true), g, &spec).0;
        // On the lower rim, 1.35 mm up: a miss, not a jam (the rim at the engagement depth
        // alone, 2.69 mm, called it jammed).
        assert_eq!(read(0.00135, &g), StepOutcome::Missed);
        assert_eq!(read(0.0025, &g), StepOutcome::Missed);
        assert_eq!(read(0.0028, &g), StepOutcome::Missed);
        // Between the rims, and below the lower one: stuck inside the receiver.
        assert_eq!(read(0.0019, &g), StepOutcome::Jammed);
        assert_eq!(read(0.0006, &g), StepOutcome::Jammed);
        assert_eq!(read(0.00005, &g), StepOutcome::Seated);
        // Without landings only the engagement depth's rim remains.
        g.rims = RimLandings::at_engagement(0.00274, 0.00005);
        assert_eq!(read(0.00135, &g), StepOutcome::Jammed);
    }

    #[test]
    fn a_trace_is_read_in_the_insertion_frame_and_decimated_keeping_its_ends() {
        let g = geometry();
        let trace: Vec<ContactSample> = (0..100)
            .map(|k| ContactSample {
                t: f64::from(k) * 0.01,
                tcp: [0.1, -0.4, 0.02 + 0.003 - f64::from(k) * 3e-5],
                wrench: [3.0, 4.0, f64::from(k) * 0.1, 0.0, 0.0, 0.0],
            })
            .collect();
        let all = trace_samples(&trace, &g, 2, 200);
        assert_eq!(all.len(), 100);
        assert!((all[0].height_mm - 3.0).abs() < 1e-9);
        assert!((all[99].force_n - 9.9).abs() < 1e-9);
        assert!((all[99].lateral_n - 5.0).abs() < 1e-9);
        assert!(all.iter().all(|s| s.probe == 2));
        let some = trace_samples(&trace, &g, 0, 10);
        assert_eq!(some.len(), 10);
        assert_eq!(some[0], all[0].clone_with_probe(0));
        assert_eq!(some[9], all[99].clone_with_probe(0));
        assert!(some.windows(2).all(|w| w[0].t_s < w[1].t_s));
    }

    impl WrenchSample {
        fn clone_with_probe(&self, probe: u32) -> WrenchSample {
            WrenchSample { probe, ..*self }
        }
    }

    #[test]
    fn a_seat_the_wrist_no_longer_feels_or_that_rose_is_refused() {
        let spec = ForceInsertionSpec::default();
        assert!(confirm_seat(9.5, 0.00001, &spec).is_ok());
        let why = confirm_seat(1.0, 0.00001, &spec).unwrap_err();
        assert!(why.contains("1.0 N"), "{why}");
        let why = confirm_seat(10.0, 0.0008, &spec).unwrap_err();
        assert!(why.contains("0.800 mm"), "{why}");
    }

    #[test]
    fn the_spiral_stays_on_rings_of_the_capture_band() {
        let s = spiral(0.000145, 12);
        assert_eq!(s.len(), 12);
        for p in &s[..8] {
            assert!(((p[0].hypot(p[1])) - 0.000145).abs() < 1e-12);
        }
        for p in &s[8..] {
            assert!(((p[0].hypot(p[1])) - 0.00029).abs() < 1e-12);
        }
        // Every lateral error up to twice the band is within the band of some probe of the
        // first ring or of the seat itself.
        for i in 0..72 {
            let a = f64::from(i) * std::f64::consts::TAU / 72.0;
            for r in [0.00015, 0.0002, 0.00025] {
                let e = [r * a.cos(), r * a.sin()];
                let near = s[..8]
                    .iter()
                    .any(|p| (e[0] - p[0]).abs().max((e[1] - p[1]).abs()) <= 0.000145);
                assert!(near, "error {e:?} not caught");
            }
        }
    }
}
