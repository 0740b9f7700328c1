//! The engine: the state machine that runs every assembly step of one episode on a
//! [`Workcell`], one method per [`State`].

use std::time::Duration;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector2, Vector3};
use robots::kinematics::Joints;
use robots::robot::RobotError;
use sim::cell::geometry::PartGeometry;

use super::blended;
use super::cell_io::{CellIo, InsertionCheck, Workcell};
use super::context::EpisodeContext;
use super::events::{EventLog, ShakeStart};
use super::geometry::CellKnowledge;
use super::insertion;
use super::planning::{Motion, NamedMotion, Planner, Speeds, grasped_offset};
use super::seat_check::{self, SEAT_CHECK_FAILED, SeatTolerance, arm_in_fixture_view};
use super::selection::{Rejection, Selection, UnposedObstacle, select};
use super::state::State;
use super::step::StepState;
use super::view::{AWAY_HEIGHT, GRIPPER_RADIUS, arm_in_feeder_view, arm_near_feeder};
use crate::episode::{
    EpisodeRecord, GRASP_MISSED, PERCEPTION_MISSED, PoseError, RECORD_VERSION, StepOutcome,
};
use perception::{DetectedPart, PartPerception, Perceived};

/// Error-budget name of a step given up because the feeder held none of its part.
pub const FEEDER_EXHAUSTED: &str = "feeder.parts";
/// Error-budget name of a step given up because the camera detected no part at all (pointed
/// away from the feeder, or nothing in view).
pub const CAMERA_SAW_NOTHING: &str = "camera.view";
/// Error-budget name of a step given up after `max_shakes` shakes left no usable instance.
pub const FEEDER_SHAKE_BOUND: &str = "feeder.max_shakes";

/// Step between the samples of a motion's trajectory searched for the first instant the arm is
/// clear of the feeder, s (the controller's period).
const SHAKE_TRACE_STEP: f64 = 0.002;

/// Margin above [`AWAY_HEIGHT`] plus the gripper's (or held part's) radius that the TCP rises
/// to when a shake finds it near the feeder, metres.
const CLEAR_MARGIN: f64 = 0.01;

/// A feeder shake decided and waiting for the arm and any held part to clear the feeder.
#[derive(Debug, Clone, Copy)]
struct PendingShake {
    /// The step whose parts it shakes up.
    for_step: usize,
    /// Cell clock when it was decided.
    since: f64,
    /// What was near the feeder then.
    near: Option<&'static str>,
}

/// A frame of the feeder taken and perceived for a later step while the arm worked elsewhere
/// (`[motion] overlap`).
struct Ahead {
    /// The step it was taken for.
    step: usize,
    /// What perception found.
    perceived: Perceived,
    /// Cell clock when perception's result is ready (capture time plus perception time).
    ready_at: f64,
}

/// Why the state machine stopped the episode early.
enum Stop {
    /// A robot command failed.
    Robot(State, RobotError),
    /// A state overran its bound.
    Timeout(State, Duration),
}

impl Stop {
    fn text(&self) -> String {
        match self {
            Stop::Robot(s, e) => format!("{s:?}: {e}"),
            Stop::Timeout(s, d) => format!("{s:?} timed out after {d:?}"),
        }
    }
}

/// One episode in progress: its context, the cell and perception it drives, and its state.
pub(super) struct Engine<'a> {
    ctx: EpisodeContext<'a>,
    cell: &'a mut dyn Workcell,
    perception: &'a mut dyn PartPerception,
    log: EventLog,
    /// Home joints, fixed by the Home state.
    home: Joints,
    /// Clock when homing ended: the assembly cycle starts there.
    cycle_start: f64,
    /// Index of the assembly step in progress.
    index: usize,
    /// The state of that step.
    step: StepState,
    /// Shakes started for the next step while this one inserts.
    shakes_ahead: u32,
    /// Records of the steps finished.
    records: Vec<crate::episode::StepRecord>,
    /// Parts seated so far, with their target poses (obstacles for planning).
    placed: Vec<(String, Isometry3<f64>)>,
    /// Why the episode stopped early.
    abort: Option<String>,
    /// Why the last recovery (shake, retract, insertion retry) was chosen, for the event log.
    last_reason: String,
    /// Why the last plan runs higher than usual ([`super::planning::Raised`]), for the event
    /// log.
    plan_note: String,
    /// With blending on, a pick's lift held back to start the insertion's blended path, and
    /// the joints it ends at (where the insertion is planned from).
    deferred_lift: Option<(NamedMotion, Joints)>,
    /// With overlap on, the next step's feeder frame taken and perceived during an insertion.
    ahead: Option<Ahead>,
    /// What became of the last overlapped capture, for the event log.
    ahead_note: String,
    /// A shake decided (for the next step after a pick, or for this one) and held back until
    /// the arm and the held part are away from the feeder; it starts at the first instant of a
    /// motion at which they are.
    shake_pending: Option<PendingShake>,
    /// What became of the pending shake started during the last motion, if one was.
    shake_result: Option<Result<(), String>>,
}

impl<'a> Engine<'a> {
    /// An episode ready to start at Home.
    pub(super) fn new(
        ctx: EpisodeContext<'a>,
        cell: &'a mut dyn Workcell,
        perception: &'a mut dyn PartPerception,
    ) -> Self {
        Self {
            log: EventLog::new(ctx.episode),
            ctx,
            cell,
            perception,
            home: [0.0; 6],
            cycle_start: 0.0,
            index: 0,
            step: StepState::new(0.0, 0),
            shakes_ahead: 0,
            records: Vec::new(),
            placed: Vec::new(),
            abort: None,
            last_reason: String::new(),
            plan_note: String::new(),
            deferred_lift: None,
            ahead: None,
            ahead_note: String::new(),
            shake_pending: None,
            shake_result: None,
        }
    }

    /// Runs the state machine to its end and returns the episode record and its events.
    pub(super) async fn run(mut self) -> (EpisodeRecord, EventLog) {
        let mut state = State::Home;
        let now = self.clock();
        self.log.push(None, state, state, now, "start");
        while !state.is_terminal() {
            let bound = self.ctx.settings.timeouts.of(state);
            let next = match tokio::time::timeout(bound, self.run_state(state)).await {
                Ok(r) => r,
                Err(_) => Err(Stop::Timeout(state, bound)),
            };
            let (next, detail) = match next {
                Ok(n) => {
                    let d = match n {
                        State::Shake | State::Retract => self.last_reason.clone(),
                        State::PlanInsert if state == State::Verify => self.last_reason.clone(),
                        // The force-guided insertion's readings and verdict, and what became
                        // of an overlapped capture.
                        State::Verify if state == State::Insert => {
                            let force = self.step.force.as_ref().map(|v| v.describe());
                            let ahead = std::mem::take(&mut self.ahead_note);
                            [force.unwrap_or_default(), ahead]
                                .into_iter()
                                .filter(|t| !t.is_empty())
                                .collect::<Vec<_>>()
                                .join("; ")
                        }
                        State::Perceive if state == State::Capture => {
                            std::mem::take(&mut self.ahead_note)
                        }
                        State::Capture | State::Done if state == State::Verify => {
                            std::mem::take(&mut self.ahead_note)
                        }
                        // A plan raised above a refusal: how high and why.
                        State::Pick | State::Insert => std::mem::take(&mut self.plan_note),
                        _ => String::new(),
                    };
                    (n, d)
                }
                Err(stop) => (State::SafeStop, self.safe_stop(stop).await),
            };
            let step = (self.index < self.steps()).then_some(self.index);
            let now = self.clock();
            self.log.push(step, state, next, now, detail);
            if let (State::Insert, Some(v)) = (state, self.step.force.as_ref()) {
                self.log.attach_trace(v.trace.clone());
            }
            state = next;
        }
        let success = self.records.len() == self.steps()
            && self
                .records
                .iter()
                .all(|r| r.outcome == StepOutcome::Seated);
        let record = EpisodeRecord {
            version: RECORD_VERSION,
            scenario: self.ctx.scenario.to_string(),
            seed: self.ctx.seed,
            episode: self.ctx.episode,
            success,
            steps: std::mem::take(&mut self.records),
            cycle_time_s: self.clock() - self.cycle_start,
            wall_time_s: self.log.wall_time_s(),
            abort: self.abort.take(),
            phases: self.log.phases(),
        };
        (record, self.log)
    }

    /// Runs one state; returns the next.
    async fn run_state(&mut self, state: State) -> Result<State, Stop> {
        match state {
            State::Home => self.home(state).await,
            State::Capture => self.capture(state).await,
            State::Perceive => Ok(self.perceive()),
            State::Select => self.select(state).await,
            State::Shake => self.shake(state).await,
            State::PlanPick => self.plan_pick(state).await,
            State::Pick => self.pick(state).await,
            State::VerifyGrasp => Ok(self.verify_grasp()),
            State::Retract => self.retract(state).await,
            State::PlanInsert => self.plan_insert(state).await,
            State::Insert => self.insert(state).await,
            State::Verify => self.verify(state).await,
            State::Done | State::SafeStop => Ok(state),
        }
    }

    /// Open the gripper, go home; the assembly cycle starts there.
    async fn home(&mut self, state: State) -> Result<State, Stop> {
        let configured = self.ctx.settings.home;
        let knowledge = self.ctx.knowledge;
        let robot = self.cell.robot();
        let r = async {
            robot.open_gripper().await?;
            let q = robot.joints().await?;
            let home = configured.unwrap_or_else(|| knowledge.safe_home(&q));
            if robots::kinematics::joint_distance(&home, &q) > 1e-9 {
                let speeds = Speeds::within(robot.limits(), 0.01);
                robot.move_j(home, speeds.joint).await?;
            }
            Ok::<_, RobotError>(home)
        }
        .await;
        self.home = r.map_err(|e| Stop::Robot(state, e))?;
        self.cycle_start = self.clock();
        self.step = StepState::new(self.cycle_start, 0);
        Ok(State::Capture)
    }

    /// Take a camera frame (the cell waits for the feeder to settle). With overlap on, a frame
    /// taken and perceived for this step during the last insertion is used instead.
    async fn capture(&mut self, state: State) -> Result<State, Stop> {
        if self.ahead.as_ref().is_some_and(|a| a.step == self.index) {
            self.step.frame = None;
            self.step.excluded.clear();
            self.ahead_note = "the frame taken during the last insertion".into();
            return Ok(State::Perceive);
        }
        // A frame taken for an earlier step is stale.
        if self.ahead.as_ref().is_some_and(|a| a.step < self.index) {
            self.ahead = None;
        }
        // A shake for this step still held back (the arm never left the feeder since it was
        // decided) starts now, away from the feeder; the capture waits for it.
        if self.shake_pending.is_some_and(|p| p.for_step < self.index) {
            self.shake_pending = None;
        }
        if self.shake_pending.is_some()
            && let Err(why) = self.shake_away(state).await?
        {
            tracing::warn!(
                episode = self.ctx.episode,
                "held-back shake not started: {why}"
            );
        }
        match self.io().capture() {
            Ok(f) => {
                self.step.frame = Some(f);
                self.step.excluded.clear();
                Ok(State::Perceive)
            }
            Err(e) => {
                self.last_reason = e.to_string();
                Ok(self.finish_step(StepOutcome::Aborted, Some(e.to_string()), vec![], None))
            }
        }
    }

    /// Radius of the held part's bounding sphere around the TCP, metres (`None`: empty
    /// fingers).
    fn held_radius(&self) -> Option<f64> {
        let sel = self.step.selection.as_ref()?;
        let g = self.ctx.knowledge.part(&sel.detection.part)?;
        let (lo, hi) = g.aabb;
        let reach = (hi - lo).norm() / 2.0 + (sel.tcp_T_part.translation.vector).norm();
        Some(reach)
    }

    /// With overlap on, over the fixture during an insertion: capture the feeder for the next
    /// step and perceive it, when the feeder is at rest and neither the arm nor the held part
    /// is in the camera's view of it (the arm's pose from its joints, against the calibrated
    /// camera); a frame with the arm in view is never taken, and the next step captures anew.
    async fn capture_ahead(&mut self, state: State) -> Result<(), Stop> {
        let next = self.index + 1;
        if !self.ctx.settings.overlap || next >= self.steps() {
            return Ok(());
        }
        // A shake still waiting for the arm to leave the feeder will move the parts.
        if let Some(p) = self.shake_pending {
            let what = p.near.unwrap_or("arm");
            self.ahead_note = format!("shake held back: the {what} is near the feeder");
            return Ok(());
        }
        // Where the arm is now: the check below reads the same pose.
        let q = self.joints(state).await?;
        if self.io().feeder_at_rest() != Some(true) {
            self.ahead_note = "no capture ahead: the feeder is still settling".into();
            return Ok(());
        }
        if let Some(what) = arm_in_feeder_view(self.ctx.knowledge, &q, self.held_radius()) {
            self.ahead_note =
                format!("capture ahead refused: the {what} is in the camera's view of the feeder");
            return Ok(());
        }
        let taken = self.clock();
        let frame = match self.io().capture() {
            Ok(f) => f,
            Err(e) => {
                self.ahead_note = format!("capture ahead failed: {e}");
                return Ok(());
            }
        };
        match self.perception.perceive(&frame) {
            Ok(perceived) => {
                self.ahead_note = format!("captured ahead for step {next} at {taken:.3} s");
                self.ahead = Some(Ahead {
                    step: next,
                    perceived,
                    ready_at: taken + self.ctx.settings.perception_time,
                });
            }
            Err(e) => self.ahead_note = format!("perception ahead failed: {e}"),
        }
        Ok(())
    }

    /// The insertion judged, before the release: a second chance for the next step's capture
    /// when the first (before the insert) found the feeder still settling or the arm in view.
    async fn capture_ahead_again(&mut self, state: State) -> Result<(), Stop> {
        if self.ahead.as_ref().is_some_and(|a| a.step > self.index) {
            return Ok(());
        }
        self.capture_ahead(state).await
    }

    /// Estimate the poses of the parts in the frame.
    fn perceive(&mut self) -> State {
        let r = match (self.step.frame.take(), self.ahead.take()) {
            (_, Some(a)) if a.step == self.index => {
                // Perception ran while the arm inserted: wait only for what remains.
                self.io().wait_until(a.ready_at);
                Ok(a.perceived)
            }
            (Some(f), _) => {
                let done = self.clock() + self.ctx.settings.perception_time;
                let r = self.perception.perceive(&f);
                self.io().wait_until(done);
                r
            }
            (None, _) => Ok(Perceived::default()),
        };
        match r {
            Ok(p) => {
                let base_T_table = &self.ctx.knowledge.geometry.base_T_table;
                self.step.unposed = UnposedObstacle::all(&p.unposed, base_T_table);
                self.step.detections = p.parts;
                State::Select
            }
            Err(e) => self.finish_step(
                StepOutcome::Aborted,
                Some(format!("perception failed: {e}")),
                vec!["perception".into()],
                None,
            ),
        }
    }

    /// Choose an instance to pick, or shake, or give the step up.
    async fn select(&mut self, state: State) -> Result<State, Stop> {
        let candidates: Vec<DetectedPart> = self
            .step
            .detections
            .iter()
            .filter(|d| !self.step.excluded.contains(&d.index) && !self.step.missed_before(d))
            .cloned()
            .collect();
        // Grasp yaw and travel are judged from where the arm is now.
        let here = self.joints(state).await?;
        let c = self.ctx;
        let mut result = select(
            c.knowledge,
            c.catalog,
            self.index,
            &candidates,
            &self.step.unposed,
            &here,
            &c.settings.selection,
        );
        // Excluded detections still count as neighbours for finger clearance.
        if candidates.len() != self.step.detections.len()
            && let Some(chosen) = &result.chosen
            && self.blocked_by_excluded(chosen)
        {
            self.step.excluded.insert(chosen.detection.index);
            return Ok(State::Select);
        }
        match result.chosen.take() {
            Some(sel) => {
                let audit = self.io().audit(&sel.detection);
                self.step.perception_error = audit.and_then(|a| a.table_error);
                self.step.perception_verdict = audit.map(|a| a.verdict);
                self.step.confidence = Some(sel.detection.confidence);
                self.step.selection = Some(sel);
                Ok(State::PlanPick)
            }
            None => {
                self.last_reason = result.summary();
                if self.step.shakes < c.max_shakes {
                    return Ok(State::Shake);
                }
                let cause = format!(
                    "no usable {} after {} shakes ({})",
                    self.step_part(),
                    self.step.shakes,
                    self.last_reason
                );
                // Named causes for the error budget: an exhausted feeder, or parts there that
                // the shake bound gave no chance to come to rest usably.
                let any = result
                    .rejected
                    .iter()
                    .any(|(_, r)| !matches!(r, Rejection::OtherPart));
                let part = self.step_part();
                let missed = (self.cell.io())
                    .missed(&part, &self.step.detections)
                    .unwrap_or(0);
                let part_missed_grasp = self
                    .step
                    .detections
                    .iter()
                    .any(|d| d.part == part && self.step.missed_before(d));
                let source = if part_missed_grasp {
                    GRASP_MISSED
                } else if missed > 0 {
                    PERCEPTION_MISSED
                } else if any {
                    FEEDER_SHAKE_BOUND
                } else if result.rejected.is_empty() {
                    CAMERA_SAW_NOTHING
                } else {
                    FEEDER_EXHAUSTED
                };
                Ok(self.finish_step(StepOutcome::Aborted, Some(cause), vec![source.into()], None))
            }
        }
    }

    /// Whether an excluded detection stands closer to `chosen`'s open fingers than the margin.
    fn blocked_by_excluded(&self, chosen: &Selection) -> bool {
        let k = self.ctx.knowledge;
        let margin = self.ctx.settings.selection.finger_margin;
        self.step.detections.iter().any(|n| {
            n.index != chosen.detection.index
                && (self.step.excluded.contains(&n.index) || self.step.missed_before(n))
                && k.part(&n.part).is_some_and(|g| {
                    k.finger_distance(
                        &chosen.base_T_grasp,
                        chosen.opening,
                        g.hull.as_ref(),
                        &n.base_T_part,
                    ) < margin
                })
        })
    }

    /// Shake the feeder so parts come to rest anew, never with the arm or a held part near it:
    /// an arm that is (after a missed grasp it stands just above the feeder) first rises
    /// clear, and the shake starts the instant it is.
    async fn shake(&mut self, state: State) -> Result<State, Stop> {
        // The parts move: a frame taken ahead no longer shows them.
        self.ahead = None;
        let since = self.clock();
        self.shake_pending = Some(PendingShake {
            for_step: self.index,
            since,
            near: None,
        });
        match self.shake_away(state).await? {
            Ok(()) => {
                self.step.missed_at.clear();
                Ok(State::Capture)
            }
            Err(e) => {
                self.shake_pending = None;
                Ok(self.finish_step(StepOutcome::Aborted, Some(e), vec![], None))
            }
        }
    }

    /// Starts the pending shake ([`Self::shake_pending`]) now if the arm and any held part are
    /// away from the feeder; otherwise raises the TCP straight up until they are (then, if
    /// still not, goes home), the shake starting at the first instant of that motion at which
    /// they are clear. `Err` with why when the arm could not be brought clear or the feeder
    /// failed.
    async fn shake_away(&mut self, state: State) -> Result<Result<(), String>, Stop> {
        let Some(mut pending) = self.shake_pending else {
            return Ok(Ok(()));
        };
        let k = self.ctx.knowledge;
        let held = self.held_radius();
        let q = self.joints(state).await?;
        let Some(near) = arm_near_feeder(k, &q, held) else {
            let now = self.clock();
            return Ok(self.start_shake(now, q, "rest", 0.0, false));
        };
        if pending.near.is_none() {
            pending.near = Some(near);
            self.shake_pending = Some(pending);
        }
        // Straight up until the gripper (or the held part) clears the height at which a shake
        // could reach it.
        let robot = self.cell.robot();
        let tcp = robot.tcp_pose().await.map_err(|e| Stop::Robot(state, e))?;
        let speeds = Speeds::within(robot.limits(), 0.01);
        let base_T_table = k.geometry.base_T_table;
        let table_T_tcp = base_T_table.inverse() * tcp;
        let clear = AWAY_HEIGHT + GRIPPER_RADIUS.max(held.unwrap_or(0.0)) + CLEAR_MARGIN;
        let rise = (clear - table_T_tcp.translation.z).max(0.0);
        let up = base_T_table * Translation3::new(0.0, 0.0, rise) * table_T_tcp;
        let moves = [
            ("clear the feeder", Motion::MoveL(up, speeds.fast)),
            ("home", Motion::MoveJ(self.home, speeds.joint)),
        ];
        self.shake_result = None;
        for m in moves {
            self.execute(state, std::slice::from_ref(&m)).await?;
            if let Some(r) = self.shake_result.take() {
                return Ok(r);
            }
        }
        let what = self.shake_pending.and_then(|p| p.near).unwrap_or("arm");
        Ok(Err(format!(
            "no shake: the {what} stays near the feeder even at home"
        )))
    }

    /// After an arm motion that started at `t0` on the cell's clock (named `motion`): starts
    /// the pending shake at the first instant of it at which the arm and any held part are
    /// away from the feeder ([`arm_near_feeder`]). Where the cell can replay the motion
    /// ([`CellIo::last_motion_trace`], the simulation), its trajectory is searched every
    /// [`SHAKE_TRACE_STEP`] and the shake dated at that instant, mid-motion; otherwise the
    /// arm's reported joints at the motion's end decide, and the shake starts then.
    async fn shake_when_clear(&mut self, state: State, motion: &str, t0: f64) -> Result<(), Stop> {
        if self.shake_pending.is_none() {
            return Ok(());
        }
        let k = self.ctx.knowledge;
        let held = self.held_radius();
        let trace = self
            .io()
            .last_motion_trace(SHAKE_TRACE_STEP)
            .filter(|t| t.first().is_some_and(|(t, _)| *t >= t0 - 1e-9));
        let clear = match trace {
            Some(trace) => trace
                .into_iter()
                .find(|(_, q)| arm_near_feeder(k, q, held).is_none())
                .map(|(t, q)| (t, q, true)),
            None => {
                let q = self.joints(state).await?;
                let now = self.clock();
                arm_near_feeder(k, &q, held)
                    .is_none()
                    .then_some((now, q, false))
            }
        };
        if let Some((t, q, mid)) = clear {
            let r = self.start_shake(t, q, motion, t - t0, mid);
            if let Err(e) = &r {
                tracing::warn!(episode = self.ctx.episode, "shake failed: {e}");
            }
            self.shake_result = Some(r);
        }
        Ok(())
    }

    /// Starts the pending shake at `at` on the cell's clock with the arm at `q` (`mid`: dated
    /// during the last motion, [`CellIo::shake_feeder_at`]), counts it against its step and
    /// records it in the events.
    fn start_shake(
        &mut self,
        at: f64,
        q: Joints,
        motion: &str,
        into: f64,
        mid: bool,
    ) -> Result<(), String> {
        let Some(p) = self.shake_pending.take() else {
            return Ok(());
        };
        let r = if mid {
            self.io().shake_feeder_at(at)
        } else {
            self.io().shake_feeder()
        };
        if let Err(e) = r {
            return Err(e.to_string());
        }
        if p.for_step == self.index {
            self.step.shakes += 1;
        } else {
            self.shakes_ahead += 1;
        }
        // The parts move: a frame taken ahead for that step no longer shows them.
        if self.ahead.as_ref().is_some_and(|a| a.step == p.for_step) {
            self.ahead = None;
        }
        let shake = ShakeStart {
            for_step: p.for_step,
            t_s: at,
            joints: q,
            held_radius_m: self.held_radius(),
            motion: motion.to_string(),
            into_motion_s: into,
            held_back_s: at - p.since,
            waited_for: p.near.map(str::to_string),
        };
        self.log.shake_started(shake);
        Ok(())
    }

    /// Plan the pick of the chosen instance; an unplannable instance is excluded.
    async fn plan_pick(&mut self, state: State) -> Result<State, Stop> {
        let Some(sel) = self.step.selection.clone() else {
            return Ok(State::Select);
        };
        if let Some((lift, _)) = self.deferred_lift.take() {
            // A step given up after its last grasp failed left the lift undone.
            self.execute(state, &[lift]).await?;
        }
        let start = self.joints(state).await?;
        let placed = self.placed_shapes();
        let k: &'a CellKnowledge = self.ctx.knowledge;
        let feeder: Vec<(&'a PartGeometry, Isometry3<f64>)> = self
            .step
            .detections
            .iter()
            .filter_map(|d| Some((k.part(&d.part)?, d.base_T_part)))
            .collect();
        match self.planner().pick(&sel, &start, &placed, &feeder) {
            Ok(plan) => {
                self.plan_note = plan
                    .raised
                    .as_ref()
                    .map_or_else(String::new, |r| format!("pick plan {r}"));
                self.step.plan = Some(plan);
                Ok(State::Pick)
            }
            Err(e) => {
                self.last_reason = format!("pick plan: {e}");
                self.step.excluded.insert(sel.detection.index);
                Ok(State::Select)
            }
        }
    }

    /// Approach, grasp, lift.
    async fn pick(&mut self, state: State) -> Result<State, Stop> {
        let Some(plan) = self.step.plan.take() else {
            return Ok(State::PlanPick);
        };
        self.step.attempts += 1;
        // A new part in the fingers: nothing learnt from an earlier one applies.
        self.step.correction = Isometry3::identity();
        self.step.slip = 0.0;
        let mut motions = plan.motions;
        self.deferred_lift = None;
        if self.ctx.settings.planning.blend_radius > 0.0
            && matches!(motions.last(), Some(("lift", Motion::MoveL(..))))
        {
            // Blending: the lift starts the insertion's path (the grasp is judged before it).
            self.deferred_lift = motions.pop().map(|lift| (lift, plan.end_joints));
        }
        self.execute(state, &motions).await?;
        Ok(State::VerifyGrasp)
    }

    /// Check that a part is between the fingers; retract and retry, or give the step up.
    fn verify_grasp(&mut self) -> State {
        if self.io().part_in_gripper().unwrap_or(true) {
            State::PlanInsert
        } else if self.step.attempts < self.ctx.settings.max_grasp_attempts {
            self.last_reason = "grasp failed: nothing between the fingers".into();
            if let Some(sel) = &self.step.selection {
                let at = sel.detection.base_T_part.translation.vector;
                self.step.missed_at.push(at);
            }
            State::Retract
        } else {
            let cause = format!("grasp failed {} times", self.step.attempts);
            self.finish_step(
                StepOutcome::Aborted,
                Some(cause),
                vec![GRASP_MISSED.into()],
                None,
            )
        }
    }

    /// Open the gripper and back away upwards, then look again.
    async fn retract(&mut self, state: State) -> Result<State, Stop> {
        self.deferred_lift = None;
        let clearance = self.ctx.settings.planning.clearance_height;
        let opening = self.step.selection.as_ref().map(|s| s.opening);
        let robot = self.cell.robot();
        let r = async {
            match opening {
                Some(w) => robot.open_gripper_to(w).await?,
                None => robot.open_gripper().await?,
            }
            let tcp = robot.tcp_pose().await?;
            let up = Translation3::new(0.0, 0.0, clearance) * tcp;
            let speeds = Speeds::within(robot.limits(), 0.01);
            robot.move_l(up, speeds.fast).await
        }
        .await;
        r.map_err(|e| Stop::Robot(state, e))?;
        Ok(State::Capture)
    }

    /// Plan the insertion of the held part (with the slip and search correction learnt so
    /// far); an unplannable insertion puts the part back and gives the step up.
    async fn plan_insert(&mut self, state: State) -> Result<State, Stop> {
        let Some(sel) = self.step.selection.clone() else {
            return Ok(State::Done);
        };
        let k: &'a CellKnowledge = self.ctx.knowledge;
        let Some(g) = k.part(&sel.detection.part) else {
            return Ok(State::Done);
        };
        // The part slipped up the fingers (TCP −z) by what earlier attempts measured.
        let tcp_T_part =
            Translation3::new(0.0, 0.0, -self.step.slip) * grasped_offset(&sel.tcp_T_part);
        let correction = self.step.correction;
        // With blending, the lift held back from the pick leads the insertion's path from here.
        let now = self.joints(state).await?;
        let (start, lead) = match self.deferred_lift {
            Some((lift, lifted)) => (lifted, Some((now, lift))),
            None => (now, None),
        };
        let placed = self.placed_shapes();
        match self.planner().insert_after(
            self.index,
            ((g, &tcp_T_part), sel.opening),
            &correction,
            &start,
            &placed,
            lead.as_ref().map(|(q, m)| (q, m)),
        ) {
            Ok(plan) => {
                self.plan_note = plan
                    .raised
                    .as_ref()
                    .map_or_else(String::new, |r| format!("insertion plan {r}"));
                self.step.plan = Some(plan);
                if self.step.insertions == 0 {
                    self.shake_ahead(&sel, &start);
                }
                Ok(State::Insert)
            }
            Err(e) => {
                self.deferred_lift = None;
                let cause = format!("insertion plan: {e}");
                // Put the part down where it came from rather than carry it around (let go
                // 1 mm above the grasp: the grasp may have shifted it down).
                let robot = self.cell.robot();
                let back = async {
                    let slow = Speeds::within(robot.limits(), 0.01).slow;
                    robot
                        .move_l(Translation3::new(0.0, 0.0, 0.001) * sel.base_T_grasp, slow)
                        .await?;
                    robot.open_gripper_to(sel.opening).await
                }
                .await;
                back.map_err(|e| Stop::Robot(state, e))?;
                Ok(self.finish_step(StepOutcome::Aborted, Some(cause), vec![], None))
            }
        }
    }

    /// Transfer, pre-insert and insert; the fingers stay closed until the insertion is judged.
    async fn insert(&mut self, state: State) -> Result<State, Stop> {
        let Some(mut plan) = self.step.plan.take() else {
            return Ok(State::PlanInsert);
        };
        if let Some((lift, _)) = self.deferred_lift.take() {
            plan.motions.insert(0, lift);
        }
        let split = plan
            .motions
            .iter()
            .position(|(_, m)| matches!(m, Motion::Open(_)))
            .unwrap_or(plan.motions.len());
        self.step.insertions += 1;
        self.step.pending = plan.motions[split..].to_vec();
        let Some(spec) = self.ctx.force else {
            // Over the fixture before the slow insert: the next step's capture, overlapped.
            let insert = plan.motions[..split]
                .iter()
                .rposition(|(n, _)| *n == "insert")
                .unwrap_or(split);
            self.execute(state, &plan.motions[..insert]).await?;
            self.capture_ahead(state).await?;
            self.execute(state, &plan.motions[insert..split]).await?;
            return Ok(State::Verify);
        };
        // Force-guided: the planner's moves to the lead-in, then the guarded descent in place
        // of its position-controlled insert.
        let (approach, seated) = match plan.motions[..split].split_last() {
            Some((("insert", Motion::MoveL(pose, _)), before)) => (before, *pose),
            _ => {
                self.execute(state, &plan.motions[..split]).await?;
                return Ok(State::Verify);
            }
        };
        self.execute(state, approach).await?;
        self.capture_ahead(state).await?;
        let k = self.ctx.knowledge;
        let s = &k.steps[self.index];
        let capture = s.clearance / 2.0 + s.lead_in;
        let held = self.step.selection.as_ref();
        let rims = match held.and_then(|sel| k.part(&sel.detection.part)) {
            Some(g) => self.ctx.rims.landings(
                g,
                &k.base_T_targets[self.index],
                &k.base_T_insertions[self.index],
                &self.destination_first(),
                (capture, s.lead_in),
                spec.seat_band,
            ),
            None => insertion::RimLandings::at_engagement(
                plan.engagement,
                insertion::rim_tolerance(s.lead_in),
            ),
        };
        let geometry = insertion::InsertionGeometry {
            seated,
            base_T_ins: k.base_T_insertions[self.index],
            engagement: plan.engagement,
            capture,
            lead_in: s.lead_in,
            slow: self.planner().speeds.slow,
            rims,
        };
        let r = match insertion::planned_descent(self.cell.robot(), &geometry, spec).await {
            Ok(first) => {
                if self.step.insertions == 1 {
                    // The lateral error no search or retry has offset yet, as the simulated
                    // cell knows it (production: nothing), for the budget of a step given up.
                    self.step.planned_truth = self.io().seating_check();
                }
                insertion::search_and_confirm(self.cell.robot(), &geometry, spec, first).await
            }
            Err(e) => Err(e),
        };
        let clock = self.clock();
        self.log.motion_done("insert", clock);
        self.step.force = Some(r.map_err(|e| Stop::Robot(state, e))?);
        Ok(State::Verify)
    }

    /// Judge the insertion with the part still held when the cell can (retrying a jam or miss
    /// within the bound); otherwise release, retreat and record what the cell says.
    async fn verify(&mut self, state: State) -> Result<State, Stop> {
        if let Some(v) = self.step.force.take() {
            return self.verify_force(state, v).await;
        }
        if let Some(c) = self.io().seating_check()
            && c.outcome != StepOutcome::Seated
            && self.step.insertions < self.ctx.max_insertion_attempts
        {
            return self.retry_insertion(state, c).await;
        }
        self.capture_ahead_again(state).await?;
        let pending = std::mem::take(&mut self.step.pending);
        self.execute(state, &pending).await?;
        let Some(c) = self.io().insertion_check() else {
            return Ok(self.finish_step(
                StepOutcome::Missed,
                Some("the cell reported no insertion".into()),
                vec![],
                None,
            ));
        };
        if c.outcome == StepOutcome::Seated {
            if let Some((outcome, why)) = self.check_seat(state).await? {
                let sources = vec![SEAT_CHECK_FAILED.into()];
                return Ok(self.finish_step(outcome, Some(why), sources, c.pose_error));
            }
            let target = self.ctx.knowledge.base_T_targets[self.index];
            self.placed.push((self.step_part(), target));
        }
        let cause = c.cause.map(|t| match self.step.insertions {
            0 | 1 => t,
            n => format!("{t} (after {n} insertion attempts)"),
        });
        Ok(self.finish_step(c.outcome, cause, c.sources, c.pose_error))
    }

    /// Judge a force-guided insertion by the cell's own verdict: a confirmed seat is released
    /// and recorded as the cell then says (the simulated cell's truth; production has only the
    /// force verdict); an unseated part is retried within the bound, and after the last attempt
    /// lifted clear in the fingers, never released, and the step fails with the cause.
    async fn verify_force(
        &mut self,
        state: State,
        v: insertion::ForceVerdict,
    ) -> Result<State, Stop> {
        self.step.force_record = Some(v.record());
        if v.outcome == StepOutcome::Seated {
            self.capture_ahead_again(state).await?;
            let pending = std::mem::take(&mut self.step.pending);
            self.execute(state, &pending).await?;
            let c = self.io().insertion_check().unwrap_or(InsertionCheck {
                outcome: StepOutcome::Seated,
                cause: None,
                sources: vec![],
                pose_error: None,
                stop_height: None,
            });
            if c.outcome == StepOutcome::Seated {
                if let Some((outcome, why)) = self.check_seat(state).await? {
                    let sources = vec![SEAT_CHECK_FAILED.into()];
                    let why = format!(
                        "{why} (released on a force-confirmed seat: {}; after {} insertion \
                         attempts)",
                        v.cause, self.step.insertions
                    );
                    return Ok(self.finish_step(outcome, Some(why), sources, c.pose_error));
                }
                let target = self.ctx.knowledge.base_T_targets[self.index];
                self.placed.push((self.step_part(), target));
            }
            let cause = c.cause.map(|t| {
                format!(
                    "{t} (released on a force-confirmed seat: {}; after {} insertion attempts)",
                    v.cause, self.step.insertions
                )
            });
            return Ok(self.finish_step(c.outcome, cause, c.sources, c.pose_error));
        }
        // What the simulated cell knows of the held part (nothing in production), for the
        // record's error budget.
        let truth = self.io().seating_check();
        let check = InsertionCheck {
            outcome: v.outcome,
            cause: Some(v.cause.clone()),
            sources: truth
                .as_ref()
                .map(|t| t.sources.clone())
                .unwrap_or_default(),
            pose_error: truth.as_ref().and_then(|t| t.pose_error),
            stop_height: None,
        };
        if self.step.insertions < self.ctx.max_insertion_attempts {
            return self.retry_insertion(state, check).await;
        }
        self.lift_clear(state).await?;
        let cause = format!(
            "{} after {} insertion attempts; not released: the part stays in the fingers",
            v.cause, self.step.insertions
        );
        // Blamed as a plain cell's missed insertion is, on the sources of the lateral error
        // the search could not recover: the planned descent's, before the spiral's and the
        // retries' offsets (the last probe's error is mostly those offsets).
        let (sources, pose_error) = match self.step.planned_truth.take() {
            Some(t) if !t.sources.is_empty() => (t.sources, t.pose_error),
            _ => (check.sources, check.pose_error),
        };
        Ok(self.finish_step(v.outcome, Some(cause), sources, pose_error))
    }

    /// With `[seat_check]` on, after a seat's release and retreat: a capture of the fixture
    /// with the arm out of the camera's view of it, and the placed part measured on it
    /// ([`seat_check::measure_seat`]). The retreat ends above the fixture, between it and the
    /// camera, so the arm first moves aside out of the camera's views of the fixture and the
    /// feeder ([`seat_check::pose_out_of_view`]; home when no pose is); a capture with the arm
    /// or a held part still in view is refused, never used. `None` when
    /// the seat passed (or no check is configured); otherwise the step's outcome and why.
    async fn check_seat(&mut self, state: State) -> Result<Option<(StepOutcome, String)>, Stop> {
        let Some(spec) = self.ctx.seat_check else {
            return Ok(None);
        };
        let k = self.ctx.knowledge;
        let tol = SeatTolerance::of(spec, k, self.index);
        // A part its receiver hides by construction (no outline of its own at its target) is
        // recorded not visible and keeps its seated verdict: no capture could show it, so none
        // is taken and the arm does not move for one.
        if let Some(n) = seat_check::hidden_by_construction(k, self.ctx.catalog, self.index) {
            let m = Err(n);
            self.step.seat_check = Some(seat_check::record(&m, &tol, None));
            if let (_, Some(why)) = seat_check::judge(&m, &tol) {
                let note = format!("seat check: {why}");
                self.ahead_note = [std::mem::take(&mut self.ahead_note), note]
                    .into_iter()
                    .filter(|t| !t.is_empty())
                    .collect::<Vec<_>>()
                    .join("; ");
            }
            return Ok(None);
        }
        let mut q = self.joints(state).await?;
        if arm_in_fixture_view(k, &q, None).is_some() {
            // Sideways at the retreat's height to the nearest pose out of the views of the
            // fixture and the feeder, a joint move as the planner's transits; home when none is.
            let joint = self.planner().speeds.joint;
            let tcp = (self.cell.robot().tcp_pose().await).map_err(|e| Stop::Robot(state, e))?;
            let to = seat_check::pose_out_of_view(k, &tcp, &q).map_or(self.home, |(_, q)| q);
            let r = self.cell.robot().move_j(to, joint).await;
            let clock = self.clock();
            self.log.motion_done("retreat", clock);
            r.map_err(|e| Stop::Robot(state, e))?;
            q = self.joints(state).await?;
        }
        let refused = crate::episode::SeatCheckRecord {
            verdict: crate::episode::SeatCheckVerdict::Refused,
            offset_mm: None,
            yaw_mrad: None,
            support: None,
            samples: 0,
            tolerance: [tol.lateral * 1e3, tol.yaw * 1e3],
            true_offset_mm: None,
        };
        if let Some(what) = arm_in_fixture_view(k, &q, None) {
            let why =
                format!("seat check refused: the {what} is in the camera's view of the fixture");
            self.step.seat_check = Some(refused);
            return Ok(Some((StepOutcome::Aborted, why)));
        }
        let started = std::time::Instant::now();
        let frame = match self.io().capture_fixture() {
            Ok(f) => f,
            Err(e) => {
                let why = format!("seat check refused: the fixture capture failed: {e}");
                self.step.seat_check = Some(refused);
                return Ok(Some((StepOutcome::Aborted, why)));
            }
        };
        let m = seat_check::measure_seat(k, self.ctx.catalog, self.index, &frame);
        let ms = started.elapsed().as_secs_f64() * 1e3;
        let index = self.index;
        let truth = (self.io().placed_truth(index)).map(|p| seat_check::true_offset(k, index, &p));
        let rec = seat_check::record(&m, &tol, truth);
        self.step.seat_check = Some(rec);
        let (_, why) = seat_check::judge(&m, &tol);
        let note = match (&m, &why) {
            (Ok(m), None) => format!(
                "seat check passed: {:.3} mm, {:+.1} mrad, {:.0} % of {} own outline samples \
                 (capture and alignment in {ms:.1} ms)",
                m.offset.norm() * 1e3,
                m.yaw * 1e3,
                100.0 * m.support,
                m.samples
            ),
            (_, Some(w)) => format!("seat check: {w} (capture and alignment in {ms:.1} ms)"),
            (Err(_), None) => String::new(),
        };
        self.ahead_note = [std::mem::take(&mut self.ahead_note), note]
            .into_iter()
            .filter(|t| !t.is_empty())
            .collect::<Vec<_>>()
            .join("; ");
        // Seen by the true camera as the calibrated one does (checked above), but should the
        // frame's camera differ: still no capture could show it.
        if m.as_ref().is_err_and(|n| n.by_geometry) {
            return Ok(None);
        }
        Ok(why.map(|w| (StepOutcome::Missed, w)))
    }

    /// The rest of the insertion plan with the fingers kept closed: the held part lifted clear
    /// of its receiver along the planned retreat.
    async fn lift_clear(&mut self, state: State) -> Result<(), Stop> {
        let lift: Vec<(&'static str, Motion)> = std::mem::take(&mut self.step.pending)
            .into_iter()
            .filter(|(_, m)| !matches!(m, Motion::Open(_)))
            .map(|(_, m)| ("lift clear", m))
            .collect();
        self.execute(state, &lift).await
    }

    /// A jammed or missed insertion with the part still in the fingers: lift it clear along
    /// the insertion axis (the retreat pose, fingers closed), then correct the next attempt:
    /// the measured stop height is how far the part slipped up the fingers, so the held part's
    /// estimate moves up by it (the next insertion goes that much deeper); and a search offset
    /// (lateral for a miss, yaw for a jam, since a real cell measures neither error directly)
    /// is tried, a different one each attempt.
    async fn retry_insertion(
        &mut self,
        state: State,
        check: InsertionCheck,
    ) -> Result<State, Stop> {
        self.lift_clear(state).await?;
        // The part pushed back comes out a little higher in the fingers than it went in.
        let planning = &self.ctx.settings.planning;
        let slip_cap = planning.clearance_height / 2.0;
        self.step.slip = (self.step.slip + check.stop_height.unwrap_or(0.0)).clamp(0.0, slip_cap);
        let k = self.step.insertions as usize; // retries so far, ≥ 1
        let search = planning.search;
        let step = &self.ctx.knowledge.steps[self.index];
        let lateral = step
            .lead_in
            .max(step.clearance / 2.0)
            .max(search.min_lateral);
        let (offset, yaw) = match check.outcome {
            StepOutcome::Missed => {
                const PATTERN: [(f64, f64); 4] = [(1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)];
                let (x, y) = PATTERN[(k - 1) % PATTERN.len()];
                let ring = ((k - 1) / PATTERN.len() + 1) as f64;
                (Vector2::new(x, y) * lateral * ring, 0.0)
            }
            _ => {
                let ring = (k.div_ceil(2)) as f64;
                let sign = if k % 2 == 1 { 1.0 } else { -1.0 };
                (Vector2::zeros(), sign * ring * search.yaw_step)
            }
        };
        self.step.correction = Isometry3::from_parts(
            Translation3::new(offset.x, offset.y, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw),
        );
        let what = match check.outcome {
            StepOutcome::Missed => "missed",
            _ => "jammed",
        };
        self.last_reason = format!(
            "insertion {} {what} ({}); retry {} of {}",
            self.step.insertions,
            check.cause.as_deref().unwrap_or("not seated"),
            self.step.insertions,
            self.ctx.max_insertion_attempts - 1
        );
        Ok(State::PlanInsert)
    }

    /// With this step's part out of the feeder: when the frame that found it shows no usable
    /// instance for the next step, start a shake now, so the feeder settles while the arm
    /// inserts (the next step's capture waits for the parts to rest). Counts against the next
    /// step's shake bound.
    fn shake_ahead(&mut self, picked: &Selection, here: &Joints) {
        let next = self.index + 1;
        if next >= self.steps() || self.shakes_ahead >= self.ctx.max_shakes {
            return;
        }
        let rest: Vec<DetectedPart> = self
            .step
            .detections
            .iter()
            .filter(|d| d.index != picked.detection.index)
            .cloned()
            .collect();
        let c = self.ctx;
        let ahead = select(
            c.knowledge,
            c.catalog,
            next,
            &rest,
            &self.step.unposed,
            here,
            &c.settings.selection,
        );
        if ahead.chosen.is_none() {
            // Held back until the arm and the held part are away from the feeder: it starts at
            // the first instant of a later motion at which they are.
            let since = self.clock();
            let near = arm_near_feeder(self.ctx.knowledge, here, self.held_radius());
            self.shake_pending = Some(PendingShake {
                for_step: next,
                since,
                near,
            });
        }
    }

    /// A robot error or an overrun: stop the arm (bounded), record the step in progress as
    /// aborted, and say why.
    async fn safe_stop(&mut self, stop: Stop) -> String {
        let text = stop.text();
        tracing::warn!(episode = self.ctx.episode, "safe stop: {text}");
        // Errors here change nothing (the arm may be gone).
        let _ = tokio::time::timeout(Duration::from_secs(2), self.cell.robot().stop()).await;
        if self.records.len() <= self.index && self.index < self.steps() {
            let now = self.clock();
            let record = self.step.record(
                self.step_part(),
                StepOutcome::Aborted,
                Some(text.clone()),
                vec![],
                None,
                now,
            );
            self.records.push(record);
        }
        self.abort = Some(text.clone());
        text
    }

    /// Closes the current step with an outcome; returns the next state.
    fn finish_step(
        &mut self,
        outcome: StepOutcome,
        cause: Option<String>,
        sources: Vec<String>,
        pose_error: Option<PoseError>,
    ) -> State {
        let now = self.clock();
        // A failure after picking a misperceived part is that perception failure's.
        let sources = match self.step.perception_verdict.and_then(|v| v.source()) {
            Some(source) if outcome != StepOutcome::Seated => vec![source.into()],
            _ => sources,
        };
        let record = self
            .step
            .record(self.step_part(), outcome, cause, sources, pose_error, now);
        self.records.push(record);
        if outcome == StepOutcome::Seated && self.index + 1 < self.steps() {
            self.index += 1;
            // A shake started for this step while the last one inserted counts against its
            // bound.
            self.step = StepState::new(now, std::mem::take(&mut self.shakes_ahead));
            State::Capture
        } else {
            State::Done
        }
    }

    /// Runs `motions` in order; the first failure stops the episode.
    async fn execute(
        &mut self,
        state: State,
        motions: &[(&'static str, Motion)],
    ) -> Result<(), Stop> {
        let mut next = 0;
        while let Some((name, m)) = motions.get(next) {
            if let Some(n) = self.try_blend(state, &motions[next..]).await? {
                next += n;
                continue;
            }
            next += 1;
            let t0 = self.clock();
            let robot = self.cell.robot();
            let r = match m {
                Motion::MoveJ(q, s) => robot.move_j(*q, *s).await,
                Motion::MoveL(p, s) => robot.move_l(*p, *s).await,
                Motion::Open(width) => robot.open_gripper_to(*width).await,
                Motion::Close => robot.close_gripper().await,
            };
            let clock = self.clock();
            self.log.motion_done(name, clock);
            tracing::debug!(
                episode = self.ctx.episode,
                waypoint = name,
                clock,
                "motion done"
            );
            if let Err(e) = r {
                tracing::warn!(
                    episode = self.ctx.episode,
                    waypoint = name,
                    "motion failed: {e}"
                );
                return Err(Stop::Robot(state, e));
            }
            if matches!(m, Motion::MoveJ(..) | Motion::MoveL(..)) {
                self.shake_when_clear(state, name, t0).await?;
            }
        }
        Ok(())
    }

    /// With blending on (`[motion] blend_radius`), the leading run of fast arm moves of
    /// `motions` (joint moves and straight lines at the fast speed; never the slow segments
    /// into a grasp or an insertion) as one blended path, when there are two or more. The
    /// robot's limit check is the only one ([`robots::limited::Limited`] runs
    /// [`robots::limited::check_path`], sampled every millisecond): a path it refuses with a
    /// [`RobotError::LimitViolation`] never moved the arm and runs stop by stop. `Some(n)` when
    /// it ran the first `n` motions.
    async fn try_blend(
        &mut self,
        state: State,
        motions: &[NamedMotion],
    ) -> Result<Option<usize>, Stop> {
        let radius = self.ctx.settings.planning.blend_radius;
        if radius <= 0.0 {
            return Ok(None);
        }
        let fast = self.planner().speeds.fast.speed;
        let Some(path) = blended::leading_path(motions, radius, fast) else {
            return Ok(None);
        };
        let n = path.len();
        let t0 = self.clock();
        let r = self.cell.robot().move_path(path).await;
        if let Err(RobotError::LimitViolation(e)) = &r {
            tracing::debug!(
                episode = self.ctx.episode,
                waypoint = motions[0].0,
                "blended path refused, moving stop by stop: {e}"
            );
            return Ok(None);
        }
        let clock = self.clock();
        // One span, the transit's: the path is its joint move with the corners rounded.
        let name = motions[..n]
            .iter()
            .find(|(_, m)| matches!(m, Motion::MoveJ(..)))
            .unwrap_or(&motions[0])
            .0;
        self.log.motion_done(name, clock);
        r.map_err(|e| Stop::Robot(state, e))?;
        self.shake_when_clear(state, name, t0).await?;
        Ok(Some(n))
    }

    fn planner(&mut self) -> Planner<'a> {
        let config = self.ctx.settings.planning;
        Planner {
            knowledge: self.ctx.knowledge,
            config,
            speeds: Speeds::within(self.cell.robot().limits(), config.slow_speed),
        }
    }

    /// The fixture and every part seated so far, as planning obstacles.
    fn placed_shapes(&self) -> Vec<(&'a PartGeometry, Isometry3<f64>)> {
        let k: &'a CellKnowledge = self.ctx.knowledge;
        let fixture = k
            .part(&k.geometry.fixture_part)
            .map(|f| (f, k.geometry.base_T_fixture));
        let placed = self
            .placed
            .iter()
            .filter_map(|(name, pose)| Some((k.part(name)?, *pose)));
        fixture.into_iter().chain(placed).collect()
    }

    /// The parts in place ([`Self::placed_shapes`]) with what this step's part goes into first.
    fn destination_first(&self) -> Vec<(&'a PartGeometry, Isometry3<f64>)> {
        let mut placed = self.placed_shapes();
        let step = &self.ctx.knowledge.steps[self.index];
        if let Some(name) = sim::cell::geometry::destination_part(step)
            && let Some(i) = placed.iter().rposition(|(g, _)| g.name == name)
        {
            let d = placed.remove(i);
            placed.insert(0, d);
        }
        placed
    }

    async fn joints(&mut self, state: State) -> Result<Joints, Stop> {
        self.cell
            .robot()
            .joints()
            .await
            .map_err(|e| Stop::Robot(state, e))
    }

    fn io(&mut self) -> &mut dyn CellIo {
        self.cell.io()
    }

    fn clock(&mut self) -> f64 {
        self.cell.io().clock()
    }

    fn steps(&self) -> usize {
        self.ctx.knowledge.steps.len()
    }

    fn step_part(&self) -> String {
        self.ctx
            .knowledge
            .steps
            .get(self.index)
            .map(|s| s.part.clone())
            .unwrap_or_default()
    }
}
