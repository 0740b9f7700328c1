//! Force-guided insertion (`[force_insertion]`), one strategy for the simulated cell and a
//! production arm alike: both are a `robots::Robot` with a wrist sensor
//! ([`Robot::move_until_contact`], [`Robot::wrench`]).
//!
//! 1. The planner's moves bring the held part to the lead-in (transfer, pre-insert).
//! 2. A guarded descent towards the seat, [`ForceInsertionSpec::overtravel`] beyond it, stops
//!    where the wrist feels [`ForceInsertionSpec::contact_force`] against the motion.
//! 3. [`classify`] tells the outcome from force and depth: no contact at all is a miss with
//!    nothing under the tool; first contact (the stop, less the press's compliance) within
//!    [`ForceInsertionSpec::seat_band`] of seated is a seat; at the receiver's top (within half
//!    the lead-in of the engagement depth) a miss on the rim; in between a jam.
//! 4. A miss on the rim or a jam starts a bounded spiral search within the capture band: lift
//!    clear, step sideways to the next point (rings of radius k × capture band, 8k points each),
//!    descend again; a seat, or a descent that meets nothing, ends it.
//! 5. A seat is confirmed before the fingers open ([`confirm_seat`]): the wrist must still feel
//!    the part pressed, and the arm must still be at seated depth.
//!
//! The engine retries what this returns unseated (a jam with a yaw search, a miss with a wider
//! lateral offset) within `policy.max_insertion_attempts`, and never releases a part that was
//! not confirmed seated.

use nalgebra::{Isometry3, Translation3, Vector3};
use robots::robot::{ContactOutcome, LinearMotion, Robot, RobotError};

use crate::episode::StepOutcome;
use crate::scenario::ForceInsertionSpec;

/// Height above the receiver's top to which a spiral probe lifts the part off the rim, as a
/// multiple of the step's lead-in (at least [`MIN_PROBE_LIFT`]).
const PROBE_LIFT_LEAD_INS: f64 = 2.0;
/// Smallest lift off the rim between spiral probes, metres.
const MIN_PROBE_LIFT: f64 = 1e-4;
/// Share of the contact force the wrist must still feel for a seat to be confirmed.
const CONFIRM_FORCE_SHARE: f64 = 0.5;

/// The geometry of one insertion, in the base frame.
#[derive(Debug, Clone, Copy)]
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
}

impl Probe {
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
}

impl ForceVerdict {
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
/// says seated (within `seat_band`), missed on the rim (within half the lead-in of the
/// engagement depth, or above it) or jammed (in between). Returns the outcome and the height.
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
    let verdict = if height <= spec.seat_band {
        StepOutcome::Seated
    } else if height >= geometry.engagement - geometry.lead_in / 2.0 {
        StepOutcome::Missed
    } else {
        StepOutcome::Jammed
    };
    (verdict, height)
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
    Ok(Probe {
        offset,
        contact: outcome.contact,
        height,
        wrench: outcome.wrench,
        outcome: verdict,
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
    let mut probes = vec![descend(robot, geometry, spec, [0.0, 0.0]).await?];
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
        probes.push(descend(robot, geometry, spec, offset).await?);
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
    let (outcome, cause) = match last.outcome {
        StepOutcome::Seated => {
            let reading = robot.wrench().await?;
            let force_out = Vector3::new(reading[0], reading[1], reading[2]).dot(&geometry.out());
            let pose = robot.tcp_pose().await?;
            let stop =
                (pose.translation.vector - geometry.seated.translation.vector).dot(&geometry.out());
            let height = stop + force_out.max(0.0) / spec.contact_stiffness;
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
    Ok(ForceVerdict {
        outcome,
        cause,
        probes,
    })
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
        }
    }

    fn stop(height: f64, force: f64, contact: bool) -> ContactOutcome {
        ContactOutcome {
            stopped_at: Isometry3::translation(0.1, -0.4, 0.02 + height),
            wrench: [0.0, 0.0, force, 0.0, 0.0, 0.0],
            contact,
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
